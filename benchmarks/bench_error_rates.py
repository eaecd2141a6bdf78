"""Error rates of a report's comparisons and intervals, by simulation (a measurement, not a test).

- Family-wise error under the global null (every value drawn from one distribution, so any
  "worse than the best" is false) over a grid of shapes, values x seeds, with unequal n and
  unequal variances (among them 2 or 3 values of 2 to 4 seeds with sd 1 against 10): the
  answers' step-down at margin 0 (``comparison.compare(..., 0.0).worse``, the IQM's
  tests; nothing below 4 seeds), the tie's closed Holm-Welch step-down of means with min(n) -
  1 df for every pair, and the rule the step-down replaced (Holm over each value's two-sided
  Welch test against the best).
- Power against one truly better value (1 sd above the others): the share of the truly worse
  values called worse, by all three.
- Coverage of every interval a report prints, at n = 2, 3, 4, 5, 10, on normal, left-skewed
  (skew-normal, shape -4), right-skewed (lognormal, sigma 0.5), strongly right-skewed
  (lognormal, sigma 1) and failing-seed (N(0, 1), with probability 0.1 shifted by -4) data.
  The final score, AUC and training-time intervals are one method, ``mean_interval``
  (measured through ``mean_intervals``, of which it is one row): the studentised
  bootstrap (bootstrap-t) interval from 5 seeds on, 2,000 resamples, Hall's skewness-corrected
  t interval below; they share one row. Hall's interval at every n (the learning-curve bands)
  and the plain Student-t interval are measured on the same samples and printed apart (not in
  ``coverage.csv`` nor in the last line), with the mean width of each interval of the mean
  relative to the Student-t interval's. P(improvement)'s Newcombe interval is measured for a
  value 1 sd better, n seeds a side.
- The margin (``comparison.compare`` at ``--margin``, 0.2 x the best's |IQM|, 1 sd here), on
  normal, heavy-tailed, skewed and failing-seed noise, each centred on its IQM (the answers are
  about the IQM, so a value's true location is its IQM): P(some value answered equivalent while
  truly worse by the margin), the others exactly the margin below the best; the power to
  answer a truly equal value equivalent at 5 and 10 seeds; and races at the margin and at three
  times it: P(the race's selection is truly more than the margin below the best), the runs
  they use and how often the 10 seeds' budget cuts them short.
- Unequal spreads with skew: 2 and 4 values x 3, 4, 5, 8 and 10 seeds, sd 0.25 against 1
  (1:4, the wide one's sd the margin), the others exactly the margin below the best, the wide values
  either the tested ones or the best, on normal (the control), failing-seed and right-skewed
  (lognormal sigma 1) noise: P(some value answered equivalent) and P(some value answered worse),
  both false there. The last line's max equivalence error covers these cells too.
- The most-repeatable and fastest rules under equal truths, at unequal n.

``--write-coverage`` stores the coverage table as ``kraby_study/coverage.csv``, from which
reports print the measured coverage of intervals drawn from few seeds, and of any interval
whose measured coverage falls below 0.93. The last line is ``max family-wise error X.XXX over
N shapes (alpha 0.05); min coverage at n>=5 Y.YY; max equivalence error Z.ZZZ``, the coverage
rounded down (0.93 means at least 0.930); the lines before it give it unrounded and the worst
race. Usage::

    python benchmarks/bench_error_rates.py [--simulations 2000] [--coverage-simulations 20000]
        [--race-simulations 1000] [--margin 0.2] [--write-coverage]
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd
from scipy import stats as sps

from kraby_study.decision.comparison import (
    ALPHA,
    ANSWER_FROM,
    MARGIN,
    compare,
    holm,
)
from kraby_study.decision.coverage import COVERAGE_PATH
from kraby_study.decision.intervals import (
    hall_interval,
    iqm_interval,
    mean_intervals,
    t_interval,
)
from kraby_study.decision.measures import iqr, iqr_unbiased, p_improvement_interval
from kraby_study.decision.race import race
from kraby_study.decision.verdict import verdict
from kraby_study.plan.spec import RaceRules

SEED = 20240522
SHAPES: list[tuple[str, list[int], list[float]]] = [
    # (name, seeds per value, sd per value)
    ("2 x 2", [2] * 2, [1.0] * 2),
    ("3 x 3", [3] * 3, [1.0] * 3),
    ("5 x 5", [5] * 5, [1.0] * 5),
    ("8 x 5", [5] * 8, [1.0] * 8),
    ("8 x 10", [10] * 8, [1.0] * 8),
    ("12 x 3", [3] * 12, [1.0] * 12),
    ("12 x 20", [20] * 12, [1.0] * 12),
    ("4, n 2/5/10/20", [2, 5, 10, 20], [1.0] * 4),
    ("6, n 3-10, sd 1-3", [3, 3, 5, 5, 10, 10], [1.0, 3.0, 1.0, 3.0, 1.0, 3.0]),
    ("12, n 2-20, sd 0.5-2", [2, 3, 4, 5, 6, 8, 10, 12, 14, 16, 18, 20],
     [0.5, 2.0] * 6),
    # Equal n, very unequal spreads: Welch-Satterthwaite's df over-rejected here (0.063 at
    # 2 x 2), so below 4 seeds the step-down takes min(n) - 1.
    ("2 x 2, sd 1/10", [2] * 2, [1.0, 10.0]),
    ("2 x 3, sd 1/10", [3] * 2, [1.0, 10.0]),
    ("2 x 4, sd 1/10", [4] * 2, [1.0, 10.0]),
    ("3 x 2, sd 1/1/10", [2] * 3, [1.0, 1.0, 10.0]),
    ("3 x 3, sd 1/10/10", [3] * 3, [1.0, 10.0, 10.0]),
]
POWER_SHAPES = [(3, 3), (3, 5), (5, 5), (5, 10), (8, 5), (8, 10), (12, 10)]
NS = (2, 3, 4, 5, 10)


class FailingSeed:
    """A score whose seed fails now and then: N(0, 1), or with probability ``p`` N(-4, 1) (a
    seed that learns little). The methods the coverage simulation reads of a SciPy
    distribution: rvs, mean, std, ppf (by interpolating the cdf on a fine grid)."""

    def __init__(self, p: float = 0.1, shift: float = -4.0) -> None:
        self.p, self.shift = p, shift
        grid = np.linspace(shift - 9.0, 9.0, 400_001)
        self._grid = grid
        self._cdf = (1 - p) * sps.norm.cdf(grid) + p * sps.norm.cdf(grid - shift)

    def rvs(self, size: tuple[int, ...], random_state: np.random.Generator) -> np.ndarray:
        failed = random_state.random(size) < self.p
        return random_state.normal(size=size) + np.where(failed, self.shift, 0.0)

    def mean(self) -> float:
        return self.p * self.shift

    def std(self) -> float:
        return math.sqrt(1 + self.p * (1 - self.p) * self.shift ** 2)

    def ppf(self, q: np.ndarray) -> np.ndarray:
        return np.interp(q, self._cdf, self._grid)


DISTRIBUTIONS = {"normal": sps.norm(), "skew-normal -4": sps.skewnorm(-4),
                 "lognormal 0.5": sps.lognorm(0.5), "lognormal 1": sps.lognorm(1.0),
                 "failing seed 0.1": FailingSeed()}
"""The coverage grid: normal, skewed either way, strongly right-skewed (lognormal sigma 1: the
mean's intervals cover 0.87 to 0.91 there) and a failing-seed mixture."""


def old_rule(scores: dict[int, np.ndarray]) -> list[int]:
    """The replaced rule: Holm over each value's two-sided Welch p against the best.

    The Welch tests (Welch-Satterthwaite df) are computed here in one vectorised call: one
    ``scipy.stats.ttest_ind`` per pair cost most of the benchmark's time. Simulated samples
    always spread, so no constant-sample rule is needed.
    """
    best = max(scores, key=lambda g: float(np.mean(scores[g])))
    others = [g for g in scores if g != best]
    x = scores[best]
    spread = np.array([np.var(scores[g], ddof=1) / len(scores[g]) for g in others])
    n = np.array([len(scores[g]) for g in others], dtype=float)
    top = np.var(x, ddof=1) / len(x)
    diff = np.mean(x) - np.array([np.mean(scores[g]) for g in others])
    df = (top + spread) ** 2 / (top ** 2 / (len(x) - 1) + spread ** 2 / (n - 1))
    pvalues = 2 * sps.t.sf(np.abs(diff) / np.sqrt(top + spread), df)
    adjusted = holm(list(pvalues))
    return [g for g, p in zip(others, adjusted, strict=True) if p < ALPHA]


def min_df_rule(scores: dict[int, np.ndarray]) -> list[int]:
    """The step-down as it was before: min(n_i, n_j) - 1 df for every pair, also at equal n.

    The same closed Holm step-down as ``compare`` at margin 0 (pi_g = (k - 1) min_j p(j > g),
    Holm over the pi_g, the best never worse), written out here with the old df rule.
    """
    groups = list(scores)
    n = np.array([len(scores[g]) for g in groups], dtype=float)
    mean = np.array([np.mean(scores[g]) for g in groups])
    spread = np.array([np.var(scores[g], ddof=1) for g in groups]) / n
    beats = sps.t.sf(np.subtract.outer(mean, mean) / np.sqrt(np.add.outer(spread, spread)),
                     np.minimum.outer(n, n) - 1)
    np.fill_diagonal(beats, np.nan)
    pi = np.minimum(1.0, (len(groups) - 1) * np.nanmin(beats, axis=0))
    best = groups[int(np.argmax(mean))]
    adjusted = holm(list(pi))
    return [g for g, p in zip(groups, adjusted, strict=True) if g != best and p < ALPHA]


def draw(rng: np.random.Generator, ns: list[int], sds: list[float],
         means: list[float] | None = None) -> dict[int, np.ndarray]:
    means = means or [0.0] * len(ns)
    return {g: rng.normal(m, s, n) for g, (n, s, m) in enumerate(zip(ns, sds, means, strict=True))}


def family_wise(job: tuple[str, list[int], list[float], int, int]
                ) -> tuple[str, float, float, float]:
    """P(some value called worse) under the global null: the step-down, the step-down with
    min(n) - 1 df everywhere, and the old rule."""
    name, ns, sds, simulations, seed = job
    rng = np.random.default_rng(seed)
    new = before = old = 0
    for _ in range(simulations):
        scores = draw(rng, ns, sds)
        new += bool(compare(scores, 0.0).worse)
        before += bool(min_df_rule(scores))
        old += bool(old_rule(scores))
    return name, new / simulations, before / simulations, old / simulations


def power(job: tuple[int, int, int, int]) -> tuple[str, float, float, float]:
    """Share of the truly worse values called worse, one value 1 sd better: the step-down,
    the step-down with min(n) - 1 df everywhere, and the old rule."""
    k, n, simulations, seed = job
    rng = np.random.default_rng(seed)
    new = before = old = 0
    for _ in range(simulations):
        scores = draw(rng, [n] * k, [1.0] * k, [1.0] + [0.0] * (k - 1))
        new += len(set(compare(scores, 0.0).worse) - {0})
        before += len(set(min_df_rule(scores)) - {0})
        old += len(set(old_rule(scores)) - {0})
    calls = simulations * (k - 1)
    return f"{k} x {n}", new / calls, before / calls, old / calls


MEAN_INTERVAL = ("mean: Hall's t below 5 seeds, bootstrap-t from 5 (final score, AUC, "
                 "training time)")
HALL = "mean Hall skewness-corrected t at every n (learning-curve bands)"
PLAIN = "mean plain Student-t interval (replaced)"
COMPARED = (HALL, PLAIN)


def true_iqm(dist: object) -> float:
    q = np.linspace(0.25, 0.75, 200_001)
    return float(np.mean(dist.ppf(q)))  # type: ignore[attr-defined]


def coverage(job: tuple[str, int, int, int]) -> list[dict[str, object]]:
    """Coverage of each interval for one distribution and n."""
    name, n, simulations, seed = job
    dist = DISTRIBUTIONS[name]
    rng = np.random.default_rng(seed)
    mu, sd = float(dist.mean()), float(dist.std())
    iqm_truth = true_iqm(dist)
    big = dist.rvs(size=(2, 400_000), random_state=rng)
    improvement_truth = float(np.mean(big[0] + sd > big[1]))
    # Every sample drawn at once: one scipy rvs call per sample costs as much as an interval.
    samples = dist.rvs(size=(simulations, 3, n), random_state=rng)
    iqm_hits = 0
    for x in samples[:, 0]:
        low, high = iqm_interval(x)
        iqm_hits += low <= iqm_truth <= high
    first = samples[:, 0]
    # The report's interval of a mean, all samples at once (mean_interval is one row of it).
    _, low, high = mean_intervals(first)
    mean_hits = int(np.sum((low <= mu) & (mu <= high)))
    mean_width = float(np.sum(high - low))
    centred = first - first.mean(axis=1, keepdims=True)
    skewness = np.mean(centred ** 3, axis=1) / np.mean(centred ** 2, axis=1) ** 1.5
    hall_low, hall_high = hall_interval(first.mean(axis=1), first.std(axis=1, ddof=1), n,
                                              skewness)
    low, high = t_interval(first.mean(axis=1), first.std(axis=1, ddof=1), n)
    plain_hits = int(np.sum((low <= mu) & (mu <= high)))
    hall_hits = int(np.sum((hall_low <= mu) & (mu <= hall_high)))
    plain_width = float(np.mean(high - low))
    widths = {MEAN_INTERVAL: mean_width / simulations / plain_width,
              HALL: float(np.mean(hall_high - hall_low)) / plain_width}
    improvement_hits = 0
    for better, other in zip(samples[:, 1] + sd, samples[:, 2], strict=True):
        low, high = p_improvement_interval(better, other)
        improvement_hits += low <= improvement_truth <= high
    return [
        {"interval": MEAN_INTERVAL, "distribution": name,
         "n": n, "coverage": mean_hits / simulations, "simulations": simulations},
        {"interval": HALL, "distribution": name,
         "n": n, "coverage": hall_hits / simulations, "simulations": simulations},
        {"interval": PLAIN, "distribution": name,
         "n": n, "coverage": plain_hits / simulations, "simulations": simulations},
        *({"interval": f"width: {interval}", "distribution": name, "n": n,
           "coverage": width, "simulations": simulations}
          for interval, width in widths.items()),
        {"interval": "IQM trimmed-t interval", "distribution": name, "n": n,
         "coverage": iqm_hits / simulations, "simulations": simulations},
        {"interval": "P(improvement) Newcombe interval", "distribution": name, "n": n,
         "coverage": improvement_hits / simulations, "simulations": simulations},
    ]


def repeatable(simulations: int, seed: int) -> dict[str, float]:
    """P(the n = 2 value is the most repeatable) against an n = 10 value, one distribution."""
    rng = np.random.default_rng(seed)
    raw = fair = 0
    for _ in range(simulations):
        a, b = rng.normal(size=2), rng.normal(size=10)
        raw += iqr(a) < iqr(b)
        fair += iqr_unbiased(a) < iqr_unbiased(b)
    return {"raw IQR": raw / simulations, "rescaled IQR": fair / simulations}


def fastest(simulations: int, seed: int) -> dict[str, float]:
    """P(the value that lost seeds is fastest): 3 against 10 complete seeds, one distribution of
    seconds to the threshold (lognormal, median 55 s); runs end at 80 s, so about 10 % of seeds
    never reach it."""
    rng = np.random.default_rng(seed)
    old = new = decided = 0
    end = 80.0
    for _ in range(simulations):
        times = [rng.lognormal(4.0, 0.3, n) for n in (3, 10)]
        reached = [t[t < end] for t in times]
        means = [float(np.mean(r)) if len(r) else math.nan for r in reached]
        old += means[0] < means[1] or (np.isnan(means[1]) and not np.isnan(means[0]))
        restricted = {g: (float(np.mean(np.minimum(t, end))) if len(r) else math.nan)
                      for g, (t, r) in enumerate(zip(times, reached, strict=True))}
        result = verdict(compare({0: [0.0] * 3, 1: [0.0] * 10}, 0.0), {}, restricted, {})
        new += result.fastest == 0
        decided += result.fastest is not None
    return {"old (mean over seeds that reached)": old / simulations,
            "restricted mean (non-reaching at the run's end)": new / max(decided, 1)}


LOCATION = -5.0
"""True mean of the best value in the margin's simulations: with unit noise and the default
margin 0.2 x |best mean|, the margin is 1 sd."""
NOISES = ("normal", "heavy-tailed t3", "skewed", "failing seed")
"""Noises of the margin's simulations, each with mean 0 and sd 1: normal; Student's t with 3
df (heavy tails); minus a lognormal with sigma 1 (a long lower tail, as a seed that learns
less); a failing seed (N(0, 1), with probability 0.1 shifted by -4)."""
EQUIVALENCE_SHAPES = [(2, 3), (2, 5), (2, 10), (3, 5), (5, 5), (5, 10), (8, 10)]
POWER_EQUIVALENCE = [(2, 5), (2, 10), (5, 5), (5, 10)]
SPREAD_NOISES = ("normal", "failing seed", "right-skewed")
"""Noises of the unequal-spread cells: normal (the control), the failing seed, and a lognormal
with sigma 1 (a long upper tail, skewness 6.2)."""
SPREAD_SHAPES = [(2, 3), (2, 4), (2, 5), (2, 8), (2, 10), (4, 3), (4, 4), (4, 5), (4, 8), (4, 10)]
"""3, 5 and 10 seeds, the fewest seeds answered (4, ``ANSWER_FROM``; 3 is refused) and 8."""
WIDE = ("tested", "best")
"""Which values of an unequal-spread cell spread four times as much as the others: the values
tested (on the margin), or the best."""
SPREADS = (0.25, 1.0)
"""Sd of the narrow and the wide values of the unequal-spread cells (1:4): the wide one's sd is
the margin at the default (0.2 x |LOCATION|), where "equivalent" can be answered at 5 and 10
seeds; with the narrow one's sd the margin, it almost never is, and a false "equivalent" cannot
be seen."""
RACE_SHAPES = [(3, 10), (5, 10), (8, 10)]
RACE_CONFIGS = ("slippage", "spaced")
"""Means of the raced values: ``slippage``, the best one margin above all the others (the
indifference zone's least favourable configuration); ``spaced``, a half margin apart."""


LOGNORMAL_SD = math.sqrt((math.e - 1) * math.e)
"""Sd of a lognormal with sigma 1."""
FAILING_SD = math.sqrt(1 + 0.09 * 16)
"""Sd of the failing-seed mixture: N(0, 1), with probability 0.1 shifted by -4."""


def _standard_noise(rng: np.random.Generator, kind: str, size: tuple[int, ...]) -> np.ndarray:
    """Noise of one of :data:`NOISES` or :data:`SPREAD_NOISES` with sd 1, before centring."""
    if kind == "normal":
        return rng.normal(size=size)
    if kind == "heavy-tailed t3":
        return rng.standard_t(3, size=size) / math.sqrt(3.0)
    if kind in ("skewed", "right-skewed"):
        z = rng.lognormal(0.0, 1.0, size=size) / LOGNORMAL_SD
        return -z if kind == "skewed" else z
    failed = rng.random(size) < 0.1
    return (rng.normal(size=size) + np.where(failed, -4.0, 0.0)) / FAILING_SD


def noise_iqm(kind: str) -> float:
    """The population interquartile mean of :func:`_standard_noise`'s ``kind``: the mean of its
    quantile function over (0.25, 0.75), by the midpoint rule on 200,000 steps."""
    q = (np.arange(200_000) + 0.5) / 200_000 * 0.5 + 0.25
    if kind in ("normal", "heavy-tailed t3"):
        return 0.0  # symmetric about 0
    if kind in ("skewed", "right-skewed"):
        lognormal = float(np.mean(sps.lognorm(1.0).ppf(q))) / LOGNORMAL_SD
        return -lognormal if kind == "skewed" else lognormal
    return float(np.mean(FailingSeed().ppf(q))) / FAILING_SD


_CENTRES: dict[str, float] = {}


def unit_noise(rng: np.random.Generator, kind: str, size: tuple[int, ...]) -> np.ndarray:
    """Noise of one of :data:`NOISES` or :data:`SPREAD_NOISES`, sd 1, centred on its
    interquartile mean (:func:`noise_iqm`): the four answers are about each value's IQM, so a
    value's true location in these simulations is its IQM. For the symmetric noises it is also
    the mean."""
    if kind not in _CENTRES:
        _CENTRES[kind] = noise_iqm(kind)
    return _standard_noise(rng, kind, size) - _CENTRES[kind]


def equivalence_error(job: tuple[int, int, str, int, int, float]
                      ) -> tuple[str, str, float, float]:
    """P(some value answered equivalent while truly worse by the margin): the best at
    :data:`LOCATION`, the k - 1 others exactly the margin below it (the least favourable
    case), the margin ``fraction`` x |best mean| read from the data as the report reads it.
    Also P(any wrong answer there): one of the others answered equivalent or worse (at the
    margin's edge, "worse by more than the margin" is false too), or the true best answered
    worse."""
    k, n, kind, simulations, seed, fraction = job
    rng = np.random.default_rng(seed)
    delta = fraction * abs(LOCATION)
    means = np.array([LOCATION] + [LOCATION - delta] * (k - 1))
    wrong = anything = 0
    for _ in range(simulations):
        x = means[:, None] + unit_noise(rng, kind, (k, n))
        result = compare({g: x[g] for g in range(k)}, fraction)
        wrong += any(g != 0 for g in result.equivalent)
        anything += any(g != 0 for g in result.equivalent) or bool(result.worse)
    return f"{k} x {n}", kind, wrong / simulations, anything / simulations


def spread_cell(k: int, wide: str, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """The true means and sds of an unequal-spread cell: the best at :data:`LOCATION`, the
    k - 1 others exactly the margin below it; the wide values (the larger of
    :data:`SPREADS`) the tested ones (``wide`` "tested") or the best ("best")."""
    delta = fraction * abs(LOCATION)
    means = np.array([LOCATION] + [LOCATION - delta] * (k - 1))
    narrow, broad = SPREADS
    sds = np.array([broad if wide == "best" else narrow]
                   + [broad if wide == "tested" else narrow] * (k - 1))
    return means, sds


def spread_error(job: tuple[int, int, str, str, int, int, float]
                 ) -> tuple[str, str, str, float, float]:
    """Unequal spreads (1:4, :data:`SPREADS`) with skew: the best at :data:`LOCATION`, the
    k - 1 others exactly the margin below it, the ``wide`` values (the tested ones or the best)
    four times as spread as the others. P(some other value answered equivalent), false since
    each is truly on the margin; and P(some value answered worse), false since none is more
    than the margin below the best."""
    k, n, kind, wide, simulations, seed, fraction = job
    rng = np.random.default_rng(seed)
    means, sds = spread_cell(k, wide, fraction)
    equivalent = worse = 0
    for _ in range(simulations):
        x = means[:, None] + sds[:, None] * unit_noise(rng, kind, (k, n))
        result = compare({g: x[g] for g in range(k)}, fraction)
        equivalent += any(g != 0 for g in result.equivalent)
        worse += bool(result.worse)
    return f"{k} x {n}", kind, wide, equivalent / simulations, worse / simulations


def equivalence_power(job: tuple[int, int, str, int, int, float]) -> tuple[str, str, float]:
    """Share of the truly equal values answered equivalent: k values of one mean, n seeds."""
    k, n, kind, simulations, seed, fraction = job
    rng = np.random.default_rng(seed)
    found = 0
    for _ in range(simulations):
        x = LOCATION + unit_noise(rng, kind, (k, n))
        found += len(compare({g: x[g] for g in range(k)}, fraction).equivalent)
    return f"{k} x {n}", kind, found / (simulations * (k - 1))


def race_selection(job: tuple[int, int, str, str, int, int, float]
                   ) -> tuple[str, str, str, float, float, float, float]:
    """Races at the margin (min_seeds 4, alpha 0.05 over the looks): P(the selection, the
    highest mean on all their seeds among the values not dropped, is truly more than the
    margin below the best), the runs used over the fixed design's, and the share of races
    cut by the seeds' budget with more than one value still racing (truncation)."""
    k, n, kind, config, simulations, seed, fraction = job
    rng = np.random.default_rng(seed)
    delta = fraction * abs(LOCATION)
    step = delta if config == "slippage" else delta / 2
    means = np.array([LOCATION] + [LOCATION - (step if config == "slippage" else step * i)
                                   for i in range(1, k)])
    rules = RaceRules(seeds=n, round_seeds=tuple(range(n)), min_seeds=ANSWER_FROM, alpha=ALPHA,
                      margin=fraction)
    outside = truncated = used = 0
    for _ in range(simulations):
        x = means[:, None] + unit_noise(rng, kind, (k, n))
        state = race(list(range(k)), {v: dict(enumerate(x[v])) for v in range(k)}, rules)
        left = {**state.dropped, **state.settled}
        runs = {v: left[v].round if v in left else state.rounds for v in range(k)}
        chosen = max(state.candidates, key=lambda v: float(np.mean(x[v, :runs[v]])))
        outside += means[chosen] < means.max() - delta
        truncated += len(state.survivors) > 1
        used += sum(runs.values())
    return (f"{k} x {n}", kind, config, delta, outside / simulations,
            used / (simulations * k * n), truncated / simulations)


def noisy_cheap(job: tuple[int, int, int, float]) -> tuple[int, float, float]:
    """The reviewer's front (issue 35): six candidates, five of the best mean with sd 1, and a
    cheap one 1.5 sd below them with sd 3. P(the cheap one is selected) by fastest_equivalent
    (among those shown within the margin, 1 sd here), and how often it is the best, which
    every rule then selects; selecting it is wrong, it is beyond the margin."""
    n, simulations, seed, fraction = job
    rng = np.random.default_rng(seed)
    evidence = best = 0
    for _ in range(simulations):
        scores = {g: LOCATION + rng.normal(size=n) for g in range(5)}
        scores[5] = LOCATION - 1.5 + 3.0 * rng.normal(size=n)
        result = compare(scores, fraction)
        # It is the cheapest, so each rule selects it when it admits it, or when it is best.
        evidence += result.best == 5 or 5 in result.equivalent
        best += result.best == 5
    return n, evidence / simulations, best / simulations


def table(frame: pd.DataFrame) -> str:
    columns = list(frame.columns)
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for row in frame.itertuples(index=False):
        lines.append("| " + " | ".join(f"{v:.3f}" if isinstance(v, float) else str(v)
                                       for v in row) + " |")
    return "\n".join(lines)


def wide_table(cover: pd.DataFrame) -> pd.DataFrame:
    """The coverage rows as one row per interval and distribution, one column per n."""
    wide = cover.pivot_table(index=["interval", "distribution"], columns="n",
                             values="coverage", sort=False).reset_index()
    wide.columns = [c if isinstance(c, str) else f"n={c}" for c in wide.columns]
    return wide


def main() -> None:
    """Run the simulations, print the tables and the summary line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--simulations", type=int, default=2000,
                        help="simulations of each family-wise error shape (half for power)")
    parser.add_argument("--coverage-simulations", type=int, default=20_000,
                        help="simulations of each interval, distribution and n (Monte-Carlo "
                             "SE 0.0015 at 0.95)")
    parser.add_argument("--race-simulations", type=int, default=1000,
                        help="simulated races of each shape, noise and configuration")
    parser.add_argument("--margin", type=float, default=MARGIN,
                        help="the margin as a fraction of the best's |IQM| (compare.margin; "
                             f"default {MARGIN:g}: 1 sd in these simulations)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--write-coverage", action="store_true",
                        help=f"store the coverage table as {COVERAGE_PATH}")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    start = time.perf_counter()
    sims = args.simulations
    with ProcessPoolExecutor(args.workers) as pool:
        fwer = list(pool.map(family_wise, [(name, ns, sds, sims, SEED + i)
                                           for i, (name, ns, sds) in enumerate(SHAPES)]))
        powers = list(pool.map(power, [(k, n, sims // 2, SEED + 100 + i)
                                       for i, (k, n) in enumerate(POWER_SHAPES)]))
        jobs = [(name, n, args.coverage_simulations, SEED + 200 + 10 * i + j)
                for i, name in enumerate(DISTRIBUTIONS) for j, n in enumerate(NS)]
        covered = [row for rows in pool.map(coverage, jobs) for row in rows]
        margin = args.margin
        equivalence = list(pool.map(equivalence_error, [
            (k, n, kind, sims, SEED + 500 + 10 * i + j, margin)
            for i, (k, n) in enumerate(EQUIVALENCE_SHAPES) for j, kind in enumerate(NOISES)]))
        spread = list(pool.map(spread_error, [
            (k, n, kind, wide, sims, SEED + 2000 + 100 * h + 10 * i + j, margin)
            for h, wide in enumerate(WIDE) for i, (k, n) in enumerate(SPREAD_SHAPES)
            for j, kind in enumerate(SPREAD_NOISES)]))
        found = list(pool.map(equivalence_power, [
            (k, n, kind, sims // 2, SEED + 700 + 10 * i + j, margin)
            for i, (k, n) in enumerate(POWER_EQUIVALENCE) for j, kind in enumerate(NOISES)]))
        # The race at the margin, and at three times it, where it can settle values.
        raced = list(pool.map(race_selection, [
            (k, n, kind, config, args.race_simulations,
             SEED + 900 + 1000 * m + 100 * c + 10 * i + j, fraction)
            for m, fraction in enumerate((margin, min(1.0, 3 * margin)))
            for c, config in enumerate(RACE_CONFIGS) for i, (k, n) in enumerate(RACE_SHAPES)
            for j, kind in enumerate(NOISES)]))
    se = math.sqrt(ALPHA * (1 - ALPHA) / sims)
    fwer_frame = pd.DataFrame(fwer, columns=["values x seeds", "FWER step-down",
                                             "FWER step-down, min(n) - 1 df",
                                             "FWER old rule"])
    print(f"Family-wise error under the global null ({sims:,} simulations each, "
          f"Monte-Carlo SE {se:.3f} at 0.05):")
    print(table(fwer_frame))
    print(f"\nPower: share of truly worse values called worse, one value 1 sd better "
          f"({sims // 2:,} simulations each):")
    print(table(pd.DataFrame(powers, columns=["values x seeds", "step-down",
                                              "step-down, min(n) - 1 df", "old rule"])))
    measured = pd.DataFrame(covered)
    width_rows = measured["interval"].str.startswith("width: ")
    widths = measured[width_rows].assign(interval=lambda f: f["interval"].str[7:])
    compared = measured[measured["interval"].isin(COMPARED)]
    cover = measured[~width_rows & ~measured["interval"].isin(COMPARED)].reset_index(drop=True)
    cover_se = math.sqrt(0.95 * 0.05 / args.coverage_simulations)
    print(f"\nCoverage of the 95 % intervals ({args.coverage_simulations:,} simulations each, "
          f"Monte-Carlo SE {cover_se:.4f} at 0.95):")
    print(table(wide_table(cover)))
    print("\nFor comparison, on the same samples: Hall's interval at every n (the learning-curve "
          "bands; the summary's from 2 to 4 seeds) and the plain Student-t interval:")
    print(table(wide_table(compared)))
    print("\nMean width of the intervals of the mean over the mean width of the Student-t "
          "interval (same samples):")
    print(table(wide_table(widths)))
    print("\nRules under equal truths:")
    for what, shares in (("most repeatable: P(n=2 value beats an n=10 value)",
                          repeatable(sims, SEED + 300)),
                         ("fastest: P(3-seed value beats a 10-seed value | a value is fastest)",
                          fastest(sims, SEED + 400))):
        print(f"- {what}: " + ", ".join(f"{k} {v:.3f}" for k, v in shares.items()))
    print(f"\nThe margin ({args.margin:g} x the best's |IQM|, 1 sd here; {sims:,} simulations "
          f"each, Monte-Carlo SE {se:.3f} at 0.05). P(some value answered equivalent while "
          "truly worse by the margin), the k - 1 others exactly the margin below the best:")
    eq_frame = pd.DataFrame(equivalence, columns=["values x seeds", "noise", "P(false equivalent)",
                                                  "P(any wrong answer)"])
    print(table(eq_frame.pivot_table(index="values x seeds", columns="noise",
                                     values="P(false equivalent)", sort=False).reset_index()))
    print("\nOn the same simulations, P(any wrong answer): an other value answered equivalent or "
          "worse, or the true best answered worse (the two kinds together, at most 2 alpha by "
          "Bonferroni):")
    print(table(eq_frame.pivot_table(index="values x seeds", columns="noise",
                                     values="P(any wrong answer)", sort=False).reset_index()))
    spread_frame = pd.DataFrame(spread, columns=["values x seeds", "noise", "wide",
                                                 "P(false equivalent)", "P(false worse)"])
    narrow, broad = SPREADS
    print(f"\nUnequal spreads with skew ({sims:,} simulations each, Monte-Carlo SE {se:.3f} at "
          f"0.05): sd {narrow:g} against {broad:g} (the margin), the others exactly the margin "
          "below the best; wide: the values tested are the wide ones, or the best is. "
          "P(some value answered equivalent) and P(some value answered worse), both false here:")
    print(table(spread_frame.pivot_table(
        index=["values x seeds", "wide"], columns="noise",
        values=["P(false equivalent)", "P(false worse)"], sort=False).pipe(
            lambda f: f.set_axis([f"{a}, {b}" for a, b in f.columns], axis=1)).reset_index()))
    print(f"\nPower: share of truly equal values answered equivalent ({sims // 2:,} "
          "simulations each):")
    print(table(pd.DataFrame(found, columns=["values x seeds", "noise", "power"]).pivot_table(
        index="values x seeds", columns="noise", values="power", sort=False).reset_index()))
    cheap = [noisy_cheap((n, sims, SEED + 1500 + n, margin)) for n in (3, 10)]
    print("\nThe noisy cheap candidate: six front trials, the cheap one 1.5 sd below the five "
          f"others with three times their sd; P(it is selected) ({sims:,} simulations each):")
    print(table(pd.DataFrame(cheap, columns=["seeds", "fastest_equivalent",
                                             "final_score (it is the best)"])))
    race_frame = pd.DataFrame(raced, columns=["values x seeds", "noise", "means",
                                              "margin (sd)", "P(selection outside the margin)",
                                              "runs used / fixed", "truncated"])
    race_se = math.sqrt(ALPHA * (1 - ALPHA) / args.race_simulations)
    print(f"\nRaces at the margin (min_seeds {ANSWER_FROM}, alpha {ALPHA:g} over the looks; "
          f"{args.race_simulations:,} races each, Monte-Carlo SE {race_se:.3f} at 0.05): "
          "P(the selection is truly more than the margin below the best), runs used over the "
          "fixed design's, and the share cut at the last seed with more than one value still "
          "racing. slippage: the best one margin above all others; spaced: a half margin "
          "apart; at the margin (1 sd) and at three times it:")
    print(table(race_frame))
    if args.write_coverage:
        cover.to_csv(COVERAGE_PATH, index=False, float_format="%.4f")
        print(f"\ncoverage table written to {COVERAGE_PATH}")
    print(f"\n{time.perf_counter() - start:.0f} s on {args.workers} worker(s)")
    worst = float(fwer_frame["FWER step-down"].max())
    at_five = cover[cover["n"] >= 5]
    lowest = at_five.loc[at_five["coverage"].idxmin()]
    least = float(lowest["coverage"])
    print(f"unrounded min coverage at n>=5: {least:.4f} ({lowest['interval']}, "
          f"{lowest['distribution']}, n = {lowest['n']}; Monte-Carlo SE "
          f"{math.sqrt(least * (1 - least) / args.coverage_simulations):.4f})")
    worst_race = race_frame.loc[race_frame["P(selection outside the margin)"].idxmax()]
    print(f"max P(race selection outside the margin) "
          f"{worst_race['P(selection outside the margin)']:.3f} ({worst_race['values x seeds']}"
          f", {worst_race['noise']}, {worst_race['means']}, margin "
          f"{worst_race['margin (sd)']:g} sd); min power at 10 seeds "
          f"{min(p for shape, _, p in found if shape.endswith('x 10')):.3f}")
    worst_worse = spread_frame.loc[spread_frame["P(false worse)"].idxmax()]
    print(f"max P(false worse) with unequal spreads {worst_worse['P(false worse)']:.3f} "
          f"({worst_worse['values x seeds']}, {worst_worse['noise']}, wide "
          f"{worst_worse['wide']}); max P(false equivalent) at equal spreads "
          f"{float(eq_frame['P(false equivalent)'].max()):.3f}")
    equivalence_max = max(float(eq_frame["P(false equivalent)"].max()),
                          float(spread_frame["P(false equivalent)"].max()))
    # Rounded down, so that the line never shows more coverage than was measured.
    print(f"max family-wise error {worst:.3f} over {len(SHAPES)} shapes (alpha {ALPHA:g}); "
          f"min coverage at n>=5 {math.floor(least * 100 + 1e-9) / 100:.2f}; "
          f"max equivalence error {equivalence_max:.3f}")


if __name__ == "__main__":
    main()
