"""The API's one reader of the answers layer: where each stored study stands, a study's runs,
its four answers and what its rule selected, as typed objects; and the same four answers over
any seed scores.

Every value of a sweep is answered on the interquartile mean (IQM) of its seeds' final
scores, against the value with the highest IQM, at a margin that is a fraction of the best's
|IQM| (docs/reference/statistics.md): **best**; **equivalent** (shown within the margin of
the best: multiple comparisons with the best with a margin, Edwards and Hsu 1983, in Nelson
and Matejcik's Bonferroni form); **worse** (shown below it by more than the margin: a closed
Holm step-down); **undecided** (neither). Each kind of wrong answer has probability at most
alpha. The comparison itself is `kraby_study.decision.comparison.compare`; this module
only reads it, and the stored studies through `kraby_study.answers`: every other module of
the API that needs an answer asks this one.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

from kraby_study.errors import StoreError

if TYPE_CHECKING:
    import pandas as pd

    from kraby_study.answers.selected import Selection
    from kraby_study.answers.standing import StudyStanding
    from kraby_study.decision.comparison import Comparison

MARGIN = 0.2
"""The default margin, as a fraction of the best value's |IQM| (``compare.margin``)."""
ALPHA = 0.05
"""The default error rate of each kind of wrong answer."""


@dataclass(frozen=True)
class StudyInfo:
    """Where one stored study stands.

    Attributes:
        name: Its name in the store.
        kind: ``sweep``, ``train``, ``search``, ``confirm`` or ``optuna``.
        complete: Complete runs (or trials).
        failed: Failed runs.
        pruned: Pruned runs.
        running: Runs running now, here or elsewhere.
        planned: Runs planned (a search: its trial total).
        ran_on: Where its runs ran (``1 node``, ``3 nodes, 2 CPU models``; ``-`` for none).
        selected: What it selects so far, in a few words (``-`` when nothing is complete).
        retry: How many runs failed and the command that runs them again with the same
            seeds and settings (None when none failed).
    """

    name: str
    kind: str
    complete: int
    failed: int
    pruned: int
    running: int
    planned: int
    ran_on: str
    selected: str
    retry: str | None = None


def study_info(standing: StudyStanding) -> StudyInfo:
    """A study's standing as the API hands it out."""
    tally = standing.tally
    return StudyInfo(name=standing.name, kind=standing.kind.value, complete=tally.complete,
                     failed=tally.failed, pruned=tally.pruned, running=tally.running,
                     planned=tally.planned, ran_on=standing.placement.text(),
                     selected=standing.selected, retry=standing.retry_line())


@dataclass(frozen=True)
class Run:
    """One counted run of a stored study (a sweep's value x seed, a search's trial).

    Attributes:
        number: The trial's number in the store.
        outcome: ``complete``, ``failed``, ``pruned`` or ``pending``.
        score: Its final score (None unless complete).
        seed: Its (first) seed.
        value: A sweep's value, as the report writes it (None for a search's trial).
        params: A search trial's sampled settings (empty for a sweep's run).
        env_steps: Env steps it trained.
        wall_time: Seconds it took.
        cpu_time: CPU seconds it used.
        failure: Why it failed or was stopped ("" otherwise).
    """

    number: int
    outcome: str
    score: float | None
    seed: int | None
    value: str | None = None
    params: dict[str, Any] = field(default_factory=dict)
    env_steps: float | None = None
    wall_time: float | None = None
    cpu_time: float | None = None
    failure: str = ""


@dataclass(frozen=True)
class Runs:
    """A stored study's counted runs, in trial-number order; iterate, or read
    `to_frame`."""

    study: str
    kind: str
    runs: list[Run]

    def __iter__(self) -> Iterator[Run]:
        return iter(self.runs)

    def __len__(self) -> int:
        return len(self.runs)

    def to_frame(self) -> pd.DataFrame:
        """One row per run; a search's settings as one column each (``param_NAME``)."""
        import pandas as pd

        rows = []
        for run in self.runs:
            row = asdict(run)
            params = row.pop("params")
            rows.append({**row, **{f"param_{k}": v for k, v in params.items()}})
        columns = [f.name for f in Run.__dataclass_fields__.values() if f.name != "params"]
        return pd.DataFrame(rows, columns=list(dict.fromkeys(
            columns + [c for row in rows for c in row])))


