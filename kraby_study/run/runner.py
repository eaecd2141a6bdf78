"""Schedule trials on worker processes and record what they return.

The runner is the same for sweeps, searches and single runs: a TrialSource hands out claimed
trials and records their results (in the parent process: the single writer), an executor's pool
runs them (worker processes here, or a Ray cluster). A worker that dies has its trial run again;
Ctrl-C stops everything, keeping what is complete and queueing the interrupted trials for the
next run.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, TextIO

from kraby_study.errors import ClusterLost, DatabaseLost, first_line
from kraby_study.plan.spec import TrialSpec
from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import Failure, Outcome, Tally, failure, failure_kind
from kraby_study.run.executor import Executor
from kraby_study.run.pool import Event, Pool
from kraby_study.run.progress import Progress
from kraby_study.store.store import LOST_DATABASE

MAX_WORKER_DEATHS = 3
"""A trial whose worker dies this many times is recorded as failed instead of run again."""


class TrialSource(Protocol):
    """Where trials come from and where their results go; trials are named by number."""

    def next_trial(self) -> tuple[int, TrialSpec] | None:
        """Claim the next trial to run, or None when there is nothing left to start."""

    def started(self, number: int, machine: Mapping[str, str]) -> None:
        """Note that a trial started on a machine (its facts: hostname, CPU, versions)."""

    def checkpoint(self, number: int, step: int, value: float) -> bool:
        """Record an intermediate value; False prunes the trial."""

    def stopped_why(self, number: int) -> str | None:
        """Why the source itself stopped a trial at a checkpoint (not its pruner), in a few
        words for the trial's progress line; None when it did not."""

    def using(self, number: int, steps: int, cpu: float) -> None:
        """Note the env steps a running trial has trained and the CPU seconds it has used so
        far."""

    def record(self, number: int, spec: TrialSpec, result: TrialResult) -> None:
        """Store a finished trial."""

    def requeue(self, number: int, spec: TrialSpec, reason: str) -> None:
        """Give back a trial that will not finish in this command, to run again."""

    def heartbeat(self, numbers: list[int]) -> None:
        """Tell the store these trials are alive."""

    def running_elsewhere(self) -> bool:
        """Whether other commands still run trials that could come back (PostgreSQL)."""


@dataclass
class CommandRun(Tally):
    """What one command ran: the trials it ended, by outcome, and whether it was stopped."""

    interrupted: bool = False
    errors: int = 0
    """Failed trials whose failure is an error (not a divergence, which is a result)."""

    def count(self, ended: Outcome, reason: str | None = None) -> None:
        """Count one trial that ended (``reason``: its failure, if any)."""
        name = ended.value
        setattr(self, name, getattr(self, name) + 1)
        if ended == Outcome.FAILED and failure_kind(reason) == Failure.ERROR:
            self.errors += 1

    def errors_line(self) -> str | None:
        """What a command says when some of its runs ended in errors, or None."""
        if not self.errors:
            return None
        return (f"{self.errors} run(s) ended in an error (not a divergence): `kraby-study "
                "list` counts them and the report gives their reasons")


class Retrying:
    """A TrialSource whose calls are retried while the database is out of reach."""

    def __init__(self, source: TrialSource, patience: float, stream: TextIO) -> None:
        self._source = source
        self._patience = patience
        self._stream = stream

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._source, name)
        if not callable(attr):
            return attr

        def call(*args: Any) -> Any:
            deadline = time.monotonic() + self._patience
            delay = 0.5
            while True:
                try:
                    return attr(*args)
                except LOST_DATABASE as err:
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


