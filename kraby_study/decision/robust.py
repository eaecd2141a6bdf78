"""Tests of interquartile-mean contrasts, from which the four answers are decided.

The four answers ([`kraby_study.decision.comparison`][]) are claims about each value's interquartile
mean (IQM: the 25 % trimmed mean of its seeds' final scores, as rliable reports it), not its mean.
No test of a mean holds its level at a few seeds when a value's seeds sometimes fail and the spreads
differ (docs/reference/statistics.md, "Answers that hold when seeds fail"): a sample that drew no
failure carries no sign of it, and a mean moves with every failure, however rare. The IQM moves
little with the failures a value has at most a quarter
of the time; those are counted apart ([`kraby_study.decision.failed_seeds`][]).

Every contrast is C = w_j T_j - T_g of two values' IQMs T (w_j from the margin,
[`margin_weights`][kraby_study.decision.comparison.margin_weights]). Two tests of it:

- the **percentile bootstrap** (Wilcox 2017, sec. 5.4; Keselman, Othman, Wilcox and Fradette
  2004): each value's seeds resampled apart (paired: the common seeds resampled together),
  ``resamples`` times; the p of "C > 0" is (1 + the resamples with C* <= 0) / (1 + resamples),
  likewise for "C < 0". The resamples are seeded by the sample's values, so the same sample
  always gives the same p;
- **Yuen's test** of trimmed means (Yuen 1974; paired: Yuen's test for dependent trimmed
  means, Wilcox 2017, sec. 5.9.5): C over its winsorised standard error, against Student's t
  with Welch's degrees of freedom on the h = n - 2 floor(n / 4) values each side keeps (paired:
  h - 1).

The answers read the larger of the two p: a claim needs both tests. Below
[`ANSWER_FROM`][kraby_study.records.values.ANSWER_FROM] seeds a side no pair is tested, and no value
is answered worse or equivalent. Each test alone failed somewhere on the grid of
``benchmarks/bench_error_rates.py`` and ``benchmarks/bench_skewed_spreads.py``: Yuen's where a
right-skewed best spreads four times as much as the value tested (a false "equivalent" about 0.09 at
2 values x 10 seeds), the bootstrap below 8 seeds (0.08 to 0.09 at 5 and 6 seeds) and at the small
levels of a large family (a family-wise error of 0.066 at 8 values x 10 seeds, normal scores, all
equal).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy

from kraby_study.records.values import ANSWER_FROM

TRIM = 0.25
"""The share of seeds cut from each end: the interquartile mean."""
RESAMPLES = 1999
"""Fewest bootstrap resamples; more when the family is so large that Holm's smallest level
needs a finer p ([`resamples_for`][kraby_study.decision.robust.resamples_for])."""
MAX_RESAMPLES = 49_999
SEED = 20261201
"""Seed of the resamples, with each sample's values."""
CONSTANT_RTOL = 1e-9
"""A sample whose range is at most this times the scale of the scores compared (their largest
absolute value) has no spread, and a contrast within it of 0 is none: float noise such as 0.7
against 0.7 + 1e-15 is not a difference (the answers' tests and the Welch tests of
[`kraby_study.decision.comparison`][] alike)."""
NAME = (f"the percentile bootstrap of the IQM contrast and Yuen's trimmed-mean test, both "
        f"rejecting; no answer below {ANSWER_FROM} seeds")


def iqm(x: np.ndarray) -> np.ndarray:
    """The IQM along the last axis, as ``scipy.stats.trim_mean(x, 0.25)``: floor(n / 4) values
    cut from each end, the plain mean below 4 values (computed here with NumPy alone, so that a
    command that needs only the best value loads no part of SciPy)."""
    s = np.sort(np.asarray(x, dtype=float), axis=-1)
    n = s.shape[-1]
    g = int(TRIM * n)
    return s[..., g:n - g].mean(axis=-1)


def resamples_for(values: int, alpha: float) -> int:
    """Resamples enough for the smallest level the answers' procedure tests at, alpha / (k (k -
    1)) for k values, to be reached by a certain difference: at least
    [`RESAMPLES`][kraby_study.decision.robust.RESAMPLES], at most
    [`MAX_RESAMPLES`][kraby_study.decision.robust.MAX_RESAMPLES]."""
    need = 2 * values * max(values - 1, 1) / alpha
    return int(min(MAX_RESAMPLES, max(RESAMPLES, math.ceil(need))))


