"""What a stored study's definition says of how it scores: its objectives, its seeding and its
evaluation episodes, and what a definition that does not record one of them is read as."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from kraby_study.errors import ConfigError
from kraby_study.records.attributes import TrialAttrs
from kraby_study.records.stored import Outcome, StoredTrial, outcome
from kraby_study.records.values import score

# A search's objectives ------------------------------------------------------------------------

FINAL_FRACTION = 0.1
"""A run's final score averages the episodes that end in this last fraction of its steps."""

REWARDS = ("final_reward", "evaluation")
"""A search's rewards, maximised: the mean episode reward over the last 10 % of training, or
the deterministic policy's mean return over the run's evaluation episodes."""
COSTS = ("training_time",)
"""A search's costs, minimised: ``training_time`` is CPU seconds per seed
([`TrialMeasures.training_time`][kraby_study.records.attributes.TrialMeasures.training_time])."""


def objective_names(objective: Any) -> list[str]:
    """A search's objective as names: one name (as stored by a one-objective search) or a
    list of names."""
    if isinstance(objective, str):
        return [objective]
    return [str(name) for name in objective]


def check_objective(objective: Any) -> list[str]:
    """The objective's names, a reward first and then any cost; ConfigError, one line, for an
    unknown name, more than two, two rewards, two costs or a cost alone."""
    names = objective_names(objective)
    shown = f"search.objective={_listed(names)}"
    for name in names:
        if name not in REWARDS + COSTS:
            raise ConfigError(f"{shown}: unknown objective {name!r}: choose a reward "
                              f"({' or '.join(REWARDS)}), optionally with the cost "
                              f"{' or '.join(COSTS)}")
    rewards = [n for n in names if n in REWARDS]
    costs = [n for n in names if n in COSTS]
    if len(names) > 2:
        raise ConfigError(f"{shown}: at most two objectives, a reward and a cost, got "
                          f"{len(names)}")
    if len(rewards) != 1:
        raise ConfigError(f"{shown}: " + ("two rewards: give one reward and a cost, e.g. "
                                          "[final_reward,training_time]" if rewards else
                                          "a cost alone: give a reward with it, e.g. "
                                          "[final_reward,training_time]"))
    if len(costs) > 1:
        raise ConfigError(f"{shown}: two costs: give one reward and one cost")
    return rewards + costs


def _listed(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else f"[{','.join(names)}]"


def stored_objective(names: Sequence[str]) -> str | list[str]:
    """The objective as a search's definition stores it: one name as a string (as every
    one-objective search stored it), two as a list."""
    return names[0] if len(names) == 1 else list(names)


SEEDING = "streams"
"""The seeding scheme of a new study: each leg of a run its own child stream of the run's seed
(``numpy.random.SeedSequence(seed).spawn(n_envs)``)."""
UNRECORDED_SEEDING = "offset"
"""The scheme of a study whose definition has no ``seeding`` key: leg i seeded with seed + i."""
SEEDING_TEXT = {
    "streams": "streams: env i of the run with seed s (one of its ppo.n_envs environments) "
               "draws from child i of numpy.random.SeedSequence(s), so no two runs share an "
               "env's stream",
    "offset": "offset: env i of the run with seed s is seeded with s + i, so runs s and s + 1 "
              "share all envs but one (the scheme before streams)",
}
"""How reports and ``--dry-run`` name each scheme."""


def seed_text(seeds: Iterable[int]) -> str:
    """Seeds as ranges, e.g. ``0-9, 12 (11 seeds)``; ``none`` when there are none."""
    ordered = sorted(set(seeds))
    if not ordered:
        return "none"
    parts: list[str] = []
    start = prev = ordered[0]
    for seed in [*ordered[1:], None]:
        if seed is not None and seed == prev + 1:
            prev = seed
            continue
        parts.append(str(start) if start == prev else f"{start}-{prev}")
        if seed is not None:
            start = prev = seed
    return f"{', '.join(parts)} ({len(ordered)} seed{'s' if len(ordered) != 1 else ''})"


def stored_seeding(definition: Mapping[str, Any]) -> str:
    """A stored definition's seeding scheme: its ``seeding``, offset when it has none."""
    return str(definition.get("seeding", UNRECORDED_SEEDING))


EVAL_SETS = ("run", "fixed")
"""Where a run's evaluation episodes come from: ``run``, its own, drawn from its seed's
evaluation stream (a test set no run of another seed shares: a confirm's fresh seeds never
see its search's episodes); ``fixed``, one set every run shares (a study whose definition has no
``eval_set``)."""
EVAL_SET = "run"
"""The evaluation set of a new study."""
UNRECORDED_EVAL_SET = "fixed"
"""The evaluation set of a study whose definition has no ``eval_set``."""
EVAL_EPISODES = 200
"""Evaluation episodes per run of a new study (docs/reference/statistics.md: their standard error
against the margin on Pendulum-v1 and the leg)."""
UNRECORDED_EVAL_EPISODES = 16
"""Evaluation episodes of a study whose definition has no ``eval_episodes`` (a search's always has
one)."""


def _evaluation_part(definition: Mapping[str, Any]) -> Mapping[str, Any]:
    """Where a stored definition keeps its evaluation settings: a search's ``search``
    section, the definition itself for a confirm."""
    search = definition.get("search")
    return search if isinstance(search, Mapping) else definition


def stored_eval_set(definition: Mapping[str, Any]) -> str:
    """A stored definition's evaluation set: its ``eval_set``, fixed when it has none."""
    return str(_evaluation_part(definition).get("eval_set", UNRECORDED_EVAL_SET))


def stored_enqueue(definition: Mapping[str, Any]) -> list[str] | None:
    """A stored search's enqueued ppo configs; None when the definition is not a search's."""
    search = definition.get("search")
    if not isinstance(search, Mapping) or search.get("enqueue") is None:
        return None
    return [str(name) for name in search["enqueue"]]


def stored_eval_episodes(definition: Mapping[str, Any]) -> int | None:
    """A stored definition's evaluation episodes; None when it stores none (a study not
    scored by evaluation)."""
    episodes = _evaluation_part(definition).get("eval_episodes")
    return int(episodes) if episodes is not None else None


def two_objectives(definition: Mapping[str, Any]) -> bool:
    """Whether a stored search definition has a reward and a cost."""
    objective = definition.get("search", {}).get("objective", REWARDS[0])
    return len(objective_names(objective)) == 2


def scored_by_evaluation(definition: Mapping[str, Any]) -> bool:
    """Whether a stored study's runs are scored by the evaluation objective (a confirm of an
    evaluation search stores its objective; every other study is scored by final_reward)."""
    return definition.get("objective") == REWARDS[1]


def stored_floor(definition: Mapping[str, Any]) -> str | None:
    """A stored two-objective search's floor (an enqueued ppo config's name); None for a search
    stored without one (one objective, ``search.floor=null``, or made before floors existed)."""
    floor = definition.get("search", {}).get("floor")
    return str(floor) if floor is not None and two_objectives(definition) else None


def floor_score(trials: Iterable[StoredTrial], floor: str) -> float | None:
    """The score of a search's floor: its complete trial enqueued as ``ppo=<floor>`` (the first
    such attempt); None while none is complete."""
    for trial in trials:
        if (outcome(trial) == Outcome.COMPLETE and TrialAttrs.of(trial).enqueued == f"ppo={floor}"
                and score(trial) is not None):
            return score(trial)
    return None
