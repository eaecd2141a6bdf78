"""Tests of the mean measured where the four answers' t-tests do not hold (a measurement).

``bench_error_rates.py`` measures the answers of ``comparison.compare`` with spreads 1:4 and
skewed noise, and finds a false "equivalent" or a false "worse" well above alpha on some cells.
This benchmark measures, on the same cells, other tests of the same contrast
(w_j mu_j - mu_g, :func:`comparison.margin_weights`) in the same decision rules (the closed
Holm step-down for "worse", Bonferroni multiple comparisons with the best for "equivalent"):

- ``Welch t``: ``comparison.compare`` itself (the rules below reproduce it from its p-values).
- ``bootstrap-t``: the studentised bootstrap test of the contrast (Hall and Wilson 1991): each
  value's seeds resampled apart, T* = (C* - C) / se*, p the share of T* at or beyond the
  observed t (one added to both counts); :data:`RESAMPLES` resamples.
- ``Yuen-Welch 20 %``: Yuen's test of 20 % trimmed means with Welch's degrees of freedom
  (``scipy.stats.ttest_ind(trim=0.2)``); it tests trimmed means, not means.
- ``Welch t at alpha / 4``: the same t-tests with both answers decided at 0.0125.
- ``refuse on unequal sds``: Welch's, with no answer drawn from a pair whose sample sds differ
  by more than a factor :data:`SD_RATIO`.
- ``refuse on skewness``: Welch's, with a test refused on the side where the contrast's
  estimated skewness (from the samples' third moments) makes the t-test liberal, beyond
  :data:`SKEW_LIMIT` (the first Edgeworth term of a studentised mean, Hall 1992).
- More seeds: the Welch and bootstrap-t tests at 20 and 40 seeds.

And the power of each: the share of truly equal values answered equivalent, and of values
truly three margins below the best answered worse (equal spreads, sd 1 = the margin). Usage::

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
from bench_error_rates import LOCATION, SPREADS, spread_cell, table, unit_noise
from scipy import stats as sps

from kraby_study.decision.comparison import ALPHA, MARGIN, holm, margin_weights, welch_pairs

SEED = 20240540
RESAMPLES = 999
SD_RATIO = 2.0
SKEW_LIMIT = 0.1
NOISES = ("failing seed", "right-skewed")
SHAPES = [(2, 3), (2, 5), (2, 10), (4, 3), (4, 5), (4, 10)]
MORE_SEEDS = [(2, 20), (2, 40)]
POWER_NOISES = ("normal", "failing seed", "right-skewed")
POWER_SHAPES = [(2, 5), (2, 10), (4, 10)]
FAR = 3.0
"""How many margins below the best the truly worse values of the power of "worse" are."""

PValues = Callable[[list[np.ndarray], np.ndarray, np.random.Generator],
                   tuple[np.ndarray, np.ndarray, float]]
"""(samples, weights, generator) -> p of "w_j mu_j - mu_g > 0" and of "< 0" for every pair
[j, g], and the level at which the answers are decided."""


def welch(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
          ) -> tuple[np.ndarray, np.ndarray, float]:
    """compare's tests: one-sided Welch t-tests of the contrast (``comparison.welch_pairs``)."""
    tests = welch_pairs(samples, w)
    return tests.greater(0.0), tests.less(0.0), ALPHA


def welch_quarter(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray, float]:
    """compare's tests, the answers decided at alpha / 4."""
    greater, less, _ = welch(samples, w, rng)
    return greater, less, ALPHA / 4