def seeded(x: np.ndarray, seed: int = SEED) -> np.random.Generator:
    """A generator seeded with ``seed`` and a SHA-256 digest of the sample's values: a sample
    always gets the same resamples, different samples independent ones."""
    digest = hashlib.sha256(np.ascontiguousarray(x, dtype="<f8").tobytes()).digest()
    words = [int.from_bytes(digest[i:i + 8], "little") for i in range(0, len(digest), 8)]
    return np.random.default_rng([seed, *words])


def _winsorised(x: np.ndarray) -> tuple[np.ndarray, int]:
    """The sample winsorised at g = floor(n / 4) on each end (in its own order), and h = n - 2g."""
    n = len(x)
    g = int(TRIM * n)
    s = np.sort(x)
    return np.clip(x, s[g], s[n - g - 1]), n - 2 * g


def yuen_parts(x: np.ndarray) -> tuple[float, float, int]:
    """(IQM, d, h) of one sample: d = (n - 1) s_w^2 / (h (h - 1)) is the squared standard error
    of its trimmed mean (s_w the winsorised sd), h the values it keeps (Yuen 1974)."""
    winsorised, h = _winsorised(x)
    d = (len(x) - 1) * float(np.var(winsorised, ddof=1)) / (h * (h - 1))
    return float(iqm(x)), d, h


@dataclass(frozen=True)
class IqmTests:
    """The tests of every ordered pair's contrast: entry [j, g] is about w_j T_j - T_g.

    ``greater`` and ``less`` are the p of "> 0" and "< 0" the answers read (NaN where the pair
    is not tested: fewer than [`ANSWER_FROM`][kraby_study.records.values.ANSWER_FROM] seeds); ``se``
    and ``df`` are Yuen's standard error and degrees of freedom of the contrast (what
    [`Comparison.resolvable`][kraby_study.decision.comparison.Comparison.resolvable] reads), NaN
    where untested. The diagonal is meaningless."""

    greater: np.ndarray
    less: np.ndarray
    se: np.ndarray
    df: np.ndarray
    tested: np.ndarray


def _bootstrap_p(c_star: np.ndarray, resamples: int) -> tuple[float, float]:
    """The percentile bootstrap's p of "C > 0" and of "C < 0" from the resampled contrasts."""
    return ((1 + int(np.sum(c_star <= 0))) / (1 + resamples),
            (1 + int(np.sum(c_star >= 0))) / (1 + resamples))


def _yuen_p(c: float, se: float, df: float) -> tuple[float, float]:
    """Yuen's p of "C > 0" and of "C < 0"."""
    t = c / se
    return float(scipy.special.stdtr(df, -t)), float(scipy.special.stdtr(df, t))


def _decide(c: float, scale: float, boot: tuple[float, float], yuen: tuple[float, float],
            flat: bool) -> tuple[float, float]:
    """The p the answers read: certain when neither side spreads, the bootstrap's where Yuen's
    standard error is 0 (every value a trimmed mean keeps is equal), else the larger of
    both."""
    if flat:
        tol = CONSTANT_RTOL * scale
        return (0.0 if c > tol else 1.0), (0.0 if c < -tol else 1.0)
    if not math.isfinite(yuen[0]):
        return boot
    return max(boot[0], yuen[0]), max(boot[1], yuen[1])


