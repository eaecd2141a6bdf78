"""A pool and an executor whose runs end at once, each with the result a function of its spec
gives: a race or a racing search driven through the real runner without training."""

from __future__ import annotations

from collections.abc import Callable

from kraby_study.plan.spec import TrialSpec
from kraby_study.records.attributes import TrialResult
from kraby_study.run.pool import Event

Result = Callable[[TrialSpec], TrialResult]


class InstantPool:
    """Every submitted run ends at the next look at the events, with ``result(spec)``."""

    def __init__(self, size: int, result: Result) -> None:
        self.size = size
        self.result = result
        self.playing: dict[int, TrialSpec] = {}
        self.submitted: list[TrialSpec] = []

    def idle(self) -> int:
        return self.size - len(self.playing)

    def submit(self, number: int, spec: TrialSpec) -> None:
        self.playing[number] = spec
        self.submitted.append(spec)

    def running(self) -> dict[int, TrialSpec]:
        return dict(self.playing)

    def events(self, timeout: float) -> list[Event]:
        out = [Event("result", number, self.result(spec))
               for number, spec in self.playing.items()]
        self.playing.clear()
        return out

    def reply(self, event: Event, keep_going: bool) -> None:
        raise AssertionError("these runs never checkpoint")

    def close(self, terminate: bool = False) -> None:
        self.playing.clear()


class InstantExecutor:
    """Builds [`InstantPool`][]s; ``pools`` keeps each, to read what was submitted."""

    def __init__(self, result: Result) -> None:
        self.result = result
        self.pools: list[InstantPool] = []

    def workers(self, configured: int | None) -> int:
        return configured or 1

    def pool(self, size: int) -> InstantPool:
        self.pools.append(InstantPool(size, self.result))
        return self.pools[-1]
