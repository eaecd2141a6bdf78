"""One worker process: runs the trials its pool sends and reports back.

Started by [`WorkerPool`][kraby_study.run.pool.WorkerPool] as ``python -m kraby_study.run.worker FD
SHARDS`` with one end of a pipe as FD. It imports only what a trial needs (torch, stable-baselines3,
the environments), never the command line, the configuration tree or the database, and trains with
one torch thread. SHARDS is the number of processes each trial's
legs are stepped in (see `kraby_envs.sharded`); it changes speed, not results.
"""

from __future__ import annotations

import os
import signal
import sys
import traceback
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from kraby_study.plan.spec import TrialSpec
    from kraby_study.records.attributes import TrialResult
    from kraby_study.run.callback import CheckpointHook, TrialProgress


def attempt(spec: TrialSpec, shards: int, checkpoint: CheckpointHook | None,
            progress: TrialProgress) -> TrialResult:
    """Run one trial; an exception (a bug, a bad environment) comes back as a failed result,
    so it never kills the worker or the study."""
    from kraby_study.records.attributes import TrialResult
    from kraby_study.records.stored import Failure, Outcome, failure
    from kraby_study.run.trial import run_trial

    try:
        return run_trial(spec, checkpoint if spec.reports else None, progress,
                         shards=shards)
    except Exception as err:
        last = traceback.format_exception_only(type(err), err)[-1].strip()
        return TrialResult(outcome=Outcome.FAILED, env_steps=0, wall_time=0.0,
                           failure=failure(Failure.ERROR, last))


def serve(conn: Connection, shards: int) -> None:
    """Runs trials until the pool sends None or goes away."""
    import torch

    # Loaded before the first trial is asked for: a worker started ahead of its work (see
    # LocalExecutor.prestart) pays its imports while the command opens the store.
    import kraby_study.run.callback  # noqa: F401
    import kraby_study.run.trial  # noqa: F401
    from kraby_study.run.provenance import trial_facts

    torch.set_num_threads(1)
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the pool is gone (a killed parent resets the pipe)
            return
        if message is None:
            return
        number, spec = message

        def progress(step: int, cpu: float, number: int = number) -> None:
            conn.send(("progress", number, (step, cpu)))

        def checkpoint(step: int, value: float, number: int = number) -> bool:
            conn.send(("checkpoint", number, step, value))
            return bool(conn.recv())

        conn.send(("started", number, trial_facts(spec.settings["env"])))
        result = attempt(spec, shards, checkpoint, progress)
        try:
            conn.send(("result", number, result))
        except OSError:
            return


def main() -> None:
    # Ctrl-C reaches the whole process group: the parent decides what stops.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    serve(Connection(int(sys.argv[1])), int(sys.argv[2]))
    # Every result is sent and every env closed: skip the interpreter's teardown of torch and
    # the rest (about a second the command would wait for at its end).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


if __name__ == "__main__":
    main()
