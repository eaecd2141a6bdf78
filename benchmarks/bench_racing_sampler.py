"""Benchmark: which sampler a racing search should ask its challengers from, and by which rule
they leave, on a surrogate of the leg.

Run: python benchmarks/bench_racing_sampler.py --data sqlite:///methods.db --cpu-budget 1592
         [--repetitions 20] [--arms tpe gp random] [--cap 10] [--steps 20480]
         [--trees 200] [--out racing_sampler.csv]

An arm is a sampler (``tpe``, ``gp``, ``random``), or a sampler and overrides of the racing
search joined by ``+``: ``tpe+racing.below=look`` races TPE's challengers under another rule.

A racing search spends most of its CPU training runs, so comparing its samplers on the leg
itself would cost hours per repetition. This benchmark races them on a surrogate instead
(Eggensperger, Hutter, Hoos and Leyton-Brown, AAAI 2015: a regression model fitted on measured
runs stands in for training): the real racing search (``kraby-study optuna --racing``'s own
code: the sampler, the race's decisions, the store, the CPU budget) runs on a pool whose every
run ends at once with the surrogate's score.

**The surrogate**, fitted on every complete leg run of ``--data`` at ``--steps`` steps a run
(searches, campaign sweeps, confirms: each trial's settings and its seeds' scores):

- the mean score of a configuration: a random forest (scikit-learn, ``--trees`` trees) on the
  search space's coordinates (the observation one-hot; log2 of n_steps and of the minibatch
  count; n_epochs, gamma, clip_range, gae_lambda; log10 of learning_rate and ent_coef), fitted
  on the configurations' mean scores weighted by their seeds. Its 5-fold cross-validated
  Spearman correlation with the measured means is printed: a surrogate that does not rank
  configurations says little about samplers;
- a seed's score: that mean plus a residual drawn from the measured seeds' residuals around
  their configuration's mean (configurations with 2 or more seeds, scaled by sqrt(n/(n-1))),
  from the quarter of configurations whose mean is nearest the predicted one (the leg's
  spread differs between good and bad settings). Each (repetition, configuration, seed) draws
  from its own generator, so two samplers that ask the same configuration on the same seed
  see the same score (common random numbers);
- a run's CPU seconds: a second forest on the same coordinates, fitted on log CPU s per seed.

Pruned, failed and diverged runs are not in the data, and every surrogate run completes: the
benchmark says nothing of how a sampler meets settings that diverge.

**The measurement:** for each repetition r and arm, one racing search of ``--cpu-budget``
CPU seconds (``search.sampler``, ``search.seed=r``, ``seed=100r``, from the documented starting
point ``search.enqueue=[start]``, the incumbent's cap ``budget.seeds=--cap``, 2 workers, as
benchmarks/bench_methods.py runs the racing arm), stored in a fresh SQLite file. Its pick is
its incumbent; the pick's worth is the surrogate's mean score of it (no noise: what the pick
is worth, not what its seeds said). The CPU a sampler spends asking counts against the budget
as in a real search.

The table gives per arm the mean worth of its picks with a 95 % Student-t interval over
repetitions, the configurations asked and the seeds the incumbent earned; then, for each pair
of arms, the mean paired difference and the exact two-sided Wilcoxon signed-rank p
(scipy; zero differences dropped), alpha 0.05, n the repetitions.
``--out`` gets one row per search as it ends. A rerun of the same command reads the rows
already there and runs only the searches missing (stop it at any time and rerun it); rows of
another setup (``--data`` with other runs, another budget, cap, steps or trees) stop it with a
message.

Each pair's line reads ``bench_racing_sampler: <first arm> - <second arm> worth difference D
(95 % t CI [lo, hi], n repetitions), exact two-sided Wilcoxon p P``.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import io
import json
import math
import re
import statistics
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import optuna
from bench_head import StubExecutor, StubPool
from bench_search import signed_rank, t_interval
from scipy import stats
from sklearn.ensemble import RandomForestRegressor
from sklearn.model_selection import KFold

import kraby_study as ks
from kraby_study.answers.racing_search import racing_search
from kraby_study.api.optuna_search import search_plan
from kraby_study.errors import ConfigError
from kraby_study.plan.spec import TrialSpec
from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import Outcome
from kraby_study.run.provenance import trial_facts
from kraby_study.run.racing_search import run_racing_search
from kraby_study.store.store import opened

OBSERVATIONS = ["default", "with_tip", "with_tip_to_target", "sin_angles"]
FEATURES = [*(f"obs={o}" for o in OBSERVATIONS), "log2 n_steps", "log2 minibatches",
            "n_epochs", "gamma", "clip_range", "gae_lambda", "log10 learning_rate",
            "log10 ent_coef"]
NOISE_BINS = 4
SAMPLERS = ("tpe", "gp", "random")


def coordinates(settings: Mapping[str, Any]) -> list[float]:
    """A leg configuration's place in the search space (FEATURES, in order)."""
    env, ppo = settings["env"], settings["ppo"]
    rollout = int(ppo["n_steps"]) * int(ppo["n_envs"])
    return [*(float(env["observation"] == o) for o in OBSERVATIONS),
            math.log2(int(ppo["n_steps"])), math.log2(rollout / int(ppo["batch_size"])),
            float(ppo["n_epochs"]), float(ppo["gamma"]), float(ppo["clip_range"]),
            float(ppo["gae_lambda"]), math.log10(float(ppo["learning_rate"])),
            math.log10(max(float(ppo["ent_coef"]), 1e-12))]