@dataclass(frozen=True)
class ValueAnswer:
    """One value's answer against the best.

    Attributes:
        value: The value (a sweep's value as the report writes it; a key of the scores given
            to `compare`).
        seeds: Its complete seeds.
        iqm: The interquartile mean of their scores (NaN without any).
        answer: ``best``, ``equivalent``, ``worse``, ``undecided``, or ``too few seeds``
            (fewer than the comparison's ``min_seeds``: not compared).
        p_worse: Holm-adjusted p of "within the margin of the best" (< alpha: worse); None for
            the best and the values not compared.
        p_equivalent: Bonferroni p of "more than the margin below the best" (< alpha:
            equivalent); None likewise.
    """

    value: Any
    seeds: int
    iqm: float
    answer: str
    p_worse: float | None = None
    p_equivalent: float | None = None


@dataclass(frozen=True)
class Answers:
    """Every value's answer against the best, at a stated margin and alpha.

    Attributes:
        values: One answer per value, in the given order.
        best: The value with the highest IQM among those compared (None if none is).
        margin: The margin as a fraction of the best's |IQM|.
        margin_units: The margin in score units (``margin`` x |IQM of the best|).
        alpha: The error rate of each kind of wrong answer.
        min_seeds: The fewest complete seeds a value needs to be compared.
        method: The procedure, named as the report names it.
        warnings: Why some answers cannot be reached (too few seeds, a margin below what
            the seeds resolve).
        study: The stored study answered (None for `compare`).
        parameter: A sweep's swept setting (None otherwise).
        rule: The study's selection rule (None for `compare`).
        selected: The value the rule selects, once the study is finished (None otherwise).
    """

    values: list[ValueAnswer]
    best: Any
    margin: float
    margin_units: float
    alpha: float
    min_seeds: int
    method: str
    warnings: list[str] = field(default_factory=list)
    study: str | None = None
    parameter: str | None = None
    rule: str | None = None
    selected: Any = None

    def answer(self, value: Any) -> str:
        """One value's answer (KeyError for a value not given)."""
        for found in self.values:
            if found.value == value:
                return found.answer
        raise KeyError(value)

    def to_frame(self) -> pd.DataFrame:
        """One row per value: value, seeds, iqm, answer, p_worse, p_equivalent."""
        import pandas as pd

        return pd.DataFrame([asdict(v) for v in self.values],
                            columns=[f for f in ValueAnswer.__dataclass_fields__])


def compare(scores: Mapping[Hashable, Sequence[float]], margin: float = MARGIN,
            alpha: float = ALPHA, min_seeds: int = 2) -> Answers:
    """Answer each value's seed scores against the best: best, equivalent, worse or undecided.

    Args:
        scores: Final scores of the seeds, by value (NaN ignored); higher is better.
        margin: The smallest difference that matters, as a fraction of the best value's
            |IQM| (0: no value can be shown equivalent).
        alpha: The error rate of each kind of wrong answer.
        min_seeds: The fewest scores a value needs to be compared (at least 2). Below 4
            seeds on either side no test holds its error rate, so such a value is
            undecided by rule.

    Returns:
        The `Answers`.

    Examples:
        >>> import kraby_study as ks
        >>> found = ks.compare({"a": [10.0, 10.2, 9.9, 10.1, 10.0, 9.8],
        ...                     "b": [5.0, 5.3, 4.9, 5.2, 5.1, 4.8]})
        >>> found.best, found.answer("b")
        ('a', 'worse')
    """
    from kraby_study.answers.seed_scores import sweep_comparison
    from kraby_study.decision.comparison import CompareOptions, answers_name

    keys = list(scores)
    by_index = {i: [float(s) for s in scores[key]] for i, key in enumerate(keys)}
    options = CompareOptions(margin=float(margin), alpha=float(alpha), min_seeds=int(min_seeds))
    found = sweep_comparison(by_index, (), options)
    return _answers(found, by_index, dict(enumerate(keys)), answers_name(alpha))


