"""A campaign in the report: its chain, each stage's selected value beside the documented one,
and the settings it ends with; ``<campaign>/campaign.csv`` and a section of the index.

The selected values are the stage sweeps' own ``selected`` rows, so the campaign table and each
stage's summary always agree.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from kraby_study.answers.sweep_evidence import Sweep
from kraby_study.decision.comparison import ALPHA, answers_name
from kraby_study.decision.race import Drop
from kraby_study.decision.selection import RULE_TEXT
from kraby_study.decision.summary import note_part
from kraby_study.records.stored import Outcome
from kraby_study.records.values import value_key, value_label
from kraby_study.report.document import Block, Heading, Links, Table, Text, write_csvs

COLUMNS = ["stage", "study", "parameter", "rule", "selected", "documented", "agree", "status",
           "notes"]


def campaigns(sweeps: dict[str, Sweep]) -> dict[str, dict[str, Any]]:
    """Campaign name -> the record of its latest stored stage (which lists every stage)."""
    found: dict[str, dict[str, Any]] = {}
    for sweep in sweeps.values():
        record = sweep.data.ledger.attrs.campaign
        if not record:
            continue
        name = str(record["name"])
        if int(record.get("stage", 0)) >= int(found.get(name, {}).get("stage", 0)):
            found[name] = record
    return dict(sorted(found.items()))


def _selected(sweep: Sweep | None) -> int | None:
    if sweep is None or "selected" not in sweep.summary:
        return None
    rows = sweep.summary.index[sweep.summary["selected"].astype(bool)]
    return int(rows[0]) if len(rows) else None


def _settings(sweep: Sweep, vi: int) -> dict[str, Any]:
    """The settings the selected value's runs trained with."""
    numbers = set(sweep.trials.loc[(sweep.trials["vi"] == vi)
                                   & (sweep.trials["outcome"] == Outcome.COMPLETE), "number"])
    for trial in sweep.data.trials:
        if trial.number in numbers and trial.user_attrs.get("settings"):
            return dict(trial.user_attrs["settings"])
    return {}


def stage_notes(sweep: Sweep | None) -> str:
    """How a stage's selection was decided: the procedure behind its best and ties, whether
    the stage raced (it then selects among the race's survivors) and the values it left out
    for too few seeds."""
    if sweep is None:
        return ""
    compared = sweep.comparison
    margin = compared.margin_text() if compared is not None else "margin 0"
    alpha = compared.alpha if compared is not None else ALPHA
    text = (f"best and answers ({answers_name(alpha)}): {margin}; only values with at least "
            f"{sweep.min_seeds} complete seeds can be selected")
    race = sweep.race
    if race is not None:
        def when(left: dict[int, Drop]) -> str:
            return ", ".join(f"{sweep.labels[vi]} after round {drop.round}"
                             for vi, drop in sorted(left.items(),
                                                    key=lambda item: (item[1].round, item[0])))

        among = ("the values it did not drop" if race.rules.margin > 0 else "the survivors")
        settled = (f"; settled equivalent: {when(race.settled)}" if race.settled else "")
        text += (f"; raced ({race.rules.describe()}), selected among {among}; dropped: "
                 f"{when(sweep.dropped) or 'none'}{settled}; {race.saved_text()}")
    left = ([(r["value"], r["complete"]) for _, r in sweep.summary.iterrows()
             if note_part(r["note"], "left out: ")] if "note" in sweep.summary else [])
    if left:
        text += "; left out: " + ", ".join(
            f"{value} ({n} seed{'s' if n != 1 else ''})" for value, n in left)
    return text


def campaign_table(record: dict[str, Any], sweeps: dict[str, Sweep]) -> pd.DataFrame:
    """One row per stage (columns ``COLUMNS``); ``selected`` is empty until a stage is
    finished, ``agree`` empty where there is no documented value to compare."""
    rows = []
    for number, stage in enumerate(record["stages"], start=1):
        sweep = sweeps.get(str(stage["name"]))
        vi = _selected(sweep)
        documented = stage.get("documented")
        selected = sweep.values[vi] if sweep is not None and vi is not None else None
        agree: Any = ""
        if vi is not None and documented is not None:
            agree = value_key(selected) == value_key(documented)
        rows.append({"stage": number, "study": stage["name"], "parameter": stage["parameter"],
                     "rule": stage["select"],
                     "selected": value_label(selected) if vi is not None else "",
                     "documented": value_label(documented) if documented is not None else "",
                     "agree": agree,
                     "status": sweep.status() if sweep is not None else "not run yet",
                     "notes": stage_notes(sweep)})
    return pd.DataFrame(rows, columns=COLUMNS)


