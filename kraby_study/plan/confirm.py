"""A confirm study: configurations retrained on fresh seeds, one arm per configuration.

A search's best trial is the best of many noisy draws, an optimistic estimate. ``confirm``
retrains the top configurations of a search (or the top values of a sweep), and any baseline
config, on seeds no trial of the source used, at the source's budget. Its seeds start at
``TEST_SEED`` (1000), apart from the tuning seeds every other command starts at 0, as ARLBench
keeps its test seeds (100 on) apart from its tuning seeds (0-9). Pure: the arms come in already
read from the store.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from omegaconf import DictConfig

from kraby_study.config.validate import validate_run_length
from kraby_study.errors import ConfigError
from kraby_study.plan.racing import race_rules
from kraby_study.plan.settings import model_path, settings_with_ppo, tensorboard_run
from kraby_study.plan.space import objectives
from kraby_study.plan.spec import (
    StudyPlan,
    TrialSpec,
    evaluation_of,
    seeding_of,
    with_evaluation,
    with_seeding,
)
from kraby_study.records.attributes import SelectRule, StudyKind
from kraby_study.records.definition import REWARDS
from kraby_study.records.stored import sweep_key

TEST_SEED = 1000
"""A new confirm study's first seed when confirm.seed is null."""

PARAMETER = "config"
"""The Optuna parameter of a confirm study's trials: the arm's label."""


@dataclass(frozen=True)
class Arm:
    """One configuration a confirm study retrains."""

    label: str
    """Its name in tables and legends: ``t12`` (a search trial), ``gamma=0.8`` (a sweep's
    value) or ``ppo=tuned`` (a baseline config)."""
    settings: dict[str, Any]
    """The resolved env and ppo settings it trains with, exactly as its source stored them."""
    origin: str
    """Where it comes from, in words."""
    source_score: float | None = None
    """Its score in the source study (a trial's value, or a value's mean final score)."""


@dataclass(frozen=True)
class ConfirmedStudy:
    """The study whose top configurations are confirmed, as read from the store."""

    name: str
    arms: list[Arm]
    """Its top configurations, best first."""
    used_seeds: set[int]
    """Every seed its trials trained."""
    steps: int
    curve_every: int
    env_keys: list[str]
    """Env settings it varied (written with the ppo settings by ``best``)."""
    two_objectives: bool = False
    """A two-objective search: its arms are trials of its front, spread along it."""
    objective: str = "final_reward"
    """How its runs were scored, and so how the confirm scores its arms: final_reward, or
    evaluation (the deterministic policy's mean return; the confirm's runs on episodes of
    their own fresh seeds)."""


def baseline_arm(name: str, overrides: Sequence[str]) -> Arm:
    """A ppo config file as a confirm arm: the command's settings with ``ppo=NAME``."""
    return Arm(label=f"ppo={name}", settings=settings_with_ppo(name, overrides),
               origin=f"the config ppo={name}")


def fresh_seeds(used: set[int], count: int, first: int = 0) -> list[int]:
    """``count`` seeds from ``first`` on that are not in ``used``."""
    seeds: list[int] = []
    seed = first
    while len(seeds) < count:
        if seed not in used:
            seeds.append(seed)
        seed += 1
    return seeds


def distinct_arms(arms: Sequence[Arm]) -> list[Arm]:
    """One arm per distinct configuration, in the order first seen: arms whose complete
    settings are equal (a search trial that was an enqueued config, a baseline given twice)
    become one, labelled with each of their names (``t0 = ppo=tuned``), their origins joined,
    with the first source score there is."""
    groups: dict[str, list[Arm]] = {}
    for arm in arms:
        groups.setdefault(json.dumps(arm.settings, sort_keys=True, default=str), []).append(arm)
    out = []
    for same in groups.values():
        labels = list(dict.fromkeys(arm.label for arm in same))
        origins = list(dict.fromkeys(arm.origin for arm in same))
        score = next((a.source_score for a in same if a.source_score is not None), None)
        out.append(Arm(label=" = ".join(labels), settings=same[0].settings,
                       origin="; ".join(origins), source_score=score))
    return out


