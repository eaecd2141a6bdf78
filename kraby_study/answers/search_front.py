"""A stored two-objective search's front and its selection: what ``list``, ``best``,
``confirm`` and the report read of it ([`kraby_study.decision.front`][] holds the rules)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from kraby_study.decision.comparison import CompareOptions
from kraby_study.decision.front import FRONT_RULES, FrontChoice, Point, front_choice, pareto_front
from kraby_study.errors import ConfigError
from kraby_study.records.attributes import SelectRule, TrialAttrs
from kraby_study.records.definition import floor_score
from kraby_study.records.stored import Outcome, StoredTrial, known_number, outcome
from kraby_study.records.values import cost, score


@dataclass(frozen=True)
class SearchFront:
    """The front of a two-objective search's counted trials and the trial its rule selects."""

    points: list[Point[int]]
    """Every complete trial with a score and a cost, keyed by the number the search knows it
    by (its first attempt's, whichever attempt holds it now: a retry of an interrupted one)."""
    front: list[Point[int]]
    """The trials on the front, cheapest first."""
    choice: FrontChoice[int] | None
    """The trial the search's rule selects from the front; None when nothing is complete."""
    floor: str | None = None
    """The search's floor (an enqueued ppo config's name), if it has one."""
    floor_score: float | None = None
    """The floor's measured score: the front holds only trials scoring at least this; None
    without a floor, or while the floor is not measured (then every trial may be on it)."""

    @property
    def floor_text(self) -> str:
        """The floor in words, for ``best`` and the report; empty without one."""
        if self.floor is None:
            return ""
        if self.floor_score is None:
            return f"floor ppo={self.floor} not measured yet: no trial left out"
        below = sum(1 for p in self.points if p.score < self.floor_score)
        return (f"floor ppo={self.floor}, score {self.floor_score:.4g}: {below} complete "
                f"trial(s) below it are infeasible, off the front")


def seed_scores(trial: StoredTrial) -> list[float]:
    """A trial's seed scores as stored (``scores``); its score alone when it stores none."""
    stored = TrialAttrs.of(trial).scores
    if stored:
        return [float(s) for s in stored]
    mean = score(trial)
    return [] if mean is None else [mean]


def front_rule(stored: str | None, options: CompareOptions | None = None) -> SelectRule:
    """The rule a search's front is selected by: ``compare.select`` when given, else the rule
    the search stored (a two-objective search stores fastest_equivalent), else
    fastest_equivalent; a retired stored name is answered by today's rule
    ([`SelectRule.of`][kraby_study.records.attributes.SelectRule.of]).

    Raises:
        ConfigError: ``compare.select`` names a rule a front cannot take (auc: a search
            stores no curve per seed to compare).
    """
    if options is not None and options.select is not None:
        rule = SelectRule.check(options.select, "compare.select")
        if rule not in FRONT_RULES:
            raise ConfigError(f"compare.select={rule} cannot select from a front: use one of "
                              f"{', '.join(FRONT_RULES)}")
        return rule
    return SelectRule.of(stored) if stored is not None else SelectRule.FASTEST_EQUIVALENT


def search_front(trials: Sequence[StoredTrial], floor: str | None = None,
                 rule: str = SelectRule.FASTEST_EQUIVALENT,
                 options: CompareOptions | None = None) -> SearchFront:
    """The front of a two-objective search's counted trials, and its selection.

    Args:
        trials: The search's counted trials.
        floor: Its floor ([`stored_floor`][kraby_study.records.definition.stored_floor]): once
            the floor's trial is complete, trials scoring below it are left out of the front (and
            so of the selection and of ``confirm``); they stay among ``points``.
        rule: The front's rule ([`front_rule`][kraby_study.answers.search_front.front_rule]).
        options: The comparison's margin and seeds; None: the defaults.
    """
    points = [Point(known_number(t), float(score(t)), float(cost(t)))  # type: ignore[arg-type]
              for t in trials if outcome(t) == Outcome.COMPLETE and score(t) is not None
              and cost(t) is not None]
    measured = None if floor is None else floor_score(trials, floor)
    feasible = [p for p in points if measured is None or p.score >= measured]
    front = pareto_front(feasible)
    on_front = {p.key for p in front}
    samples = {known_number(t): seed_scores(t) for t in trials if known_number(t) in on_front}
    choice = front_choice(front, samples, rule, options or CompareOptions())
    return SearchFront(points=points, front=front, choice=choice, floor=floor,
                       floor_score=measured)


def point_text(point: Point[int]) -> str:
    """A front's trial in a few words: ``trial 7 (score -0.0123, 8.41 CPU s/seed)``."""
    return f"trial {point.key} (score {point.score:.4g}, {point.cost:.3g} CPU s/seed)"


def front_short(found: SearchFront) -> str:
    """A two-objective search's standing for ``list``: the front's size and its selection."""
    if found.choice is None:
        return "-"
    rule = found.choice.rule if found.choice.tested else "best score, untested"
    return f"front of {len(found.front)}; {point_text(found.choice.chosen)}, {rule}"


def front_lines(found: SearchFront) -> list[str]:
    """The front as ``best`` prints it: one line per trial (trial, score, cost), each trial's
    answer against the best score and the selection marked."""
    choice = found.choice
    lines = [f"front ({len(found.front)} of {len(found.points)} complete trials; score, cost "
             "in CPU s per seed):"]
    if found.floor_text:
        lines.append(f"  ({found.floor_text})")
    if choice is not None and choice.comparison is not None:
        lines.append(f"  (answers against the best score: {choice.comparison.margin_text()})")
        warning = choice.comparison.resolution_text()
        if warning:
            lines.append(f"  (warning: {warning})")
    for point in sorted(found.front, key=lambda p: -p.score):
        marks = []
        compared = choice.comparison if choice is not None else None
        if choice is not None and point.key == choice.best.key:
            marks.append("best score")
        elif compared is not None and point.key in compared.answers:
            marks.append(str(compared.answers[point.key]))
        if choice is not None and point.key == choice.chosen.key:
            marks.append("selected")
        mark = f"  [{', '.join(marks)}]" if marks else ""
        lines.append(f"  trial {point.key:>4}  {point.score:>10.4g}  {point.cost:>8.3g}{mark}")
    return lines
