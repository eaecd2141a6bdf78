"""A search's files (figures, CSV and Markdown tables) and its section of the index."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from kraby_study.answers.search_evidence import (
    Search,
    configuration_frame,
    front_frame,
    front_trials,
    top_trials,
)
from kraby_study.records.attributes import StudyKind
from kraby_study.records.stored import Outcome, known_number
from kraby_study.records.values import score
from kraby_study.report import search_plots
from kraby_study.report.document import Block, Heading, Image, Items, Links, Table, Text, write_csvs
from kraby_study.report.document import to_markdown as blocks_to_markdown
from kraby_study.report.search_format import format_param
from kraby_study.report.study_report import StudyReport
from kraby_study.report.style import number, styled

TITLES = {"history": "optimization history", "importances": "parameter importances",
          "slices": "slice plots", "intermediate": "intermediate values",
          "parallel": "parallel coordinates", "pareto": "score against cost, the front"}
CAPTIONS = {
    "pareto": "Every complete trial's mean final score over its seeds against its mean cost "
              "(CPU seconds per seed). The front (no other trial scores at least as high for "
              "at most its cost) is joined as a staircase and labelled by trial number; "
              "diamonds mark the enqueued configurations, the star the selected trial (the "
              "cheapest of the front's best score and the trials shown equivalent to it). A "
              "dashed line, when the search has a floor, is the floor configuration's score: "
              "trials below it are infeasible and off the front.",
    "history": "Objective of every complete trial on the seeds it was first trained on, by "
               "trial number, and the best value so far; a rechecked trial also as a ring at "
               "its objective over all its seeds, joined by a thin line; pruned and failed "
               "trials marked along the bottom.",
    "importances": "PED-ANOVA parameter importances (Optuna's default evaluator): how much "
                   "each parameter matters for reaching the top 10 % of complete trials.",
    "slices": "Objective against each parameter, one point per complete trial, coloured by "
              "trial number.",
    "intermediate": "Values reported at checkpoints; pruned trials stop where the pruner "
                    "stopped them (x); a rechecked trial's line is its first seeds' (its "
                    "recheck reports none).",
    "parallel": "Every complete trial as a line through its parameters and its objective.",
}
SEED_SCORES_CAPTION = ("Each seed's final score, at the env steps where that seed ends (the "
                       "wilcoxon pruner compares them with the best trial's same seeds); "
                       "pruned trials stop after the seed where the pruner stopped them (x).")


def caption(search: Search, stem: str) -> str:
    """A figure's caption; the intermediate values of a wilcoxon search are seed scores."""
    if stem == "intermediate" and search_plots.seed_scores(search):
        return SEED_SCORES_CAPTION
    return CAPTIONS[stem]


def _cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return number(float(value))


def top_table(search: Search) -> Table:
    """The top trials as formatted cells, best first."""
    top = top_trials(search)
    header = ["rank", "trial", "objective", "seeds", "CPU s per seed", *search.params,
              "env steps", "time (s)"]
    rows = []
    # Records keep each column's type: iterrows would make every cell a float (256.0) when
    # all parameters are numbers, as on a gym env's space.
    for row in top.to_dict("records"):
        rows.append([str(int(row["rank"])), str(int(row["trial"])), _cell(row["value"]),
                     f"{int(row['seeds'])}" if np.isfinite(row["seeds"]) else "-",
                     _cell(row["training_time"]),
                     *[format_param(row[p], search.distributions.get(p)) for p in search.params],
                     f"{int(row['env_steps']):,}" if np.isfinite(row["env_steps"]) else "-",
                     f"{row['wall_time']:.0f}" if np.isfinite(row["wall_time"]) else "-"])
    marks = ["best"] + [""] * (len(rows) - 1) if rows else []
    return Table(header, rows, marks=marks)


def racing_table(search: Search) -> Table:
    """A racing search's configurations as formatted cells, in the order asked for; the
    incumbent marked best."""
    assert search.racing is not None
    header = ["configuration", "seeds", "IQM", "CPU s per run", "how it left", *search.params]
    rows, marks = [], []
    for config in search.racing.configurations:
        rows.append([config.key + (f" ({config.enqueued})" if config.enqueued else ""),
                     str(config.seeds), _cell(config.iqm), _cell(config.cpu),
                     config.left_text(),
                     *[format_param(config.params.get(p), search.distributions.get(p))
                       for p in search.params]])
        marks.append("best" if config is search.racing.incumbent else "")
    return Table(header, rows, marks=marks)


