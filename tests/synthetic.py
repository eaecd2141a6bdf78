"""Synthetic stores shaped like real ones, for the report's tests and benchmark (a fixture,
not part of the package).

Finished trials are added whole through Optuna with the attributes a real run leaves, and their
curves through the store in one bulk insert, so a store of hundreds of runs takes seconds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import optuna
from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution
from optuna.trial import TrialState, create_trial

from kraby_study.answers.raced import race_record
from kraby_study.decision.race import race
from kraby_study.plan.spec import RaceRules, fingerprint
from kraby_study.records.attributes import CurvePoint, StudyAttrs, TrialAttrs
from kraby_study.records.stored import (
    Failure,
    Outcome,
    diverged_runs,
    ended_runs,
    failure,
    latest_by_key,
    sweep_key,
)
from kraby_study.store.ledger import StudyLedger
from kraby_study.store.store import Store

SETTINGS: dict[str, Any] = {
    "env": {"observation": "default", "delta": 0.5, "time_step": 0.05 / 12, "frameskip": 12,
            "max_episode_steps": 32},
    "ppo": {"n_envs": 32, "n_steps": 32, "batch_size": 1024, "n_epochs": 30, "gamma": 0.8,
            "gae_lambda": 0.95, "clip_range": 0.2, "ent_coef": 0.01, "vf_coef": 0.5,
            "max_grad_norm": 0.5, "learning_rate": 0.01, "net_arch": [64, 64],
            "activation": "tanh"},
}

DIVERGED = failure(Failure.DIVERGED, "the policy's parameters became NaN")


@dataclass
class Run:
    """One run of a synthetic sweep.

    Attributes:
        value: The swept value.
        seed: The run's seed.
        outcome: complete, failed, pruned (a raced value's retry withdrawn once the value was
            dropped) or pending (queued, not run yet).
        final_score: Final score of a complete run.
        wall_time: Training time (s).
        failure: Reason of a failed run.
        curve: (step, mean_reward, wall_time) points; empty for none.
        model_path: Saved model, if any.
    """

    value: Any
    seed: int
    outcome: Outcome = Outcome.COMPLETE
    final_score: float | None = None
    wall_time: float = 10.0
    failure: str | None = None
    curve: list[tuple[int, float, float]] = field(default_factory=list)
    model_path: str | None = None


def learning_curve(final: float, steps: int, points: int, wall_time: float,
                   rng: np.random.Generator, start: float = -4.0) -> list[tuple[int, float, float]]:
    """An exponential approach from ``start`` to ``final`` with noise, evenly binned."""
    every = max(1, steps // points)
    grid = np.arange(1, points + 1) * every
    shape = 1.0 - np.exp(-grid / (0.25 * steps))
    reward = start + (final - start) * shape + rng.normal(0.0, 0.04 * abs(final - start) + 1e-3,
                                                         points)
    clock = wall_time * grid / grid[-1]
    return [(int(s), float(r), float(c)) for s, r, c in zip(grid, reward, clock, strict=True)]


def define(store: Store, name: str, kind: str, definition: dict[str, Any],
           planned: int) -> StudyLedger:
    """A new study of the given kind and definition."""
    attrs = StudyAttrs(kind=kind, definition=definition, fingerprint=fingerprint(definition),
                       planned=planned)
    return store.define(name, attrs, pruner=optuna.pruners.NopPruner())


def add_sweep(store: Store, name: str, parameter: str, values: Sequence[Any],
              runs: Sequence[Run], steps: int = 250_000, curve_every: int = 1000,
              racing: RaceRules | None = None) -> StudyLedger:
    """A sweep study holding the given runs, with the attributes the runner stores; with
    ``racing``, a raced sweep (see :func:`add_raced_sweep`)."""
    definition = {"kind": "sweep", "parameter": parameter, "values": list(values),
                  "settings": SETTINGS, "steps": steps, "curve_every": curve_every}
    if racing is not None:
        definition["racing"] = racing.stored()
    ledger = define(store, name, "sweep", definition, len(runs))
    study = optuna.load_study(study_name=name, storage=store.storage)
    short = parameter.split(".")[-1]
    distribution = CategoricalDistribution(list(values))
    curves: dict[int, list[tuple[int, float, float]]] = {}
    for number, run in enumerate(runs):
        key = sweep_key(list(values).index(run.value), run.seed)
        if run.outcome == Outcome.PENDING:
            ledger.queue({short: run.value}, TrialAttrs(key=key, seed=run.seed))
            continue
        settings = {"env": dict(SETTINGS["env"]), "ppo": dict(SETTINGS["ppo"])}
        settings[parameter.split(".")[0]][short] = run.value
        attrs = TrialAttrs(
            key=key, seed=run.seed, settings=settings, steps=steps, model_path=run.model_path,
            env_steps=steps, wall_time=run.wall_time, started="2025-01-01T00:00:00+00:00",
            ended="2025-01-01T00:10:00+00:00")
        if run.outcome == Outcome.COMPLETE:
            attrs.final_score = run.final_score
            state, value = TrialState.COMPLETE, run.final_score
        elif run.outcome == Outcome.PRUNED:
            attrs.failure = run.failure or "withdrawn: its value was dropped by the race"
            state, value = TrialState.PRUNED, None
        else:
            attrs.failure = run.failure or DIVERGED
            state, value = TrialState.FAIL, None
        study.add_trials([create_trial(state=state, value=value, params={short: run.value},
                                       distributions={short: distribution},
                                       user_attrs=attrs.stored())])
        curves[number] = run.curve
    write_curves(ledger, curves)
    return ledger


def add_raced_sweep(store: Store, name: str, parameter: str, values: Sequence[Any],
                    runs: Sequence[Run], rules: RaceRules, select: str | None = None,
                    steps: int = 250_000, curve_every: int = 1000) -> StudyLedger:
    """A raced sweep as the race leaves it: its definition has a ``racing`` entry (``rules``;
    the runs' seeds must be its ``round_seeds``), its runs are the ones the race made (a value
    the test means dropped has fewer), and the race replayed on them is stored on the study
    (``StudyAttrs.race``) beside the selection rule ``select``."""
    ledger = add_sweep(store, name, parameter, values, runs, steps, curve_every, racing=rules)
    latest = latest_by_key(ledger.trials())
    done = ended_runs(latest, list(rules.round_seeds))
    state = race(list(range(len(values))), done, rules,
                 diverged_runs(latest, list(rules.round_seeds)))
    ledger.update(StudyAttrs(select=select, race=race_record(list(values), state, done)))
    return ledger


def write_curves(ledger: StudyLedger, curves: dict[int, list[tuple[int, float, float]]]) -> None:
    """Store the curves of trials (by trial number), (step, reward, seconds) points, in one
    transaction."""
    ledger.write_curves({number: [CurvePoint(step, reward, clock, 32)
                                  for step, reward, clock in points]
                         for number, points in curves.items()})


def sweep_runs(values: Sequence[Any], seeds: int, points: int, steps: int,
               rng: np.random.Generator, failed: int = 0) -> list[Run]:
    """Runs of a plausible sweep: the middle values do best; ``failed`` runs diverged."""
    runs = []
    middle = (len(values) - 1) / 2
    for index, value in enumerate(values):
        level = -0.4 - 0.12 * (index - middle) ** 2
        for seed in range(seeds):
            final = level + rng.normal(0.0, 0.08)
            wall = 60.0 * (1.0 + 0.3 * index) * rng.uniform(0.9, 1.1)
            runs.append(Run(value=value, seed=seed, final_score=final, wall_time=wall,
                            curve=learning_curve(final, steps, points, wall, rng)))
    for run in runs[len(runs) - failed:]:
        run.outcome, run.final_score = Outcome.FAILED, None
        run.failure = failure(Failure.DIVERGED,
                              "ValueError: invalid values (nan) in the policy's output")
    return runs


def add_search(store: Store, name: str, trials: int, rng: np.random.Generator,
               steps: int = 250_000, checkpoints: int = 10, points: int = 250) -> StudyLedger:
    """A search study: TPE-free random parameters, intermediate values, pruned and failed trials."""
    ledger = define(store, name, "search", {"kind": "search", "steps": steps}, trials)
    study = optuna.load_study(study_name=name, storage=store.storage)
    distributions = {
        "learning_rate": FloatDistribution(1e-4, 1.0, log=True),
        "gamma": FloatDistribution(0.2, 0.9999),
        "n_epochs": IntDistribution(1, 50),
        "activation": CategoricalDistribution(["tanh", "relu"]),
    }
    curves: dict[int, list[tuple[int, float, float]]] = {}
    every = steps // checkpoints
    for number in range(trials):
        params = {
            "learning_rate": float(10 ** rng.uniform(-4, 0)),
            "gamma": float(rng.uniform(0.2, 0.9999)),
            "n_epochs": int(rng.integers(1, 51)),
            "activation": str(rng.choice(["tanh", "relu"])),
        }
        final = (-0.3 - 0.15 * (math.log10(params["learning_rate"]) + 2) ** 2
                 - 0.4 * abs(params["gamma"] - 0.8) + rng.normal(0, 0.05))
        wall = float(rng.uniform(50, 150))
        curve = learning_curve(final, steps, points, wall, rng)
        marks = {(i + 1) * every: float(np.mean([r for s, r, _ in curve
                                                 if i * every < s <= (i + 1) * every]))
                 for i in range(checkpoints)}
        state, value = TrialState.COMPLETE, final
        attrs = TrialAttrs(env_steps=steps, wall_time=wall)
        if number % 5 == 4:
            stop = every * int(rng.integers(2, checkpoints))
            marks = {s: v for s, v in marks.items() if s <= stop}
            curve = [p for p in curve if p[0] <= stop]
            state, value = TrialState.PRUNED, None
            attrs.pruned_at, attrs.env_steps = stop, stop
        elif number % 23 == 22:
            state, value, marks, curve = TrialState.FAIL, None, {}, curve[:20]
            attrs.failure = DIVERGED
        study.add_trials([create_trial(state=state, value=value, params=params,
                                       distributions=distributions, user_attrs=attrs.stored(),
                                       intermediate_values=marks)])
        curves[number] = curve
    write_curves(ledger, curves)
    return ledger


def add_trials(store: Store, name: str, trials: Sequence[optuna.trial.FrozenTrial]) -> None:
    """Add finished trials to a stored study as they are (Optuna's own API: the package's store
    has no door for trials that did not run)."""
    optuna.load_study(study_name=name, storage=store.storage).add_trials(list(trials))


def percentile_p(first: Sequence[float], second: Sequence[float], weight: float = 1.0
                 ) -> tuple[float, float]:
    """The percentile bootstrap's p of "w T_1 - T_2 > 0" and "< 0" (T: IQM), recounted apart
    from the project's tests: each sample's own seeded resamples (decision.robust.seeded, 1,999
    of them) with SciPy's trimmed mean."""
    from scipy import stats

    from kraby_study.decision.robust import seeded

    def drawn(x: Sequence[float]) -> np.ndarray:
        a = np.asarray(x, dtype=float)
        index = seeded(a).integers(0, len(a), size=(1999, len(a)))
        return stats.trim_mean(a[index], 0.25, axis=1)

    contrast = weight * drawn(first) - drawn(second)
    return (1 + float(np.sum(contrast <= 0))) / 2000, (1 + float(np.sum(contrast >= 0))) / 2000


