"""Run a raced plan: seeds in rounds, the values the race drops get no more.

Nothing is queued up front. Each claim, under the study's plan lock, replays the race on the
stored results ([`race`][kraby_study.decision.race.race]) and queues the one run it wants next: the
lowest seed index any value still in the race lacks, the best-standing value first. So every value
in the race gets its seed k before any value gets seed k + 1, and when a round's last runs are all
taken, idle workers start the next round, best-standing values first (those least likely to be
dropped). A value is judged on its first r seeds only; a seed it ran ahead of its round is kept and
counted. After every recorded run the race is replayed and stored on the study
(``StudyAttrs.race``); a dropped value's queued retry is withdrawn (ended as pruned).
"""

from __future__ import annotations

import math

from optuna.trial import FrozenTrial

from kraby_study.answers.raced import race_record, replay
from kraby_study.decision.race import Race
from kraby_study.plan.spec import RaceRules, StudyPlan, TrialSpec
from kraby_study.records.attributes import StudyAttrs, TrialAttrs, TrialResult
from kraby_study.records.stored import is_interrupted, latest_by_key, place
from kraby_study.run.plan_source import PlanSource
from kraby_study.store.ledger import StudyLedger

WITHDRAWN = "withdrawn: its value was dropped by the race"


class RaceSource(PlanSource):
    """Hands out a raced plan's runs one round at a time and records the race."""

    def __init__(self, ledger: StudyLedger, plan: StudyPlan) -> None:
        super().__init__(ledger, plan)
        assert plan.racing is not None
        self.rules: RaceRules = plan.racing
        seeds = list(self.rules.round_seeds)
        self.place: dict[str, tuple[int, int]] = {}
        for spec in plan.specs:
            where = place(spec.key, seeds)
            assert where is not None, spec.key
            self.place[spec.key] = where

    def standing(self, latest: dict[str, FrozenTrial]
                 ) -> tuple[Race[int], dict[int, dict[int, float]]]:
        """The race replayed on the latest attempt of each run, and the ended runs it read."""
        return replay(self.rules, len(self.plan.values), latest)

    def queue_missing(self) -> int:
        """Store where the race stands; nothing is queued ahead (see
        [`next_trial`][kraby_study.run.race_source.RaceSource.next_trial])."""
        with self.ledger.plan_lock():
            self._store_race()
        return 0

    def next_trial(self) -> tuple[int, TrialSpec] | None:
        """Queue and claim the run the race wants next; None when it wants none now."""
        with self.ledger.plan_lock():
            latest = latest_by_key(self.ledger.trials())
            state, runs = self.standing(latest)
            if state.over:
                return None
            for key in self._wanted_order(state, runs, latest):
                trial = latest.get(key)
                spec = self.specs[key]
                if trial is None or is_interrupted(trial):
                    params = {name: spec.value for name in self.choices}
                    self.ledger.queue(params, TrialAttrs(key=key, seed=spec.seed))
                claimed = self.ledger.claim({key}, self.choices)
                if claimed is not None:
                    self.ledger.set_attrs(claimed.number, TrialAttrs(
                        settings=spec.settings, steps=spec.steps, model_path=spec.model_path))
                    return claimed.number, spec
        return None

    def _wanted_order(self, state: Race[int], runs: dict[int, dict[int, float]],
                      latest: dict[str, FrozenTrial]) -> list[str]:
        """Runs the race wants that nobody runs or ran: lowest seed index first, then the
        best-standing value (highest mean of its complete runs), then the study's order."""
        means = standing_means(runs)

        def free(key: str) -> bool:
            trial = latest.get(key)
            return trial is None or trial.state.name == "WAITING" or is_interrupted(trial)

        keys = [key for key, (value, index) in self.place.items()
                if state.wanted(value, index) and free(key)]
        return sorted(keys, key=lambda k: (self.place[k][1],
                                           -means.get(self.place[k][0], -math.inf),
                                           self.place[k][0]))

    def record(self, number: int, spec: TrialSpec, result: TrialResult) -> None:
        """Store a finished run, then the race it moves on."""
        super().record(number, spec, result)
        with self.ledger.plan_lock():
            self._store_race()

    def _store_race(self) -> None:
        latest = latest_by_key(self.ledger.trials())
        state, runs = self.standing(latest)
        for key, (value, index) in self.place.items():
            trial = latest.get(key)
            if (trial is not None and trial.state.name == "WAITING"
                    and not state.wanted(value, index)):
                self.ledger.withdraw(trial.number, WITHDRAWN)
        wanted = sum(1 for key, (value, index) in self.place.items()
                     if key not in latest and state.wanted(value, index))
        self.ledger.update(StudyAttrs(planned=len(latest) + wanted,
                                      race=race_record(self.plan.values, state, runs)))


def standing_means(runs: dict[int, dict[int, float]]) -> dict[int, float]:
    """Mean final score of each value's complete runs
    ([`ended_runs`][kraby_study.records.stored.ended_runs]), by value index."""
    scores = {v: [x for x in by_seed.values() if not math.isnan(x)] for v, by_seed in runs.items()}
    return {v: math.fsum(s) / len(s) for v, s in scores.items() if s}


def race_line(ledger: StudyLedger) -> str:
    """Where a raced study stands, in one line: runs against the fixed design, drops."""
    stored = ledger.attrs.race or {}
    runs, fixed = int(stored.get("runs", 0)), int(stored.get("fixed_runs", 0))
    dropped = [f"{v['value']} after round {v['dropped_at']}" for v in stored.get("values", [])
               if v.get("dropped_at") is not None]
    settled = [f"{v['value']} after round {v['settled_at']}" for v in stored.get("values", [])
               if v.get("settled_at") is not None]
    share = f" ({100 * runs / fixed:.0f} %)" if fixed else ""
    return (f"race {ledger.name}: {runs} of {fixed} runs{share}, {stored.get('rounds', 0)} "
            f"round(s) decided, dropped: {', '.join(dropped) if dropped else 'none'}"
            + (f", settled equivalent: {', '.join(settled)}" if settled else "")
            + ("; the race is over" if stored.get("over") else ""))

