"""Which tests of the IQM contrast hold alpha where seeds fail: the measurement behind the four
answers' tests (a measurement, not a test).

The four answers of ``comparison.compare`` are about each value's interquartile mean (IQM) and
read their p-values from ``decision.robust``: the percentile bootstrap of the IQM contrast from
8 seeds a side, the larger of it and Yuen's trimmed-mean test from 4, no answer below 4. This
benchmark measures that rule against each of its parts alone, on the cells of
``bench_error_rates.spread_error`` (2 and 4 values, spreads 1:4, normal, failing-seed and
lognormal sigma 1 noise, the others exactly the margin below the best, the wide values the
tested ones or the best) at 3, 4, 5, 6, 8 and 10 seeds, each noise centred on its IQM, so that
every answered "equivalent" or "worse" is wrong:

- ``answers (compare)``: ``comparison.compare`` itself.
- ``Yuen alone``: Yuen's test of 25 % trimmed means with Welch's df
  (``scipy.stats.ttest_ind(trim=0.25)``, independent of the project's code), at every n.
- ``percentile bootstrap alone``: the percentile bootstrap of the IQM contrast (written here
  apart from the project's code), at every n.
- ``Welch t of means``: the same rules on Welch t-tests of the mean contrast (written here),
  on the same cells centred on each noise's mean (their truth).

All but the first put their p-values into compare's rules (the closed Holm step-down for
"worse", Bonferroni multiple comparisons with the best for "equivalent"; a fast test holds that
these rules, fed the project's own p-values, give compare's answers). And the power of each:
the share of truly equal values answered equivalent, and of values truly three margins below
the best answered worse (equal spreads, sd 1 = the margin). Usage::

    python benchmarks/bench_skewed_spreads.py [--simulations 2000] [--workers 2]
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd
from bench_error_rates import (
    LOCATION,
    SPREADS,
    _standard_noise,
    spread_cell,
    table,
    unit_noise,
)
from scipy import stats as sps

from kraby_study.decision.comparison import (
    ALPHA,
    MARGIN,
    compare,
    holm,
    margin_weights,
)
from kraby_study.decision.robust import iqm_pairs

SEED = 20261201
RESAMPLES = 1999
NOISES = ("normal", "failing seed", "right-skewed")
SHAPES = [(k, n) for k in (2, 4) for n in (3, 4, 5, 6, 8, 10)]
POWER_NOISES = ("normal", "failing seed", "right-skewed")
POWER_SHAPES = [(2, 5), (2, 10), (4, 10)]
FAR = 3.0
"""How many margins below the best the truly worse values of the power of "worse" are."""
MEAN_CENTRES = {"normal": 0.0, "heavy-tailed t3": 0.0}

PValues = Callable[[list[np.ndarray], np.ndarray, np.random.Generator],
                   tuple[np.ndarray, np.ndarray]]
"""(samples, weights, generator) -> p of "w_j T_j - T_g > 0" and of "< 0" for every pair
[j, g], NaN where a pair is not tested."""


def trimmed(x: np.ndarray) -> np.ndarray:
    """The 25 % trimmed mean along the last axis (``scipy.stats.trim_mean``)."""
    return np.asarray(sps.trim_mean(x, 0.25, axis=-1))


def yuen(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
         ) -> tuple[np.ndarray, np.ndarray]:
    """Yuen's test of 25 % trimmed means with Welch's df, every pair (equal n) in two calls."""
    x = np.vstack(samples)
    first = np.broadcast_to((w[:, None] * x)[:, None, :], (len(x), *x.shape))
    second = np.broadcast_to(x[None, :, :], (len(x), *x.shape))
    greater = sps.ttest_ind(first, second, axis=-1, equal_var=False, trim=0.25,
                            alternative="greater").pvalue
    less = sps.ttest_ind(first, second, axis=-1, equal_var=False, trim=0.25,
                         alternative="less").pvalue
    return np.asarray(greater), np.asarray(less)


def percentile(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
               ) -> tuple[np.ndarray, np.ndarray]:
    """The percentile bootstrap of every IQM contrast: each value's seeds resampled apart."""
    x = np.vstack(samples)
    k, n = x.shape
    drawn = trimmed(x[np.arange(k)[:, None, None], rng.integers(0, n, size=(k, RESAMPLES, n))])
    contrast = w[:, None, None] * drawn[:, None, :] - drawn[None, :, :]
    return ((1 + np.sum(contrast <= 0, axis=2)) / (1 + RESAMPLES),
            (1 + np.sum(contrast >= 0, axis=2)) / (1 + RESAMPLES))


