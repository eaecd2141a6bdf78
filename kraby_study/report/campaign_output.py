"""A campaign in the report: its chain, each stage's selected value beside the documented one,
and the settings it ends with; ``<campaign>/campaign.csv`` and a section of the index.

The selected values are the stage sweeps' own ``selected`` rows, so the campaign table and each
stage's summary agree, except where later stages were built on another value: a selection that
later work ran on is a stored fact (each later stage records the value it took and the rule that
chose it), so the table shows that value and rule, and says what today's rule selects when it
differs ([`ran_on`][kraby_study.report.campaign_output.ran_on]).
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
from kraby_study.records.attributes import SelectRule
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
    if sweep is None:
        return None
    return next((value_index for value_index, row in enumerate(sweep.rows) if row.selected), None)


def _settings(sweep: Sweep, value_index: int) -> dict[str, Any]:
    """The settings the selected value's runs trained with."""
    numbers = set(sweep.trials.loc[(sweep.trials["value_index"] == value_index)
                                   & (sweep.trials["outcome"] == Outcome.COMPLETE), "number"])
    for trial in sweep.data.trials:
        if trial.number in numbers and trial.user_attrs.get("settings"):
            return dict(trial.user_attrs["settings"])
    return {}


def stage_notes(sweep: Sweep | None) -> str:
    """How a stage's selection was decided: the procedure behind its best and answers, whether
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
            return ", ".join(f"{sweep.labels[value_index]} after round {drop.round}"
                             for value_index, drop in sorted(left.items(),
                                                    key=lambda item: (item[1].round, item[0])))

        among = ("the values it did not drop" if race.rules.margin > 0 else "the survivors")
        settled = (f"; settled equivalent: {when(race.settled)}" if race.settled else "")
        text += (f"; raced ({race.rules.describe()}), selected among {among}; dropped: "
                 f"{when(sweep.dropped) or 'none'}{settled}; {race.saved_text()}")
    left = [(r.value, r.complete) for r in sweep.rows if note_part(r.note, "left out: ")]
    if left:
        text += "; left out: " + ", ".join(
            f"{value} ({n} seed{'s' if n != 1 else ''})" for value, n in left)
    return text


def ran_on(record: dict[str, Any], sweeps: dict[str, Sweep], name: str
           ) -> dict[str, Any] | None:
    """The value later stored stages ran on from stage ``name``, as the first of them recorded
    it (``setting``, ``value``, ``study``, ``rule``), when today's answers would not give it:
    it was chosen by another rule than the stage's today, or today's rule selects nothing
    (under the command's seeds); None otherwise (the stage's own selection is what later
    stages took)."""
    sweep = sweeps.get(name)
    for stage in record["stages"]:
        later = sweeps.get(str(stage["name"]))
        for taken in (later.data.ledger.attrs.inputs or []) if later is not None else []:
            if taken.get("study") == name:
                today = sweep is not None and _selected(sweep) is not None
                ruled = sweep is not None and taken.get("rule") == sweep.rule
                return None if today and ruled else taken
    return None


def campaign_table(record: dict[str, Any], sweeps: dict[str, Sweep]) -> pd.DataFrame:
    """One row per stage (columns ``COLUMNS``); ``selected`` is empty until a stage is
    finished, ``agree`` empty where there is no documented value to compare. A stage whose
    later stages ran on a value another rule chose shows that value and rule
    ([`ran_on`][kraby_study.report.campaign_output.ran_on]), and its notes say what today's rule
    selects."""
    rows = []
    for number, stage in enumerate(record["stages"], start=1):
        name = str(stage["name"])
        sweep = sweeps.get(name)
        value_index = _selected(sweep)
        documented = stage.get("documented")
        found = value_index is not None
        selected = (sweep.values[value_index] if sweep is not None and value_index is not None
                    else None)
        rule = str(SelectRule.of(str(stage["select"])))
        notes = stage_notes(sweep)
        taken = ran_on(record, sweeps, name)
        if taken is not None:
            today = (f"today's rule {sweep.rule} selects {value_label(selected)}"
                     if sweep is not None and found else "today's rule selects nothing yet")
            same = found and value_key(selected) == value_key(taken["value"])
            notes = (f"later stages ran on {value_label(taken['value'])}, selected by "
                     f"{taken['rule']}; {today}" + (", the same" if same else "")
                     + (f"; {notes}" if notes else ""))
            selected, rule, found = taken["value"], str(taken["rule"]), True
        agree: Any = ""
        if found and documented is not None:
            agree = value_key(selected) == value_key(documented)
        rows.append({"stage": number, "study": name, "parameter": stage["parameter"],
                     "rule": rule, "selected": value_label(selected) if found else "",
                     "documented": value_label(documented) if documented is not None else "",
                     "agree": agree,
                     "status": sweep.status() if sweep is not None else "not run yet",
                     "notes": notes})
    return pd.DataFrame(rows, columns=COLUMNS)


def end_settings(record: dict[str, Any],
                 sweeps: dict[str, Sweep]) -> tuple[int, dict[str, Any]]:
    """The last finished stage's number and the settings its selected value trained with
    (0 and {} when no stage is finished)."""
    last, settings = 0, {}
    for number, stage in enumerate(record["stages"], start=1):
        sweep = sweeps.get(str(stage["name"]))
        value_index = _selected(sweep)
        taken = ran_on(record, sweeps, str(stage["name"]))
        if sweep is not None and taken is not None:
            keys = [value_key(v) for v in sweep.values]
            key = value_key(taken["value"])
            value_index = (keys.index(key) if key in keys
                  else None)
        if sweep is None or value_index is None:
            break
        last, settings = number, _settings(sweep, value_index)
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
    rules = "; ".join(f"{rule}: {RULE_TEXT[rule]}" if rule in RULE_TEXT else
                      f"{rule}: a retired rule, kept where later stages ran on its choice"
                      for rule in dict.fromkeys(table["rule"]))
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