def racing_verdict(search: Search) -> str:
    """One sentence on a racing search's pick, its incumbent, and how the others left."""
    assert search.racing is not None
    inc = search.racing.incumbent
    if inc is None or not np.isfinite(inc.iqm):
        return "No configuration has a complete seed yet."
    params = ", ".join(f"{p}={format_param(inc.params.get(p), search.distributions.get(p))}"
                       for p in search.params if p in inc.params)
    rules = search.racing.rules
    return (f"Picked: configuration {inc.key}, the incumbent, IQM {number(inc.iqm)} over "
            f"{inc.seeds} seeds ({params}). {search.racing.summary()}. Each challenger was "
            f"compared with the incumbent after each of its seeds from seed {rules.min_seeds} "
            f"on (the answers' step-down on the IQM at compare.margin {rules.margin:g}, alpha "
            f"{rules.alpha:g} spent over {rules.looks} looks, {rules.look_alpha:.3g} each"
            f"{', paired by seed' if rules.paired else ''}); the incumbent's seeds are capped "
            f"at {rules.seeds}.")


def failed_items(search: Search) -> list[str]:
    """One line per failed trial: number (and attempt, when a retry or recheck failed),
    parameters, reason."""
    failed = search.trials[search.trials["outcome"] == Outcome.FAILED]
    items = []
    for _, row in failed.iterrows():
        params = ", ".join(f"{p}={format_param(row[p], search.distributions.get(p))}"
                           for p in search.params)
        name = (f"trial {row['trial']}" if row["trial"] == row["number"]
                else f"trial {row['trial']}, attempt {row['number']}")
        items.append(f"{name} ({params}): {row['failure'] or 'failed'}")
    return items


def _tables(search: Search, folder: Path) -> list[Path]:
    frames: list[tuple[str, pd.DataFrame]] = [("trials.csv", search.trials),
                                              ("top_trials.csv", top_trials(search))]
    if search.racing is not None:
        frames.append(("configurations.csv", configuration_frame(search.racing)))
    if not search.data.curves.empty:
        frames.append(("curves.csv", search.data.curves.rename(columns={"number": "trial"})[
            ["trial", "step", "mean_reward", "wall_time", "episodes"]]))
    if search.importances:
        frames.append(("importances.csv", pd.DataFrame(
            sorted(search.importances.items(), key=lambda kv: -kv[1]),
            columns=["parameter", "importance"])))
    return write_csvs(folder, frames)


def verdict(search: Search) -> str:
    """One sentence on the best trial; of a two-objective search, on its front and the trial
    its rule selects; of a racing search, on its incumbent."""
    if search.racing is not None:
        return racing_verdict(search)
    best = search.best
    if best is None:
        return "No trial is complete yet."
    params = ", ".join(f"{p}={format_param(best.params.get(p), search.distributions.get(p))}"
                       for p in search.params if p in best.params)
    text = f"Best: trial {known_number(best)}, objective {number(float(score(best)))} ({params})."
    if search.front is None or search.front.choice is None:
        return text
    choice = search.front.choice
    chosen = choice.chosen
    floor = f" ({search.front.floor_text})" if search.front.floor_text else ""
    return (f"Front: {len(search.front.front)} of {len(search.front.points)} complete trials"
            f"{floor}. "
            f"Best score: trial {choice.best.key}, {number(choice.best.score)} at "
            f"{choice.best.cost:.3g} CPU s per seed. Selected by {choice.rule_text}: trial "
            f"{chosen.key}, score {number(chosen.score)} at {chosen.cost:.3g} CPU s per seed.")


def result_text(search: Search) -> str:
    """The index overview's cell: the best trial, and of a two-objective search the selected
    one."""
    if search.racing is not None:
        inc = search.racing.incumbent
        return ("no complete seed" if inc is None or not np.isfinite(inc.iqm) else
                f"incumbent {inc.key}, IQM {number(inc.iqm)} over {inc.seeds} seeds")
    best = search.best
    if best is None:
        return "no complete trial"
    text = f"best trial {known_number(best)}, objective {number(float(score(best)))}"
    choice = search.front.choice if search.front is not None else None
    return text if choice is None else f"{text}; selected trial {choice.chosen.key}"


def front_cells(search: Search) -> Table:
    """The front as formatted cells, best score first; the selected trial marked best."""
    header = ["trial", "score", "cost (CPU s/seed)", "enqueued", "answer", *search.params]
    rows, marks = [], []
    for trial in front_trials(search):
        test = "best score" if trial.best else (trial.answer or "-")
        rows.append([str(trial.trial) + (" (selected)" if trial.selected else ""),
                     _cell(trial.score), f"{trial.cost:.3g}", str(trial.enqueued or "-"),
                     test,
                     *[format_param(trial.params[p], search.distributions.get(p))
                       for p in search.params]])
        marks.append("best" if trial.selected else "tie" if trial.equivalent or trial.best
                     else "")
    return Table(header, rows, marks=marks)


