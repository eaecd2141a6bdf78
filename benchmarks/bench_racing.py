"""Racing against the fixed design (a measurement, not a test).

Two parts:

- ``--store URL``: replays racing (``kraby_study.decision.race.race``, the rules ``racing.*`` and
  ``compare.margin`` would use; ``--margin``, default ``compare.margin``'s 0.2) on every
  complete fixed-design sweep of a store (every value with all its seeds) and prints, per
  study, the runs the race uses against the fixed design's, the values it drops (shown worse)
  and settles (shown equivalent) and when, the raced selection (the study's own rule, or
  ``--rule``, among the values not dropped, on the seeds the race ran) and whether it lies
  within the margin of the fixed design's best by the fixed design's own IQMs (all seeds;
  the margin in score units: the fraction x the fixed best's |IQM|), and the fixed design's
  best set (the best value and those shown equivalent to it). A replay runs rounds in
  lockstep: a live race may also run up to one round ahead on idle workers (docs/guide/studies.md,
  Racing).
- ``--simulations N``: the race's family-wise error under the global null (every value from
  one distribution, so any drop is false) and its savings and error when one value is 1 or 2 sd
  better, over a grid of shapes and noises (normal or skewed, with or without a part that a
  seed gives every value alike), each with ``N`` simulated races.

Both race with the answers' tests of the IQM (the percentile bootstrap and Yuen's test, both
needed), unpaired by default; ``--paired`` races with their paired forms on the seeds values
share (``racing.paired=true``). The simulations race at margin 0 (their scores are centred
on 0, where a margin relative to the best's |IQM| means nothing):
``benchmarks/bench_error_rates.py`` measures races at a margin.

Usage::

    python benchmarks/bench_racing.py --store sqlite:///quick10.db [--margin 0.2]
        [--rule final_score] [--min-seeds 4] [--alpha 0.05] [--simulations 2000] [--paired]
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from kraby_study.decision.comparison import MARGIN, compare
from kraby_study.decision.measures import auc
from kraby_study.decision.race import race
from kraby_study.decision.robust import iqm
from kraby_study.decision.selection import select
from kraby_study.plan.spec import RaceRules
from kraby_study.records.attributes import SelectRule, StudyKind, TrialAttrs
from kraby_study.records.stored import Outcome, counted, outcome, parse_sweep_key
from kraby_study.records.values import ANSWER_FROM, value_label
from kraby_study.store.store import opened_for_reading

SEED = 20261125
SHAPES = [(3, 10), (5, 10), (8, 10), (12, 10), (5, 5), (8, 20)]
"""Values x seeds of the simulated races (the documented studies have 4 to 8 values)."""


@dataclass(frozen=True)
class Replay:
    """One study's race replayed on its fixed-design runs."""

    study: str
    values: int
    seeds: int
    fixed_runs: int
    raced_runs: int
    dropped: list[str]
    raced_selection: str
    fixed_best_set: list[str]
    settled: list[str]
    """Values the race settled as equivalent, with the round (value@round)."""
    margin: float
    """The margin in score units: the fraction x the fixed design's best |IQM|."""
    within: bool
    """The raced selection's fixed-design IQM is within the margin of the fixed best's."""
    gap: float
    """The fixed best's IQM minus the raced selection's (both on all seeds)."""
    seed_share: float
    """The share of a score's variance that its seed gives every value alike (values with a
    failed run left out): :func:`seed_share`, what paired looks exploit (``rho`` of the
    simulations)."""

    @property
    def inside(self) -> bool:
        """The raced selection is in the fixed design's best set."""
        return self.raced_selection in self.fixed_best_set


def replay_store(url: str, min_seeds: int, alpha: float, paired: bool = False,
                 margin: float = MARGIN, rule: str | None = None) -> list[Replay]:
    """Replay racing on every sweep of the store whose values all have the same number (>= 2)
    of seeds, every run complete or failed."""
    out = []
    with opened_for_reading(url) as store:
        for name in store.study_names():
            ledger = store.load(name)
            attrs = ledger.attrs
            if StudyKind.of(attrs.kind) != StudyKind.SWEEP or attrs.definition.get("racing"):
                continue
            found = replay_study(ledger, min_seeds, alpha, paired, margin, rule)
            if found is not None:
                out.append(found)
    return out


