"""One worker process: runs the trials its pool sends and reports back.

Started by :class:`kraby_study.workers.WorkerPool` as ``python -m kraby_study.worker FD
PHYSICS`` with one end of a pipe as FD. It imports only what a trial needs (torch,
stable-baselines3, the environments), never the command line, the configuration tree or the
database, and trains with one torch thread. PHYSICS is the number of processes each trial's
legs are stepped in (see :mod:`kraby_envs.sharded`); it changes speed, not results.
"""

from __future__ import annotations

import signal
import sys
import traceback
from multiprocessing.connection import Connection


def serve(conn: Connection, physics_processes: int) -> None:
    """Runs trials until the pool sends None or goes away."""
    import torch

    torch.set_num_threads(1)
    from kraby_study.trial import TrialResult, run_trial

    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the pool is gone (a killed parent resets the pipe)
            return
        if message is None:
            return
        trial_id, spec = message

        def progress(step: int, trial_id: int = trial_id) -> None:
            conn.send(("progress", trial_id, step))

        def checkpoint(step: int, value: float, trial_id: int = trial_id) -> bool:
            conn.send(("checkpoint", trial_id, step, value))
            return bool(conn.recv())

        try:
            result = run_trial(spec, checkpoint if spec.checkpoint_every else None, progress,
                               physics_processes=physics_processes)
        except Exception as err:  # a bug or a bad environment must not kill the study
            last = traceback.format_exception_only(type(err), err)[-1].strip()
            result = TrialResult(key=spec.key, status="failed", failure=f"error: {last}")
        try:
            conn.send(("result", trial_id, result))
        except OSError:
            return


def main() -> None:
    # Ctrl-C reaches the whole process group: the parent decides what stops.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    serve(Connection(int(sys.argv[1])), int(sys.argv[2]))


if __name__ == "__main__":
    main()