def configuration_key(settings: Mapping[str, Any]) -> str:
    """One name for equal settings, whichever study trained them."""
    return json.dumps({"env": settings["env"], "ppo": settings["ppo"]}, sort_keys=True)


@dataclass
class Measured:
    """One configuration's measured seeds at the benchmark's budget."""

    settings: dict[str, Any]
    scores: list[float]
    cpu_per_seed: list[float]


def measured_runs(url: str, steps: int) -> dict[str, Measured]:
    """Every complete leg run of the store at ``steps`` steps a run, by configuration (read with
    Optuna: a trial's ``settings``, its seeds' ``scores`` and its ``cpu_time``)."""
    found: dict[str, Measured] = {}
    for name in optuna.study.get_all_study_names(storage=url):
        study = optuna.load_study(study_name=name, storage=url)
        for trial in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,)):
            attrs = trial.user_attrs
            settings = attrs.get("settings")
            if (not isinstance(settings, dict) or "observation" not in settings.get("env", {})
                    or int(attrs.get("steps") or 0) != steps):
                continue
            scores = [float(s) for s in attrs.get("scores") or [attrs.get("final_score")]
                      if s is not None and math.isfinite(float(s))]
            if not scores:
                continue
            entry = found.setdefault(configuration_key(settings), Measured(settings, [], []))
            entry.scores += scores
            entry.cpu_per_seed.append(float(attrs.get("cpu_time") or 0.0) / len(scores))
    return found


