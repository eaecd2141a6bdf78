"""Run an Optuna search: ask the sampler for trials until the study holds its total, prune."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, TextIO

from omegaconf import DictConfig
from optuna.trial import FrozenTrial, TrialState

from kraby_study.errors import ConfigError
from kraby_study.plan.settings import model_path, resolved_settings, tensorboard_run
from kraby_study.plan.space import (
    apply_params,
    checkpoint_every,
    fitted_params,
    objectives,
    outside_space,
    pruner_name,
    recheck_plan,
    recheck_text,
    search_cpu_budget,
    search_definition,
    search_floor,
    search_trial_cap,
    trial_cap_text,
    wilcoxon_seeds,
)
from kraby_study.plan.spec import TrialSpec, evaluation_of, fingerprint, seeding_of
from kraby_study.records.attributes import SelectRule, StudyAttrs, TrialAttrs, TrialResult
from kraby_study.records.definition import floor_score
from kraby_study.records.stored import Failure, Outcome, counted, failure, search_key, spent_cpu
from kraby_study.records.values import value_label
from kraby_study.run.executor import Executor
from kraby_study.run.progress import Progress
from kraby_study.run.recheck import (
    combined,
    cpu_per_step,
    first_seed,
    leaders,
    next_recheck,
    reserve,
    to_spend,
)
from kraby_study.run.runner import CommandRun, Retrying, run_trials
from kraby_study.run.sampling import directions, distributions, make_pruner, make_sampler
from kraby_study.run.source import BudgetedSource, requeue_orphans, retry_failed
from kraby_study.store.ledger import StudyLedger
from kraby_study.store.store import Store

FLOOR_CONSTRAINT = "floor"
"""The name of a trial's floor constraint in Optuna (``FrozenTrial.constraints``)."""

SHORT_NAMES = {"learning_rate": "lr", "nminibatches": "nmb", "n_steps": "n_steps",
               "n_epochs": "epochs", "gae_lambda": "lambda", "clip_range": "clip",
               "ent_coef": "ent", "observation": "obs"}
"""Shorter parameter names for progress lines (others are written as they are)."""


def short_label(params: dict[str, Any], key: str) -> str:
    """A search trial as progress lines name it: its sampled values in short, then its key."""
    values = " ".join(f"{SHORT_NAMES.get(name, name)}={value_label(_rounded(value))}"
                      for name, value in params.items())
    return f"{values} ({key})"


def _rounded(value: Any) -> Any:
    """Three significant figures, or as many more (up to 6) as keep a value off a whole
    number it is not: gamma 0.9999 reads 0.9999, not 1."""
    if not isinstance(value, float):
        return value
    for digits in range(3, 7):
        rounded = float(f"{value:.{digits}g}")
        if not rounded.is_integer() or value.is_integer():
            return rounded
    return rounded


@dataclass(frozen=True)
class RunningTrial:
    """A trial this command runs: the env steps and CPU seconds it has used so far, of how many."""

    total: int
    """Env steps it trains if nothing stops it (its steps times its seeds)."""
    done: int = 0
    """Env steps it has trained."""
    cpu: float = 0.0
    """CPU seconds it has used."""
    capped: bool = True
    """Whether it may be stopped for its cost (not a configuration the search evaluates
    first, nor a recheck)."""
    cost_stop: float | None = None
    """The CPU seconds it was projected to use when it was stopped for its cost."""


