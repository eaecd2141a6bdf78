"""One comparison with the best for every verdict: the table's answers, the selection rules,
campaigns, ``best``, ``${winner:...}``, races and the front all read its :class:`Comparison`.

Each value of the family (the values with ``min_seeds`` complete seeds) gets one of four
answers about its **interquartile mean** (IQM, the 25 % trimmed mean of its seeds' final
scores), for a margin delta >= 0 in score units, the smallest difference that matters
(``compare.margin``, a fraction of the best value's |IQM|):

- **best**: the highest IQM (the first in order on equal IQMs).
- **worse**: shown worse than the highest true IQM by more than delta.
- **equivalent**: shown within delta of the highest true IQM of the others.
- **undecided**: neither; every value with fewer than
  :data:`~kraby_study.decision.robust.ANSWER_FROM` seeds, where no answer holds its error rate.

The IQM and not the mean: when a setting's seeds sometimes fail, no test of a mean holds its
level at a few seeds (a sample that drew no failure shows none), and the measured rates of
the earlier releases' Welch tests of means reached 0.23 there. The IQM moves little with
failures a value has at most a quarter of the time, and the failures are counted apart
(:mod:`kraby_study.decision.failed_seeds`). The tests of each IQM contrast are in
:mod:`kraby_study.decision.robust`.

**Worse: a closed step-down** (Marcus, Peritz and Gabriel 1976) of the hypotheses
H_g: "value g is within delta of the highest true IQM" (at delta = 0: "g is *a* best"). The
local test of an intersection H_S (every value in S within delta of every other) rejects when
some g in S is beaten by some other value j by more than delta in a one-sided test of
T_j - T_g > delta at level alpha / (|S| (k - 1)): under H_S no j exceeds any g in S by more
than delta, so the Bonferroni inequality over those |S| (k - 1) tests holds its level. The
closure is Holm's (1979) step-down on pi_g = min(1, (k - 1) min_j p(T_j - T_g > delta)), and g
is worse when its adjusted p is < alpha. Hsu's multiple comparisons with the best (Hsu 1996,
ch. 4) control the claim "this value is not the strict best", which is true under ties, not
"worse than the best"; they are not used for this answer.

**Equivalent: multiple comparisons with the best with a margin** (Edwards and Hsu 1983; Hsu
1996, ch. 4), in the Bonferroni form of Nelson and Matejcik (1995): g is equivalent when, for
every other value j, the one-sided test of T_j - T_g < delta rejects at level
alpha / (k - 1). A false "equivalent" on g needs the test against the value with the highest
true IQM to err, so over the at most k - 1 values truly worse by delta or more the chance of
any false "equivalent" is at most alpha, whichever value the data make the best: choosing the
best from the data costs no further multiplicity. At delta = 0 no value is equivalent.

Each kind of wrong answer has probability at most alpha; a wrong answer of either kind at most
2 alpha (Bonferroni). Both are measured in ``benchmarks/bench_error_rates.py``, on normal,
heavy-tailed, skewed and failing-seed scores, with spreads 1:4 among them: from
:data:`~kraby_study.decision.robust.ANSWER_FROM` seeds every cell is within alpha and its
Monte-Carlo error.

The margin is a fraction f of the reference's |IQM| (reported in score units as f x |IQM of the
best|), so "j above g by more than the margin" is the contrast (1 - f sign(T_j)) T_j - T_g > 0,
and every test against the margin is a test of that contrast (:func:`margin_weights`).

**Tied** (:attr:`Comparison.tied`, :attr:`Comparison.p_adjusted`) is not one of the four
answers: the earlier releases' closed step-down at margin 0 over one-sided Welch t-tests of
means (or paired t-tests on the seeds two values share, ``paired``), kept for the
``fastest_tied`` rule so that stored studies select as before. Welch's degrees of freedom are
Welch-Satterthwaite's between values of equal n from :data:`SATTERTHWAITE_FROM` seeds on, and
the conservative min(n_i, n_j) - 1 otherwise (:func:`welch_df`).

Values with fewer than ``min_seeds`` complete seeds are left out of the family: they are
never best, equivalent, undecided or worse.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Generic, TypeVar

import numpy as np
import scipy  # submodules load on first use: `list` loads none for a rule that needs no test

from kraby_study.decision.robust import ANSWER_FROM, CONSTANT_RTOL, iqm, iqm_pairs
from kraby_study.decision.robust import NAME as TESTS_NAME
from kraby_study.records.values import best_group

ALPHA = 0.05
MIN_SEEDS = 2
"""Fewest complete seeds a value needs to be in the family (at least 2)."""
MARGIN = 0.2
"""Default ``compare.margin``: the margin as a fraction of the best value's |mean final score|
(docs/reference/statistics.md justifies it against this project's data)."""
POWER = 0.8
"""The power at which :attr:`Comparison.resolvable` is the smallest margin the seeds resolve."""
SATTERTHWAITE_FROM = 4
"""From this many seeds a side (equal n), Welch's test takes Welch-Satterthwaite's degrees of
freedom; below, and at unequal n, min(n_i, n_j) - 1."""
PROCEDURE = ("closed Holm step-down over one-sided Welch t-tests with Welch-Satterthwaite "
             f"degrees of freedom between values of equal n from {SATTERTHWAITE_FROM} seeds, "
             "min(n) - 1 otherwise (each value as a best)")
"""The test of :attr:`Comparison.tied` (margin 0, means), the ``fastest_tied`` rule's."""
PROCEDURE_SHORT = "closed Holm-Welch step-down"
EQUIVALENCE = ("multiple comparisons with the best with a margin (Edwards and Hsu 1983), "
               "Bonferroni form (Nelson and Matejcik 1995)")

K = TypeVar("K", bound=Hashable)


class Answer(StrEnum):
    """What the comparison says of one value of the family."""

    BEST = "best"
    EQUIVALENT = "equivalent"
    WORSE = "worse"
    UNDECIDED = "undecided"


def procedure_name(alpha: float = ALPHA) -> str:
    """How reports name the test of "tied", e.g. 'closed Holm-Welch step-down, alpha 0.05'."""
    return f"{PROCEDURE_SHORT}, alpha {alpha:g}"


def answers_name(alpha: float = ALPHA) -> str:
    """How reports name the four answers' procedure."""
    return (f"answers on the interquartile mean (IQM) of the seeds; worse: closed Holm "
            f"step-down against the margin, alpha {alpha:g}; equivalent: {EQUIVALENCE}; "
            f"tests: {TESTS_NAME}; each kind of wrong answer at most {alpha:g}, measured on "
            "skewed scores of unequal spreads too")


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
    :func:`welch_df`; NaN with fewer than 2 values on either side.

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


def welch_df(n: np.ndarray, spread: np.ndarray, first: np.ndarray | None = None
             ) -> np.ndarray:
    """Degrees of freedom of the one-sided Welch t-test of every pair of samples.

    Welch-Satterthwaite's df when the two samples have equal n of at least
    :data:`SATTERTHWAITE_FROM`, min(n_i, n_j) - 1 otherwise.

    Args:
        n: Sample sizes, one per sample (each at least 2).
        spread: Each sample's variance over its n (the squared standard error of its mean).
        first: The same for a sample in the first place of a pair, when it is weighted there
            (:func:`welch_pairs`); None: ``spread``.

    Returns:
        A k x k array; entry [i, j] is the df of the test between samples i and j.
    """
    first = spread if first is None else first
    # At unequal n the estimated df grows exactly when the small sample's variance is small
    # by chance: with n = 2 against n = 20 and Welch-Satterthwaite's df everywhere, the
    # step-down's family-wise error reached 0.106 (bench_error_rates.py). At equal n of 2 or 3
    # the same happens when one value spreads far more than the other: 2 values x 2 seeds with
    # sd 1 and 10 gave 0.063, 2 x 3 gave 0.056. min(n_i, n_j) - 1 is conservative for the
    # Behrens-Fisher problem whatever the variances (Hsu 1938; Mickey and Brown 1966). From 4
    # seeds on at equal n Welch's test holds its level, and that bound would cost most of the
    # power (family-wise error 0.003 at 5 x 5, alpha 0.05); after each round of racing every
    # survivor has equal n.
    se2 = np.add.outer(first, spread)
    with np.errstate(divide="ignore", invalid="ignore"):
        satterthwaite = se2 ** 2 / np.add.outer(first ** 2 / (n - 1), spread ** 2 / (n - 1))
    # Both variances zero: the statistic is decided by the constant-sample rule, any df will do.
    satterthwaite = np.where(np.isfinite(satterthwaite), satterthwaite,
                             np.add.outer(n, n) - 2)
    own = np.equal.outer(n, n) & (np.minimum.outer(n, n) >= SATTERTHWAITE_FROM)
    return np.where(own, satterthwaite, np.minimum.outer(n, n) - 1)


@dataclass(frozen=True)
class PairTests:
    """The t statistics' parts of every ordered pair of samples: entry [j, g] compares j with g.

    ``diff`` is w_j mean_j - mean_g (the mean of w_j x_j - x_g over common seeds when paired;
    w_j = 1 unless weighted, see :func:`welch_pairs`), ``se`` its standard error, ``df`` its
    degrees of freedom, ``flat`` where neither side spreads within :data:`CONSTANT_RTOL` of
    ``scale`` (the difference is then certain), ``tested`` where a test is possible at all. The
    diagonal is meaningless.
    """

    diff: np.ndarray
    se: np.ndarray
    df: np.ndarray
    flat: np.ndarray
    scale: np.ndarray
    tested: np.ndarray

    def greater(self, shift: float = 0.0) -> np.ndarray:
        """One-sided p of "mu_j - mu_g > shift" for every pair; NaN where untested."""
        with np.errstate(divide="ignore", invalid="ignore"):
            # Student's t survival function as scipy.stats.t.sf computes it, called as the raw
            # ufunc: a tenth of the cost inside the benchmarks' simulations.
            p = scipy.special.stdtr(self.df, -(self.diff - shift) / self.se)
        certain = np.where(self.diff - shift > CONSTANT_RTOL * self.scale, 0.0, 1.0)
        return np.where(self.tested, np.where(self.flat, certain, p), math.nan)

    def less(self, shift: float) -> np.ndarray:
        """One-sided p of "mu_j - mu_g < shift" for every pair; NaN where untested."""
        with np.errstate(divide="ignore", invalid="ignore"):
            p = scipy.special.stdtr(self.df, (self.diff - shift) / self.se)
        certain = np.where(shift - self.diff > CONSTANT_RTOL * self.scale, 0.0, 1.0)
        return np.where(self.tested, np.where(self.flat, certain, p), math.nan)


def welch_pairs(samples: Sequence[np.ndarray], weights: np.ndarray | None = None) -> PairTests:
    """:class:`PairTests` of Welch's unpaired tests (each sample at least 2 values), vectorised
    so the procedure stays cheap inside the simulations of the benchmarks.

    ``weights`` (w_j, one per sample) test the contrast w_j mu_j - mu_g instead of the
    difference: a margin that is a fraction f of the reference's |mean| makes
    "mu_j - mu_g > f |mu_j|" the contrast (1 - f sign(mu_j)) mu_j - mu_g > 0, whose standard
    error counts the noise of the reference's mean in the margin (:func:`margin_weights`).
    """
    n = np.array([len(x) for x in samples], dtype=float)
    w = np.ones(len(n)) if weights is None else np.asarray(weights, dtype=float)
    mean = np.array([np.mean(x) for x in samples])
    var = np.array([np.var(x, ddof=1) for x in samples])
    top = np.array([np.max(np.abs(x)) for x in samples])
    flat = np.array([np.ptp(x) for x in samples]) <= CONSTANT_RTOL * top
    spread = var / n
    first = w ** 2 * spread
    se2 = np.add.outer(first, spread)
    # Neither sample spreads (within the tolerance), or one does not and the other's variance
    # vanishes: a difference of means is certain or none.
    both_flat = np.logical_and.outer(flat, flat) | (np.logical_or.outer(flat, flat) & ~(se2 > 0))
    return PairTests(diff=np.subtract.outer(w * mean, mean), se=np.sqrt(se2),
                     df=welch_df(n, spread, first), flat=both_flat,
                     scale=np.maximum.outer(top, top),
                     tested=np.ones((len(n), len(n)), dtype=bool))


def paired_pairs(samples: Sequence[np.ndarray], weights: np.ndarray | None = None
                 ) -> PairTests:
    """:class:`PairTests` of paired t-tests: the samples are aligned (position i of each is the
    same seed, NaN where that run has no score), and j - g is tested on the differences over
    the seeds both have, with n - 1 degrees of freedom for n such pairs; untested with fewer
    than 2 pairs.

    A seed shared by two values (the same initial weights, the same action-noise stream) moves
    both their scores the same way, and the difference removes that part of the noise (a
    randomised complete block design, seeds as blocks; F-Race blocks on instances the same way,
    Nelson and Matejcik's common random numbers likewise). ``weights`` as in
    :func:`welch_pairs`: the differences are w_j x_j - x_g.
    """
    x = np.vstack([np.asarray(s, dtype=float) for s in samples])
    w = np.ones(len(x)) if weights is None else np.asarray(weights, dtype=float)
    d = (w[:, None] * x)[:, None, :] - x[None, :, :]
    both = np.isfinite(d)
    n = both.sum(axis=2).astype(float)
    d0 = np.where(both, d, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = d0.sum(axis=2) / n
        var = np.where(both, (d0 - mean[:, :, None]) ** 2, 0.0).sum(axis=2) / (n - 1)
        top = np.nanmax(np.abs(x), axis=1)
        scale = np.maximum.outer(top, top)
        spread = np.where(both, d, -np.inf).max(axis=2) - np.where(both, d, np.inf).min(axis=2)
        se = np.sqrt(var / n)
    return PairTests(diff=mean, se=se, df=np.maximum(n - 1, 1),
                     flat=spread <= CONSTANT_RTOL * scale, scale=scale, tested=n >= 2)


def welch_greater_matrix(samples: Sequence[np.ndarray], shift: float = 0.0) -> np.ndarray:
    """One-sided Welch p-values of every ordered pair at once: entry [j, g] is the p of
    "mu_j - mu_g > shift" (:func:`welch_greater_p` at shift 0); the diagonal is meaningless."""
    return welch_pairs(samples).greater(shift)


def paired_greater_matrix(samples: Sequence[np.ndarray], shift: float = 0.0) -> np.ndarray:
    """One-sided paired t-test p-values of every ordered pair at once: entry [j, g] is the p of
    "mu_j - mu_g > shift" on the seeds both have (:func:`paired_pairs`); NaN with fewer than 2
    common seeds. Differences without spread are compared by their mean within
    :data:`CONSTANT_RTOL`: p = 0 when it exceeds the shift beyond it, else p = 1."""
    return paired_pairs(samples).greater(shift)


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


def margin_weights(means: np.ndarray, fraction: float) -> np.ndarray:
    """The weights w_j = 1 - fraction x sign(mean_j) of :func:`welch_pairs` and
    :func:`~kraby_study.decision.robust.iqm_pairs` for a margin that is ``fraction`` of the
    reference's |location| (its IQM in the answers): "mu_g within f |mu_j| of mu_j" is
    mu_g - w_j mu_j >= 0 (the sign read from the sample; the leg's scores are all negative, so
    w = 1 + f there)."""
    return 1.0 - float(fraction) * np.sign(np.asarray(means, dtype=float))


def margin_units(fraction: float, best_mean: float) -> float:
    """The margin in score units: ``fraction`` of the best value's |IQM| (0 for a NaN)."""
    return float(fraction) * abs(best_mean) if math.isfinite(best_mean) else 0.0


@dataclass(frozen=True)
class Comparison(Generic[K]):
    """The result of :func:`compare` on the current samples: every verdict reads it."""

    best: K | None
    """The value with the highest IQM among those with enough seeds; None if none has."""
    p_adjusted: dict[K, float]
    """Holm-adjusted p of "this value's mean is a best" (the Welch step-down at margin 0 of the
    earlier releases, :data:`PROCEDURE`) for every value in the family, NaN for the best
    itself; < alpha: not a best. What :attr:`tied` reads, not an answer."""
    worse: list[K]
    """Values shown worse than the best by more than the margin, in the given order."""
    tied: list[K]
    """Values other than the best not shown worse at margin 0 by :attr:`p_adjusted` (adjusted p
    >= alpha): what earlier releases called tied, and what ``fastest_tied`` reads; in the
    given order."""
    left_out: dict[K, int] = field(default_factory=dict)
    """Values with some but fewer than ``min_seeds`` complete seeds: their count of seeds."""
    alpha: float = ALPHA
    min_seeds: int = MIN_SEEDS
    fraction: float = 0.0
    """The margin as a fraction of the best's |IQM| (``compare.margin``)."""
    margin: float = 0.0
    """The margin in score units: ``fraction`` x |IQM of the best|."""
    answers: dict[K, Answer] = field(default_factory=dict)
    """Every value of the family's answer, in the given order."""
    p_worse: dict[K, float] = field(default_factory=dict)
    """Holm-adjusted p of "within the margin of the highest IQM" (NaN for the best; 1 where no
    pair of the value is tested, below :data:`~kraby_study.decision.robust.ANSWER_FROM`
    seeds)."""
    p_equivalent: dict[K, float] = field(default_factory=dict)
    """Bonferroni p of "more than the margin below the highest IQM of the others": (k - 1)
    x the largest p over the others (NaN for the best; 1 at margin 0 and where a pair is not
    tested)."""
    resolvable: dict[K, float] = field(default_factory=dict)
    """Per value other than the best, about the smallest margin at which a value truly equal to
    the best is shown equivalent with probability :data:`POWER`:
    (t(1 - alpha / (k - 1)) + t(POWER)) x Yuen's standard error of its IQM contrast with the
    best, with Yuen's degrees of freedom (absent where untested)."""
    family: list[K] = field(default_factory=list)
    """The values with enough seeds, in the given order."""
    unanswered: list[K] = field(default_factory=list)
    """Values of the family other than the best that no test reaches: fewer than
    :data:`~kraby_study.decision.robust.ANSWER_FROM` seeds, on their side or the best's.
    Undecided by rule, whatever their scores; in the given order."""

    @property
    def equivalent(self) -> list[K]:
        """Values shown within the margin of the best, in the given order."""
        return [g for g, a in self.answers.items() if a == Answer.EQUIVALENT]

    @property
    def undecided(self) -> list[K]:
        """Values neither shown worse nor equivalent, in the given order."""
        return [g for g, a in self.answers.items() if a == Answer.UNDECIDED]

    @property
    def resolution(self) -> float:
        """The seeds' resolution of the study: the median of :attr:`resolvable` over the values
        other than the best (NaN with none)."""
        finite = [v for v in self.resolvable.values() if math.isfinite(v)]
        return float(statistics.median(finite)) if finite else math.nan

    @property
    def below_resolution(self) -> bool:
        """A margin above 0 smaller than the seeds' resolution: few values can be shown
        equivalent at these seeds."""
        return self.fraction > 0 and math.isfinite(self.resolution) and (
            self.margin < self.resolution)

    def margin_text(self) -> str:
        """The margin as reports state it, e.g. 'margin 0.0028 in score units (0.2 x the
        best's |IQM| 0.014)'."""
        if self.fraction <= 0:
            return "margin 0 (no value can be shown equivalent)"
        return (f"margin {self.margin:.3g} in score units ({self.fraction:g} x the best's "
                f"|IQM| {abs(self.margin / self.fraction):.4g})")

    def unanswered_text(self) -> str | None:
        """Why some values are undecided whatever their scores; None when every value could
        be answered."""
        if not self.unanswered:
            return None
        return (f"{len(self.unanswered)} of {len(self.family) - 1} values compared with fewer "
                f"than {ANSWER_FROM} seeds (or against a best with fewer): undecided by rule, "
                f"since no test holds its error rate there on skewed scores")

    def resolution_text(self) -> str | None:
        """A warning when the margin is below the seeds' resolution; None otherwise."""
        if not self.below_resolution:
            return None
        return (f"the margin {self.margin:.3g} is below what these seeds resolve (median "
                f"{self.resolution:.3g}: (t + t_{POWER:g}) x the standard error of a difference "
                "with the best); few values can be shown equivalent, more seeds would")


@dataclass(frozen=True)
class CompareOptions:
    """How a command compares and selects: the margin, the error rate, the seeds a value needs
    and, optionally, a rule read instead of each study's stored one."""

    margin: float = MARGIN
    """``compare.margin``: the margin as a fraction of the best's |IQM| (0: none)."""
    alpha: float = ALPHA
    min_seeds: int = MIN_SEEDS
    """``report.min_seeds``, clamped to at least 2 by :func:`evidence` alone."""
    select: str | None = None
    """``compare.select``: a selection rule applied instead of the stored one; None: the
    study's own."""

    @classmethod
    def of(cls, cfg: object) -> CompareOptions:
        """The options of a composed config (its ``compare`` and ``report`` sections; a section
        or key it lacks takes the default)."""
        compare_cfg = getattr(cfg, "compare", None)
        report_cfg = getattr(cfg, "report", None)
        margin = getattr(compare_cfg, "margin", None)
        min_seeds = getattr(report_cfg, "min_seeds", None)
        select = getattr(compare_cfg, "select", None)
        return cls(margin=MARGIN if margin is None else float(margin),
                   min_seeds=MIN_SEEDS if min_seeds is None else int(min_seeds),
                   select=None if select is None else str(select))


def seeds_needed(min_seeds: int) -> int:
    """The seeds a value needs to be in the family: ``min_seeds``, at least 2 (a test needs
    two). The one place the setting is clamped."""
    return max(2, int(min_seeds))


def evidence(scores: Mapping[K, Sequence[float]], min_seeds: int = MIN_SEEDS
             ) -> tuple[int, dict[K, np.ndarray], dict[K, int]]:
    """The seeds a value needs (:func:`seeds_needed`), the values that have them (the family,
    NaN dropped), and the others that have some: their count of seeds."""
    need = seeds_needed(min_seeds)
    clean = {g: _clean(v) for g, v in scores.items()}
    family = {g: x for g, x in clean.items() if len(x) >= need}
    left_out = {g: len(x) for g, x in clean.items() if 0 < len(x) < need}
    return need, family, left_out


def best_by_iqm(samples: Mapping[K, np.ndarray]) -> K | None:
    """The value with the highest IQM (the first such in order; NaN never wins); None if no
    value has a sample."""
    return best_group({g: [float(iqm(np.asarray(x, dtype=float)))]
                       for g, x in samples.items() if len(x)})


def best_with_evidence(scores: Mapping[K, Sequence[float]], min_seeds: int = MIN_SEEDS
                       ) -> K | None:
    """The value with the highest IQM among those with ``min_seeds`` complete seeds (the
    best of :func:`compare`, without its tests); None if none has them."""
    _, family, _ = evidence(scores, min_seeds)
    return best_by_iqm(family)


def _step_down(matrix: np.ndarray) -> list[float]:
    """Holm over pi_g = min(1, (k - 1) min_j p[j, g]); an untested pair (NaN) does not count
    against g."""
    k = len(matrix)
    beaten = np.where(np.eye(k, dtype=bool) | np.isnan(matrix), 1.0, matrix)
    pi = np.minimum(1.0, (k - 1) * np.min(beaten, axis=0)) if k > 1 else np.ones(1)
    return holm(list(pi))


def compare(scores: Mapping[K, Sequence[float]], margin: float = MARGIN, alpha: float = ALPHA,
            min_seeds: int = MIN_SEEDS, paired: bool = False, tests: bool = True
            ) -> Comparison[K]:
    """Every value's answer against the best: best, equivalent, worse or undecided.

    A function of the current per-value samples only, so it can be applied after each round of
    seeds (its p-values are those of this look; repeated looks are not corrected for here).

    Args:
        scores: Final scores of the complete seeds by value, in the study's order (NaN ignored).
        margin: The margin as a fraction of the best value's |IQM| (0: no value equivalent).
        alpha: The error rate of each kind of wrong answer.
        min_seeds: Fewest complete seeds a value needs to be in the family (at least 2).
        paired: The samples are aligned by seed (position i of every sample is the same seed,
            NaN where that run has no score) and each pair of values is compared on their
            common seeds (paired t-tests for :attr:`Comparison.tied`; the common seeds
            resampled together, and Yuen's test for dependent trimmed means, for the answers).
        tests: False: only the best, the family and the values left out, no test (``list``
            and the rules that need none stay clear of scipy.stats).

    Returns:
        The :class:`Comparison`.
    """
    need, family, left_out = evidence(scores, min_seeds)
    best = best_by_iqm(family)
    fraction = float(margin)
    if best is None or not tests:
        return Comparison(best, {}, [], [], left_out, alpha, need, fraction,
                          family=list(family))
    groups = list(family)
    k = len(groups)
    locations = np.array([float(iqm(family[g])) for g in groups])
    delta = margin_units(fraction, float(locations[groups.index(best)]))
    weights = margin_weights(locations, fraction) if delta > 0 else None
    if paired:
        aligned = [np.asarray(scores[g], dtype=float).ravel() for g in groups]
        if len({len(x) for x in aligned}) > 1:
            raise ValueError("paired samples must be aligned by seed: equal lengths")
        means = paired_pairs(aligned)
        robust = iqm_pairs(aligned, weights, alpha, paired=True)
    else:
        means = welch_pairs([family[g] for g in groups])
        robust = iqm_pairs([family[g] for g in groups], weights, alpha)
    # With a margin, "j beats g by more than f |T_j|" is the contrast w_j T_j - T_g > 0 (the
    # weights): its tests count the reference's noise in the margin, which a margin read off
    # the sample and then held fixed would leave out (an equivalence error of 0.059 at
    # 2 values x 10 seeds, normal data, alpha 0.05, with the t-tests of earlier releases).
    at_zero = _step_down(means.greater(0.0))
    at_margin = _step_down(robust.greater)
    b = groups.index(best)
    others = max(k - 1, 1)
    if delta > 0:
        # An untested pair (NaN) cannot show g within the margin of j.
        below = np.where(np.isnan(robust.less), 1.0, robust.less)
        np.fill_diagonal(below, 0.0)
        equivalent = np.minimum(1.0, others * np.max(below, axis=0))
    else:
        equivalent = np.ones(k)
    with np.errstate(invalid="ignore"):
        quantiles = (scipy.special.stdtrit(robust.df[b], 1 - alpha / others)
                     + scipy.special.stdtrit(robust.df[b], POWER))
    resolvable = np.where(robust.tested[b], quantiles * robust.se[b], math.nan)
    p_adjusted, p_worse, p_equivalent, answers, resolved = {}, {}, {}, {}, {}
    for i, g in enumerate(groups):
        if g == best:
            p_adjusted[g] = p_worse[g] = p_equivalent[g] = math.nan
            answers[g] = Answer.BEST
            continue
        p_adjusted[g], p_worse[g] = at_zero[i], at_margin[i]
        p_equivalent[g] = float(equivalent[i])
        if robust.tested[b, i]:
            resolved[g] = float(resolvable[i])
        answers[g] = (Answer.WORSE if p_worse[g] < alpha else
                      Answer.EQUIVALENT if p_equivalent[g] < alpha else Answer.UNDECIDED)
    worse = [g for g in groups if answers[g] == Answer.WORSE]
    tied = [g for g in groups if g != best and not p_adjusted[g] < alpha]
    unanswered = [g for i, g in enumerate(groups)
                  if answers[g] == Answer.UNDECIDED and not robust.tested[b, i]]
    return Comparison(best, p_adjusted, worse, tied, left_out, alpha, need, fraction, delta,
                      answers, p_worse, p_equivalent, resolved, groups, unanswered)


def compare_with_best(scores: Mapping[K, Sequence[float]], alpha: float = ALPHA,
                      min_seeds: int = MIN_SEEDS, paired: bool = False) -> Comparison[K]:
    """:func:`compare` at margin 0: which values are worse than the best IQM (the answers'
    step-down at margin 0) and which are tied by the Welch step-down of earlier releases; none
    equivalent."""
    return compare(scores, 0.0, alpha, min_seeds, paired)
