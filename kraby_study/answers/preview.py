"""What the store already holds of a planned command, and how long the rest should take
(``--dry-run``); read without Optuna, and nothing is created or written.

The rate is measured on the store itself: env steps over wall time of its complete trials (one
worker each). Trials do not record the machine they ran on, so the rate is this store's, not
necessarily this machine's. A search with a CPU budget is timed by its CPU seconds instead, at
the CPU seconds a worker used per second of wall time in the store's trials: how many env steps
they train depends on the settings the search asks for.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from kraby_study.answers.resumed import resumed_stage
from kraby_study.answers.winners import StoreWinners, Unfinished
from kraby_study.plan.campaign import Campaign, Stage, stage_file
from kraby_study.plan.preview import Count, plan_count, stage_count
from kraby_study.plan.spec import fingerprint
from kraby_study.plan.sweep import expand_study
from kraby_study.records.attributes import StudyAttrs
from kraby_study.records.definition import SEEDING_TEXT, seed_text, stored_seeding
from kraby_study.records.stored import Outcome, Tally, counted, outcome, spent_cpu, tally
from kraby_study.store.rows import has_store, reading
from kraby_study.store.url import shown_url


@dataclass(frozen=True)
class Measured:
    """Env steps and wall time summed over a store's complete trials."""

    trials: int = 0
    env_steps: int = 0
    wall_time: float = 0.0
    cpu_wall: float = 0.0
    """Wall time of the complete trials that stored their CPU seconds."""
    cpu_time: float = 0.0
    """Their CPU seconds (user + system, worker and env processes)."""

    @property
    def rate(self) -> float | None:
        """Env steps per second of one worker; None with nothing measured."""
        return self.env_steps / self.wall_time if self.trials and self.wall_time > 0 else None

    @property
    def cpu_rate(self) -> float | None:
        """CPU seconds one worker uses per second of wall time; None with nothing measured."""
        return self.cpu_time / self.cpu_wall if self.cpu_wall > 0 and self.cpu_time > 0 else None


@dataclass(frozen=True)
class StoredSoFar:
    """What a store holds for a dry run: each named study's tally, and its measured rate."""

    tallies: dict[str, Tally] = field(default_factory=dict)
    """Counted outcomes of the named studies that are stored (missing ones are absent)."""
    measured: Measured = field(default_factory=Measured)
    spent: dict[str, float] = field(default_factory=dict)
    """CPU seconds each stored named study has used, every attempt counted (as its CPU
    budget counts them)."""

    def cpu_left(self, count: Count) -> float:
        """CPU seconds a CPU-budgeted search has still to spend (0 without a budget)."""
        if count.cpu_budget is None:
            return 0.0
        return max(count.cpu_budget - self.spent.get(count.study, 0.0), 0.0)


def read_stored(url: str, counts: Sequence[Count]) -> StoredSoFar:
    """The stored outcomes of the counted studies and the store's measured rate; a store not
    made yet (no SQLite file, or no tables) holds nothing, and is not created.

    Raises:
        ConfigError: The URL is not a supported database URL.
        StoreError: The store cannot be read, or holds a counted study under another definition
            (as the real command would refuse it); one line.
    """
    if not has_store(url):
        return StoredSoFar()
    planned = {c.study: c.trials for c in counts}
    definitions = {c.study: c.definition for c in counts}
    tallies: dict[str, Tally] = {}
    spent: dict[str, float] = {}
    trials, steps, seconds, cpu_wall, cpu = 0, 0, 0.0, 0.0, 0.0
    with reading(url) as reader:
        for study in reader.studies():
            kept = counted(study.trials)
            if study.name in planned:
                check_definition(url, study.name, study.attrs, definitions.get(study.name))
                tallies[study.name] = tally(kept, planned[study.name])
                spent[study.name] = spent_cpu(study.trials)
            for trial in kept:
                attrs = trial.user_attrs
                if (outcome(trial) is not Outcome.COMPLETE or not attrs.get("env_steps")
                        or not attrs.get("wall_time")):
                    continue
                trials += 1
                steps += int(attrs["env_steps"])
                seconds += float(attrs["wall_time"])
                if attrs.get("cpu_time"):
                    cpu_wall += float(attrs["wall_time"])
                    cpu += float(attrs["cpu_time"])
    return StoredSoFar(tallies=tallies, measured=Measured(trials, steps, seconds, cpu_wall, cpu),
                       spent=spent)