def yuen_p(first: Sequence[float], second: Sequence[float], weight: float = 1.0
           ) -> tuple[float, float]:
    """SciPy's Yuen test (25 % trimmed means, Welch's df) of w x_1 against x_2, both ways."""
    from scipy import stats

    a, b = weight * np.asarray(first, dtype=float), np.asarray(second, dtype=float)
    return (float(stats.ttest_ind(a, b, equal_var=False, trim=0.25,
                                  alternative="greater").pvalue),
            float(stats.ttest_ind(a, b, equal_var=False, trim=0.25, alternative="less").pvalue))


RACE_RULES = RaceRules(seeds=6, round_seeds=tuple(range(6)), min_seeds=4, alpha=0.05)
"""The example race's rules: 6 seeds, looks after rounds 4 to 6 at 0.05 / 3 = 0.0167 each."""
RACE_VALUES = [0.3, 0.1, 0.2]
"""The example race's values in its study file's order (the report sorts them: 0.1, 0.2, 0.3)."""
RACE_FINALS: dict[float, list[float | None]] = {
    0.1: [1.00, 1.02, 0.98, 1.01, -1.0, 3.0],
    0.2: [0.97, 1.01, 0.96, 0.99, -1.0, 2.9],
    0.3: [0.30, 0.35, 0.25, 0.28, None],
}
"""Final scores by seed (None: failed). 0.3 is far below the others over the first four
seeds, so the look after round 4 drops it; its fifth seed, run ahead of the round, failed, and
its sixth was queued and withdrawn. The survivors' later seeds spread so widely that neither
is shown within the margin of the other: the fastest (0.3 at 10 s, then 0.2 at 60 s, against
100 s) cannot buy the selection."""
RACE_WALL = {0.1: 100.0, 0.2: 60.0, 0.3: 10.0}


