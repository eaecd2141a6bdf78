"""A racing search as its stored runs tell it: each configuration's seeds, its IQM and how it
left, and the incumbent it picks, replayed
([`intensify`][kraby_study.decision.race.intensify]) from the runs in the order they ended.

A racing search stores one trial per run (a configuration, a seed), keyed
``c<configuration>-s<seed>``, as a race stores a sweep; its definition holds its race's rules
(``racing``). The replay reads the latest attempt of each run, so the same store gives the same
search whichever command reads it: ``best``, ``list``, ``confirm`` and the report.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from kraby_study.decision.race import Intensification, Left, RunEnd, Standing, intensify
from kraby_study.decision.robust import iqm
from kraby_study.plan.spec import RaceRules
from kraby_study.records.attributes import StudyKind, TrialAttrs
from kraby_study.records.stored import (
    Outcome,
    StoredTrial,
    is_diverged,
    latest_by_key,
    outcome,
    parse_racing_key,
)

REFUSED = "refused:"
"""How the failure of a run whose settings the search's rules refused begins, after its kind."""


def racing_rules(kind: str | None, definition: Mapping[str, Any]) -> RaceRules | None:
    """The race of a racing search (a search whose definition stores ``racing``); None for any
    other study."""
    if kind != StudyKind.SEARCH:
        return None
    return RaceRules.of(dict(definition))


@dataclass(frozen=True)
class RacedConfiguration:
    """One configuration of a racing search, as the report and ``best`` show it."""

    number: int
    """Its number, in the order the search asked for configurations (from 0)."""
    params: dict[str, Any]
    """Its sampled settings, by parameter name."""
    settings: dict[str, Any]
    """The resolved env and ppo settings it trained with (empty before any run started)."""
    scores: dict[int, float]
    """Its ended runs' final scores by seed index (NaN: failed)."""
    cpu: float
    """Mean CPU seconds per ended run."""
    standing: Standing[int]
    enqueued: str | None = None
    """The configuration it was evaluated first as (``search.enqueue``), e.g. ppo=tuned."""

    @property
    def key(self) -> str:
        """``c3``."""
        return f"c{self.number}"

    @property
    def seeds(self) -> int:
        """Seeds ended (complete or failed)."""
        return len(self.scores)

    @property
    def failed(self) -> int:
        """Runs ended without a score."""
        return sum(1 for s in self.scores.values() if math.isnan(s))

    @property
    def iqm(self) -> float:
        """The IQM of its complete seeds' final scores (NaN with none)."""
        clean = np.asarray([s for s in self.scores.values() if not math.isnan(s)], dtype=float)
        return float(iqm(clean)) if len(clean) else math.nan

    def evidence_text(self) -> str:
        """``IQM 162.2 over 6 seeds (2 failed)``."""
        failed = f" ({self.failed} failed)" if self.failed else ""
        return f"IQM {self.iqm:.4g} over {self.seeds} seeds{failed}"

    def left_text(self) -> str:
        """How it left: ``incumbent``, ``worse at seed 4 (p 0.0021)``, ``replaced by c7 at
        seed 6``, ``equivalent at seed 5, not cheaper``, ``below the incumbent at seed 6 (IQM
        on the common seeds)``, ``racing``, ``refused``."""
        s = self.standing
        p = f", p {s.p:.2g}" if math.isfinite(s.p) else ""
        by = f"c{s.by}" if s.by is not None else "the incumbent"
        if s.left == Left.INCUMBENT:
            return "incumbent" + (" (replaced its predecessor as equivalent and cheaper)"
                                  if s.cheaper else "")
        if s.left == Left.WORSE and s.diverged:
            return f"worse than {by} at seed {s.seeds}: {s.diverged} of {s.seeds} runs diverged{p}"
        if s.left == Left.WORSE:
            return f"worse than {by} at seed {s.seeds}{p}"
        if s.left == Left.EQUIVALENT:
            return f"equivalent to {by} at seed {s.seeds}, not cheaper{p}"
        if s.left == Left.BELOW:
            return f"below {by} at seed {s.seeds} (IQM on the common seeds)"
        if s.left == Left.REPLACED:
            return f"replaced by {by} after {s.seeds} seeds{p}"
        return str(s.left.value)