@dataclass
class _Run:
    """The state of one command's scheduling loop: one handler per worker event."""

    source: TrialSource
    pool: Pool
    progress: Progress
    summary: CommandRun = field(default_factory=CommandRun)
    deaths: dict[int, int] = field(default_factory=dict)

    def submit(self, number: int, spec: TrialSpec) -> None:
        self.pool.submit(number, spec)
        self.progress.start(spec.label, spec.steps * spec.seeds)

    def claim(self) -> bool:
        """Fill the idle workers; False when the source had nothing left to hand out."""
        while self.pool.idle() > 0:
            claimed = self.source.next_trial()
            if claimed is None:
                return False
            self.submit(*claimed)
        return True

    def on_started(self, event: Event, spec: TrialSpec) -> None:
        self.source.started(event.number, event.payload)

    def on_progress(self, event: Event, spec: TrialSpec) -> None:
        step, cpu = event.payload
        self.source.using(event.number, int(step), float(cpu))
        self.progress.step(spec.label, int(step))

    def on_checkpoint(self, event: Event, spec: TrialSpec) -> None:
        step, value = event.payload
        self.pool.reply(event, self.source.checkpoint(event.number, step, value))

    def on_result(self, event: Event, spec: TrialSpec) -> None:
        self.finish(event.number, spec, event.payload)

    def on_died(self, event: Event, spec: TrialSpec) -> None:
        _, why = event.payload
        self.deaths[event.number] = self.deaths.get(event.number, 0) + 1
        if self.deaths[event.number] >= MAX_WORKER_DEATHS:
            reason = f"its worker died {MAX_WORKER_DEATHS} times (last {why})"
            self.finish(event.number, spec, TrialResult(
                outcome=Outcome.FAILED, env_steps=0, wall_time=0.0,
                failure=failure(Failure.ERROR, reason)))
        else:
            # Same trial, new worker: the trial stays claimed, so nothing is lost.
            self.progress.interrupt(spec.label, f"worker {why}, rerun")
            self.submit(event.number, spec)

    def finish(self, number: int, spec: TrialSpec, result: TrialResult) -> None:
        why = self.source.stopped_why(number)
        self.source.record(number, spec, result)
        self.summary.count(result.outcome, result.failure)
        self.progress.finish(spec.label, result, cost=spec.cost is not None, why=why)

    def stop(self, why: str = "stopped by the user") -> None:
        """Ctrl-C (or the executor's machines lost): stop the workers and give their trials
        back to run next time."""
        self.summary.interrupted = True
        running = self.pool.running()
        self.pool.close(terminate=True)
        for number, spec in running.items():
            self.source.requeue(number, spec, failure(Failure.INTERRUPTED, why))
            self.progress.interrupt(spec.label, "queued for the next run")


def run_trials(source: TrialSource, workers: int, progress: Progress, executor: Executor,
               heartbeat_seconds: float = 5.0, poll_seconds: float = 2.0) -> CommandRun:
    """Run every trial the source hands out, ``workers`` at once on the executor's pool.

    When nothing is left to claim but other commands still run trials of the study (several
    machines on PostgreSQL), it keeps polling: a trial whose owner died comes back to the queue
    once its heartbeat is stale, and this command runs it.
    """
    pool = executor.pool(workers)
    run = _Run(source, pool, progress)
    handlers = {"started": run.on_started, "progress": run.on_progress,
                "checkpoint": run.on_checkpoint, "result": run.on_result, "died": run.on_died}
    last_beat = 0.0
    next_claim = 0.0
    ctrl_c = _CtrlC()
    try:
        ctrl_c.install()
        while True:
            ctrl_c.check()
            if time.monotonic() >= next_claim and not run.claim():
                next_claim = time.monotonic() + poll_seconds
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
                spec = running.get(event.number)
                if spec is not None:
                    handlers[event.kind](event, spec)
                if event.kind == "result":
                    # An ended trial can make the source want more (a racing search waits
                    # for an incumbent's first seeds): ask again now, not after the poll.
                    next_claim = 0.0
    except KeyboardInterrupt:
        run.stop()
    except ClusterLost:
        run.stop("the cluster running it was lost")
        raise
    finally:
        ctrl_c.restore()
        pool.close()
        progress.close()
    return run.summary
