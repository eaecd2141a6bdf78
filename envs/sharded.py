"""A world of many legs split into shards that step in parallel, one process each.

PyBullet holds Python's global lock while it steps, so threads cannot step the physics in
parallel; processes can. Shard 0 lives in the calling process, every other shard in a
:mod:`kraby_envs.shard_server` process. The legs keep the bases they have in the whole
world, so a leg moves bit for bit the same whatever the number of shards: the number
is a matter of speed only, never of results.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Sequence
from multiprocessing import Pipe
from typing import Any

import numpy as np

from .config import LegConfig
from .task import TARGET_CENTRE
from .world import LegWorld, grid_positions, observe_legs

State = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Joint angles, joint velocities and base-relative tip positions, each (k, 3)."""


class ShardProcess:
    """One shard of the legs, simulated by a :mod:`kraby_envs.shard_server` process.

    Requests are sent at once and answered in order, so the caller can send a step,
    do its own shard's work, and only then collect the answer.
    """

    def __init__(self, config: LegConfig, bases: np.ndarray) -> None:
        ours, theirs = Pipe()
        self._process = subprocess.Popen(
            [sys.executable, "-m", "kraby_envs.shard_server", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),),
            stdin=subprocess.DEVNULL,
        )
        theirs.close()
        self._conn = ours
        self.n_legs = len(bases)
        self.send("init", config, np.asarray(bases, dtype=float))

    def send(self, operation: str, *args: Any) -> None:
        """Sends a request; its answer comes from :meth:`receive`, in order."""
        try:
            self._conn.send((operation, args))
        except OSError:
            self._raise_stopped()

    def receive(self) -> Any:
        """The answer to the oldest request not yet received."""
        try:
            status, value = self._conn.recv()
        except (EOFError, OSError):
            self._raise_stopped()
        if status != "ok":
            raise RuntimeError(f"shard process: {value}")
        return value

    def call(self, operation: str, *args: Any) -> Any:
        self.send(operation, *args)
        return self.receive()

    def _raise_stopped(self) -> None:
        code = self._process.poll()
        raise RuntimeError(f"a shard process stopped (exit code {code})")

    def close(self) -> None:
        """Stops the process; safe to call twice."""
        if self._process.poll() is None:
            try:
                self._conn.send(("close", ()))
            except OSError:
                pass
            try:
                self._process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        self._conn.close()


