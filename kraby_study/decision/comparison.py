"""One comparison with the best for every verdict: the table's answers, the selection rules,
campaigns, ``best``, ``${winner:...}``, races and the front all read its
[`Comparison`][kraby_study.decision.comparison.Comparison].

Each value of the family (the values with ``min_seeds`` complete seeds) gets one of four
answers about its **interquartile mean** (IQM, the 25 % trimmed mean of its seeds' final
scores), for a margin delta >= 0 in score units, the smallest difference that matters
(``compare.margin``, a fraction of the best value's |IQM|):

- **best**: the highest IQM (the first in order on equal IQMs).
- **worse**: shown worse than the highest true IQM by more than delta.
- **equivalent**: shown within delta of the highest true IQM of the others.
- **undecided**: neither; every value with fewer than
  [`ANSWER_FROM`][kraby_study.records.values.ANSWER_FROM] seeds, where no answer holds its error
  rate.

The IQM and not the mean: when a setting's seeds sometimes fail, no test of a mean holds its
level at a few seeds (a sample that drew no failure shows none). The IQM moves little with
failures a value has at most a quarter of the time, and the failures are counted apart
([`kraby_study.decision.failed_seeds`][]). The tests of each IQM contrast are in
[`kraby_study.decision.robust`][].

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
[`ANSWER_FROM`][kraby_study.records.values.ANSWER_FROM] seeds every cell is within alpha and its
Monte-Carlo error.

The margin is a fraction f of the reference's |IQM| (reported in score units as f x |IQM of the
best|), so "j above g by more than the margin" is the contrast (1 - f sign(T_j)) T_j - T_g > 0,
and every test against the margin is a test of that contrast
([`margin_weights`][kraby_study.decision.comparison.margin_weights]).

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

from kraby_study.decision.robust import ANSWER_FROM, iqm, iqm_pairs
from kraby_study.decision.robust import NAME as TESTS_NAME
from kraby_study.records.values import best_group

ALPHA = 0.05
MIN_SEEDS = 2
"""Fewest complete seeds a value needs to be in the family (at least 2)."""
MARGIN = 0.2
"""Default ``compare.margin``: the margin as a fraction of the best value's |IQM|
(docs/reference/statistics.md justifies it against this project's data)."""
POWER = 0.8
"""The power at which
[`Comparison.resolvable`][kraby_study.decision.comparison.Comparison.resolvable] is the smallest
margin the seeds resolve."""
EQUIVALENCE = ("multiple comparisons with the best with a margin (Edwards and Hsu 1983), "
               "Bonferroni form (Nelson and Matejcik 1995)")

K = TypeVar("K", bound=Hashable)


class Answer(StrEnum):
    """What the comparison says of one value of the family."""

    BEST = "best"
    EQUIVALENT = "equivalent"
    WORSE = "worse"
    UNDECIDED = "undecided"


def answers_name(alpha: float = ALPHA) -> str:
    """How reports name the four answers' procedure."""
    return (f"answers on the interquartile mean (IQM) of the seeds; worse: closed Holm "
            f"step-down against the margin, alpha {alpha:g}; equivalent: {EQUIVALENCE}; "
            f"tests: {TESTS_NAME}; each kind of wrong answer at most {alpha:g}, measured on "
            "skewed scores of unequal spreads too")


def _clean(values: Sequence[float]) -> np.ndarray:
    x = np.asarray(values, dtype=float).ravel()
    return x[~np.isnan(x)]


def p_text(p: float) -> str:
    """A p as reports print it: ``< 0.001``, else three decimals (``0.004``)."""
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


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
    """The weights w_j = 1 - fraction x sign(mean_j) of
    [`iqm_pairs`][kraby_study.decision.robust.iqm_pairs] for a margin that is ``fraction`` of the
    reference's |location| (its IQM in the answers): "mu_g within f |mu_j| of mu_j" is
    mu_g - w_j mu_j >= 0 (the sign read from the sample; the leg's scores are all negative, so
    w = 1 + f there)."""
    return 1.0 - float(fraction) * np.sign(np.asarray(means, dtype=float))


def margin_units(fraction: float, best_mean: float) -> float:
    """The margin in score units: ``fraction`` of the best value's |IQM| (0 for a NaN)."""
    return float(fraction) * abs(best_mean) if math.isfinite(best_mean) else 0.0


@dataclass(frozen=True)
class Comparison(Generic[K]):
    """The result of [`compare`][kraby_study.decision.comparison.compare] on the current samples:
    every verdict reads it."""

    best: K | None
    """The value with the highest IQM among those with enough seeds; None if none has."""
    worse: list[K]
    """Values shown worse than the best by more than the margin, in the given order."""
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
    pair of the value is tested, below [`ANSWER_FROM`][kraby_study.records.values.ANSWER_FROM]
    seeds)."""
    p_equivalent: dict[K, float] = field(default_factory=dict)
    """Bonferroni p of "more than the margin below the highest IQM of the others": (k - 1)
    x the largest p over the others (NaN for the best; 1 at margin 0 and where a pair is not
    tested)."""
    resolvable: dict[K, float] = field(default_factory=dict)
    """Per value other than the best, about the smallest margin at which a value truly equal to
    the best is shown equivalent with probability [`POWER`][kraby_study.decision.comparison.POWER]:
    (t(1 - alpha / (k - 1)) + t(POWER)) x Yuen's standard error of its IQM contrast with the
    best, with Yuen's degrees of freedom (absent where untested)."""
    family: list[K] = field(default_factory=list)
    """The values with enough seeds, in the given order."""
    unanswered: list[K] = field(default_factory=list)
    """Values of the family other than the best that no test reaches: fewer than
    [`ANSWER_FROM`][kraby_study.records.values.ANSWER_FROM] seeds, on their side or the best's.
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
        """The seeds' resolution of the study: the median of
        [`resolvable`][kraby_study.decision.comparison.Comparison.resolvable] over the values other
        than the best (NaN with none)."""
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
    """``report.min_seeds``, clamped to at least 2 by
    [`evidence`][kraby_study.decision.comparison.evidence] alone."""
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
    """The seeds a value needs ([`seeds_needed`][kraby_study.decision.comparison.seeds_needed]), the
    values that have them (the family, NaN dropped), and the others that have some: their count of
    seeds."""
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
    best of [`compare`][kraby_study.decision.comparison.compare], without its tests); None if none
    has them."""
    _, family, _ = evidence(scores, min_seeds)
    return best_by_iqm(family)