def _write_front_files(search: Search, folder: Path, section: list[Block]) -> list[Path]:
    """pareto.csv and summary.md of a two-objective search."""
    csv = write_csvs(folder, [("pareto.csv", front_frame(front_trials(search),
                                                         search.params))])
    summary = folder / "summary.md"
    # The verdict (section[1]) names the rule that selected; the description follows it.
    summary.write_text(blocks_to_markdown([
        Heading(f"{search.data.name}: the front", 1), *section[1:3],
        front_cells(search)]), encoding="utf-8")
    return [*csv, summary]


def write_search(search: Search, folder: Path, rel: str, fmt: str) -> StudyReport:
    """Draw a search's figures and write its tables into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    report = StudyReport(name=search.data.name, kind=search.data.kind, folder=folder,
                         status=search.status(), finished=search.finished)
    has_complete = bool(search.complete)
    figures: list[tuple[str, Any]] = []
    if has_complete and search.front is not None:
        figures.append(("pareto", search_plots.pareto))
    if has_complete:
        figures.append(("history", search_plots.history))
        if search.importances:
            figures.append(("importances", search_plots.importances))
        if search.params:
            figures += [("slices", search_plots.slices), ("parallel", search_plots.parallel)]
    else:
        report.notes.append("no complete trial yet: no history, slices or parallel coordinates")
    if any(t.intermediate_values for t in search.data.trials):
        figures.append(("intermediate", search_plots.intermediate))
    if not search.importances:
        report.notes.append(search.importance_note)
    images: list[Block] = []
    with styled():
        for stem, draw in figures:
            path = draw(search, folder / f"{stem}.{fmt}")
            report.files.append(path)
            images.append(Image(f"{rel}/{path.name}", TITLES[stem], caption(search, stem)))
    tables = _tables(search, folder)
    kind = "Optuna search" if search.data.kind == StudyKind.SEARCH else "Optuna study"
    direction = "maximised" if search.maximize else "minimised"
    objectives = (f"objective {direction}" if search.front is None else
                  "two objectives: the score maximised, the cost (CPU s per seed) minimised")
    section: list[Block] = [
        Heading(search.data.name, 2),
        Text(verdict(search)),
        Text(f"{kind} over {len(search.params)} parameter(s), {objectives}. "
             f"Status: {search.status()}.")]
    if search.front is not None and search.front.front:
        section += [Text(f"The front ({len(search.front.front)} trials), best score first:"),
                    front_cells(search)]
    if search.racing is not None:
        section += [Text(f"Configurations ({len(search.racing.configurations)}, in the order "
                         "the sampler asked for them; a trial is one run, a configuration on "
                         "one seed): seeds ended, IQM of the final scores, how each left:"),
                    racing_table(search)]
    else:
        section += [Text(f"Top {len(top_trials(search))} complete trials (of equal objectives, "
                         "the one on more seeds, then the one with fewer CPU s per seed, "
                         "first):"), top_table(search)]
    failed = failed_items(search)
    if failed:
        section += [Text(f"Failed trials ({len(failed)}):"), Items(failed)]
    top_md = folder / "top_trials.md"
    top_md.write_text(blocks_to_markdown([Heading(f"{search.data.name}: top trials", 1),
                                          *section[1:]]), encoding="utf-8")
    report.files += tables + [top_md]
    report.result = result_text(search)
    front_files = (_write_front_files(search, folder, section)
                   if search.front is not None and search.front.front else [])
    report.files += front_files
    report.blocks = section + images + [
        Links("Tables", [(p.name, f"{rel}/{p.name}")
                         for p in [*front_files[::-1], top_md, *tables]])]
    return report


def policy_candidates(search: Search) -> list[tuple[str, dict[str, Any], str]]:
    """Saved models of complete trials, best first: (path, settings, description)."""
    done = sorted(search.complete, key=lambda t: float(score(t)),  # type: ignore[arg-type]
                  reverse=search.maximize)
    out = []
    for trial in done:
        path = trial.user_attrs.get("model_path")
        if isinstance(path, str) and path:
            out.append((path, dict(trial.user_attrs.get("settings") or {}),
                        f"trial {known_number(trial)} (objective {number(float(score(trial)))})"))
    return out
