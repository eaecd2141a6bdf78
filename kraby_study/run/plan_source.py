"""The trial source of a study plan (a sweep, a confirm study or a train run): queue its runs in
the store, hand them out, record their results."""

from __future__ import annotations

from optuna.trial import FrozenTrial

from kraby_study.plan.spec import StudyPlan, TrialSpec
from kraby_study.records.attributes import StudyAttrs, StudyKind, TrialAttrs
from kraby_study.records.stored import is_interrupted, latest_by_key
from kraby_study.records.values import param_name
from kraby_study.run.source import StudySource
from kraby_study.store.ledger import StudyLedger


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
