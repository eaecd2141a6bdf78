"""Which values are worse than the best: one procedure for the table's ties, the selection
rules, campaigns, the verdict and ``best``, callable after every round of seeds.

The best value is chosen from the same data that is then tested against it, so testing each
value against the best and correcting over those k - 1 tests (Holm) does not hold its
family-wise error: under the global null its error grows with k and n (0.096 at 8 values x 10
seeds). Hsu's multiple comparisons with the best (Hsu 1996, ch. 4) hold their level for the
claim "this value is not the strict best", which is true under ties; a report claims "worse
than the best", which is false for every value under the global null, and MCB's one-sided
Dunnett critical value is then too small.

The procedure here is a closed test (Marcus, Peritz and Gabriel 1976) of the hypotheses
H_g: "value g has the highest true mean" (g is *a* best). The local test of an intersection
H_S (every value in S is a best) rejects when some g in S is beaten by some other value j in a
one-sided Welch t-test at level alpha / (|S| (k - 1)): under H_S no j has a higher true mean
than any g in S, so the Bonferroni inequality over those |S| (k - 1) tests holds its level.
With Bonferroni local tests the closure is Holm's (1979) step-down on the k p-values
pi_g = min(1, (k - 1) min_j p(j > g)). The adjusted p of g is Holm's; g is "worse than the
best" when it is < alpha. Under the global null every claim is false, and the family-wise
error is at most alpha whatever value the data make the best; under any configuration of
means, a value with the highest true mean is called worse with probability at most alpha.
Welch's t-test (unequal variances) makes this hold for unequal n and variances, as far as the
Welch approximation holds (measured in ``benchmarks/bench_error_rates.py``). Its degrees of
freedom are Welch-Satterthwaite's between values of equal n, where Welch's test holds its level,
and the conservative min(n_i, n_j) - 1 between values of unequal n, where Welch-Satterthwaite's
let the family-wise error reach 0.106 (:func:`welch_df`).

Values with fewer than ``min_seeds`` complete seeds are left out of the family: they are
never best, tied or worse.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np
import scipy  # its submodules load on first use: list and best pay for scipy.stats only to test

from kraby_study.records import best_group

ALPHA = 0.05
MIN_SEEDS = 2
"""Fewest complete seeds a value needs to be best, tied, or to win any verdict (at least 2)."""
CONSTANT_RTOL = 1e-9
"""A sample whose range is at most this times the scale of the scores compared (their largest
absolute value) has no spread: float noise such as 0.7 against 0.7 + 1e-15 is not a
difference."""
PROCEDURE = ("closed Holm step-down over one-sided Welch t-tests with Welch-Satterthwaite "
             "degrees of freedom between values of equal n, min(n) - 1 between values of "
             "unequal n (each value as a best)")
PROCEDURE_SHORT = "closed Holm-Welch step-down"

K = TypeVar("K", bound=Hashable)


def procedure_name(alpha: float = ALPHA) -> str:
    """How reports name the procedure, e.g. 'closed Holm-Welch step-down, alpha 0.05'."""
    return f"{PROCEDURE_SHORT}, alpha {alpha:g}"


def _clean(values: Sequence[float]) -> np.ndarray:
    x = np.asarray(values, dtype=float).ravel()
    return x[~np.isnan(x)]


def no_spread(x: np.ndarray, scale: float) -> bool:
    """True when a sample's range is negligible against ``scale`` (:data:`CONSTANT_RTOL`)."""
    return bool(np.ptp(x) <= CONSTANT_RTOL * scale) if len(x) else True


def _scale(x: np.ndarray, y: np.ndarray) -> float:
    return float(max(np.max(np.abs(x)), np.max(np.abs(y))))


def welch_greater_p(a: Sequence[float], b: Sequence[float]) -> float:
    """One-sided Welch t-test p-value of "mean of a > mean of b", with the degrees of freedom of
    :func:`welch_df` (Welch-Satterthwaite's at equal n, the conservative min(n_a, n_b) - 1 at
    unequal n); NaN with fewer than 2 values on either side.

    Two samples without spread (:func:`no_spread`) are compared by their means within the same
    tolerance: p = 0 when a's mean is higher by more than it, else p = 1.
    """
    x, y = _clean(a), _clean(b)
    if len(x) < 2 or len(y) < 2:
        return math.nan
    return float(welch_greater_matrix([x, y])[0, 1])