def confirm_rule(cfg: DictConfig, source: ConfirmedStudy | None) -> SelectRule:
    """The confirm study's selection rule: ``confirm.select``, or fastest_equivalent for a
    two-objective search's front (the cheapest settings shown equivalent to the best, on
    fresh seeds) and final_score otherwise; ConfigError for a name that is not a rule."""
    if cfg.confirm.select is not None:
        return SelectRule.check(str(cfg.confirm.select), "confirm.select")
    if source is not None and source.two_objectives:
        return SelectRule.FASTEST_EQUIVALENT
    return SelectRule.FINAL_SCORE


def confirm_name(source: str | None, baselines: list[str], name: str | None = None) -> str:
    """``name`` (``confirm.name``) when given; else ``NAME-confirm``, or
    ``confirm-<baselines>`` when only baselines are retrained."""
    if name is not None:
        return str(name)
    return f"{source}-confirm" if source else "confirm-" + "+".join(baselines)


def confirm_plan(cfg: DictConfig, source: ConfirmedStudy | None, baselines: list[Arm]) -> StudyPlan:
    """One spec per (arm, fresh seed): the source's top arms first, then the baselines.

    Raises:
        ConfigError: Two arms share a label, or there is no arm at all.
    """
    given = (source.arms if source else []) + baselines
    arms = distinct_arms(given)
    labels = [arm.label for arm in arms]
    if not arms:
        raise ConfigError("confirm needs --study-name NAME or at least one --baseline ppo=NAME")
    if len(set(labels)) != len(labels):
        raise ConfigError(f"confirm: two configurations are named alike ({', '.join(labels)})")
    first = TEST_SEED if cfg.confirm.seed is None else int(cfg.confirm.seed)
    # A source's runs set how the arms are scored; baselines alone take the command's reward
    # (search.objective, final_reward by default).
    objective = source.objective if source else objectives(cfg)[0]
    # The confirm's test set is its own: each fresh seed's episodes (eval_set run), as many as
    # the command settles, whatever set and number its source searched on.
    eval_set, episodes = evaluation_of(cfg)
    seeds = fresh_seeds(source.used_seeds if source else set(), int(cfg.confirm.seeds),
                        first=first)
    scheme = seeding_of(cfg)
    racing = race_rules(cfg, seeds, "confirm.seeds")
    steps = source.steps if source else int(cfg.budget.steps)
    curve_every = source.curve_every if source else int(cfg.budget.curve_every)
    name = confirm_name(source.name if source else None, [a.label for a in baselines],
                        cfg.confirm.name)
    at = f" at {source.name}'s {steps} steps" if source else ""
    for arm in arms:
        validate_run_length(arm.settings["env"], arm.settings["ppo"], steps, objective,
                            where=f"confirm{at}, {arm.label}: ", fixed_steps=source is not None)
    specs = [TrialSpec(study=name, key=sweep_key(index, seed), seed=seed, steps=steps,
                       curve_every=curve_every, settings=arm.settings, value=arm.label,
                       model_path=model_path(cfg, name, sweep_key(index, seed)),
                       label=f"{arm.label} seed {seed}",
                       tensorboard_run=tensorboard_run(cfg, name, arm.label), seeding=scheme,
                       objective=objective, eval_episodes=episodes, eval_set=eval_set)
             for index, arm in enumerate(arms) for seed in seeds]
    definition = {
        "kind": StudyKind.CONFIRM.value, "parameter": PARAMETER, "values": labels,
        "source": source.name if source else None,
        "source_winner": arms[0].label if source and source.arms else None,
        "arms": [{"label": a.label, "origin": a.origin, "source_score": a.source_score,
                  "settings": a.settings} for a in arms],
        "seeds": seeds, "steps": steps, "curve_every": curve_every,
        "env_keys": source.env_keys if source else [],
    }
    if objective != REWARDS[0]:
        # Only a confirm of an evaluation search stores its objective: every other confirm
        # keeps the definition (and the fingerprint) it had before confirms scored that way.
        definition = with_evaluation({**definition, "objective": objective,
                                      "eval_episodes": episodes}, eval_set)
    if racing is not None:
        definition["racing"] = racing.stored()
    return StudyPlan(name=name, parameter=PARAMETER, values=labels, specs=specs,
                     definition=with_seeding(definition, scheme), racing=racing,
                     select=confirm_rule(cfg, source).value)