class Surrogate:
    """The leg at one budget, as fitted on measured runs: a configuration's mean score, a
    seed's score (mean plus a measured residual) and a run's CPU seconds."""

    def __init__(self, runs: Mapping[str, Measured], trees: int) -> None:
        configs = list(runs.values())
        self.x = np.array([coordinates(c.settings) for c in configs])
        self.means = np.array([statistics.fmean(c.scores) for c in configs])
        self.weights = np.array([len(c.scores) for c in configs], dtype=float)
        self.trees = trees
        self._cache: dict[str, tuple[float, float]] = {}
        self.mean_model = self._forest(self.x, self.means, self.weights)
        cpu = np.array([math.log(max(statistics.fmean(c.cpu_per_seed), 1e-3)) for c in configs])
        self.cpu_model = self._forest(self.x, cpu, None)
        residuals: list[tuple[float, float]] = []
        for config, mean in zip(configs, self.means, strict=True):
            n = len(config.scores)
            if n >= 2:
                residuals += [(float(mean), (s - mean) * math.sqrt(n / (n - 1)))
                              for s in config.scores]
        if not residuals:
            raise SystemExit("bench_racing_sampler: no configuration of --data has 2 seeds; "
                             "the seed noise cannot be measured")
        residuals.sort()
        # Residual pools by their configuration's mean: NOISE_BINS groups of equal size.
        edges = np.quantile([m for m, _ in residuals], np.linspace(0, 1, NOISE_BINS + 1))
        self.edges = edges[1:-1]
        self.pools = [np.array([r for m, r in residuals
                                if int(np.searchsorted(self.edges, m, side="right")) == b])
                      for b in range(NOISE_BINS)]
        self.pools = [p if len(p) else np.array([r for _, r in residuals]) for p in self.pools]
        self.seeds = len(residuals)

    def _forest(self, x: np.ndarray, y: np.ndarray, weights: np.ndarray | None
                ) -> RandomForestRegressor:
        model = RandomForestRegressor(n_estimators=self.trees, min_samples_leaf=2,
                                      random_state=0, n_jobs=1)
        model.fit(x, y, sample_weight=weights)
        return model

    def cross_validated(self) -> tuple[float, int]:
        """5-fold cross-validated Spearman correlation of predicted and measured configuration
        means, and how many configurations it is over."""
        folds = KFold(n_splits=min(5, len(self.means)), shuffle=True, random_state=0)
        predicted = np.empty_like(self.means)
        for train, test in folds.split(self.x):
            model = self._forest(self.x[train], self.means[train], self.weights[train])
            predicted[test] = model.predict(self.x[test])
        return float(stats.spearmanr(predicted, self.means).statistic), len(self.means)

    def mean(self, settings: Mapping[str, Any]) -> float:
        return self._predicted(settings)[0]

    def cpu(self, settings: Mapping[str, Any]) -> float:
        return self._predicted(settings)[1]

    def _predicted(self, settings: Mapping[str, Any]) -> tuple[float, float]:
        """(mean score, CPU s a run) of a configuration, each predicted once."""
        key = configuration_key(settings)
        if key not in self._cache:
            x = np.array([coordinates(settings)])
            self._cache[key] = (float(self.mean_model.predict(x)[0]),
                                float(math.exp(self.cpu_model.predict(x)[0])))
        return self._cache[key]

    def score(self, settings: Mapping[str, Any], seed: int, repetition: int) -> float:
        """One seed's score: the mean plus a residual drawn by (repetition, configuration,
        seed) from the pool of configurations whose mean is nearest."""
        mean = self.mean(settings)
        pool = self.pools[int(np.searchsorted(self.edges, mean, side="right"))]
        digest = hashlib.sha256(configuration_key(settings).encode()).digest()
        draw = np.random.default_rng([repetition, seed, int.from_bytes(digest[:8], "little")])
        return mean + float(pool[draw.integers(len(pool))])


@dataclass
class Search:
    """What one racing search on the surrogate picked, and what it cost."""

    arm: str
    repetition: int
    worth: float
    """The surrogate's mean score of the pick."""
    iqm: float
    """The pick's IQM over the seeds the search gave it."""
    seeds: int
    configurations: int
    runs: int
    cpu: float
    ask_cpu: float
    """CPU seconds asking the sampler took (counted in ``cpu``)."""
    pick: str
    setup: str = ""
    """What the search ran on: --data, its configurations and seeds, the budget, the cap,
    the steps and the trees (a rerun reuses only rows of the same setup)."""

    @classmethod
    def row(cls, row: Mapping[str, str]) -> Search:
        """A search read back from a row of ``--out``."""
        kinds = {"repetition": int, "seeds": int, "configurations": int, "runs": int,
                 "worth": float, "iqm": float, "cpu": float, "ask_cpu": float}
        return cls(**{key: kinds.get(key, str)(row[key]) for key in cls.__dataclass_fields__})


