"""Worker processes that run trials and send their results back to the parent.

Workers never open the database: the parent is the single writer (SQLite allows one). Each worker
is a fresh interpreter running [`kraby_study.run.worker`][], fed one spec at a time through its own
pipe, so a worker that dies (killed, out of memory) is seen at once as the end of its pipe and only
its own trial needs running again.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from multiprocessing import Pipe
from multiprocessing.connection import Connection, wait
from typing import Any, Protocol

from kraby_study.plan.spec import TrialSpec


@dataclass
class WorkerSlot:
    """A worker process, its end of the pipe, and the trial it runs (None: idle)."""

    process: subprocess.Popen[bytes]
    conn: Connection
    number: int | None = None
    spec: TrialSpec | None = None


@dataclass(frozen=True)
class Event:
    """Something a worker said or did: started, progress, checkpoint, result or died.

    The payload is the machine's facts (started:
    [`machine_facts`][kraby_study.run.provenance.machine_facts]), (step, the trial's CPU seconds so
    far) (progress), (step, value) (checkpoint), the TrialResult (result), or (spec, why) (died: why
    the worker is gone, e.g. ``exit code -9``).
    """

    kind: str
    number: int
    payload: Any = None
    slot: Any = None
    """Where the trial runs, for a reply to a checkpoint."""


def as_event(message: tuple[Any, ...], slot: Any) -> Event:
    """A worker's message, ``(kind, number, *rest)``, as an Event."""
    kind, number, *rest = message
    payload = (rest[0], rest[1]) if kind == "checkpoint" else rest[0]
    return Event(kind, number, payload, slot)


class Pool(Protocol):
    """Trial slots that run specs and report back: the seam between the runner and whatever
    runs trials (worker processes here, a Ray cluster). The runner alone writes the store."""

    def idle(self) -> int:
        """How many more trials the pool can take now."""

    def submit(self, number: int, spec: TrialSpec) -> None:
        """Start a trial in an idle slot."""

    def running(self) -> dict[int, TrialSpec]:
        """The trials being run, by trial number."""

    def events(self, timeout: float) -> list[Event]:
        """What the trials said or did within ``timeout`` seconds."""

    def reply(self, event: Event, keep_going: bool) -> None:
        """Answer a checkpoint: True lets the trial go on, False prunes it."""

    def close(self, terminate: bool = False) -> None:
        """Stop every slot: politely when idle, at once when ``terminate``."""


def start_worker(shards: int) -> WorkerSlot:
    """A new worker process (``python -m kraby_study.run.worker``), its pipe, no trial yet."""
    ours, theirs = Pipe()
    process = subprocess.Popen(
        [sys.executable, "-m", "kraby_study.run.worker", str(theirs.fileno()), str(shards)],
        pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL)
    theirs.close()
    return WorkerSlot(process, ours)


def stop_workers(slots: list[WorkerSlot], terminate: bool = False) -> None:
    """Stop workers: politely (they finish nothing: they are idle), or at once."""
    for slot in slots:
        try:
            if terminate:
                slot.process.terminate()
            else:
                slot.conn.send(None)
        except (BrokenPipeError, OSError):
            pass
    for slot in slots:
        _exit_code(slot.process)
        slot.conn.close()


class WorkerPool:
    """Up to ``size`` worker processes, started when there is work for them.

    Each worker steps its trials' legs in ``shards`` processes. ``spares`` are workers started
    ahead (with the same shards), taken before any new one is started.
    """

    def __init__(self, size: int, shards: int = 1, spares: list[WorkerSlot] | None = None) -> None:
        self.size = size
        self.shards = shards
        self._slots: list[WorkerSlot] = []
        self._spares = spares if spares is not None else []

    def _start(self) -> WorkerSlot:
        slot = self._spares.pop() if self._spares else start_worker(self.shards)
        self._slots.append(slot)
        return slot

    def idle(self) -> int:
        """How many more trials the pool can take now."""
        busy = sum(1 for s in self._slots if s.number is not None)
        return self.size - busy

    def submit(self, number: int, spec: TrialSpec) -> None:
        """Give a trial to an idle worker, starting one if needed."""
        slot = next((s for s in self._slots if s.number is None), None) or self._start()
        slot.number, slot.spec = number, spec
        slot.conn.send((number, spec))

    def running(self) -> dict[int, TrialSpec]:
        """The trials being run, by trial id."""
        return {s.number: s.spec for s in self._slots if s.number is not None and s.spec}

    def events(self, timeout: float) -> list[Event]:
        """What the workers said or did within ``timeout`` seconds."""
        if not self._slots:
            return []
        ready = set(wait([s.conn for s in self._slots], timeout=timeout))
        out: list[Event] = []
        for slot in list(self._slots):
            if slot.conn in ready and not self._drain(slot, out):
                # Its pipe ended: the worker is gone (only its exit closes the pipe).
                self._slots.remove(slot)
                slot.conn.close()
                code = _exit_code(slot.process)
                if slot.number is not None:
                    out.append(Event("died", slot.number, (slot.spec, f"exit code {code}")))
        return out

    @staticmethod
    def _drain(slot: WorkerSlot, out: list[Event]) -> bool:
        """Adds what the worker said to ``out``; False when its pipe has ended."""
        try:
            while slot.conn.poll():
                event = as_event(slot.conn.recv(), slot)
                if event.kind == "result":
                    slot.number, slot.spec = None, None
                out.append(event)
        except (EOFError, OSError):
            return False
        return True

    @staticmethod
    def reply(event: Event, keep_going: bool) -> None:
        """Answer a checkpoint: True lets the trial go on, False prunes it."""
        assert event.slot is not None
        try:
            event.slot.conn.send(keep_going)
        except (BrokenPipeError, OSError):
            pass

    def close(self, terminate: bool = False) -> None:
        """Stop every worker: politely when idle, at once when ``terminate``."""
        stop_workers(self._slots, terminate)
        self._slots.clear()


def _exit_code(process: subprocess.Popen[bytes], patience: float = 10.0) -> int:
    """The exit code of a worker that is stopping, killing it after ``patience`` seconds."""
    try:
        return process.wait(timeout=patience)
    except subprocess.TimeoutExpired:
        process.kill()
        return process.wait()