class SearchSource(BudgetedSource):
    """Asks the sampler for trials until the study holds its total; prunes at checkpoints."""

    def __init__(self, ledger: StudyLedger, cfg: DictConfig) -> None:
        super().__init__(ledger)
        self.cfg = cfg
        self.total = int(cfg.search.trials)
        self.cpu_budget = search_cpu_budget(cfg)
        self.trial_cap = search_trial_cap(cfg)
        self.space = distributions(cfg)
        self.recheck, self.recheck_seeds = recheck_plan(cfg)
        self._rechecks: dict[int, Any] = {}  # recheck trial -> the trial it rechecks
        self._running: dict[int, RunningTrial] = {}  # trial number -> its steps and CPU so far
        # Exploring ended for the rechecks: it does not start again, in this command nor in a
        # later one under the same budget.
        self._explored = (self.cpu_budget is not None and bool(self.recheck)
                          and ledger.attrs.explored == self.cpu_budget)

    def running_cpu(self) -> float:
        """CPU seconds the trials this command runs have used so far."""
        return sum(running.cpu for running in self._running.values())

    def _to_spend(self, trials: list[Any]) -> float:
        """CPU seconds the trials this command runs could still use, each trained to its
        last env step ([`to_spend`][kraby_study.run.recheck.to_spend])."""
        rate = cpu_per_step(trials)
        return sum(to_spend(running.done, running.total, running.cpu, rate)
                   for running in self._running.values())

    def using(self, number: int, steps: int, cpu: float) -> None:
        """Note the env steps a running trial has trained and the CPU seconds it has used so
        far."""
        if number in self._running:
            self._running[number] = replace(self._running[number], done=steps, cpu=cpu)

    @property
    def explored(self) -> bool:
        """Whether exploring has ended to pay for the rechecks
        ([`exploring`][kraby_study.run.search_source.SearchSource.exploring])."""
        return self._explored

    def exploring(self, trials: list[Any]) -> bool:
        """Whether the search still asks its sampler for new trials: its total is not reached
        and, with rechecks under a CPU budget, the budget holds what is spent, what the
        running trials could still use (each to its last step) and the rechecks of today's
        leaders, so a costly trial running beside the last ones does not take the rechecks' share.
        Once exploring has ended for the
        rechecks it does not start again, in this command nor in a later one under the same
        budget: the rest of the budget is the rechecks' (a running recheck's CPU is not
        reserved once it starts, so room would seem to open while it runs, and a trial
        explored then could lead at the end on its search seeds alone). A trial that starts
        costly, or one another machine runs, can still leave the last rechecks unpaid."""
        if len(counted(trials)) >= self.total:
            return False
        if self.cpu_budget is None or not self.recheck:
            return True
        if self._explored:
            return False
        reserved = reserve(trials, self.recheck, self.recheck_seeds)
        self._explored = (spent_cpu(trials) + self.running_cpu() + self._to_spend(trials)
                          + reserved >= self.cpu_budget)
        return not self._explored

    def next_trial(self) -> tuple[int, TrialSpec] | None:
        """Ask for the next trial (a queued retry first, then new ones while exploring, then
        rechecks of the leading trials), or None when all is done or the CPU budget is used.

        With rechecks, the best trial is rechecked even once the budget is used: a recheck
        that drops a leader as the budget runs out puts the next trial first on its search
        seeds alone, whose score overstates it as the dropped leader's did, and the search
        would pick it so. Only that recheck starts past the budget (and the next, if it too
        drops), so the search overshoots its budget by what they use."""
        while True:
            with self.ledger.plan_lock():
                over = self.over_budget()
                trials = self.ledger.trials()
                waiting = any(t.state == TrialState.WAITING for t in trials)
                if over or (not waiting and not self.exploring(trials)):
                    leader = self._recheck_due(trials, over=over, waiting=waiting)
                    if leader is None:
                        return None
                    leader_attrs = TrialAttrs.of(leader)
                    self.ledger.queue(leader.params, TrialAttrs(
                        key=leader_attrs.key, recheck_of=leader.number,
                        enqueued=leader_attrs.enqueued))
                asked = time.process_time()
                trial = self.ledger.ask(self.space)
                # The sampler runs in this process: its CPU counts against the budget.
                self.ledger.set_attrs(trial.number, TrialAttrs(
                    suggest_cpu=time.process_time() - asked))
            number = trial.number
            params = {name: trial.params[name] for name in self.space}
            try:
                trial_cfg = apply_params(self.cfg, params)
            except ConfigError as err:
                self.ledger.refuse(number, failure(Failure.ERROR, str(err)))
                continue
            # A retry keeps the key of the trial it replaces; a new trial is named by its number.
            key = str(trial.user_attrs.get("key", search_key(number)))
            spec = self._spec(key, trial_cfg, params)
            of = trial.user_attrs.get("recheck_of")
            if of is not None:
                # Complete, so it stays as read here until the recheck is recorded.
                original = next(t for t in self.ledger.trials() if t.number == int(of))
                spec = self._recheck_spec(spec, original)
                self._rechecks[number] = original
            self.ledger.set_attrs(number, TrialAttrs(
                key=spec.key, seed=spec.seed, settings=spec.settings, steps=spec.steps,
                model_path=spec.model_path))
            capped = of is None and "enqueued" not in trial.user_attrs
            self._running[number] = RunningTrial(total=spec.steps * spec.seeds, capped=capped)
            return number, spec

    def _recheck_due(self, trials: Sequence[FrozenTrial], *, over: bool,
                     waiting: bool) -> FrozenTrial | None:
        """The leading trial to recheck next. None when no rechecks are asked for, or when
        the budget is used while a retry waits (``ask`` would run the retry, so nothing may
        be queued); else the best trial not rechecked yet among the top one past the budget,
        or among the top ``recheck`` once exploring has ended (None when all are)."""
        if not self.recheck or (over and waiting):
            return None
        return next_recheck(trials, 1 if over else self.recheck)

    def _spec(self, key: str, trial_cfg: DictConfig, params: dict[str, Any]) -> TrialSpec:
        return search_spec(self.cfg, self.ledger.name, key, trial_cfg, params)

    def _recheck_spec(self, spec: TrialSpec, original: Any) -> TrialSpec:
        """A recheck of the trial ``original``: the seeds after its own, nothing for the
        pruner."""
        seed = first_seed(original)
        seeds = (f"seed {seed}" if self.recheck_seeds == 1
                 else f"seeds {seed}-{seed + self.recheck_seeds - 1}")
        return replace(spec, seed=seed, seeds=self.recheck_seeds, checkpoint_every=None,
                       seed_scores=False, label=f"{spec.label} recheck, {seeds}")

    def checkpoint(self, number: int, step: int, value: float) -> bool:
        """Report an intermediate value to the pruner; False stops the trial: the pruner
        stops it, or it is projected to use more than its share of the CPU budget
        ([`projected_past_cap`][kraby_study.run.search_source.SearchSource.projected_past_cap])."""
        if not self.ledger.checkpoint(number, step, value):
            return False
        projected = self.projected_past_cap(number)
        if projected is None:
            return True
        self.ledger.set_attrs(number, TrialAttrs(cost_stop=round(projected, 1)))
        self._running[number] = replace(self._running[number], cost_stop=projected)
        return False

    def stopped_why(self, number: int) -> str | None:
        """A trial stopped for its cost: ``projected to use 412 CPU s, past the cap of 300
        (search.trial_share)``; None for any other."""
        running = self._running.get(number)
        if running is None or running.cost_stop is None:
            return None
        return (f"projected to use {running.cost_stop:,.0f} CPU s, past the cap of "
                f"{self.trial_cap:,.0f} (search.trial_share)")

    def projected_past_cap(self, number: int) -> float | None:
        """The CPU seconds a running trial would use to its last env step (what it has used
        and [`to_spend`][kraby_study.run.recheck.to_spend]), when that passes the search's cap on
        one trial (``search.trial_share`` of the budget); None when it does not, when there
        is no cap, or for a trial the cap spares (an enqueued configuration, a recheck)."""
        running = self._running.get(number)
        if self.trial_cap is None or running is None or not running.capped:
            return None
        projected = running.cpu + to_spend(running.done, running.total, running.cpu,
                                           cpu_per_step(self.ledger.trials()))
        return projected if projected > self.trial_cap else None

    def requeue(self, number: int, spec: TrialSpec, reason: str) -> None:
        """Give back a trial that will not finish in this command, to run again."""
        self._running.pop(number, None)
        super().requeue(number, spec, reason)

    def record(self, number: int, spec: TrialSpec, result: TrialResult) -> None:
        """Store a finished trial. Under a floor a complete one first gets its constraint
        ``floor``: the floor's measured score minus its own (feasible at 0 or less; 0 while the
        floor is not measured). Optuna's samplers rank feasible trials first. A recheck is
        stored with the seeds of the trial it rechecks
        ([`combined`][kraby_study.run.recheck.combined])."""
        self._running.pop(number, None)  # its stored cpu_time counts from now on
        if number in self._rechecks:
            result = combined(self._rechecks[number], result)
        floor = search_floor(self.cfg)
        if (floor is not None and result.outcome == Outcome.COMPLETE
                and result.final_score is not None):
            measured = floor_score(self.ledger.trials(), floor)
            gap = 0.0 if measured is None else measured - float(result.final_score)
            self.ledger.set_constraint(number, FLOOR_CONSTRAINT, gap)
        super().record(number, spec, result)