def run_search(surrogate: Surrogate, arm: str, repetition: int, cpu_budget: float,
               cap: int, steps: int, folder: Path) -> Search:
    """One racing search of ``cpu_budget`` CPU s on the surrogate, in a fresh store; ``arm``
    is a sampler, then any overrides, joined by ``+``."""
    sampler, *overrides = arm.split("+")

    def result(spec: TrialSpec) -> TrialResult:
        score = surrogate.score(spec.settings, spec.seed, repetition)
        cpu = surrogate.cpu(spec.settings)
        return TrialResult(outcome=Outcome.COMPLETE, final_score=score, train_reward=score,
                           scores=[score], env_steps=steps, wall_time=cpu, cpu_time=cpu)

    name = f"surrogate-{re.sub(r'[^A-Za-z0-9_.-]', '_', arm)}-r{repetition}"
    url = f"sqlite:///{folder / name}.db"
    config = ks.compose([
        "budget=quick", f"budget.steps={steps}", f"budget.seeds={cap}", "save_models=false",
        "racing.enabled=true", f"search.sampler={sampler}", f"search.seed={repetition}",
        f"seed={100 * repetition}", "search.enqueue=[start]", f"search.cpu_budget={cpu_budget}",
        "search.trials=100000", f"search.name={name}", f"storage={url}", "workers=2",
        *overrides], command="search")
    plan = search_plan(config)
    facts = trial_facts({"kind": "leg"})
    executor = StubExecutor(lambda size: StubPool(size, facts, result))
    with opened(url) as store:
        run_racing_search(store, plan.cfg, executor, 2, io.StringIO(), live=False,
                          starts=plan.starts)
        ledger = store.load(name)
        trials = ledger.trials()
        found = racing_search(ledger.attrs.definition, trials)
    assert found is not None and found.incumbent is not None
    pick = found.incumbent
    cpu = sum(float(t.user_attrs.get("cpu_time") or 0.0) for t in trials)
    ask = sum(float(t.user_attrs.get("suggest_cpu") or 0.0) for t in trials)
    return Search(arm=arm, repetition=repetition, worth=surrogate.mean(pick.settings),
                  iqm=pick.iqm, seeds=pick.seeds, configurations=len(found.configurations),
                  runs=len(trials), cpu=cpu + ask, ask_cpu=ask, pick=pick.key)


def stored_searches(out: Path, setup: str) -> list[Search]:
    """The searches an earlier run wrote to ``out`` (none when it does not exist); a row of
    another setup stops the benchmark, since its pick was scored on another surrogate."""
    if not out.exists():
        return []
    with out.open(newline="") as handle:
        rows = [Search.row(row) for row in csv.DictReader(handle)]
    other = next((row.setup for row in rows if row.setup != setup), None)
    if other is not None:
        raise SystemExit(f"bench_racing_sampler: {out} holds searches of another setup "
                         f"({other}); give another --out")
    return rows


def append(out: Path, search: Search) -> None:
    """One search's row added to ``out`` (its header first when the file is new)."""
    new = not out.exists()
    with out.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(Search.__dataclass_fields__))
        if new:
            writer.writeheader()
        writer.writerow(search.__dict__)


def fmt(x: float) -> str:
    return f"{x:.4g}"


def table(searches: Sequence[Search], arms: Sequence[str]) -> list[str]:
    """Per arm: mean worth [95 % t interval], configurations, incumbent's seeds, CPU."""
    lines = ["| arm | searches | mean worth of the pick [95 % t CI] | configurations asked "
             "(mean) | incumbent's seeds (mean) | CPU s (mean) | asking CPU s (mean) |",
             "|---|---|---|---|---|---|---|"]
    for arm in arms:
        mine = [s for s in searches if s.arm == arm]
        worth = [s.worth for s in mine]
        low, high = t_interval(worth)
        lines.append(
            f"| {arm} | {len(mine)} | {fmt(statistics.fmean(worth))} [{fmt(low)}, "
            f"{fmt(high)}] | {statistics.fmean(s.configurations for s in mine):.1f} | "
            f"{statistics.fmean(s.seeds for s in mine):.1f} | "
            f"{statistics.fmean(s.cpu for s in mine):,.0f} | "
            f"{statistics.fmean(s.ask_cpu for s in mine):.1f} |")
    return lines


def paired(searches: Sequence[Search], first: str, second: str) -> str:
    """The paired worth difference of two arms over repetitions, with its test."""
    by = {(s.arm, s.repetition): s.worth for s in searches}
    reps = sorted(r for (name, r) in by if name == first and (second, r) in by)
    diffs = [by[(first, r)] - by[(second, r)] for r in reps]
    low, high = t_interval(diffs)
    p, _ = signed_rank(diffs, "two-sided")
    return (f"bench_racing_sampler: {first} - {second} worth difference "
            f"{fmt(statistics.fmean(diffs))} (95 % t CI [{fmt(low)}, {fmt(high)}], "
            f"{len(diffs)} repetitions), exact two-sided Wilcoxon p {p:.3g}")