class ShardedWorld:
    """The interface of :class:`kraby_envs.world.LegWorld` over ``shards`` shards.

    Every call that moves a leg refreshes its cached state, so reading the state of the
    whole world costs no round trip.

    Args:
        n_legs: Number of legs.
        config: Environment configuration.
        leg_spacing: Distance between neighbouring bases on the grid (m).
        shards: Number of shards (at most ``n_legs`` are used); 1 keeps every leg in this
            process.
    """

    def __init__(
        self, n_legs: int, config: LegConfig, leg_spacing: float = 1.0, shards: int = 1
    ) -> None:
        self.n_legs = n_legs
        self.config = config
        self.bases = grid_positions(n_legs, leg_spacing)
        self.targets = np.tile(TARGET_CENTRE, (n_legs, 1))
        shard_legs = np.array_split(np.arange(n_legs), max(1, min(shards, n_legs)))
        self._shard_legs = [legs.tolist() for legs in shard_legs]
        # Leg i is leg _local_index[i] of shard _shard_of[i].
        self._shard_of = np.concatenate([np.full(len(s), k) for k, s in enumerate(shard_legs)])
        self._local_index = np.concatenate([np.arange(len(s)) for s in shard_legs])
        self._remotes: list[ShardProcess] = []
        self._local: LegWorld | None = None
        try:
            # Remote shards start first: their interpreters load while ours builds, and
            # their first answer is only awaited when a leg is first used.
            self._remotes = [ShardProcess(config, self.bases[s]) for s in shard_legs[1:]]
            ours = shard_legs[0]
            self._local = LegWorld(len(ours), config, leg_spacing, bases=self.bases[ours])
        except BaseException:
            self.close()
            raise
        self._cached: State | None = None

    def _ready(self) -> State:
        """The state of every leg; the first call collects the shards' first answers."""
        if self._cached is None:
            self._cached = self._gather([r.receive() for r in self._remotes])
        return self._cached

    def _gather(self, remote_states: list[State]) -> State:
        assert self._local is not None
        states = [self._local.read_state(), *remote_states]
        return tuple(  # type: ignore[return-value]
            np.concatenate([s[part] for s in states]) for part in range(3)
        )

    @property
    def shards(self) -> int:
        """Number of shards, this process's included."""
        return len(self._shard_legs)

    def set_config(self, config: LegConfig) -> None:
        """Applies a new configuration to every shard."""
        assert self._local is not None
        self._ready()
        self._local.set_config(config)
        for remote in self._remotes:
            remote.call("config", config)
        self.config = config

    def place_legs(
        self, indices: Sequence[int], starts: Sequence[tuple[np.ndarray, np.ndarray]]
    ) -> None:
        """Puts legs at rest at their (angles, target) starts, one request per shard."""
        assert self._local is not None
        self._ready()
        by_shard: dict[int, list[int]] = {}
        for position, index in enumerate(indices):
            by_shard.setdefault(int(self._shard_of[index]), []).append(position)
        pending = []
        # Requests to other shards go first, so they work while this one places its legs.
        for shard, positions in sorted(by_shard.items(), key=lambda item: item[0] == 0):
            legs = [int(indices[p]) for p in positions]
            local = [int(self._local_index[i]) for i in legs]
            angles = [starts[p][0] for p in positions]
            targets = [starts[p][1] for p in positions]
            self.targets[legs] = targets
            if shard == 0:
                for leg, start, target in zip(local, angles, targets, strict=True):
                    self._local.place_leg(leg, start, target)
                self._store(legs, self._local.read_state(local))
            else:
                self._remotes[shard - 1].send("place", local, angles, targets)
                pending.append((shard, legs))
        for shard, legs in pending:
            self._store(legs, self._remotes[shard - 1].receive())

    def step(self, actions: np.ndarray) -> None:
        """Drives every leg for one control period, the shards in parallel."""
        assert self._local is not None
        self._ready()  # answers come in order: the shards' first ones before any step's
        for remote, legs in zip(self._remotes, self._shard_legs[1:], strict=True):
            remote.send("step", actions[legs])
        self._local.step(actions[self._shard_legs[0]])
        self._cached = self._gather([r.receive() for r in self._remotes])

    def _store(self, legs: list[int], state: State) -> None:
        for part, values in zip(self._ready(), state, strict=True):
            part[legs] = values

    def read_state(self, indices: Sequence[int] | None = None) -> State:
        """Joint angles, joint velocities and tip positions (base-relative), each (k, 3)."""
        state = self._ready()
        if indices is None:
            return tuple(part.copy() for part in state)  # type: ignore[return-value]
        rows = list(indices)
        return tuple(part[rows] for part in state)  # type: ignore[return-value]

    def observe(
        self, indices: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Observations, squared tip-target distances and tips, as :meth:`LegWorld.observe`."""
        targets = self.targets if indices is None else self.targets[list(indices)]
        return observe_legs(self.config, self.read_state(indices), targets)

    def render(self, index: int) -> np.ndarray:
        """An offscreen image of leg ``index`` and its target, (H, W, 3) uint8."""
        assert self._local is not None
        shard, local = int(self._shard_of[index]), int(self._local_index[index])
        if shard == 0:
            return self._local.render(local)
        self._ready()
        return self._remotes[shard - 1].call("render", local)

    def close(self) -> None:
        """Stops every shard; safe to call twice."""
        for remote in self._remotes:
            remote.close()
        self._remotes = []
        if self._local is not None:
            self._local.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown may have torn things down
            pass
