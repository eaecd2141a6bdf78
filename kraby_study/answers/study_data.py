"""Reading a store for a report: each study's counted trials and their curves, as frames.

The report only reads, through the store ([`kraby_study.store`][]); the store refuses a missing,
empty or foreign file before anything could create a database at a wrong path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pandas as pd
from optuna.trial import FrozenTrial

from kraby_study.errors import StoreError
from kraby_study.records.attributes import StudyKind, TrialAttrs
from kraby_study.records.definition import UNRECORDED_SEEDING, stored_seeding
from kraby_study.records.stored import Tally, counted, offset_leg_seeds, tally, trial_seeds
from kraby_study.store.ledger import StudyLedger
from kraby_study.store.store import Store


@dataclass
class StudyData:
    """One stored study, as the report sees it.

    Attributes:
        name: The study's name in the store.
        kind: ``sweep``, ``train``, ``search``, ``confirm`` (fresh seeds of chosen
            configurations) or ``optuna`` (a study kraby-study did not make).
        ledger: The stored study.
        definition: The stored definition (sweeps, confirm studies and single runs), else
            empty.
        trials: The trials that count
            ([`counted`][kraby_study.records.stored.counted]), in number order.
        curves: Learning-curve points of the counted trials, columns ``number, step,
            mean_reward, wall_time, episodes``.
        planned: Planned number of runs (or trials), if the store says.
        replaced: Attempts that a later attempt superseded (not results).
        rechecked: For each counted recheck (a search trial retrained on more seeds), the
            attempt it rechecked, by the recheck's number: the checkpoints its first seeds
            reported are that attempt's (a recheck reports none).
        provenance: What made its trials: each distinct provenance record, by key.
        source_seeds: A confirm study's source's seeds (the tuning seeds), None when it has
            no source or the source is not in the store.
        source_legs: Under offset seeding of that source, the seed each leg of its runs was
            reset with ([`offset_leg_seeds`][kraby_study.records.stored.offset_leg_seeds]); None
            otherwise (no source, or a source seeded by streams).
    """

    name: str
    kind: StudyKind
    ledger: StudyLedger
    definition: dict[str, Any]
    trials: list[FrozenTrial]
    curves: pd.DataFrame
    planned: int | None = None
    replaced: int = 0
    rechecked: dict[int, FrozenTrial] = field(default_factory=dict)
    provenance: dict[str, dict[str, str]] = field(default_factory=dict)
    source_seeds: list[int] | None = None
    source_legs: set[int] | None = None

    @property
    def tally(self) -> Tally:
        """Outcomes of the counted trials against the runs planned."""
        return tally(self.trials, self.planned)


def select_studies(store: Store, name: str | None) -> list[str]:
    """The names to report: every study, or the one asked for.

    Raises:
        StoreError: No study of that name; the message lists the stored ones.
    """
    names = store.study_names()
    if name is None:
        return names
    if name not in names:
        shown = ", ".join(names[:10]) + (", ..." if len(names) > 10 else "")
        raise StoreError(f"no study named {name!r} in {store.url} (studies: {shown})")
    return [name]


def load_study(store: Store, name: str) -> StudyData:
    """A study, its counted trials and their curves."""
    ledger = store.load(name)
    attrs = ledger.attrs
    kind = StudyKind.of(attrs.kind)
    if kind.swept and "parameter" not in attrs.definition:
        kind = StudyKind.OPTUNA
    every = ledger.trials()
    trials = counted(every)
    curves = ledger.curves([t.number for t in trials])
    by_number = {t.number: t for t in every}
    rechecked = {t.number: by_number[of] for t in trials
                 if (of := TrialAttrs.of(t).recheck_of) is not None and of in by_number}
    return StudyData(name=name, kind=kind, ledger=ledger, definition=dict(attrs.definition),
                     trials=trials, curves=curves, planned=attrs.planned,
                     replaced=len(every) - len(trials), rechecked=rechecked,
                     provenance=ledger.provenances(),
                     **_source(store, kind, attrs.definition))


def _source(store: Store, kind: StudyKind, definition: dict[str, Any]) -> dict[str, Any]:
    """A confirm study's source as its reproducibility page reads it: the seeds it trained (its
    tuning seeds) and, under offset seeding, its legs' seeds; nothing when it has no source or
    the source is not in the store."""
    source = definition.get("source")
    if kind != StudyKind.CONFIRM or not source or source not in store.study_names():
        return {}
    ledger = store.load(str(source))
    attrs = ledger.attrs
    per_trial = int(attrs.definition.get("seeds", 1)) if attrs.kind == StudyKind.SEARCH else 1
    trials = counted(ledger.trials())
    legs = ({leg for t in trials for leg in offset_leg_seeds(t, per_trial)}
            if stored_seeding(attrs.definition) == UNRECORDED_SEEDING else None)
    return {"source_seeds": sorted({seed for t in trials for seed in trial_seeds(t, per_trial)}),
            "source_legs": legs}