@dataclass(frozen=True)
class RacingSearch:
    """A stored racing search replayed."""

    rules: RaceRules
    configurations: list[RacedConfiguration]
    state: Intensification[int]

    @property
    def incumbent(self) -> RacedConfiguration | None:
        """The configuration it picks: the incumbent, on all its seeds."""
        if self.state.incumbent is None:
            return None
        return next(c for c in self.configurations if c.number == self.state.incumbent)

    def counts(self) -> dict[Left, int]:
        """Configurations by standing."""
        found = {left: 0 for left in Left}
        for config in self.configurations:
            found[config.standing.left] += 1
        return found

    def summary(self) -> str:
        """``12 configurations: incumbent c3 (IQM -154.2 over 8 seeds); 7 worse, 1 replaced,
        2 below, 1 equivalent``; failed seeds are counted in the seeds and named apart."""
        inc = self.incumbent
        counts = self.counts()
        parts = ", ".join(f"{n} {left.value}" for left, n in counts.items()
                          if n and left != Left.INCUMBENT)
        head = (f"incumbent {inc.key} ({inc.evidence_text()})" if inc is not None
                else "no incumbent yet")
        return f"{len(self.configurations)} configurations: {head}" + (
            f"; {parts}" if parts else "")


def run_place(trial: StoredTrial, base_seed: int) -> tuple[int, int] | None:
    """(configuration, seed index) of a racing search's run; None for another trial."""
    parsed = parse_racing_key(trial.user_attrs.get("key"))
    if parsed is None:
        return None
    return parsed[0], parsed[1] - base_seed


def racing_search(definition: Mapping[str, Any], trials: Sequence[StoredTrial]
                  ) -> RacingSearch | None:
    """A racing search replayed from its trials (every attempt; the latest of each run
    counts); None for a study that is not one."""
    rules = RaceRules.of(dict(definition))
    if rules is None:
        return None
    base = int(definition.get("seed", 0))
    latest = latest_by_key(trials)
    params: dict[int, dict[str, Any]] = {}
    settings: dict[int, dict[str, Any]] = {}
    enqueued: dict[int, str] = {}
    refused: set[int] = set()
    ends: list[tuple[tuple[int, int], RunEnd[int]]] = []
    for trial in latest.values():
        where = run_place(trial, base)
        if where is None:
            continue
        config, index = where
        attrs = TrialAttrs.of(trial)
        # A queued run holds its parameters as fixed ones until it is asked for.
        params.setdefault(config, dict(trial.params or trial.system_attrs.get("fixed_params",
                                                                              {})))
        if attrs.settings and config not in settings:
            settings[config] = attrs.settings
        if attrs.enqueued:
            enqueued[config] = attrs.enqueued
        ended = outcome(trial)
        if ended == Outcome.FAILED and REFUSED in str(attrs.failure or ""):
            refused.add(config)
            continue
        if ended == Outcome.COMPLETE and trial.value is not None:
            value = float(trial.value)
        elif ended == Outcome.FAILED:
            value = math.nan
        else:
            continue
        cpu = math.nan if attrs.cpu_time is None else float(attrs.cpu_time)
        diverged = is_diverged(trial)
        ends.append(((attrs.race_order if attrs.race_order is not None else 1 << 62, trial.number),
                     RunEnd(config, index, value, cpu, diverged=diverged)))
    order = sorted(params)
    state = intensify(order, [end for _, end in sorted(ends, key=lambda e: e[0])], rules,
                      refused)
    configurations = []
    for number in order:
        cpu = [c for c in state.cpu[number] if math.isfinite(c)]
        configurations.append(RacedConfiguration(
            number=number, params=params[number], settings=settings.get(number, {}),
            scores=dict(sorted(state.scores[number].items())),
            cpu=math.fsum(cpu) / len(cpu) if cpu else math.nan,
            standing=state.standings[number], enqueued=enqueued.get(number)))
    return RacingSearch(rules=rules, configurations=configurations, state=state)