def race_example_runs(steps: int = 4000, points: int = 40) -> list[Run]:
    """The runs of the example race (:data:`RACE_FINALS`), with curves."""
    rng = np.random.default_rng(7)
    runs = []
    for value in RACE_VALUES:
        wall = RACE_WALL[value]
        for seed, final in enumerate(RACE_FINALS[value]):
            if final is None:
                runs.append(Run(value=value, seed=seed, outcome=Outcome.FAILED, wall_time=wall))
            else:
                runs.append(Run(value=value, seed=seed, final_score=final, wall_time=wall,
                                curve=learning_curve(final, steps, points, wall, rng)))
    runs.append(Run(value=0.3, seed=5, outcome=Outcome.PRUNED, wall_time=0.0))
    return runs


VERDICT_VALUES = [0.01, 0.02, 0.05, 0.1]
VERDICT_FINALS: dict[float, list[float]] = {
    0.01: [1.00, 1.02, 0.98, 1.01, 0.99, 1.00, 1.0, 1.01],
    0.02: [0.99, 1.00, 0.98, 1.01, 0.97, 0.99, 0.99, 1.0],
    0.05: [-1.0, -0.98, -1.02, -1.01, -0.99, -1.0, -1.0, -3.5],
    0.1: [1.1, 0.6, 0.9, 1.2, 0.5, 0.8, 0.9, 0.8],
}
"""A sweep with every answer at the default margin (0.2 x |best IQM| 1.0 = 0.2): 0.01 best,
0.02 equivalent (tight and 0.01 below it), 0.05 worse (2.3 below), 0.1 undecided (0.15 below
with a wide spread: neither shown within the margin nor below it). 0.05's seed at -3.5 is a
failed seed (below the line halfway from the untrained -4 to the best's 1.0); 0.1 has, besides,
a failed run (seed 8)."""


def verdict_runs(steps: int = 4000, points: int = 40) -> list[Run]:
    """The runs of :data:`VERDICT_FINALS`, with curves, and 0.1's failed run."""
    rng = np.random.default_rng(3)
    runs = [Run(value=value, seed=seed, final_score=final, wall_time=10.0 + seed,
                curve=learning_curve(final, steps, points, 10.0 + seed, rng))
            for value, finals in VERDICT_FINALS.items() for seed, final in enumerate(finals)]
    runs.append(Run(value=0.1, seed=8, outcome=Outcome.FAILED, wall_time=3.0))
    return runs