def search_spec(cfg: DictConfig, study: str, key: str, trial_cfg: DictConfig,
                params: dict[str, Any]) -> TrialSpec:
    """The spec of a search trial: the sampled ``params`` applied (``trial_cfg``), trained on
    ``budget.seeds`` seeds from ``seed`` one after another, checkpointed for the pruner."""
    # The wilcoxon pruner pairs seeds: it sees each seed's score, nothing within a seed.
    pruner = pruner_name(cfg)
    seed_scores = pruner == "wilcoxon"
    names = objectives(cfg)
    eval_set, episodes = evaluation_of(cfg)
    # Optuna takes no intermediate value from a trial of several objectives.
    every = None if seed_scores or len(names) == 2 else checkpoint_every(cfg)
    return TrialSpec(
        study=study, key=key, seed=int(cfg.seed),
        steps=int(cfg.budget.steps), curve_every=int(cfg.budget.curve_every),
        settings=resolved_settings(trial_cfg),
        model_path=model_path(cfg, study, key),
        checkpoint_every=every, seed_scores=seed_scores, seeds=int(cfg.budget.seeds),
        objective=names[0], cost=names[1] if len(names) == 2 else None,
        eval_set=eval_set, eval_episodes=episodes,
        label=short_label(params, key),
        tensorboard_run=tensorboard_run(cfg, study, key),
        seeding=seeding_of(cfg))