def iqm_pairs(samples: Sequence[np.ndarray], weights: np.ndarray | None = None,
              alpha: float = 0.05, paired: bool = False) -> IqmTests:
    """[`IqmTests`][kraby_study.decision.robust.IqmTests] of every ordered pair of samples.

    Args:
        samples: Final scores by value (NaN dropped unless ``paired``).
        weights: w_j of each value (None: 1, the plain difference of IQMs).
        alpha: The answers' error rate, which sets the resamples
            ([`resamples_for`][kraby_study.decision.robust.resamples_for]).
        paired: The samples are aligned by seed (NaN where that run has no score) and each pair
            is tested on the seeds both have.
    """
    k = len(samples)
    w = np.ones(k) if weights is None else np.asarray(weights, dtype=float)
    resamples = resamples_for(k, alpha)
    if paired:
        return _paired(samples, w, resamples)
    x = [np.asarray(s, dtype=float) for s in samples]
    enough = np.array([len(s) >= ANSWER_FROM for s in x])
    parts = np.array([yuen_parts(s) if ok else (math.nan,) * 3
                      for s, ok in zip(x, enough, strict=True)])
    location, d, h = parts[:, 0], parts[:, 1], parts[:, 2]
    drawn = np.full((k, resamples), math.nan)
    for v in np.flatnonzero(enough):
        s = x[v]
        drawn[v] = iqm(s[seeded(s).integers(0, len(s), size=(resamples, len(s)))])
    spread = np.array([float(np.ptp(s)) if len(s) else 0.0 for s in x])
    top = np.array([float(np.max(np.abs(s))) if len(s) else 0.0 for s in x])
    tested = np.logical_and.outer(enough, enough) & ~np.eye(k, dtype=bool)
    c = np.subtract.outer(w * location, location)
    first = (w ** 2 * d)[:, None]
    s2 = first + d[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        df = s2 ** 2 / (first ** 2 / (h[:, None] - 1) + d[None, :] ** 2 / (h[None, :] - 1))
        t = c / np.sqrt(s2)
        yuen_greater = scipy.special.stdtr(df, -t)
        yuen_less = scipy.special.stdtr(df, t)
    contrast = w[:, None, None] * drawn[:, None, :] - drawn[None, :, :]  # (k, k, resamples)
    boot_greater = (1 + np.sum(contrast <= 0, axis=2)) / (1 + resamples)
    boot_less = (1 + np.sum(contrast >= 0, axis=2)) / (1 + resamples)
    scale = np.maximum.outer(top, top)
    tol = CONSTANT_RTOL * scale
    flat = np.maximum.outer(spread, spread) <= tol
    alone = ~(s2 > 0)  # Yuen's standard error 0: every kept value equal
    greater = np.where(alone, boot_greater, np.maximum(boot_greater, yuen_greater))
    less = np.where(alone, boot_less, np.maximum(boot_less, yuen_less))
    greater = np.where(flat, np.where(c > tol, 0.0, 1.0), greater)
    less = np.where(flat, np.where(c < -tol, 0.0, 1.0), less)
    return IqmTests(greater=np.where(tested, greater, math.nan),
                    less=np.where(tested, less, math.nan),
                    se=np.where(tested, np.sqrt(s2), math.nan),
                    df=np.where(tested, df, math.nan), tested=tested)


def _paired(samples: Sequence[np.ndarray], w: np.ndarray, resamples: int) -> IqmTests:
    """The paired tests: per pair, its common seeds resampled together
    (one draw of seed indices for every pair that shares the same common seeds, seeded by the
    values' scores on them), and Yuen's test for dependent trimmed means, both needed as
    unpaired (the paired percentile bootstrap alone gave a false drop 0.019 at level 0.05 / 7,
    2 values x 8 seeds)."""
    x = np.vstack([np.asarray(s, dtype=float) for s in samples])
    k = len(x)
    greater, less = np.full((k, k), math.nan), np.full((k, k), math.nan)
    se, df = np.full((k, k), math.nan), np.full((k, k), math.nan)
    tested = np.zeros((k, k), dtype=bool)
    drawn: dict[bytes, np.ndarray] = {}
    for j in range(k):
        for g in range(k):
            both = np.isfinite(x[j]) & np.isfinite(x[g])
            n = int(both.sum())
            if j == g or n < ANSWER_FROM:
                continue
            a, b = w[j] * x[j, both], x[g, both]
            wa, h = _winsorised(a)
            wb, _ = _winsorised(b)
            scale = float(max(np.max(np.abs(x[j, both])), np.max(np.abs(b))))
            c = float(iqm(a) - iqm(b))
            factor = (n - 1) / (h * (h - 1))
            s2 = factor * (np.var(wa, ddof=1) + np.var(wb, ddof=1)
                           - 2 * np.cov(wa, wb, ddof=1)[0, 1])
            yuen = _yuen_p(c, math.sqrt(s2), h - 1) if s2 > 0 else (math.nan, math.nan)
            key = both.tobytes()
            if key not in drawn:
                index = seeded(x[:, both].ravel()).integers(0, n, size=(resamples, n))
                drawn[key] = iqm(np.where(np.isfinite(x[:, both]), x[:, both], 0.0)[:, index])
            boot = _bootstrap_p(w[j] * drawn[key][j] - drawn[key][g], resamples)
            flat = float(np.ptp(a - b)) <= CONSTANT_RTOL * scale
            greater[j, g], less[j, g] = _decide(c, scale, boot, yuen, flat)
            se[j, g], df[j, g] = math.sqrt(max(s2, 0.0)), h - 1
            tested[j, g] = True
    return IqmTests(greater, less, se, df, tested)
