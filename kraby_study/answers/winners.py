"""Where ``${winner:STUDY}`` values come from: the selected values of finished studies in the
command's store ([`sweep_selection`][kraby_study.answers.selected.sweep_selection]), with a record
of each one taken.

A standalone study names stored studies directly; a campaign stage names earlier stages by their
study, stored as ``<campaign>-<study>``.

A selection that later work was built on is a stored fact, not recomputed: when a stored stage
of the campaign recorded the value it took from an earlier stage (its ``inputs``), that value
and the rule that chose it are taken again, whatever today's rules would select
([`recorded_inputs`][kraby_study.answers.winners.recorded_inputs]).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from omegaconf import DictConfig

from kraby_study.decision.comparison import CompareOptions
from kraby_study.errors import ConfigError, StoreError
from kraby_study.records.attributes import StudyKind
from kraby_study.records.stored import counted, tally
from kraby_study.records.values import value_label

if TYPE_CHECKING:
    from kraby_study.answers.selected import SweepSelection


class Unfinished(StoreError):
    """The study a ``${winner:...}`` names is not stored yet, or has runs still to come."""


@dataclass(frozen=True)
class Input:
    """A setting taken from an earlier study's selected value."""

    setting: str
    value: Any
    study: str
    rule: str

    def stored(self) -> dict[str, Any]:
        """As kept in the study's attributes."""
        return {"setting": self.setting, "value": self.value, "study": self.study,
                "rule": self.rule}

    def text(self) -> str:
        """``ppo.gamma = 0.8, selected in documented-gamma``."""
        return f"{self.setting} = {value_label(self.value)}, selected in {self.study}"


def carried(selected: SweepSelection, parameter: str, definition: dict[str, Any]) -> Any:
    """The value a selection carries into later settings.

    A ppo.batch_size equal to its study's whole rollout carries as null (one minibatch of the
    whole rollout, nminibatches 1), so it stays one batch when a later stage changes n_steps
    or n_envs; any other value carries as it is.
    """
    if parameter == "ppo.batch_size" and selected.value is not None:
        ppo = definition.get("settings", {}).get("ppo", {})
        if int(selected.value) == int(ppo.get("n_steps", 0)) * int(ppo.get("n_envs", 0)):
            return None
    return selected.value


@dataclass
class StoreWinners:
    """A [`Lookup`][kraby_study.config.winner.Lookup] reading the command's store.

    Attributes:
        names: For a campaign stage: study -> stored name of the earlier stages it may name;
            None for a standalone study (stored studies are named directly).
        recorders: Stored studies whose recorded inputs are facts to take again (a
            campaign's stages); empty: every value is selected afresh.
        inputs: Every value taken, in the order they were resolved.
    """

    names: dict[str, str] | None = None
    recorders: list[str] = field(default_factory=list)
    inputs: list[Input] = field(default_factory=list)
    _recorded: dict[str, Input] | None = None
    _cache: dict[str, tuple[SweepSelection, str, dict[str, Any]]] = field(default_factory=dict)

    def stored_name(self, study: str, setting: str, root: DictConfig) -> str:
        """The stored study a reference names; ConfigError for one it may not name."""
        where = f"{setting}: ${{winner:{study}}}"
        if self.names is None:
            current = root.get("study")
            if current is not None and str(current.get("name")) == study:
                raise ConfigError(f"{where} refers to the study itself")
            return study
        if study not in self.names:
            raise ConfigError(f"{where}: {study!r} is not an earlier stage of the campaign")
        return self.names[study]

    def __call__(self, study: str, setting: str, root: DictConfig) -> Any:
        name = self.stored_name(study, setting, root)
        if self._recorded is None:
            self._recorded = recorded_inputs(str(root.storage), self.recorders)
        if name in self._recorded:
            taken = self._recorded[name]
            self.inputs.append(Input(setting=setting, value=taken.value, study=name,
                                     rule=taken.rule))
            return taken.value
        if name not in self._cache:
            self._cache[name] = _read(str(root.storage), name, f"{setting}: ${{winner:{study}}}",
                                      CompareOptions.of(root))
        selected, parameter, definition = self._cache[name]
        value = carried(selected, parameter, definition)
        self.inputs.append(Input(setting=setting, value=value, study=name, rule=selected.rule))
        return value



def recorded_inputs(url: str, names: Sequence[str]) -> dict[str, Input]:
    """The values stored studies ``names`` ran on, by the study each was taken from: the
    first recording in ``names`` order wins (every stage of one campaign records the same).
    Nothing is created; a study not stored records nothing."""
    if not names:
        return {}
    from kraby_study.answers.resumed import stored_attrs

    found: dict[str, Input] = {}
    for name in names:
        attrs = stored_attrs(url, name)
        for taken in (attrs.inputs or []) if attrs is not None else []:
            found.setdefault(str(taken["study"]), Input(
                setting=str(taken["setting"]), value=taken["value"],
                study=str(taken["study"]), rule=str(taken["rule"])))
    return found

def _read(url: str, name: str, where: str, options: CompareOptions
          ) -> tuple[SweepSelection, str, dict[str, Any]]:
    """The selection of a finished stored sweep (under the command's margin, seeds and
    ``compare.select``), its parameter and definition.

    Raises:
        Unfinished: The study is not stored, or has runs still to come.
        StoreError: It is not a sweep, or none of its runs is complete.
    """
    # Loaded here, when a config names a winner: every ``run`` installs this lookup, and most
    # configs name none, so composing them needs no database or statistics code.
    from kraby_study.answers.selected import sweep_selection
    from kraby_study.store.store import opened, study_exists

    if not study_exists(url, name):
        raise Unfinished(f"{where}: no study {name!r} in the store yet; run it first")
    with opened(url, create=False, writer=False) as store:
        ledger = store.load(name)
        attrs = ledger.attrs
        if not StudyKind.of(attrs.kind).swept or "parameter" not in attrs.definition:
            raise StoreError(f"{where}: study {name!r} is not a sweep, so it selects no value")
        counts = tally(counted(ledger.trials()), attrs.planned)
        planned = counts.planned
        if not counts.finished:
            raise Unfinished(f"{where}: study {name!r} is incomplete ({counts.complete}/{planned}"
                             " complete); finish it first")
        selected = sweep_selection(ledger, options)
    if selected is None:
        raise StoreError(f"{where}: study {name!r} has no selectable value (0/{planned} complete,"
                         f" {counts.failed} failed, {counts.pruned} pruned)")
    return selected, str(attrs.definition["parameter"]), dict(attrs.definition)