def parse(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="store of measured leg runs (URL)")
    parser.add_argument("--cpu-budget", type=float, required=True,
                        help="CPU seconds each racing search may use")
    parser.add_argument("--repetitions", type=int, default=20)
    parser.add_argument("--arms", nargs="+", default=["tpe", "gp", "random"],
                        help="SAMPLER or SAMPLER+KEY=VALUE[+KEY=VALUE ...] (tpe, gp, random)")
    parser.add_argument("--cap", type=int, default=10, help="the incumbent's most seeds")
    parser.add_argument("--steps", type=int, default=20480, help="steps a run of --data")
    parser.add_argument("--trees", type=int, default=200)
    parser.add_argument("--out", default="racing_sampler.csv")
    args = parser.parse_args(argv)
    if args.repetitions < 1 or args.cpu_budget <= 0 or args.cap < 4 or len(args.arms) < 2:
        parser.error("needs --repetitions >= 1, --cpu-budget > 0, --cap >= 4 (the race's "
                     "first look) and 2 or more --arms")
    for arm in args.arms:
        sampler, *overrides = arm.split("+")
        if sampler not in SAMPLERS or any("=" not in o for o in overrides):
            parser.error(f"arm {arm!r}: a sampler ({', '.join(SAMPLERS)}), then any "
                         "+KEY=VALUE overrides")
    try:  # every arm's config composes before anything is fitted or run
        for arm in args.arms:
            ks.compose(["racing.enabled=true", f"budget.seeds={args.cap}",
                        *arm.split("+")[1:]], command="search")
    except ConfigError as err:
        parser.error(str(err))
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = parse(argv)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    runs = measured_runs(args.data, args.steps)
    if len(runs) < 10:
        raise SystemExit(f"bench_racing_sampler: {len(runs)} leg configuration(s) at "
                         f"{args.steps} steps in --data; the surrogate needs 10 or more")
    out = Path(args.out)
    setup = (f"data={args.data} configurations={len(runs)} "
             f"seeds={sum(len(r.scores) for r in runs.values())} cpu_budget={args.cpu_budget:g} "
             f"cap={args.cap} steps={args.steps} trees={args.trees}")
    stored = {(s.arm, s.repetition): s for s in stored_searches(out, setup)}
    surrogate = Surrogate(runs, args.trees)
    rho, n = surrogate.cross_validated()
    best = max(surrogate.mean(c.settings) for c in runs.values())
    print(f"surrogate: {n} configurations, {surrogate.seeds} seeds in the noise pools; 5-fold "
          f"cross-validated Spearman rho {rho:.2f} of predicted and measured means; best "
          f"predicted mean of a measured configuration {fmt(best)}", flush=True)
    searches: list[Search] = []
    with tempfile.TemporaryDirectory() as folder:
        for repetition in range(args.repetitions):
            for arm in args.arms:
                began = time.perf_counter()
                found = stored.get((arm, repetition))
                if found is None:
                    found = replace(run_search(surrogate, arm, repetition, args.cpu_budget,
                                               args.cap, args.steps, Path(folder)),
                                    setup=setup)
                    append(out, found)
                    where = f"{time.perf_counter() - began:.0f} s here"
                else:
                    where = f"read from {out}"
                searches.append(found)
                print(f"r{repetition} {arm}: pick {found.pick} worth {fmt(found.worth)} "
                      f"(IQM {fmt(found.iqm)} over {found.seeds} seeds), "
                      f"{found.configurations} configurations, {found.runs} runs, "
                      f"{found.cpu:,.0f} CPU s ({where})", flush=True)
    for line in table(searches, args.arms):
        print(line)
    arms = args.arms
    for i, first in enumerate(arms):
        for second in arms[i + 1:]:
            print(paired(searches, first, second))


if __name__ == "__main__":
    main()