def _answers(found: Comparison[Any], scores: Mapping[Any, Sequence[float]],
             labels: Mapping[Any, Any], method: str, **study: Any) -> Answers:
    """The comparison's answers, each value under its label."""
    import numpy as np

    from kraby_study.decision.robust import iqm

    values = []
    for key, label in labels.items():
        clean = np.asarray([s for s in scores.get(key, []) if not math.isnan(s)], dtype=float)
        answer = found.answers.get(key)
        values.append(ValueAnswer(
            value=label, seeds=len(clean), iqm=float(iqm(clean)) if len(clean) else math.nan,
            answer=answer.value if answer is not None else "too few seeds",
            p_worse=_p_or_none(found.p_worse.get(key)),
            p_equivalent=_p_or_none(found.p_equivalent.get(key))))
    warnings = [t for t in (found.unanswered_text(), found.resolution_text()) if t]
    return Answers(values=values, best=None if found.best is None else labels[found.best],
                   margin=found.fraction, margin_units=found.margin, alpha=found.alpha,
                   min_seeds=found.min_seeds, method=method, warnings=warnings, **study)


def _p_or_none(value: float | None) -> float | None:
    """A p-value as the answers hold it: None where it was not tested (NaN)."""
    return None if value is None or math.isnan(value) else float(value)


def read_runs(url: str, name: str) -> Runs:
    """A stored study's counted runs (`kraby_study.api.store.StudyStore.runs`)."""
    from kraby_study.answers.study_data import load_study, select_studies
    from kraby_study.answers.sweep_evidence import sweep_evidence
    from kraby_study.records.attributes import TrialAttrs
    from kraby_study.records.stored import outcome
    from kraby_study.store.store import opened_for_reading

    with opened_for_reading(url) as store:
        data = load_study(store, select_studies(store, name)[0])
    labels: dict[int, str] = {}
    if data.kind.seeded:
        rows = sweep_evidence(data).trials
        labels = dict(zip(rows["number"], rows["value"], strict=True))
    runs = []
    for trial in data.trials:
        attrs = TrialAttrs.of(trial)
        state = outcome(trial)
        runs.append(Run(
            number=trial.number, outcome=state.value,
            score=float(trial.value) if state.value == "complete" and trial.value is not None
            else None, seed=attrs.seed, value=labels.get(trial.number),
            params={} if labels else dict(trial.params), env_steps=attrs.env_steps,
            wall_time=attrs.wall_time, cpu_time=attrs.cpu_time,
            failure=attrs.failure or "" if state.value in ("failed", "pruned") else ""))
    return Runs(study=data.name, kind=data.kind.value, runs=runs)


def read_answers(url: str, name: str, margin: float | None = None,
                 select: str | None = None, min_seeds: int = 2) -> Answers:
    """A stored sweep's (or confirm study's) answers
    (`kraby_study.api.store.StudyStore.answers`)."""
    from kraby_study.answers.study_data import load_study, select_studies
    from kraby_study.answers.sweep_evidence import build_sweep
    from kraby_study.decision.comparison import CompareOptions, answers_name
    from kraby_study.store.store import opened_for_reading

    options = CompareOptions(margin=MARGIN if margin is None else float(margin),
                             min_seeds=min_seeds, select=select)
    with opened_for_reading(url) as store:
        data = load_study(store, select_studies(store, name)[0])
        if not data.kind.seeded:
            raise StoreError(f"study {name!r} is a {data.kind.value}: its trials are not "
                             "answered against a best; read its runs")
        sweep = build_sweep(data, options)
    labels = dict(enumerate(sweep.labels))
    # The summary's rows carry the one selection the study's rule made from this comparison.
    selected = next((row.value for row in sweep.rows if row.selected), None)
    return _answers(sweep.comparison, sweep.final_scores, labels, answers_name(ALPHA),
                    study=data.name, parameter=sweep.parameter or None, rule=str(sweep.rule),
                    selected=selected)


def read_studies(url: str) -> list[StudyInfo]:
    """Where every study of a store stands (`kraby_study.api.store.StudyStore.studies`), read
    without Optuna."""
    from kraby_study.answers.standing import store_standings

    return [study_info(s) for s in store_standings(url)]


def read_selection(url: str, study: str, campaign: str | None, margin: float | None,
                   select: str | None, min_seeds: int) -> Selection:
    """What a stored study's rule selected, or what a finished campaign ends with
    (`kraby_study.api.settings_files.best`)."""
    from kraby_study.answers.campaign import campaign_selection
    from kraby_study.answers.selected import require_selection
    from kraby_study.decision.comparison import CompareOptions
    from kraby_study.store.store import opened

    options = CompareOptions(margin=MARGIN if margin is None else float(margin),
                             min_seeds=min_seeds, select=select)
    with opened(url, create=False, writer=False) as store:
        return (campaign_selection(store, campaign, options) if campaign
                else require_selection(store.load(study), options))