def welch_two_sided_p(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided Welch's t-test p-value; NaN with fewer than 2 values on either side.

    Two samples without spread (:func:`no_spread`) are identical (p = 1) when their means differ
    by at most the tolerance, else certainly different (p = 0).
    """
    x, y = _clean(a), _clean(b)
    if len(x) < 2 or len(y) < 2:
        return math.nan
    scale = _scale(x, y)
    if no_spread(x, scale) and no_spread(y, scale):
        return 1.0 if abs(float(np.mean(x) - np.mean(y))) <= CONSTANT_RTOL * scale else 0.0
    return float(scipy.stats.ttest_ind(x, y, equal_var=False).pvalue)


def welch_df(n: np.ndarray, spread: np.ndarray) -> np.ndarray:
    """Degrees of freedom of the one-sided Welch t-test of every pair of samples.

    Welch-Satterthwaite's df when the two samples have equal n, min(n_i, n_j) - 1 otherwise.

    Args:
        n: Sample sizes, one per sample (each at least 2).
        spread: Each sample's variance over its n (the squared standard error of its mean).

    Returns:
        A k x k array; entry [i, j] is the df of the test between samples i and j.
    """
    # At unequal n the estimated df grows exactly when the small sample's variance is small
    # by chance: with n = 2 against n = 20 and Welch-Satterthwaite's df everywhere, the
    # step-down's family-wise error reached 0.106 (bench_error_rates.py). min(n_i, n_j) - 1 is
    # conservative for the Behrens-Fisher problem whatever the variances (Hsu 1938; Mickey and
    # Brown 1966). At equal n that bound costs most of the power (family-wise error 0.003 at
    # 5 x 5, alpha 0.05), and Welch's test holds its level there, so it keeps its own df; after
    # each round of racing every survivor has equal n.
    se2 = np.add.outer(spread, spread)
    with np.errstate(divide="ignore", invalid="ignore"):
        satterthwaite = se2 ** 2 / np.add.outer(spread ** 2 / (n - 1), spread ** 2 / (n - 1))
    # Both variances zero: the statistic is decided by the constant-sample rule, any df will do.
    satterthwaite = np.where(np.isfinite(satterthwaite), satterthwaite,
                             np.add.outer(n, n) - 2)
    return np.where(np.equal.outer(n, n), satterthwaite, np.minimum.outer(n, n) - 1)


def welch_greater_matrix(samples: Sequence[np.ndarray]) -> np.ndarray:
    """One-sided Welch p-values of every ordered pair at once: entry [j, g] is
    :func:`welch_greater_p` of sample j against sample g (each sample at least 2 values).

    Vectorised (one ``scipy.stats.t.sf`` call) so the procedure stays cheap inside the
    simulations of ``benchmarks/bench_error_rates.py``; the diagonal is meaningless.
    """
    n = np.array([len(x) for x in samples], dtype=float)
    mean = np.array([np.mean(x) for x in samples])
    var = np.array([np.var(x, ddof=1) for x in samples])
    top = np.array([np.max(np.abs(x)) for x in samples])
    flat = np.array([np.ptp(x) for x in samples]) <= CONSTANT_RTOL * top
    scale = np.maximum.outer(top, top)
    spread = var / n
    se2 = np.add.outer(spread, spread)
    diff = np.subtract.outer(mean, mean)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = scipy.stats.t.sf(diff / np.sqrt(se2), welch_df(n, spread))
    # Neither sample spreads (within the tolerance): a difference of means is certain or none.
    both_flat = np.logical_and.outer(flat, flat)
    certain = np.where(diff > CONSTANT_RTOL * scale, 0.0, 1.0)
    both_flat = both_flat | (np.logical_or.outer(flat, flat) & ~(se2 > 0))
    return np.where(both_flat, certain, p)


def paired_greater_matrix(samples: Sequence[np.ndarray]) -> np.ndarray:
    """One-sided paired t-test p-values of every ordered pair at once: entry [j, g] is the p of
    "mean of j > mean of g" on the differences j - g over the positions (seeds) where both are
    finite, with n - 1 degrees of freedom for n such pairs; NaN with fewer than 2 pairs.

    The samples are aligned: position i of each is the same seed. A seed shared by two values
    (the same initial weights, the same action-noise stream) moves both their scores the same
    way, and the difference removes that part of the noise (a randomised complete block design,
    seeds as blocks; F-Race blocks on instances the same way). Differences without spread
    (within :data:`CONSTANT_RTOL` of the scores' scale) are compared by their mean within the
    same tolerance: p = 0 when it is positive beyond it, else p = 1.
    """
    x = np.vstack([np.asarray(s, dtype=float) for s in samples])
    d = x[:, None, :] - x[None, :, :]
    both = np.isfinite(d)
    n = both.sum(axis=2).astype(float)
    d0 = np.where(both, d, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = d0.sum(axis=2) / n
        var = np.where(both, (d0 - mean[:, :, None]) ** 2, 0.0).sum(axis=2) / (n - 1)
        top = np.nanmax(np.abs(x), axis=1)
        scale = np.maximum.outer(top, top)
        spread = np.where(both, d, -np.inf).max(axis=2) - np.where(both, d, np.inf).min(axis=2)
        flat = spread <= CONSTANT_RTOL * scale
        p = scipy.stats.t.sf(mean / np.sqrt(var / n), np.maximum(n - 1, 1))
    certain = np.where(mean > CONSTANT_RTOL * scale, 0.0, 1.0)
    p = np.where(flat, certain, p)
    return np.where(n >= 2, p, math.nan)


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm (1979) step-down adjusted p-values, in the order given.

    With the m p-values sorted up, p(1) <= ... <= p(m), the i-th adjusted one is
    max over j <= i of min(1, (m - j + 1) p(j)). Reject where adjusted p < alpha: the chance of
    any false rejection stays <= alpha. SciPy has no Holm correction (only BH and BY).

    Returns:
        Adjusted p-values; NaN entries stay NaN and do not count in m.
    """
    p = np.asarray(pvalues, dtype=float).ravel()
    adjusted = np.full(len(p), math.nan)
    present = np.flatnonzero(~np.isnan(p))
    order = present[np.argsort(p[present], kind="stable")]
    m = len(order)
    scaled = np.minimum(1.0, (m - np.arange(m)) * p[order])
    adjusted[order] = np.maximum.accumulate(scaled)
    return [float(v) for v in adjusted]


@dataclass(frozen=True)
class Comparison(Generic[K]):
    """The result of :func:`compare_with_best` on the current samples."""

    best: K | None
    """The value with the highest mean among those with enough seeds; None if none has."""
    p_adjusted: dict[K, float]
    """Holm-adjusted p of "this value is a best" for every value in the family, NaN for the
    best itself; a value is worse than the best when it is < alpha."""
    worse: list[K]
    """Values significantly worse than the best (adjusted p < alpha), in the given order."""
    tied: list[K]
    """Values in the family other than the best that are not worse, in the given order."""
    left_out: dict[K, int] = field(default_factory=dict)
    """Values with some but fewer than ``min_seeds`` complete seeds: their count of seeds."""
    alpha: float = ALPHA
    min_seeds: int = MIN_SEEDS


def evidence(scores: Mapping[K, Sequence[float]], min_seeds: int = MIN_SEEDS
             ) -> tuple[int, dict[K, np.ndarray], dict[K, int]]:
    """The seeds a value needs (``min_seeds``, at least 2), the values that have them (the
    family, NaN dropped), and the others that have some: their count of seeds."""
    need = max(2, int(min_seeds))
    clean = {g: _clean(v) for g, v in scores.items()}
    family = {g: x for g, x in clean.items() if len(x) >= need}
    left_out = {g: len(x) for g, x in clean.items() if 0 < len(x) < need}
    return need, family, left_out


def best_with_evidence(scores: Mapping[K, Sequence[float]], min_seeds: int = MIN_SEEDS
                       ) -> K | None:
    """The value with the highest mean among those with ``min_seeds`` complete seeds (the
    best of :func:`compare_with_best`, without its tests); None if none has them."""
    _, family, _ = evidence(scores, min_seeds)
    return best_group({g: list(x) for g, x in family.items()})


def compare_with_best(scores: Mapping[K, Sequence[float]], alpha: float = ALPHA,
                      min_seeds: int = MIN_SEEDS, paired: bool = False) -> Comparison[K]:
    """Which values are worse than the best, with family-wise error at most ``alpha``.

    A function of the current per-value samples only, so it can be applied after each round of
    seeds (the adjusted p-values are those of this look; repeated looks are not corrected for).

    Args:
        scores: Final scores of the complete seeds by value, in the study's order (NaN ignored).
        alpha: Family-wise error rate.
        min_seeds: Fewest complete seeds a value needs to be in the family (at least 2: a
            Welch test needs two).
        paired: The samples are aligned by seed (position i of every sample is the same seed,
            NaN where that run has no score) and each pair of values is compared by a paired
            t-test on their common seeds (:func:`paired_greater_matrix`) instead of Welch's.

    Returns:
        The :class:`Comparison`.
    """
    need, family, left_out = evidence(scores, min_seeds)
    best = best_group({g: list(x) for g, x in family.items()})
    if best is None:
        return Comparison(None, {}, [], [], left_out, alpha, need)
    groups = list(family)
    k = len(groups)
    if paired:
        aligned = [np.asarray(scores[g], dtype=float).ravel() for g in groups]
        if len({len(x) for x in aligned}) > 1:
            raise ValueError("paired samples must be aligned by seed: equal lengths")
        matrix = paired_greater_matrix(aligned)
    else:
        matrix = welch_greater_matrix([family[g] for g in groups])
    # pi_g: Bonferroni over the k - 1 one-sided tests "some j beats g" (the local test of H_g);
    # a pair with too few common seeds to test (NaN) does not count against g.
    beaten = np.where(np.eye(k, dtype=bool) | np.isnan(matrix), 1.0, matrix)
    pi = (np.minimum(1.0, (k - 1) * np.min(beaten, axis=0)) if k > 1 else np.ones(1))
    adjusted = dict(zip(groups, holm(list(pi)), strict=True))
    adjusted[best] = math.nan
    worse = [g for g in groups if g != best and adjusted[g] < alpha]
    tied = [g for g in groups if g != best and not adjusted[g] < alpha]
    return Comparison(best, adjusted, worse, tied, left_out, alpha, need)