def project(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
            ) -> tuple[np.ndarray, np.ndarray]:
    """The project's own p-values (``decision.robust.iqm_pairs``), for the rules' check."""
    tests = iqm_pairs(samples, w)
    return tests.greater, tests.less


def welch_means(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Welch t-tests of the mean contrast w_j mean_j - mean_g, for every pair [j, g]
    (Welch-Satterthwaite's df from 4 seeds a side at equal n, min(n) - 1 otherwise): what the
    answers would be on means rather than IQMs."""
    n = np.array([len(x) for x in samples], dtype=float)
    mean = np.array([np.mean(x) for x in samples])
    spread = np.array([np.var(x, ddof=1) for x in samples]) / n
    first = w ** 2 * spread
    se2 = np.add.outer(first, spread)
    with np.errstate(divide="ignore", invalid="ignore"):
        satterthwaite = se2 ** 2 / np.add.outer(first ** 2 / (n - 1), spread ** 2 / (n - 1))
        own = np.equal.outer(n, n) & (np.minimum.outer(n, n) >= 4)
        df = np.where(own, satterthwaite, np.minimum.outer(n, n) - 1)
        t = np.subtract.outer(w * mean, mean) / np.sqrt(se2)
    return sps.t.sf(t, df), sps.t.cdf(t, df)


CANDIDATES: dict[str, PValues | None] = {
    "answers (compare)": None,
    "Yuen alone": yuen,
    "percentile bootstrap alone": percentile,
    "Welch t of means": welch_means,
}
ON_MEANS = "Welch t of means"
"""The candidate whose estimand is the mean: its cells are centred on each noise's mean."""


def answers(samples: list[np.ndarray], fraction: float, tests: PValues,
            rng: np.random.Generator, location: Callable[[np.ndarray], np.ndarray] = trimmed
            ) -> tuple[set[int], set[int]]:
    """The values answered worse and equivalent by compare's rules on other p-values: the best
    the highest ``location``; worse by Holm's step-down on pi_g = min(1, (k - 1) min_j
    p(j > g)); equivalent when not worse and (k - 1) max_j p(j - g < margin) < alpha. An
    untested pair (NaN) shows nothing."""
    k = len(samples)
    centre = np.array([float(location(x)) for x in samples])
    best = int(np.argmax(centre))
    greater, less = tests(samples, margin_weights(centre, fraction), rng)
    greater = np.where(np.isnan(greater), 1.0, greater)
    less = np.where(np.isnan(less), 1.0, less)
    beaten = np.where(np.eye(k, dtype=bool), 1.0, greater)
    worse_p = holm(list(np.minimum(1.0, (k - 1) * beaten.min(axis=0))))
    below = np.where(np.eye(k, dtype=bool), 0.0, less)
    equivalent_p = np.minimum(1.0, (k - 1) * below.max(axis=0))
    worse = {g for g in range(k) if g != best and worse_p[g] < ALPHA}
    equivalent = {g for g in range(k) if g != best and g not in worse
                  and equivalent_p[g] < ALPHA}
    return worse, equivalent


def _noise(name: str, rng: np.random.Generator, kind: str, size: tuple[int, int]
           ) -> np.ndarray:
    """The cells' noise, centred on its IQM, or on its mean for the candidate on means."""
    if name != ON_MEANS:
        return unit_noise(rng, kind, size)
    if kind not in MEAN_CENTRES:
        MEAN_CENTRES[kind] = float(np.mean(_standard_noise(np.random.default_rng(0), kind,
                                                           (4_000_000,))))
    return _standard_noise(rng, kind, size) - MEAN_CENTRES[kind]


def _answered(name: str, x: np.ndarray, fraction: float, rng: np.random.Generator
              ) -> tuple[set[int], set[int]]:
    tests = CANDIDATES[name]
    if tests is None:
        result = compare({g: x[g] for g in range(len(x))}, fraction)
        return set(result.worse), set(result.equivalent)
    location = np.mean if name == ON_MEANS else trimmed
    return answers(list(x), fraction, tests, rng, location)  # type: ignore[arg-type]


def error(job: tuple[str, int, int, str, str, int, int, float]
          ) -> tuple[str, str, str, str, float, float]:
    """P(some value answered equivalent) and P(some value answered worse) on one cell, both
    false there: the others exactly the margin below the best, the wide values (sd 1 against
    0.25) the tested ones or the best."""
    name, k, n, kind, wide, simulations, seed, fraction = job
    rng = np.random.default_rng(seed)
    means, sds = spread_cell(k, wide, fraction)
    false_equivalent = false_worse = 0
    for _ in range(simulations):
        x = means[:, None] + sds[:, None] * _noise(name, rng, kind, (k, n))
        worse, equivalent = _answered(name, x, fraction, rng)
        false_equivalent += bool(equivalent)
        false_worse += bool(worse)
    return (name, f"{k} x {n}", kind, wide, false_equivalent / simulations,
            false_worse / simulations)


def power(job: tuple[str, int, int, str, str, int, int, float]
          ) -> tuple[str, str, str, str, float]:
    """Share of the truly equal values answered equivalent (``equal``), or of the values truly
    :data:`FAR` margins below the best answered worse (``far``); sd 1, the margin."""
    name, k, n, kind, truth, simulations, seed, fraction = job
    rng = np.random.default_rng(seed)
    delta = fraction * abs(LOCATION)
    below = 0.0 if truth == "equal" else FAR * delta
    means = np.array([LOCATION] + [LOCATION - below] * (k - 1))
    found = 0
    for _ in range(simulations):
        x = means[:, None] + _noise(name, rng, kind, (k, n))
        worse, equivalent = _answered(name, x, fraction, rng)
        found += len((equivalent if truth == "equal" else worse) - {0})
    return name, f"{k} x {n}", kind, truth, found / (simulations * (k - 1))


def main() -> None:
    """Run the simulations and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--simulations", type=int, default=2000,
                        help="simulations of each cell (half for power)")
    parser.add_argument("--margin", type=float, default=MARGIN)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    start = time.perf_counter()
    sims, margin = args.simulations, args.margin
    jobs = [(name, k, n, kind, wide, sims, SEED + 1000 * c + 100 * h + 10 * i + j, margin)
            for c, name in enumerate(CANDIDATES) for h, wide in enumerate(("tested", "best"))
            for i, (k, n) in enumerate(SHAPES) for j, kind in enumerate(NOISES)]
    power_jobs = [(name, k, n, kind, truth, sims // 2,
                   SEED + 90_000 + 1000 * c + 100 * t + 10 * i + j, margin)
                  for c, name in enumerate(CANDIDATES) for t, truth in enumerate(("equal", "far"))
                  for i, (k, n) in enumerate(POWER_SHAPES)
                  for j, kind in enumerate(POWER_NOISES)]
    with ProcessPoolExecutor(args.workers) as pool:
        errors = pd.DataFrame(list(pool.map(error, jobs)),
                              columns=["test", "values x seeds", "noise", "wide",
                                       "P(false equivalent)", "P(false worse)"])
        powers = pd.DataFrame(list(pool.map(power, power_jobs)),
                              columns=["test", "values x seeds", "noise", "truth", "power"])
    se = math.sqrt(ALPHA * (1 - ALPHA) / sims)
    narrow, broad = SPREADS
    for kind in NOISES:
        for answer in ("P(false equivalent)", "P(false worse)"):
            part = errors[errors["noise"] == kind]
            print(f"\n{answer}, {kind} noise, sd {narrow:g} against {broad:g} (the margin), the "
                  f"others exactly the margin below the best ({sims:,} simulations a cell, SE "
                  f"{se:.3f} at 0.05):")
            print(table(part.pivot_table(index=["values x seeds", "wide"], columns="test",
                                         values=answer, sort=False).reset_index()))
    print(f"\nPower ({sims // 2:,} simulations each, sd 1 = the margin): equal, the share of "
          f"truly equal values answered equivalent; far, the share of values truly {FAR:g} "
          "margins below the best answered worse:")
    print(table(powers.pivot_table(index=["truth", "values x seeds", "noise"], columns="test",
                                   values="power", sort=False).reset_index()))
    errors["seeds"] = errors["values x seeds"].str.split(" x ").str[1].astype(int)
    errors["worst"] = errors[["P(false equivalent)", "P(false worse)"]].max(axis=1)
    worst = errors.pivot_table(index="seeds", columns="test", values="worst", aggfunc="max",
                               sort=False)
    print(f"\nLargest wrong-answer rate over the skewed and normal cells, by seeds (alpha "
          f"{ALPHA:g}, SE {se:.3f}):")
    print(table(worst.reset_index()))
    print(f"\n{time.perf_counter() - start:.0f} s on {args.workers} worker(s)")


if __name__ == "__main__":
    main()