def check_definition(url: str, name: str, stored: StudyAttrs,
                     definition: dict[str, Any] | None) -> None:
    """Refuse, as the real command would, a study stored under ``name`` with another
    definition (nothing to check while the definition is not known)."""
    if definition is None:
        return
    from kraby_study.store.store import check_same_definition  # loads Optuna: only here

    check_same_definition(name, shown_url(url), stored,
                          StudyAttrs(definition=definition, fingerprint=fingerprint(definition)))


def count_lines(count: Count, stored: Tally | None, found: StoredSoFar | None = None
                ) -> list[str]:
    """A study's plan: its trials and env steps, and how many the store already holds; a
    CPU-budgeted search's, led by its budget and the CPU seconds it has left (read from
    ``found``)."""
    found = found or StoredSoFar()
    most = "at most " if count.at_most or count.cpu_budget is not None else ""
    raced = " (raced: a value or configuration shown worse stops early)" if count.at_most else ""
    if count.cpu_budget is None:
        lines = [f"{count.study}: {most}{count.trials} {count.unit} ({count.shape}), "
                 f"{count.steps_per_trial:,} env steps each, {most}{count.env_steps:,} in all"
                 + raced]
    else:
        lines = [f"{count.study}: until its {count.cpu_budget:,.0f} CPU s (search.cpu_budget) "
                 f"are used, at most {count.trials:,} {count.unit} ({count.shape}), "
                 f"{count.steps_per_trial:,} env steps each{raced}",
                 f"  {budget_text(count, found)}"]
    if count.definition is not None:
        lines.append(f"  seeding {SEEDING_TEXT[stored_seeding(count.definition)]}")
        if isinstance(count.definition.get("seeds"), list):
            lines.append(f"  seeds {seed_text(count.definition['seeds'])}")
    left = ("none" if count.cpu_budget is not None and not found.cpu_left(count)
            else f"{most}{remaining_trials(count, stored)}")
    if stored is None:
        lines.append(f"  not in the store yet: 0 {count.unit} complete, {left} to run")
    else:
        lines.append(f"  in the store: {stored.complete} {count.unit} complete, "
                     f"{stored.failed} failed, {stored.pruned} pruned; {left} to run")
    return lines


def budget_text(count: Count, found: StoredSoFar) -> str:
    """A CPU-budgeted search's CPU seconds still to spend, and what ends it."""
    left = found.cpu_left(count)
    if not left:
        return (f"it has used {found.spent.get(count.study, 0.0):,.0f} CPU s, its budget: it "
                f"asks for no more {count.unit}")
    return (f"{left:,.0f} CPU s left to spend (the sampler's included); how many {count.unit} "
            f"they run depends on the settings asked for, and the {count.unit} running when "
            "they are used finish")


def remaining_trials(count: Count, stored: Tally | None) -> int:
    """Trials still to run: those planned without an ended trial."""
    return max(count.trials - (stored.ended if stored else 0), 0)


def remaining_steps(counts: Sequence[Count], found: StoredSoFar) -> int:
    """Env steps still to train over every counted study but a CPU-budgeted search (timed by
    its CPU seconds left: [`StoredSoFar.cpu_left`][StoredSoFar.cpu_left])."""
    return sum(remaining_trials(c, found.tallies.get(c.study)) * c.steps_per_trial
               for c in counts if c.cpu_budget is None)