def replay_study(ledger, min_seeds: int, alpha: float,  # noqa: ANN001
                 paired: bool = False, margin: float = MARGIN,
                 rule_name: str | None = None) -> Replay | None:
    """Replay one fixed-design sweep; None when it is not complete (or not rectangular)."""
    attrs = ledger.attrs
    values = list(attrs.definition["values"])
    trials = counted(ledger.trials())
    runs: dict[int, dict[int, float]] = {}
    seconds: dict[int, dict[int, float]] = {}
    numbers: dict[int, dict[int, int]] = {}
    seeds_seen: set[int] = set()
    for trial in trials:
        parsed = parse_sweep_key(trial.user_attrs.get("key"))
        if parsed is None:
            continue
        ended = outcome(trial)
        if ended not in (Outcome.COMPLETE, Outcome.FAILED):
            return None
        value, seed = parsed
        seeds_seen.add(seed)
        runs.setdefault(value, {})[seed] = (float(trial.value) if ended == Outcome.COMPLETE
                                            else math.nan)
        seconds.setdefault(value, {})[seed] = float(TrialAttrs.of(trial).wall_time or math.nan)
        numbers.setdefault(value, {})[seed] = trial.number
    order = sorted(seeds_seen)
    n = len(order)
    if n < 2 or len(runs) != len(values) or any(len(r) != n for r in runs.values()):
        return None
    by_round = {v: {i: runs[v][s] for i, s in enumerate(order)} for v in runs}
    rules = RaceRules(seeds=n, round_seeds=tuple(order), min_seeds=min(min_seeds, n),
                      alpha=alpha, paired=paired, margin=margin)
    state = race(list(range(len(values))), by_round, rules)
    left = {**state.dropped, **state.settled}
    used = {v: left[v].round if v in left else state.rounds for v in range(len(values))}
    rule = SelectRule.check(rule_name, "--rule") if rule_name else SelectRule.of(attrs.select)
    curves = (ledger.curves([t.number for t in trials]) if rule == SelectRule.AUC else None)

    def pick(per_value: dict[int, int]) -> int | None:
        final = {v: [by_round[v][i] for i in range(k) if not math.isnan(by_round[v][i])]
                 for v, k in per_value.items()}
        secs = {v: [seconds[v][order[i]] for i in range(k)] for v, k in per_value.items()}
        aucs: dict[int, list[float]] = {v: [] for v in per_value}
        if curves is not None:
            for v, k in per_value.items():
                for i in range(k):
                    points = curves[curves["number"] == numbers[v][order[i]]]
                    if len(points):
                        aucs[v].append(auc(points["mean_reward"].to_numpy(dtype=float)))
        return select(rule, compare(final, margin), aucs, secs)

    raced = pick({v: used[v] for v in state.candidates})
    full = {v: [x for x in by_round[v].values() if not math.isnan(x)] for v in by_round}
    fixed = compare(full, margin)
    best_set = [fixed.best, *fixed.equivalent] if fixed.best is not None else []
    iqms = {v: float(iqm(np.asarray(x))) if len(x) else math.nan for v, x in full.items()}
    best_iqm = iqms[fixed.best] if fixed.best is not None else math.nan
    units = margin * abs(best_iqm)
    gap = best_iqm - iqms[raced] if raced is not None else math.nan
    label = {v: value_label(values[v]) for v in range(len(values))}
    scores = np.array([[by_round[v][i] for i in range(n)] for v in sorted(by_round)])
    return Replay(
        study=ledger.name, values=len(values), seeds=n, fixed_runs=len(values) * n,
        raced_runs=sum(used.values()),
        dropped=[f"{label[v]}@{d.round}" for v, d in state.dropped.items()],
        raced_selection=label[raced] if raced is not None else "-",
        fixed_best_set=[label[v] for v in best_set],
        settled=[f"{label[v]}@{d.round}" for v, d in state.settled.items()],
        margin=units, within=bool(gap <= units + 1e-12), gap=gap,
        seed_share=seed_share(scores[~np.isnan(scores).any(axis=1)]))


