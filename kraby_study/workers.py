"""Worker processes that run trials and send their results back to the parent.

Workers never open the database: the parent is the single writer (SQLite allows one). Each worker
is a spawned process with one torch thread, fed one spec at a time through its own pipe, so a
worker that dies (killed, out of memory) is seen at once through its process sentinel and only its
own trial needs running again.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
import traceback
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

from kraby_study.plan import TrialSpec


def _worker_main(conn: Connection) -> None:
    # Ctrl-C reaches the whole process group: the parent decides what stops.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import torch

    torch.set_num_threads(1)
    from kraby_study.trial import TrialResult, run_trial

    while True:
        message = conn.recv()
        if message is None:
            return
        trial_id, spec = message

        def progress(step: int, trial_id: int = trial_id) -> None:
            conn.send(("progress", trial_id, step))

        def checkpoint(step: int, value: float, trial_id: int = trial_id) -> bool:
            conn.send(("checkpoint", trial_id, step, value))
            return bool(conn.recv())

        try:
            result = run_trial(spec, checkpoint if spec.checkpoint_every else None, progress)
        except Exception as err:  # a bug or a bad environment must not kill the study
            last = traceback.format_exception_only(type(err), err)[-1].strip()
            result = TrialResult(key=spec.key, status="failed", failure=f"error: {last}")
        conn.send(("result", trial_id, result))


@dataclass
class _Slot:
    process: Any
    conn: Connection
    trial_id: int | None = None
    spec: TrialSpec | None = None


@dataclass(frozen=True)
class Event:
    """Something a worker said or did: progress, checkpoint, result or died."""

    kind: str
    trial_id: int
    payload: Any = None
    slot: _Slot | None = None


class WorkerPool:
    """Up to ``size`` worker processes, started when there is work for them."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._ctx = mp.get_context("spawn")
        self._slots: list[_Slot] = []

    def _start(self) -> _Slot:
        parent, child = self._ctx.Pipe()
        process = self._ctx.Process(target=_worker_main, args=(child,), daemon=True)
        process.start()
        child.close()
        slot = _Slot(process, parent)
        self._slots.append(slot)
        return slot

    def idle(self) -> int:
        """How many more trials the pool can take now."""
        busy = sum(1 for s in self._slots if s.trial_id is not None)
        return self.size - busy

    def submit(self, trial_id: int, spec: TrialSpec) -> None:
        """Give a trial to an idle worker, starting one if needed."""
        slot = next((s for s in self._slots if s.trial_id is None), None) or self._start()
        slot.trial_id, slot.spec = trial_id, spec
        slot.conn.send((trial_id, spec))

    def running(self) -> dict[int, TrialSpec]:
        """The trials being run, by trial id."""
        return {s.trial_id: s.spec for s in self._slots if s.trial_id is not None and s.spec}

    def events(self, timeout: float) -> list[Event]:
        """What the workers said or did within ``timeout`` seconds."""
        waitables: list[Any] = [s.conn for s in self._slots] + [
            s.process.sentinel for s in self._slots]
        if not waitables:
            return []
        ready = set(wait(waitables, timeout=timeout))
        out: list[Event] = []
        for slot in list(self._slots):
            if slot.conn in ready:
                out.extend(self._drain(slot))
            if slot.process.sentinel in ready and not slot.process.is_alive():
                out.extend(self._drain(slot))
                self._slots.remove(slot)
                slot.conn.close()
                if slot.trial_id is not None:
                    code = slot.process.exitcode
                    out.append(Event("died", slot.trial_id, (slot.spec, code)))
        return out

    def _drain(self, slot: _Slot) -> list[Event]:
        out: list[Event] = []
        try:
            while slot.conn.poll():
                kind, trial_id, *rest = slot.conn.recv()
                if kind == "result":
                    slot.trial_id, slot.spec = None, None
                    out.append(Event(kind, trial_id, rest[0], slot))
                elif kind == "checkpoint":
                    out.append(Event(kind, trial_id, (rest[0], rest[1]), slot))
                else:
                    out.append(Event(kind, trial_id, rest[0], slot))
        except (EOFError, OSError):
            pass
        return out

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
        for slot in self._slots:
            try:
                if terminate:
                    slot.process.terminate()
                else:
                    slot.conn.send(None)
            except (BrokenPipeError, OSError):
                pass
        for slot in self._slots:
            slot.process.join(timeout=10)
            if slot.process.is_alive():
                slot.process.kill()
                slot.process.join()
            slot.conn.close()
        self._slots.clear()