def pruner_label(cfg: DictConfig) -> str:
    """The pruner as the start line names it; the wilcoxon pruner with its threshold, and
    the cap on one trial's CPU seconds (``search.trial_share``) where there is one."""
    pruner = pruner_name(cfg)
    if pruner == "wilcoxon":
        p = float(cfg.search.wilcoxon_p)
        return (f"wilcoxon pruner (a trial's seeds against the best's, p < {p:g}, from "
                f"{wilcoxon_seeds(p)} seeds)")
    if len(objectives(cfg)) == 2:
        floor = search_floor(cfg)
        below = f", trials below ppo={floor}'s score infeasible" if floor else ""
        return f"objectives {' and '.join(objectives(cfg))}, no pruner{below}"
    name = "no pruner" if pruner == "none" else f"{pruner} pruner"
    capped = trial_cap_text(cfg)
    if capped:
        capped += f" (search.trial_share {float(cfg.search.trial_share):g})"
    return name + capped


def take_opening(ledger: StudyLedger) -> int:
    """This command's place among the commands that started on the search (0: the first),
    counted under the plan lock, so two machines that join at once take different places. A
    search that stores no count of its commands takes its trial count."""
    with ledger.plan_lock():
        opening = ledger.attrs.openings
        if opening is None:
            opening = len(ledger.trials())
        ledger.update(StudyAttrs(openings=opening + 1))
    return opening


def warm_start(ledger: StudyLedger, cfg: DictConfig,
               starts: Sequence[tuple[str, dict[str, Any]]]) -> list[str]:
    """Queue the known configurations (name, resolved settings) a new search evaluates first, as
    far as its space holds them, at most its trial total; returns each queued one as the
    search's first line names it, with the settings its space could not hold."""
    queued: list[str] = []
    with ledger.plan_lock():
        if ledger.trials():
            return queued  # not a new search: it was warm-started when it began
        for name, settings in starts[:int(cfg.search.trials)]:
            params = fitted_params(cfg, settings)
            if params:
                ledger.queue(params, TrialAttrs(enqueued=name))
                outside = outside_space(cfg, settings)
                queued.append(name if not outside else (
                    f"{name} (outside the space, so drawn by the sampler: "
                    + ", ".join(f"{k}={value_label(v)}" for k, v in outside.items()) + ")"))
    return queued