def seed_share(x: np.ndarray) -> float:
    """The seeds' share of the variance in a k values x n seeds table: the intraclass
    correlation ICC(3,1) of Shrout and Fleiss (1979), (MS_seeds - MS_residual) / (MS_seeds +
    (k - 1) MS_residual), from a two-way analysis of variance without replication; NaN with
    fewer than 2 rows or columns."""
    k, n = x.shape
    if k < 2 or n < 2:
        return math.nan
    grand = x.mean()
    seeds = k * ((x.mean(axis=0) - grand) ** 2).sum() / (n - 1)
    residual = x - x.mean(axis=1, keepdims=True) - x.mean(axis=0, keepdims=True) + grand
    error = (residual ** 2).sum() / ((k - 1) * (n - 1))
    return float((seeds - error) / (seeds + (k - 1) * error))


NOISES = [("normal", 0.0), ("normal", 0.4), ("normal", 0.8), ("lognormal", 0.8), ("mixed", 0.8)]
"""(noise, rho: the share of the variance that a seed gives every value alike) of the simulated
races. The quick documented studies measured 0 to 0.53 (the replay's "seed share"); ``mixed``:
half the values with normal and half with lognormal noise (sigma 1), each centred on its mean."""


def noise(rng: np.random.Generator, kind: str, k: int, n: int, rho: float) -> np.ndarray:
    """k x n scores with unit variance and mean 0: a seed's shared part (share ``rho`` of the
    variance) plus each run's own, normal, lognormal (sigma 1) or half of each (``mixed``)."""
    def own(size: tuple[int, int], shape: str) -> np.ndarray:
        if shape == "normal":
            return rng.normal(size=size)
        z = rng.lognormal(0.0, 1.0, size=size)
        return (z - math.exp(0.5)) / math.sqrt((math.e - 1) * math.e)
    if kind == "mixed":
        e = np.vstack([own((k - k // 2, n), "normal"), own((k // 2, n), "lognormal")])
    else:
        e = own((k, n), kind)
    return math.sqrt(rho) * rng.normal(size=(1, n)) + math.sqrt(1 - rho) * e


def simulate(job: tuple[int, int, float, str, float, bool, int, int, int, float]
             ) -> tuple[int, int, float, str, float, float, float, float]:
    """Simulated races: (values, seeds, effect, noise, rho, share of races with a false drop,
    runs used over fixed runs, share of races that dropped the truly best value)."""
    k, n, effect, kind, rho, paired, min_seeds, sims, seed, alpha = job
    rng = np.random.default_rng(seed)
    rules = RaceRules(seeds=n, round_seeds=tuple(range(n)), min_seeds=min(min_seeds, n),
                      alpha=alpha, paired=paired)
    false_drop = 0
    best_dropped = 0
    used = 0
    for _ in range(sims):
        x = noise(rng, kind, k, n, rho)
        x[0] += effect
        state = race(list(range(k)), {v: dict(enumerate(x[v])) for v in range(k)}, rules)
        if effect == 0:
            false_drop += bool(state.dropped)
        best_dropped += 0 in state.dropped
        used += sum(state.dropped[v].round if v in state.dropped else state.rounds
                    for v in range(k))
    return (k, n, effect, kind, rho, false_drop / sims, used / (sims * k * n),
            best_dropped / sims)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--store", help="a store with complete fixed-design sweeps")
    parser.add_argument("--margin", type=float, default=MARGIN,
                        help="the race's margin as a fraction of the best's |IQM| "
                        f"(compare.margin; default {MARGIN:g}, 0: races that drop only values "
                        "shown worse)")
    parser.add_argument("--rule", default=None,
                        help="select by this rule instead of each study's stored one")
    parser.add_argument("--min-seeds", type=int, default=ANSWER_FROM)
    parser.add_argument("--alpha", type=float, default=0.05)
    parser.add_argument("--simulations", type=int, default=0,
                        help="simulated races per shape (0: none)")
    parser.add_argument("--smoke", action="store_true",
                        help="simulate the first shape and noise only (the test suite's run)")
    parser.add_argument("--paired", action="store_true",
                        help="race with the paired tests on the seeds values share "
                        "(racing.paired=true)")
    args = parser.parse_args()
    paired = args.paired
    test = "paired IQM tests" if paired else "IQM tests"
    if args.store:
        start = time.perf_counter()
        replays = replay_store(args.store, args.min_seeds, args.alpha, paired, args.margin,
                               args.rule)
        print(f"racing replayed on {args.store} ({test}, min_seeds {args.min_seeds}, alpha "
              f"{args.alpha:g}, spent equally over the looks; margin {args.margin:g} x the "
              "best's |IQM|):\n")
        print("| study | values x seeds | fixed runs | raced runs | share | dropped (after "
              "round) | settled equivalent (after round) | raced selection | fixed best minus "
              "it (margin, score units) | within the margin | fixed best set | seed share |")
        print("|---|---|---:|---:|---:|---|---|---|---|---|---|---:|")
        for r in replays:
            print(f"| {r.study} | {r.values} x {r.seeds} | {r.fixed_runs} | {r.raced_runs} | "
                  f"{100 * r.raced_runs / r.fixed_runs:.0f} % | {', '.join(r.dropped) or '-'} "
                  f"| {', '.join(r.settled) or '-'} | {r.raced_selection} | {r.gap:.4g} "
                  f"({r.margin:.3g}) | {'yes' if r.within else 'NO'} | "
                  f"{', '.join(r.fixed_best_set)} | {r.seed_share:.2f} |")
        fixed = sum(r.fixed_runs for r in replays)
        raced = sum(r.raced_runs for r in replays)
        if replays:
            print(f"\ntogether: {raced} of {fixed} runs ({100 * raced / fixed:.0f} %); raced "
                  f"selection within the margin of the fixed best in "
                  f"{sum(r.within for r in replays)} of {len(replays)} studies, inside the "
                  f"fixed best set in {sum(r.inside for r in replays)} "
                  f"({time.perf_counter() - start:.1f} s)")
        else:
            print("no complete fixed-design sweep in the store")
    if args.simulations:
        start = time.perf_counter()
        noises, shapes = (NOISES[:1], SHAPES[:1]) if args.smoke else (NOISES, SHAPES)
        jobs = [(k, n, effect, kind, rho, paired, args.min_seeds, args.simulations,
                 SEED + 1000 * m + 7 * i + j, args.alpha)
                for m, (kind, rho) in enumerate(noises) for i, (k, n) in enumerate(shapes)
                for j, effect in enumerate((0.0, 1.0, 2.0))]
        with ProcessPoolExecutor() as pool:
            found = list(pool.map(simulate, jobs))
        print(f"\nsimulated races ({test}, {args.simulations} per row, min_seeds "
              f"{args.min_seeds}, alpha {args.alpha:g}); rho: the share of the variance a seed "
              "gives every value alike; effect: the first value's mean, in sd, above the "
              "others'\n")
        print("| noise | rho | values x seeds | effect | P(any drop) under the null | "
              "runs used / fixed | P(best value dropped) |")
        print("|---|---:|---|---:|---:|---:|---:|")
        worst = 0.0
        for k, n, effect, kind, rho, fwer, share, lost in found:
            fw = f"{fwer:.3f}" if effect == 0 else "-"
            if effect == 0:
                worst = max(worst, fwer)
            print(f"| {kind} | {rho:g} | {k} x {n} | {effect:g} | {fw} | {share:.2f} | "
                  f"{lost:.3f} |")
        mcse = math.sqrt(args.alpha * (1 - args.alpha) / args.simulations)
        print(f"\nmax family-wise error of a race {worst:.3f} over {len(shapes)} shapes x "
              f"{len(noises)} noises (alpha {args.alpha:g}, Monte-Carlo se {mcse:.3f}; "
              f"{time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