def estimate_line(steps: int, measured: Measured, workers: int | None, cpu_left: float = 0.0
                  ) -> str:
    """``about 12 min at 5,100 env steps/s per worker x 2 workers, measured over 80 trials of
    this store``, or why there is no estimate; a CPU-budgeted search's ``cpu_left`` seconds
    are timed at the CPU seconds a worker uses per second (``about 21 min: 1,592 CPU s at
    0.65 CPU s/s per worker x 2 workers, ...``). ``workers`` None: not known before the
    command runs (a Ray cluster's CPUs), the estimate is one worker's."""
    rate, cpu_rate = measured.rate, measured.cpu_rate
    if rate is None:
        return "no estimate: this store has no complete trial to measure steps/s from"
    if cpu_left > 0 and cpu_rate is None:
        return "no estimate: this store has no complete trial that stored its CPU seconds"
    if steps == 0 and cpu_left <= 0:
        return "nothing left to run"
    many = workers or 1
    shown = (f"{many} worker{'s' if many != 1 else ''}" if workers
             else "1 worker (the cluster's workers are not known before it is reached)")
    seconds, rates = 0.0, []
    if steps:
        seconds += steps / (rate * many)
        rates.append(f"{steps:,} env steps at {rate:,.0f} env steps/s")
    if cpu_left > 0 and cpu_rate is not None:
        seconds += cpu_left / (cpu_rate * many)
        rates.append(f"{cpu_left:,.0f} CPU s at {cpu_rate:.2f} CPU s/s")
    at = (f" at {rate:,.0f} env steps/s" if not cpu_left
          else ": " + " and ".join(rates))
    return (f"about {duration(seconds)}{at} per worker x {shown}, measured over "
            f"{measured.trials} trial{'s' if measured.trials != 1 else ''} of this store")


def duration(seconds: float) -> str:
    """A rough length of time: '40 s', '12 min', '3.5 h'."""
    if seconds < 60:
        return f"{max(seconds, 1):.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


@dataclass(frozen=True)
class StagePreview:
    """One campaign stage as a dry run sees it."""

    stage: Stage
    count: Count
    inputs: list[str]
    """Its settings from earlier stages: their selected values, or which stage decides each
    one when that stage is not finished."""
    known: bool
    """Whether every earlier winner it takes is selected already."""


def campaign_preview(campaign: Campaign) -> list[StagePreview]:
    """Every stage's count and inputs; a stage whose earlier winners are not selected yet is
    counted from its study file, its inputs named, not guessed.

    Raises:
        ConfigError or StoreError: A stage cannot be planned (as the real command would
            refuse it); one line.
    """
    out = []
    for stage in campaign.stages:
        lookup = StoreWinners(names={s.study: s.name for s in campaign.before(stage)},
                              recorders=[s.name for s in campaign.stages])
        try:
            plan = expand_study(resumed_stage(campaign, stage, lookup))
        except Unfinished:
            pending = [f"{s.parameter} from stage {s.number} ({s.study}), not selected yet"
                       for s in campaign.before(stage) if s.parameter != stage.parameter]
            out.append(StagePreview(stage, stage_count(stage_file(campaign, stage), stage.name),
                                    pending, known=False))
            continue
        taken = [i.text() for i in lookup.inputs if i.setting != stage.parameter]
        out.append(StagePreview(stage, plan_count(plan), taken, known=True))
    return out


def preview_lines(url: str, counts: Sequence[Count], workers: int | None,
                  notes: dict[str, list[str]] | None = None) -> list[str]:
    """A dry run's plan and estimate: each study's count and what the store holds of it (with
    ``notes`` under it, e.g. a campaign stage's inputs), then the time the rest should take.

    Raises:
        ConfigError or StoreError: The store cannot be read; one line.
    """
    found = read_stored(url, counts)
    lines = ["plan (dry run: nothing is trained or written):"]
    for count in counts:
        lines += count_lines(count, found.tallies.get(count.study), found)
        lines += [f"  {note}" for note in (notes or {}).get(count.study, [])]
    if len(counts) > 1:
        lines.append(f"in all: {sum(c.trials for c in counts)} trials, "
                     f"{sum(c.env_steps for c in counts):,} env steps")
    lines.append(estimate_line(remaining_steps(counts, found), found.measured, workers,
                               sum(found.cpu_left(c) for c in counts)))
    return lines