def _step_down(matrix: np.ndarray) -> list[float]:
    """Holm over pi_g = min(1, (k - 1) min_j p[j, g]); an untested pair (NaN) does not count
    against g."""
    k = len(matrix)
    beaten = np.where(np.eye(k, dtype=bool) | np.isnan(matrix), 1.0, matrix)
    pi = np.minimum(1.0, (k - 1) * np.min(beaten, axis=0)) if k > 1 else np.ones(1)
    return holm(list(pi))


def compare(scores: Mapping[K, Sequence[float]], margin: float, *, alpha: float = ALPHA,
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
            common seeds (resampled together, and Yuen's test for dependent trimmed means).
        tests: False: only the best, the family and the values left out, no test (``list``
            and the rules that need none stay clear of scipy.stats).

    Returns:
        The [`Comparison`][kraby_study.decision.comparison.Comparison].
    """
    need, family, left_out = evidence(scores, min_seeds)
    best = best_by_iqm(family)
    fraction = float(margin)
    if best is None or not tests:
        return Comparison(best=best, worse=[], left_out=left_out, alpha=alpha,
                          min_seeds=need, fraction=fraction, family=list(family))
    groups = list(family)
    k = len(groups)
    locations = np.array([float(iqm(family[g])) for g in groups])
    delta = margin_units(fraction, float(locations[groups.index(best)]))
    weights = margin_weights(locations, fraction) if delta > 0 else None
    if paired:
        aligned = [np.asarray(scores[g], dtype=float).ravel() for g in groups]
        if len({len(x) for x in aligned}) > 1:
            raise ValueError("paired samples must be aligned by seed: equal lengths")
        robust = iqm_pairs(aligned, weights, alpha, paired=True)
    else:
        robust = iqm_pairs([family[g] for g in groups], weights, alpha)
    # With a margin, "j beats g by more than f |T_j|" is the contrast w_j T_j - T_g > 0 (the
    # weights): its tests count the reference's noise in the margin, which a margin read off
    # the sample and then kept fixed would leave out.
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
    p_worse, p_equivalent, answers, resolved = {}, {}, {}, {}
    for i, g in enumerate(groups):
        if g == best:
            p_worse[g] = p_equivalent[g] = math.nan
            answers[g] = Answer.BEST
            continue
        p_worse[g] = at_margin[i]
        p_equivalent[g] = float(equivalent[i])
        if robust.tested[b, i]:
            resolved[g] = float(resolvable[i])
        answers[g] = (Answer.WORSE if p_worse[g] < alpha else
                      Answer.EQUIVALENT if p_equivalent[g] < alpha else Answer.UNDECIDED)
    worse = [g for g in groups if answers[g] == Answer.WORSE]
    unanswered = [g for i, g in enumerate(groups)
                  if answers[g] == Answer.UNDECIDED and not robust.tested[b, i]]
    return Comparison(best=best, worse=worse, left_out=left_out, alpha=alpha, min_seeds=need,
                      fraction=fraction, margin=delta, answers=answers, p_worse=p_worse,
                      p_equivalent=p_equivalent, resolvable=resolved, family=groups,
                      unanswered=unanswered)