def end_settings(record: dict[str, Any],
                 sweeps: dict[str, Sweep]) -> tuple[int, dict[str, Any]]:
    """The last finished stage's number and the settings its selected value trained with
    (0 and {} when no stage is finished)."""
    last, settings = 0, {}
    for number, stage in enumerate(record["stages"], start=1):
        sweep = sweeps.get(str(stage["name"]))
        vi = _selected(sweep)
        if sweep is None or vi is None:
            break
        last, settings = number, _settings(sweep, vi)
    return last, settings


def settings_table(record: dict[str, Any], settings: dict[str, Any]) -> Table:
    """Each setting the campaign starts from or selects: its start value, its end value and
    the stage that set it."""
    chosen_by = {str(s["parameter"]): str(s["name"]) for s in record["stages"]}
    keys = list(record.get("start", {})) + [k for k in chosen_by
                                            if k not in record.get("start", {})]
    rows = []
    for key in keys:
        root, leaf = key.split(".", 1)
        end = settings.get(root, {}).get(leaf, "-") if settings else "-"
        start = record.get("start", {}).get(key, "(study file)")
        rows.append([key, value_label(start), value_label(end), chosen_by.get(key, "start")])
    return Table(["setting", "start", "end", "set by"], rows)


def _budget(record: dict[str, Any], sweeps: dict[str, Sweep]) -> str:
    for stage in record["stages"]:
        sweep = sweeps.get(str(stage["name"]))
        if sweep is not None and len(sweep.trials):
            steps = sweep.data.definition.get("steps")
            seeds = int(sweep.trials["seed"].nunique())
            return f"{seeds} seeds x {steps:,} env steps per value" if steps else ""
    return ""


def write_campaign(name: str, record: dict[str, Any], sweeps: dict[str, Sweep], folder: Path,
                   rel: str) -> tuple[list[Block], list[Path]]:
    """The campaign's index section and ``folder/campaign.csv``."""
    folder.mkdir(parents=True, exist_ok=True)
    table = campaign_table(record, sweeps)
    files = write_csvs(folder, [("campaign.csv", table)])
    last, settings = end_settings(record, sweeps)
    total = len(record["stages"])
    chain = " -> ".join(str(s["study"]) for s in record["stages"])
    budget = _budget(record, sweeps)
    rules = "; ".join(f"{rule}: {RULE_TEXT[rule]}" for rule in dict.fromkeys(table["rule"])
                      if rule in RULE_TEXT)
    blocks: list[Block] = [Heading(f"Campaign {name}", 2)]
    if last:
        blocks += [Text(f"Settings the campaign ends with (after stage {last}/{total}"
                        + ("" if last == total else ", not yet finished") + "):"),
                   settings_table(record, settings)]
    else:
        blocks.append(Text("No stage is finished yet."))
    blocks += [
        Table(["stage", "study", "parameter", "rule", "selected", "documented", "agree",
               "status"],
              [[str(r.stage), r.study, r.parameter, r.rule, r.selected or "-",
                r.documented or "-", {True: "yes", False: "no"}.get(r.agree, "-"), r.status]
               for r in table.itertuples(index=False)]),
        Text((str(record.get("description") or "") + " ").lstrip()
             + f"Stages in order: {chain}. Each stage runs with the values the earlier stages "
             f"selected; stage STUDY is stored as {name}-STUDY."
             + (f" Budget: {budget}." if budget else "")
             + f" Selection rules: {rules}. Each stage's answers are in its own section; "
             "campaign.csv's notes say how each stage decided."),
    ]
    blocks.append(Links("Tables", [(p.name, f"{rel}/{p.name}") for p in files]))
    return blocks, files
