"""Run a study plan (a sweep, a confirm study or a train run): queue its trials in the store,
run them, record their results."""

from __future__ import annotations

from typing import TextIO

from optuna.trial import FrozenTrial

from kraby_study.plan.spec import StudyPlan, TrialSpec
from kraby_study.records import (
    Outcome,
    StudyAttrs,
    StudyKind,
    Tally,
    TrialAttrs,
    is_interrupted,
    latest_by_key,
    outcome,
    param_name,
    tally,
)
from kraby_study.run.executor import Executor
from kraby_study.run.progress import Progress
from kraby_study.run.runner import CommandRun, Retrying, run_trials
from kraby_study.run.source import StudySource, requeue_orphans
from kraby_study.store.ledger import StudyLedger
from kraby_study.store.store import Store


def swept_name(plan: StudyPlan) -> str | None:
    """The Optuna parameter name of a sweep's value (a confirm study's configuration); None for
    a single training run."""
    swept = StudyKind.of(plan.definition.get("kind")).swept
    return param_name(plan.parameter) if swept else None


class PlanSource(StudySource):
    """Queues a plan's runs, hands them out, and records their results."""

    def __init__(self, ledger: StudyLedger, plan: StudyPlan) -> None:
        super().__init__(ledger)
        self.plan = plan
        self.specs = {spec.key: spec for spec in plan.specs}
        name = swept_name(plan)
        self.choices = {name: plan.values} if name else {}

    def queue_missing(self) -> int:
        """Queue every planned run that has no trial yet (or only an interrupted one);
        returns how many were queued."""
        with self.ledger.plan_lock():
            latest = latest_by_key(self.ledger.trials())
            existing = {key for key, trial in latest.items() if not is_interrupted(trial)}
            queued = 0
            for spec in self.plan.specs:
                if spec.key in existing:
                    continue
                params = {name: spec.value for name in self.choices}
                self.ledger.queue(params, TrialAttrs(key=spec.key, seed=spec.seed))
                queued += 1
            keys = set(latest) | set(self.specs)
            self.ledger.update(StudyAttrs(planned=len(keys)))
        return queued

    def next_trial(self) -> tuple[int, TrialSpec] | None:
        """Claim the next queued run of the plan, or None when none is left."""
        trial = self.ledger.claim(set(self.specs), self.choices)
        if trial is None:
            return None
        spec = self.specs[trial.user_attrs["key"]]
        self.ledger.set_attrs(trial.number, TrialAttrs(
            settings=spec.settings, steps=spec.steps, model_path=spec.model_path))
        return trial.number, spec

    def counted(self) -> list[FrozenTrial]:
        """The counted attempt of each planned run that has one."""
        latest = latest_by_key(self.ledger.trials())
        return [latest[key] for key in self.specs if key in latest]


def run_plan(store: Store, plan: StudyPlan, executor: Executor, workers: int, stream: TextIO,
             live: bool | None = None, heartbeat_seconds: float = 5.0,
             retry_seconds: float = 60.0) -> tuple[CommandRun, Tally]:
    """Queue, run and record a plan's trials, ``workers`` at once on the executor; returns
    this command's summary and the outcomes of the plan's runs."""
    kind = str(plan.definition.get("kind"))
    ledger = store.define(plan.name, StudyAttrs(kind=kind, definition=plan.definition,
                                                fingerprint=plan.fingerprint))
    ledger.update(plan.notes())
    requeue_orphans(ledger, stream)
    source = PlanSource(ledger, plan)
    source.queue_missing()
    before = tally(source.counted())
    pending = len(plan.specs) - before.ended
    slots = min(workers, max(pending, 1))
    print(f"study {plan.name}: {len(plan.specs)} trials, {before.complete} complete, "
          f"{before.failed} failed, {pending} to run on {slots} worker(s)", file=stream,
          flush=True)
    progress = Progress(plan.name, len(plan.specs), before.ended, stream, live)
    summary = run_trials(Retrying(source, retry_seconds, stream), slots, progress, executor,
                         heartbeat_seconds=heartbeat_seconds)
    return summary, tally(source.counted())


def closing_line(noun: str, plan: StudyPlan, counts: Tally) -> str:
    """The line a command ends with: ``study NAME: 7/10 complete, 1 failed, 2 left (rerun ...)``."""
    total = len(plan.specs)
    return (f"{noun} {plan.name}: {counts.complete}/{total} complete, {counts.failed} failed"
            + (f", {total - counts.ended} left (rerun the same command to continue)"
               if counts.ended < total else ""))


def train_outcome(store: Store, plan: StudyPlan, summary: CommandRun, seed: int,
                  stream: TextIO) -> int:
    """Print how a ``train`` run ended (score, model) and return the command's exit code: 0
    complete, 1 failed or not run, 130 interrupted."""
    trial = latest_by_key(store.load(plan.name).trials()).get(plan.specs[0].key)
    if trial is None:
        return 130 if summary.interrupted else 1
    attrs = TrialAttrs.of(trial)
    line = f"train {plan.name} seed {seed}: {outcome(trial)}"
    if trial.value is not None:
        line += f", final score {trial.value:.4g} over {attrs.env_steps} steps"
    if attrs.failure:
        line += f" ({attrs.failure})"
    print(line, file=stream)
    if attrs.model_path and trial.value is not None:
        print(f"model: {attrs.model_path}", file=stream)
    if summary.interrupted:
        return 130
    return 0 if outcome(trial) == Outcome.COMPLETE else 1
