"""Run a racing search: configurations asked from the sampler, raced over seeds against an
incumbent (SMAC's intensification decided by the project's comparison,
[`intensify`][kraby_study.decision.race.intensify]).

The unit of work is one run, a configuration on one seed, stored as one trial keyed
``c<configuration>-s<seed>`` (as a race stores a sweep). Nothing is decided in memory: each
claim, under the study's plan lock, replays the search from the store
([`racing_search`][kraby_study.answers.racing_search.racing_search]) and queues the one run it
wants next (a retry first, then [`next_run`][kraby_study.decision.race.Intensification.next_run]),
or asks the sampler for a new challenger. So a killed search, rerun, continues where it stopped,
and commands on one PostgreSQL database share it.

The sampler's view is rebuilt at each ask: an in-memory Optuna study with one complete trial
per configuration that has ended a run, valued at the IQM of its seeds so far, and the sampler
seeded from (search.seed, configurations asked), so a resumed search asks what an
uninterrupted one would have.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, TextIO

import optuna
from omegaconf import DictConfig
from optuna.trial import FrozenTrial, TrialState

from kraby_study.answers.racing_search import REFUSED, RacingSearch, racing_search, run_place
from kraby_study.decision.race import Left
from kraby_study.errors import ConfigError
from kraby_study.plan.space import (
    apply_params,
    fitted_params,
    racing_text,
    search_cpu_budget,
    search_definition,
    search_race_rules,
)
from kraby_study.plan.spec import TrialSpec, fingerprint
from kraby_study.records.attributes import StudyAttrs, TrialAttrs, TrialResult
from kraby_study.records.stored import (
    Failure,
    counted,
    failure,
    is_interrupted,
    latest_by_key,
    racing_key,
)
from kraby_study.run.executor import Executor
from kraby_study.run.progress import Progress
from kraby_study.run.runner import CommandRun, Retrying, run_trials
from kraby_study.run.sampling import directions, distributions, racing_sampler
from kraby_study.run.search_source import search_spec, short_label
from kraby_study.run.source import BudgetedSource, requeue_orphans, retry_failed
from kraby_study.store.ledger import StudyLedger
from kraby_study.store.store import Store

WITHDRAWN = "withdrawn: its configuration left the race"


class RacingSource(BudgetedSource):
    """Hands out the runs a racing search wants, one at a time, and notes its moves."""

    def __init__(self, ledger: StudyLedger, cfg: DictConfig,
                 starts: Sequence[tuple[str, dict[str, Any]]] = ()) -> None:
        super().__init__(ledger)
        self.cfg = cfg
        self.definition = ledger.attrs.definition
        self.seed_base = int(self.definition.get("seed", 0))
        """The seed of every configuration's first run; its i-th run trains seed_base + i."""
        self.total = int(cfg.search.trials)
        self.cpu_budget = search_cpu_budget(cfg)
        self.space = distributions(cfg)
        self.starts = [(name, params) for name, settings in starts
                       if (params := fitted_params(cfg, settings))]
        self._running: dict[int, float] = {}  # trial number -> CPU seconds so far
        self.progress: Progress | None = None
        """Where the race's moves are printed as they happen."""
        self._moves: list[str] = []  # noted when a run is recorded, printed after its line
        self._standings = {c.number: c.standing for c in self.standing().configurations}

    def standing(self, trials: Sequence[FrozenTrial] | None = None) -> RacingSearch:
        """The search replayed from the store."""
        found = racing_search(self.definition, self.ledger.trials() if trials is None
                              else trials)
        assert found is not None
        return found

    def running_cpu(self) -> float:
        """CPU seconds the runs this command runs have used so far."""
        return sum(self._running.values())

    def using(self, number: int, steps: int, cpu: float) -> None:
        """Note the CPU seconds a running run has used so far."""
        if number in self._running:
            self._running[number] = cpu

    def next_trial(self) -> tuple[int, TrialSpec] | None:
        """Claim the run the search wants next: a queued retry of a configuration still in the
        race, the run the race wants, or the first run of a new challenger; None when it wants
        none now (its budget used, its configurations all asked and decided, or waiting for
        runs in flight)."""
        self.print_moves()
        while True:
            with self.ledger.plan_lock():
                if self.over_budget():
                    return None
                trials = self.ledger.trials()
                found = self.standing(trials)
                latest = latest_by_key(trials)
                waiting = self._withdraw_left(found, latest)
                asked = None
                if not waiting:
                    asked = self._queue_wanted(found, latest)
                    if asked is None:
                        return None
                started = time.process_time()
                trial = self.ledger.ask(self.space)
                if asked is not None:
                    # The sampler runs in this process: its CPU counts against the budget.
                    self.ledger.set_attrs(trial.number, TrialAttrs(
                        suggest_cpu=asked + time.process_time() - started))
            claimed = self._spec(trial)
            if claimed is not None:
                return claimed

    def _withdraw_left(self, found: RacingSearch, latest: dict[str, FrozenTrial]) -> bool:
        """End the queued runs of configurations that have left the race; True when a queued
        run of one still in it waits."""
        base = self.seed_base
        standings = {c.number: c.standing.left for c in found.configurations}
        waiting = False
        for trial in latest.values():
            where = run_place(trial, base)
            if trial.state != TrialState.WAITING or where is None:
                continue
            if standings.get(where[0]) in (Left.INCUMBENT, Left.RACING):
                waiting = True
            else:
                self.ledger.withdraw(trial.number, WITHDRAWN)
        return waiting

    def _queue_wanted(self, found: RacingSearch, latest: dict[str, FrozenTrial]
                      ) -> float | None:
        """Queue the run the race wants, or a new challenger's first run; returns the CPU
        seconds asking the sampler took (0 for a known configuration), None when nothing is
        wanted now."""
        base = self.seed_base
        started: dict[int, set[int]] = {}
        for trial in latest.values():
            where = run_place(trial, base)
            if where is not None and not is_interrupted(trial):
                started.setdefault(where[0], set()).add(where[1])
        by_number = {c.number: c for c in found.configurations}
        wanted = found.state.next_run(started)
        if wanted is not None:
            config, index = wanted
            known = by_number[config]
            self.ledger.queue(known.params, TrialAttrs(
                key=racing_key(config, base + index), seed=base + index,
                enqueued=known.enqueued))
            return 0.0
        asked = len(found.configurations)
        if asked >= self.total or (asked and not found.state.challenge_open()):
            return None
        began = time.process_time()
        name, fixed = self.starts[asked] if asked < len(self.starts) else (None, {})
        params = self._ask(found, asked, fixed)
        self.ledger.queue(params, TrialAttrs(key=racing_key(asked, base), seed=base,
                                             enqueued=name))
        return time.process_time() - began

    def _ask(self, found: RacingSearch, asked: int, fixed: dict[str, Any]) -> dict[str, Any]:
        """A new configuration from the sampler, which sees each configuration that has ended
        a run at the IQM of its seeds so far; ``fixed``: the values an enqueued configuration
        sets (the sampler draws those its space does not hold), so every run of it trains the
        same settings."""
        study = optuna.create_study(direction="maximize",
                                    sampler=racing_sampler(self.cfg, asked))
        if fixed:
            study.enqueue_trial(fixed)
        for config in found.configurations:
            if math.isfinite(config.iqm) and set(config.params) == set(self.space):
                study.add_trial(optuna.trial.create_trial(
                    params=config.params, distributions=self.space, value=config.iqm))
        trial = study.ask(self.space)
        return {name: trial.params[name] for name in self.space}

    def _spec(self, trial: FrozenTrial) -> tuple[int, TrialSpec] | None:
        """The spec of a claimed run; None when its settings are refused (stored failed, and
        its configuration leaves the race)."""
        params = {name: trial.params[name] for name in self.space}
        key = str(trial.user_attrs["key"])
        seed = int(trial.user_attrs["seed"])
        try:
            trial_cfg = apply_params(self.cfg, params)
        except ConfigError as err:
            self.ledger.refuse(trial.number, failure(Failure.ERROR, f"{REFUSED} {err}"))
            return None
        config = key.split("-", 1)[0]
        spec = search_spec(self.cfg, self.ledger.name, key, trial_cfg, params)
        index = seed - self.seed_base
        spec = replace(spec, seed=seed, seeds=1, checkpoint_every=None,
                       label=short_label(params, config) + f" seed {index}")
        self.ledger.set_attrs(trial.number, TrialAttrs(
            settings=spec.settings, steps=spec.steps, model_path=spec.model_path))
        self._running[trial.number] = 0.0
        return trial.number, spec

    def requeue(self, number: int, spec: TrialSpec, reason: str) -> None:
        """Give back a run that will not finish in this command, to run again."""
        self._running.pop(number, None)
        super().requeue(number, spec, reason)

    def record(self, number: int, spec: TrialSpec, result: TrialResult) -> None:
        """Store a finished run with its place among the ended runs (the order the race is
        replayed in), then note how the race moved."""
        self._running.pop(number, None)
        with self.ledger.plan_lock():
            trials = self.ledger.trials()
            place = 1 + max((int(t.user_attrs.get("race_order") or 0) for t in trials), default=0)
            self.ledger.set_attrs(number, TrialAttrs(race_order=place))
            super().record(number, spec, result)
            found = self.standing()
            self.ledger.update(StudyAttrs(planned=len(counted(self.ledger.trials()))))
        self._note_moves(found)

    def _note_moves(self, found: RacingSearch) -> None:
        """A line for each configuration whose standing changed."""
        for config in found.configurations:
            before = self._standings.get(config.number)
            # A new incumbent is named in the line of the one it replaced.
            if before == config.standing or config.standing.left in (Left.RACING,
                                                                     Left.INCUMBENT):
                continue
            inc = found.incumbent
            self._moves.append(f"race: {config.key} {config.left_text()}" + (
                f"; incumbent {inc.key}, {inc.evidence_text()}" if inc is not None else ""))
        self._standings = {c.number: c.standing for c in found.configurations}

    def print_moves(self) -> None:
        """Print the moves noted since the last call (after the line of the run that made
        them, which the runner prints once the run is recorded)."""
        if self.progress is not None:
            for line in self._moves:
                self.progress.note(line)
        self._moves = []


