"""Run a planned sweep (or a single training run): queue its trials in the store, run, record."""

from __future__ import annotations

from typing import TextIO

import optuna
from optuna.trial import FrozenTrial, TrialState

from kraby_study.ledger import attempts_by_key, is_final_failure, value_label, was_interrupted
from kraby_study.plan import StudyPlan
from kraby_study.progress import Progress
from kraby_study.runner import Retrying, RunSummary, run_trials
from kraby_study.source import StudySource, rerun_orphans
from kraby_study.spec import TrialSpec
from kraby_study.store import PLANNED, Store


def param_name(plan: StudyPlan) -> str | None:
    """The Optuna parameter name of a sweep's value (the setting's last part)."""
    if plan.definition.get("kind") != "sweep":
        return None
    return plan.parameter.split(".")[-1]


def ensure_queued(store: Store, study: optuna.Study, plan: StudyPlan) -> int:
    """Queue every planned run that has no trial yet; returns how many were queued."""
    with store.plan_lock(study):
        latest = attempts_by_key(study.get_trials(deepcopy=False))
        existing = {key for key, trial in latest.items() if not was_interrupted(trial)}
        name = param_name(plan)
        queued = 0
        for spec in plan.specs:
            if spec.key in existing:
                continue
            params = {name: spec.value} if name else {}
            study.enqueue_trial(params=params, user_attrs={"key": spec.key, "seed": spec.seed})
            queued += 1
        planned = {t.user_attrs.get("key") for t in study.get_trials(deepcopy=False)}
        study.set_user_attr(PLANNED, max(len(plan.specs), len(planned - {None})))
    return queued


class SweepSource(StudySource):
    """Hands out a sweep's queued trials and records their results."""

    def __init__(self, store: Store, study: optuna.Study, plan: StudyPlan) -> None:
        super().__init__(store, study)
        self.plan = plan
        self.specs = {spec.key: spec for spec in plan.specs}
        self.name = param_name(plan)

    def next_trial(self) -> tuple[int, TrialSpec] | None:
        frozen = self.store.claim(self.study, set(self.specs))
        if frozen is None:
            return None
        spec = self.specs[frozen.user_attrs["key"]]
        if self.name is not None:
            optuna.Trial(self.study, frozen._trial_id).suggest_categorical(
                self.name, self.plan.values)
        self.store.set_attrs(frozen._trial_id, {
            "settings": spec.settings, "steps": spec.steps, "model_path": spec.model_path})
        return frozen._trial_id, spec

    def label(self, spec: TrialSpec) -> str:
        if self.name is None:
            return f"seed {spec.seed}"
        return f"{self.name}={value_label(spec.value)} seed {spec.seed}"

    def checkpoint(self, trial_id: int, step: int, value: float) -> bool:
        return True

    def counted(self, trials: list[FrozenTrial]) -> list[FrozenTrial]:
        latest = attempts_by_key(trials)
        return [latest[key] for key in self.specs if key in latest]


def plan_counts(study: optuna.Study, plan: StudyPlan) -> tuple[int, int]:
    """(complete, failed) among the plan's keys, counting the attempt that counts."""
    latest = attempts_by_key(study.get_trials(deepcopy=False))
    keys = [latest[s.key] for s in plan.specs if s.key in latest]
    complete = sum(1 for t in keys if t.state == TrialState.COMPLETE)
    failed = sum(1 for t in keys if is_final_failure(t))
    return complete, failed


def run_plan(store: Store, plan: StudyPlan, workers: int, stream: TextIO,
             live: bool | None = None, heartbeat_seconds: float = 5.0,
             retry_seconds: float = 60.0,
             physics_processes: int | None = None) -> tuple[RunSummary, int, int]:
    """Queue, run and record a plan's trials; returns this command's summary and the totals."""
    kind = str(plan.definition.get("kind"))
    study = store.open_study(plan.name, kind, plan.definition, plan.fingerprint)
    rerun_orphans(store, study, stream)
    ensure_queued(store, study, plan)
    complete, failed = plan_counts(study, plan)
    pending = len(plan.specs) - complete - failed
    progress = Progress(plan.name, len(plan.specs), complete + failed, stream, live)
    print(f"study {plan.name}: {len(plan.specs)} trials, {complete} complete, {failed} failed, "
          f"{pending} to run on {min(workers, max(pending, 1))} worker(s)", file=stream,
          flush=True)
    source = Retrying(SweepSource(store, study, plan), retry_seconds, stream)
    summary = run_trials(source, min(workers, max(pending, 1)), progress,  # type: ignore[arg-type]
                         heartbeat_seconds=heartbeat_seconds,
                         physics_processes=physics_processes)
    complete, failed = plan_counts(study, plan)
    return summary, complete, failed