def run_search(store: Store, cfg: DictConfig, executor: Executor, workers: int, stream: TextIO,
               live: bool | None = None, starts: Sequence[tuple[str, dict[str, Any]]] = (),
               ) -> tuple[CommandRun, StudyLedger]:
    """Run a search until its study holds ``search.trials`` trials; a new search evaluates the
    ``starts`` configurations (name, resolved settings) first."""
    definition = search_definition(cfg)
    ledger = store.define(str(cfg.search.name),
                          StudyAttrs(kind="search", definition=definition,
                                     fingerprint=fingerprint(definition)),
                          sampler=make_sampler(cfg), pruner=make_pruner(cfg),
                          directions=directions(cfg))
    ledger.update(StudyAttrs(sampler=str(cfg.search.sampler), sampler_seed=int(cfg.search.seed),
                             planned=int(cfg.search.trials), cpu_budget=search_cpu_budget(cfg)))
    if len(objectives(cfg)) == 2 and ledger.attrs.select is None and not ledger.trials():
        # A new front is selected by evidence; a stored search's attributes are not rewritten
        # (answers.search_front.front_rule answers one without a rule by the same rule).
        ledger.update(StudyAttrs(select=SelectRule.FASTEST_EQUIVALENT.value))
    opening = take_opening(ledger)
    if opening:  # resumed or joined: not the random trials an earlier command drew
        ledger.use_sampler(make_sampler(cfg, opening))
    requeue_orphans(ledger, stream)
    if cfg.retry_failed:
        retry_failed(ledger, stream)
    queued = warm_start(ledger, cfg, starts)
    if queued:
        print(f"search {ledger.name}: evaluating {', '.join(queued)} first", file=stream)
    source = SearchSource(ledger, cfg)
    counted = source.counted()
    done = sum(1 for t in counted if t.state not in (TrialState.WAITING, TrialState.RUNNING))
    left = max(0, source.total - done)
    slots = max(1, min(workers, left))
    rechecks = recheck_text(cfg)
    print(f"search {ledger.name}: {source.total} trials, {done} done, {left} to run on "
          f"{slots} worker(s); {cfg.budget.seeds} seed(s) x {cfg.budget.steps:,} steps each, "
          f"{cfg.search.sampler} sampler, {pruner_label(cfg)}{source.budget_text()}"
          f"{'; ' + rechecks if rechecks else ''}", file=stream, flush=True)
    progress = Progress(ledger.name, source.total + source.recheck, done, stream, live,
                        budget=None if source.cpu_budget is None else source.used_text)
    summary = run_trials(Retrying(source, float(cfg.db_retry_seconds), stream), slots, progress,
                         executor, heartbeat_seconds=float(cfg.heartbeat_interval))
    if source.cpu_budget is not None:
        record_budget_end(source, stream)
    if source.recheck:
        print(f"search {ledger.name}: {_leaders_text(source)}", file=stream, flush=True)
    return summary, ledger


def record_budget_end(source: SearchSource, stream: TextIO) -> None:
    """Say what a search under a CPU budget used (and how many trials it stopped for their
    cost, under ``search.trial_share``) and, when the budget stopped it before its
    total, store the trials it ran as its plan, so listing and the report count it complete.
    A search with rechecks ends its exploring before the budget is used, to pay for them; that
    is stored too, so a later command under the same budget does not explore again."""
    counted_trials = [t for t in source.counted() if t.state != TrialState.WAITING]
    ended = len(counted_trials)
    stopped = (source.over_budget() or source.explored) and ended < source.total
    cost_stopped = sum(1 for t in counted_trials if "cost_stop" in t.user_attrs)
    capped = ("" if source.trial_cap is None else
              f"; {cost_stopped} stopped past {source.trial_cap:,.0f} CPU s (search.trial_share)")
    print(f"search {source.ledger.name}: {source.spent():,.0f} of its "
          f"{source.cpu_budget or 0:,.0f} CPU s used, {ended} of {source.total} trials"
          + (" (stopped by the CPU budget)" if stopped else "") + capped,
          file=stream, flush=True)
    if stopped:
        source.ledger.update(StudyAttrs(planned=ended, explored=(
            source.cpu_budget if source.explored else None)))


def _leaders_text(source: SearchSource) -> str:
    """The end line of a search with rechecks: its leaders by all their seeds."""
    found = leaders(source.ledger.trials(), source.recheck)
    if not found:
        return "no complete trial to recheck"
    parts = []
    for lead in found:
        lead_attrs = TrialAttrs.of(lead.trial)
        seeds = len(lead_attrs.scores or [])
        mark = "" if lead_attrs.recheck_of is not None else ", not rechecked"
        parts.append(f"{lead.trial.user_attrs.get('key')} {lead.score:.4g} ({seeds} seeds{mark})")
    return "leaders by all their seeds: " + "; ".join(parts)
