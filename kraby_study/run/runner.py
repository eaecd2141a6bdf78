"""Schedule trials on worker processes and record what they return.

The runner is the same for sweeps, searches and single runs: a TrialSource hands out claimed
trials and records their results (in the parent process: the single writer), a WorkerPool runs
them. A worker that dies has its trial run again; Ctrl-C stops everything, keeping what is
complete and queueing the interrupted trials for the next run.
"""

from __future__ import annotations

import signal
import threading
import time
from dataclasses import dataclass
from typing import Any, Protocol, TextIO

from sqlalchemy import exc as sa_exc

from kraby_study.config import cores
from kraby_study.messages import first_line
from kraby_study.progress import Progress
from kraby_study.spec import TrialSpec
from kraby_study.trial import TrialResult
from kraby_study.workers import WorkerPool

MAX_WORKER_DEATHS = 3
"""A trial whose worker dies this many times is recorded as failed instead of run again."""


class TrialSource(Protocol):
    """Where trials come from and where their results go."""

    def next_trial(self) -> tuple[int, TrialSpec] | None:
        """Claim the next trial to run, or None when there is nothing left to start."""

    def label(self, spec: TrialSpec) -> str:
        """How the progress display names a trial."""

    def checkpoint(self, trial_id: int, step: int, value: float) -> bool:
        """Record an intermediate value; False prunes the trial."""

    def record(self, trial_id: int, spec: TrialSpec, result: TrialResult) -> str:
        """Store a finished trial; returns a short outcome for the progress display."""

    def interrupted(self, trial_id: int, spec: TrialSpec, reason: str) -> None:
        """Give back a trial that will not finish in this command."""

    def heartbeat(self, trial_ids: list[int]) -> None:
        """Tell the store these trials are alive."""

    def running_elsewhere(self) -> bool:
        """Whether other commands still run trials that could come back (PostgreSQL)."""


@dataclass
class RunSummary:
    """What one command did."""

    complete: int = 0
    failed: int = 0
    pruned: int = 0
    interrupted: bool = False


class DatabaseLost(RuntimeError):
    """The database stayed out of reach longer than the command was told to wait."""


class Retrying:
    """A TrialSource whose calls are retried while the database is out of reach."""

    def __init__(self, source: TrialSource, patience: float, stream: TextIO) -> None:
        self._source = source
        self._patience = patience
        self._stream = stream

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._source, name)
        if not callable(attr) or name == "label":
            return attr

        def call(*args: Any) -> Any:
            deadline = time.monotonic() + self._patience
            delay = 0.5
            while True:
                try:
                    return attr(*args)
                except (sa_exc.OperationalError, sa_exc.InterfaceError) as err:
                    if time.monotonic() >= deadline:
                        raise DatabaseLost(f"lost the database for {self._patience:.0f} s, "
                                           f"giving up: {first_line(err)}") from None
                    print(f"database out of reach ({name}), retrying in {delay:.1f} s",
                          file=self._stream, flush=True)
                    time.sleep(delay)
                    delay = min(delay * 2, 10.0)

        return call


class _CtrlC:
    """Notes Ctrl-C and lets the runner act on it between two store calls.

    A KeyboardInterrupt raised inside a claim or a record would leave a trial marked running that
    no worker holds. A second Ctrl-C interrupts at once.
    """

    def __init__(self) -> None:
        self.pressed = False
        self._previous: Any = None

    def install(self) -> None:
        """Catch SIGINT (only the main thread may set a handler)."""
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._note)

    def _note(self, signum: int, frame: Any) -> None:
        if self.pressed:
            raise KeyboardInterrupt
        self.pressed = True

    def check(self) -> None:
        """Raise KeyboardInterrupt if Ctrl-C was pressed."""
        if self.pressed:
            raise KeyboardInterrupt

    def restore(self) -> None:
        """Give SIGINT back to the handler it had before."""
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)


def run_trials(source: TrialSource, workers: int, progress: Progress,
               heartbeat_seconds: float = 5.0, poll_seconds: float = 2.0,
               physics_processes: int | None = None) -> RunSummary:
    """Run every trial the source hands out on ``workers`` processes.

    Each trial steps its legs in ``physics_processes`` processes; None gives it the cores the
    workers leave idle, so a lone trial uses the whole machine.

    When nothing is left to claim but other commands still run trials of the study (several
    machines on PostgreSQL), it keeps polling: a trial whose owner died comes back to the queue
    once its heartbeat is stale, and this command runs it.
    """
    summary = RunSummary()
    if physics_processes is None:
        physics_processes = max(1, cores() // workers)
    pool = WorkerPool(workers, physics_processes)
    deaths: dict[int, int] = {}
    last_beat = 0.0
    next_claim = 0.0
    ctrl_c = _CtrlC()
    try:
        ctrl_c.install()
        while True:
            ctrl_c.check()
            while pool.idle() > 0 and time.monotonic() >= next_claim:
                claimed = source.next_trial()
                if claimed is None:
                    next_claim = time.monotonic() + poll_seconds
                    break
                trial_id, spec = claimed
                pool.submit(trial_id, spec)
                progress.start(source.label(spec), spec.steps * spec.repeats)
            running = pool.running()
            if not running:
                if not source.running_elsewhere():
                    break
                while time.monotonic() < next_claim and not ctrl_c.pressed:
                    time.sleep(0.1)
                continue
            if time.monotonic() - last_beat >= heartbeat_seconds:
                source.heartbeat(list(running))
                last_beat = time.monotonic()
            for event in pool.events(timeout=0.5):
                spec = running.get(event.trial_id)
                if spec is None:
                    continue
                if event.kind == "progress":
                    progress.step(source.label(spec), int(event.payload))
                elif event.kind == "checkpoint":
                    step, value = event.payload
                    pool.reply(event, source.checkpoint(event.trial_id, step, value))
                elif event.kind == "result":
                    result: TrialResult = event.payload
                    outcome = source.record(event.trial_id, spec, result)
                    _count(summary, result.status)
                    progress.finish(source.label(spec), outcome)
                elif event.kind == "died":
                    _, code = event.payload
                    deaths[event.trial_id] = deaths.get(event.trial_id, 0) + 1
                    label = source.label(spec)
                    if deaths[event.trial_id] >= MAX_WORKER_DEATHS:
                        result = TrialResult(key=spec.key, status="failed",
                                             failure=f"error: its worker died {MAX_WORKER_DEATHS} "
                                             f"times (last exit code {code})")
                        progress.finish(label, source.record(event.trial_id, spec, result))
                        _count(summary, "failed")
                    else:
                        # Same trial, new worker: the trial stays claimed, so nothing is lost.
                        progress.finish(label, f"interrupted (worker exit code {code}), rerun")
                        pool.submit(event.trial_id, spec)
                        progress.start(label, spec.steps * spec.repeats)
    except KeyboardInterrupt:
        summary.interrupted = True
        running = pool.running()
        pool.close(terminate=True)
        for trial_id, spec in running.items():
            source.interrupted(trial_id, spec, "interrupted: stopped by the user")
            progress.finish(source.label(spec), "interrupted, queued for the next run")
    finally:
        ctrl_c.restore()
        pool.close()
        progress.close()
    return summary


def _count(summary: RunSummary, status: str) -> None:
    if status == "complete":
        summary.complete += 1
    elif status == "pruned":
        summary.pruned += 1
    else:
        summary.failed += 1