def run_racing_search(store: Store, cfg: DictConfig, executor: Executor, workers: int,
                      stream: TextIO, live: bool | None = None,
                      starts: Sequence[tuple[str, dict[str, Any]]] = (),
                      ) -> tuple[CommandRun, StudyLedger]:
    """Run (or resume) a racing search until its CPU budget is used or its ``search.trials``
    configurations are asked and decided, the incumbent at its cap; a new search asks the
    ``starts`` configurations (name, resolved settings) first, the first of them the first
    incumbent."""
    definition = search_definition(cfg)
    ledger = store.define(str(cfg.search.name),
                          StudyAttrs(kind="search", definition=definition,
                                     fingerprint=fingerprint(definition)),
                          # Every run is queued with its configuration's parameters: the stored
                          # study's sampler never draws, so the cheapest is kept there.
                          sampler=optuna.samplers.RandomSampler(seed=int(cfg.search.seed)),
                          directions=directions(cfg))
    ledger.update(StudyAttrs(sampler=str(cfg.search.sampler), sampler_seed=int(cfg.search.seed),
                             cpu_budget=search_cpu_budget(cfg)))
    requeue_orphans(ledger, stream)
    if cfg.retry_failed:
        retry_failed(ledger, stream)
    rules = search_race_rules(cfg)
    assert rules is not None
    source = RacingSource(ledger, cfg, starts)
    found = source.standing()
    runs = len([t for t in counted(ledger.trials()) if t.state != TrialState.WAITING])
    print(f"search {ledger.name}: up to {source.total} configurations, {len(found.configurations)}"
          f" asked, {runs} runs so far, on {workers} worker(s); {cfg.budget.steps:,} steps a "
          f"run{source.budget_text()}; {racing_text(rules, str(cfg.search.sampler))}",
          file=stream, flush=True)
    progress = Progress(ledger.name, max(runs + workers, 1), runs, stream, live,
                        budget=None if source.cpu_budget is None else source.used_text)
    source.progress = progress
    summary = run_trials(Retrying(source, float(cfg.db_retry_seconds), stream), max(1, workers),
                         progress, executor, heartbeat_seconds=float(cfg.heartbeat_interval))
    source.print_moves()
    found = source.standing()
    ended = "the CPU budget is used" if source.over_budget() else (
        "every configuration is asked and decided" if not found.state.racing
        and len(found.configurations) >= source.total else "stopped")
    print(f"search {ledger.name}: {found.summary()} ({ended}; {source.spent():,.0f} CPU s)",
          file=stream, flush=True)
    return summary, ledger
