"""What a command would run, counted before it runs (``--dry-run``): trials and env steps.

Pure: no store, no training. How much of it the store already holds is read in
[`kraby_study.answers.preview`][].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from omegaconf import DictConfig

from kraby_study.config.validate import to_container
from kraby_study.plan.space import (
    recheck_text,
    search_cpu_budget,
    search_definition,
    search_race_rules,
)
from kraby_study.plan.spec import StudyPlan


@dataclass(frozen=True)
class Count:
    """The runs of one study a command plans, and the env steps they train."""

    study: str
    """The study's name in the store."""
    trials: int
    """Trials planned (a raced plan: the most it runs)."""
    steps_per_trial: int
    """Env steps one trial trains (a search trial: every one of its seeds)."""
    shape: str
    """How the trials come about, e.g. '8 values x 10 seeds'."""
    at_most: bool = False
    """A raced plan or a racing search: a value or configuration shown worse stops early, so
    fewer may run."""
    definition: dict[str, Any] | None = None
    """The definition the command would store (and check against a stored study of the same
    name); None when not known yet (a campaign stage waiting for earlier winners)."""
    cpu_budget: float | None = None
    """A search's CPU seconds (``search.cpu_budget``): it ends once they are used, usually
    long before its trials do; None without one."""
    unit: str = "trials"
    """What one counted trial is, as the plan names it: ``trials``, or ``runs`` for a racing
    search (a trial per seed of a configuration)."""

    @property
    def env_steps(self) -> int:
        """Env steps of every planned trial."""
        return self.trials * self.steps_per_trial


def plan_count(plan: StudyPlan, arms: str = "values") -> Count:
    """A sweep's or confirm study's count: values (``arms``) x seeds."""
    values = len(plan.values)
    seeds = len(plan.specs) // values if values else 0
    steps = plan.specs[0].steps if plan.specs else 0
    return Count(study=plan.name, trials=len(plan.specs), steps_per_trial=steps,
                 shape=f"{values} {arms} x {seeds} seeds", at_most=plan.racing is not None,
                 definition=plan.definition)


def stage_count(cfg: DictConfig, name: str) -> Count:
    """A campaign stage's count from its study file alone (its earlier winners unresolved):
    values x seeds do not depend on them."""
    values = len(to_container(cfg.study["values"]))
    seeds = int(cfg.budget.seeds)
    return Count(study=name, trials=values * seeds, steps_per_trial=int(cfg.budget.steps),
                 shape=f"{values} values x {seeds} seeds", at_most=bool(cfg.racing.enabled))


def search_count(cfg: DictConfig) -> Count:
    """A search's count: ``search.trials`` trials of ``budget.seeds`` seeds each; a racing
    search's: at most ``search.trials`` configurations of up to ``budget.seeds`` runs each."""
    seeds = int(cfg.budget.seeds)
    rules = search_race_rules(cfg)
    budget = search_cpu_budget(cfg)
    cpu = None if budget is None else float(budget)
    if rules is not None:
        return Count(study=str(cfg.search.name), trials=int(cfg.search.trials) * seeds,
                     steps_per_trial=int(cfg.budget.steps), at_most=True,
                     shape=f"{int(cfg.search.trials):,} configurations (search.trials), each "
                           f"raced on {rules.min_seeds} to {seeds} seeds"
                           + _recheck_part(cfg), definition=search_definition(cfg),
                     cpu_budget=cpu, unit="runs")
    return Count(study=str(cfg.search.name), trials=int(cfg.search.trials),
                 steps_per_trial=seeds * int(cfg.budget.steps),
                 shape=f"search.trials, each {seeds} seeds x {int(cfg.budget.steps):,} env "
                       "steps" + _recheck_part(cfg), definition=search_definition(cfg),
                 cpu_budget=cpu)


def _recheck_part(cfg: DictConfig) -> str:
    """A search's rechecks as the plan names them."""
    rechecks = recheck_text(cfg)
    return f"; {rechecks} (search.recheck)" if rechecks else ""
