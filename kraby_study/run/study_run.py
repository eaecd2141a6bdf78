"""Run a study plan (a sweep, a confirm study or a train run) and say how it ended: its runs
queued, run on the executor and recorded, fixed or raced."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TextIO

from kraby_study.plan.spec import StudyPlan
from kraby_study.records.attributes import StudyAttrs, TrialAttrs
from kraby_study.records.stored import Outcome, Tally, latest_by_key, outcome, tally
from kraby_study.run.executor import Executor
from kraby_study.run.plan_source import PlanSource
from kraby_study.run.progress import Progress
from kraby_study.run.race_source import RaceSource, race_line
from kraby_study.run.runner import CommandRun, Retrying, run_trials
from kraby_study.run.source import requeue_orphans, retry_failed
from kraby_study.store.store import Store


def run_plan(store: Store, plan: StudyPlan, executor: Executor, workers: int, stream: TextIO,
             live: bool | None = None, heartbeat_seconds: float = 5.0,
             retry_seconds: float = 60.0, failed_again: bool = False) -> tuple[CommandRun, Tally]:
    """Queue, run and record a plan's trials, ``workers`` at once on the executor; returns
    this command's summary and the outcomes of the plan's runs. ``failed_again``: the plan's
    failed runs are queued again first (``retry_failed``)."""
    kind = str(plan.definition.get("kind"))
    ledger = store.define(plan.name, StudyAttrs(kind=kind, definition=plan.definition,
                                                fingerprint=plan.fingerprint))
    ledger.update(plan.notes())
    requeue_orphans(ledger, stream)
    if failed_again:
        retry_failed(ledger, stream)
    source = RaceSource(ledger, plan) if plan.racing else PlanSource(ledger, plan)
    source.queue_missing()
    before = tally(source.counted(), ledger.attrs.planned if plan.racing else None)
    total = before.planned if plan.racing else len(plan.specs)
    pending = total - before.ended
    slots = min(workers, max(pending, 1))
    shape = (f"raced, at most {total} of {len(plan.specs)} runs ({plan.racing.describe()})"
             if plan.racing else f"{len(plan.specs)} trials")
    print(f"study {plan.name}: {shape}, {before.complete} complete, {before.failed} failed, "
          f"{pending} to run on {slots} worker(s)", file=stream, flush=True)
    progress = Progress(plan.name, total, before.ended, stream, live)
    summary = run_trials(Retrying(source, retry_seconds, stream), slots, progress, executor,
                         heartbeat_seconds=heartbeat_seconds)
    if plan.racing:
        print(race_line(ledger), file=stream, flush=True)
        return summary, tally(source.counted(), ledger.attrs.planned)
    return summary, tally(source.counted())


def closing_line(noun: str, plan: StudyPlan, counts: Tally) -> str:
    """The line a command ends with: ``study NAME: 7/10 complete, 1 failed, 2 left (rerun ...)``
    (of a race: of the runs it makes at most, as it stands)."""
    total = counts.planned if plan.racing else len(plan.specs)
    return (f"{noun} {plan.name}: {counts.complete}/{total} complete, {counts.failed} failed"
            + (f", {total - counts.ended} left (rerun the same command to continue)"
               if counts.ended < total else ""))


@dataclass(frozen=True)
class TrainOutcome:
    """How a ``train`` run ended: the lines that say so, the exit code (0 complete, 1 failed
    or not run, 130 interrupted), its final score and where its model is."""

    lines: list[str]
    code: int
    score: float | None = None
    model_path: str | None = None


def train_outcome(store: Store, plan: StudyPlan, summary: CommandRun, seed: int
                  ) -> TrainOutcome:
    """How a ``train`` run ended (score, model), read from the store."""
    trial = latest_by_key(store.load(plan.name).trials()).get(plan.specs[0].key)
    if trial is None:
        return TrainOutcome([], 130 if summary.interrupted else 1)
    attrs = TrialAttrs.of(trial)
    line = f"train {plan.name} seed {seed}: {outcome(trial)}"
    if trial.value is not None:
        line += f", final score {trial.value:.4g} over {attrs.env_steps} steps"
    if attrs.failure:
        line += f" ({attrs.failure})"
    lines = [line]
    if attrs.model_path and trial.value is not None:
        lines.append(f"model: {attrs.model_path}")
    code = (130 if summary.interrupted else 0 if outcome(trial) == Outcome.COMPLETE else 1)
    return TrainOutcome(lines, code, None if trial.value is None else float(trial.value),
                        attrs.model_path)