def bootstrap_t(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray, float]:
    """Studentised bootstrap test of every contrast w_j mu_j - mu_g (Hall and Wilson 1991):
    the null distribution of t is that of T* = (C* - C) / se* over resamples of each value's
    seeds, drawn apart (the values are independent), so it carries the samples' skewness."""
    n = np.array([len(x) for x in samples], dtype=float)
    mean = np.array([np.mean(x) for x in samples])
    var = np.array([np.var(x, ddof=1) for x in samples])
    drawn = [x[rng.integers(0, len(x), size=(RESAMPLES, len(x)))] for x in samples]
    mean_star = np.array([d.mean(axis=1) for d in drawn])  # (k, B)
    var_star = np.array([d.var(axis=1, ddof=1) for d in drawn])
    contrast = np.subtract.outer(w * mean, mean)
    t = contrast / np.sqrt(np.add.outer(w ** 2 * var / n, var / n))
    c_star = (w[:, None] * mean_star)[:, None, :] - mean_star[None, :, :]
    se_star = np.sqrt((w[:, None] ** 2 * var_star / n[:, None])[:, None, :]
                      + (var_star / n[:, None])[None, :, :])
    with np.errstate(divide="ignore", invalid="ignore"):
        t_star = (c_star - contrast[:, :, None]) / se_star
    # A resample without spread on either side: +-inf, or 0 on the sample's contrast.
    t_star = np.where(np.isnan(t_star), 0.0, t_star)
    greater = (1 + np.sum(t_star >= t[:, :, None], axis=2)) / (RESAMPLES + 1)
    less = (1 + np.sum(t_star <= t[:, :, None], axis=2)) / (RESAMPLES + 1)
    return greater, less, ALPHA


def yuen(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
         ) -> tuple[np.ndarray, np.ndarray, float]:
    """Yuen's test of 20 % trimmed means with Welch's df (``scipy.stats.ttest_ind``, trim 0.2)
    of w_j x_j against x_g, every pair in one call (equal n)."""
    x = np.vstack(samples)
    first = np.broadcast_to((w[:, None] * x)[:, None, :], (len(x), *x.shape))
    second = np.broadcast_to(x[None, :, :], (len(x), *x.shape))
    greater = sps.ttest_ind(first, second, axis=-1, equal_var=False, trim=0.2,
                            alternative="greater").pvalue
    less = sps.ttest_ind(first, second, axis=-1, equal_var=False, trim=0.2,
                         alternative="less").pvalue
    return np.asarray(greater), np.asarray(less), ALPHA


def refuse_unequal_sds(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
                       ) -> tuple[np.ndarray, np.ndarray, float]:
    """Welch's tests; none between two values whose sample sds differ by more than
    :data:`SD_RATIO` (p = 1 both ways)."""
    greater, less, level = welch(samples, w, rng)
    sd = np.array([np.std(x, ddof=1) for x in samples])
    unequal = np.maximum.outer(sd, sd) > SD_RATIO * np.minimum.outer(sd, sd)
    return np.where(unequal, 1.0, greater), np.where(unequal, 1.0, less), level


def refuse_on_skewness(samples: list[np.ndarray], w: np.ndarray, rng: np.random.Generator
                       ) -> tuple[np.ndarray, np.ndarray, float]:
    """Welch's tests; a one-sided test refused (p = 1) where the contrast's estimated skewness
    k3 / se^3, k3 = w_j^3 m3_j / n_j^2 - m3_g / n_g^2 (m3 a sample's third central moment),
    is beyond :data:`SKEW_LIMIT` on the side that makes it liberal: a right-skewed contrast
    gives t a long lower tail, which a test of "< 0" reads as evidence."""
    greater, less, level = welch(samples, w, rng)
    n = np.array([len(x) for x in samples], dtype=float)
    m3 = np.array([np.mean((x - np.mean(x)) ** 3) for x in samples])
    var = np.array([np.var(x, ddof=1) for x in samples])
    k3 = np.subtract.outer(w ** 3 * m3 / n ** 2, m3 / n ** 2)
    se = np.sqrt(np.add.outer(w ** 2 * var / n, var / n))
    skew = k3 / se ** 3
    return (np.where(skew < -SKEW_LIMIT, 1.0, greater), np.where(skew > SKEW_LIMIT, 1.0, less),
            level)


