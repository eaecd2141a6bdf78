"""The process behind one shard of a :class:`kraby_envs.sharded.ShardedWorld`.

Run as ``python -m kraby_envs.shard_server FD``, where FD is the inherited end of a
``multiprocessing`` pipe. It answers each request ``(operation, arguments)`` with
``("ok", value)`` or ``("error", message)`` and exits when the pipe closes, so it never
outlives the process that started it. It imports no torch: a shard costs one interpreter
and one physics client.
"""

from __future__ import annotations

import os
import signal
import sys
from multiprocessing.connection import Connection
from typing import Any

from .config import LegConfig
from .world import LegWorld


def _handle(world: LegWorld, operation: str, args: tuple[Any, ...]) -> Any:
    if operation == "step":
        world.step(args[0])
        return world.read_state()
    if operation == "place":
        indices, angles, targets = args
        for index, start, target in zip(indices, angles, targets, strict=True):
            world.place_leg(index, start, target)
        return world.read_state(indices)
    if operation == "config":
        world.set_config(args[0])
        return None
    if operation == "render":
        return world.render(args[0])
    raise ValueError(f"unknown operation {operation!r}")


def serve(conn: Connection) -> None:
    """Builds the shard from the first request ``("init", config, bases)``, then serves."""
    try:
        operation, (config, bases) = conn.recv()
    except (EOFError, OSError):  # the owner is gone (a killed owner resets the pipe)
        return
    if operation != "init" or not isinstance(config, LegConfig):
        conn.send(("error", f"expected ('init', (config, bases)), got {operation!r}"))
        return
    world = LegWorld(len(bases), config, bases=bases)
    conn.send(("ok", world.read_state()))
    try:
        while True:
            try:
                operation, args = conn.recv()
            except (EOFError, OSError):  # the owner is gone (a killed owner resets the pipe)
                return
            if operation == "close":
                return
            try:
                reply = ("ok", _handle(world, operation, args))
            except Exception as err:  # noqa: BLE001 - the caller raises it with its message
                reply = ("error", f"{type(err).__name__}: {err}")
            try:
                conn.send(reply)
            except OSError:
                return
    finally:
        world.close()


def main() -> None:
    # Ctrl-C reaches the whole process group; the process that owns the world decides.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    serve(Connection(int(sys.argv[1])))
    # The world is closed and every reply sent: skip the interpreter's teardown, which the
    # owner would wait for when it closes its env (about 0.3 s of every run).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


if __name__ == "__main__":
    main()