CANDIDATES: dict[str, PValues] = {
    "Welch t (compare)": welch,
    "bootstrap-t": bootstrap_t,
    "Yuen-Welch 20 %": yuen,
    "Welch t at alpha / 4": welch_quarter,
    "refuse on unequal sds": refuse_unequal_sds,
    "refuse on skewness": refuse_on_skewness,
}


def answers(samples: list[np.ndarray], fraction: float, tests: PValues,
            rng: np.random.Generator) -> tuple[set[int], set[int]]:
    """The values answered worse and equivalent by compare's rules on other p-values: the best
    the highest mean; worse by Holm's step-down on pi_g = min(1, (k - 1) min_j p(j > g));
    equivalent when not worse and (k - 1) max_j p(j - g < margin) < the level."""
    k = len(samples)
    means = np.array([np.mean(x) for x in samples])
    best = int(np.argmax(means))
    greater, less, level = tests(samples, margin_weights(means, fraction), rng)
    beaten = np.where(np.eye(k, dtype=bool), 1.0, greater)
    worse_p = holm(list(np.minimum(1.0, (k - 1) * beaten.min(axis=0))))
    below = np.where(np.eye(k, dtype=bool), 0.0, less)
    equivalent_p = np.minimum(1.0, (k - 1) * below.max(axis=0))
    worse = {g for g in range(k) if g != best and worse_p[g] < level}
    equivalent = {g for g in range(k) if g != best and g not in worse
                  and equivalent_p[g] < level}
    return worse, equivalent


def error(job: tuple[str, int, int, str, str, int, int, float]
          ) -> tuple[str, str, str, str, float, float]:
    """P(some value answered equivalent) and P(some value answered worse) on the cells of
    ``bench_error_rates.spread_error``: the others exactly the margin below the best, the
    wide values (sd 1 against 0.25) the tested ones or the best."""
    name, k, n, kind, wide, simulations, seed, fraction = job
    rng = np.random.default_rng(seed)
    means, sds = spread_cell(k, wide, fraction)
    false_equivalent = false_worse = 0
    for _ in range(simulations):
        x = means[:, None] + sds[:, None] * unit_noise(rng, kind, (k, n))
        worse, equivalent = answers(list(x), fraction, CANDIDATES[name], rng)
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
        x = means[:, None] + unit_noise(rng, kind, (k, n))
        worse, equivalent = answers(list(x), fraction, CANDIDATES[name], rng)
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
    jobs += [(name, k, n, kind, wide, sims // 2, SEED + 50_000 + 1000 * c + 100 * h + 10 * i + j,
              margin)
             for c, name in enumerate(("Welch t (compare)", "bootstrap-t"))
             for h, wide in enumerate(("tested", "best"))
             for i, (k, n) in enumerate(MORE_SEEDS) for j, kind in enumerate(NOISES)]
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
                  f"others exactly the margin below the best ({sims:,} simulations a cell at 3 "
                  f"to 10 seeds, SE {se:.3f} at 0.05; {sims // 2:,} at 20 and 40 seeds):")
            print(table(part.pivot_table(index=["values x seeds", "wide"], columns="test",
                                         values=answer, sort=False).reset_index()))
    print(f"\nPower ({sims // 2:,} simulations each, sd 1 = the margin): equal, the share of "
          f"truly equal values answered equivalent; far, the share of values truly {FAR:g} "
          "margins below the best answered worse:")
    print(table(powers.pivot_table(index=["truth", "values x seeds", "noise"], columns="test",
                                   values="power", sort=False).reset_index()))
    grid = errors[errors["values x seeds"].isin([f"{k} x {n}" for k, n in SHAPES])]
    worst = grid.groupby("test", sort=False)[["P(false equivalent)", "P(false worse)"]].max()
    print(f"\nLargest on the grid of 2 and 4 values x 3, 5 and 10 seeds (alpha {ALPHA:g}, "
          f"SE {se:.3f}):")
    print(table(worst.reset_index()))
    print(f"\n{time.perf_counter() - start:.0f} s on {args.workers} worker(s)")


if __name__ == "__main__":
    main()
