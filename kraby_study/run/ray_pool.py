"""Trials on a Ray cluster: ``executor=ray``.

Each trial slot is a Ray actor reserving ``ray.cpus_per_trial`` CPUs on some node. The actor runs
one trial at a time with the same code as a local worker
([`attempt`][kraby_study.run.worker.attempt]) and keeps its messages (progress, checkpoints, the
result) in an outbox that the command drains, so the command's process stays the only writer of the
store, and a SQLite file serves a whole cluster. An actor that dies (its process killed, its node
lost) ends its trial with a ``died`` event, and the runner runs the trial again. When the cluster
itself stays out of reach for ``db_retry_seconds``, the command stops with one line; complete trials
are stored already.

An actor's start is judged by what the cluster says of it, not by a clock: Ray's actor table
names the worker process an actor was given as soon as a node places it, so an actor with a
process that has not answered yet is alive and importing (torch from a slow disk, or on a
loaded node), and counts as an answer; only ``ray.start_seconds`` bounds that start (an actor
hung in its imports is let go and its trial runs again). An actor with no process is waiting
for a CPU, and an idle actor is let go for it.
"""

from __future__ import annotations

import logging
import os
import queue
import re
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from omegaconf import DictConfig, OmegaConf

from kraby_study.errors import ClusterLost, ConfigError, first_line
from kraby_study.plan.spec import TrialSpec
from kraby_study.records.attributes import RAY_NODE, TrialResult
from kraby_study.records.stored import Failure, Outcome, failure
from kraby_study.run.pool import Event, as_event
from kraby_study.run.provenance import trial_facts
from kraby_study.run.worker import attempt

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
# Ray starts its workers at niceness 15; a local worker runs at the command's own priority.
os.environ.setdefault("RAY_worker_niceness", "0")
# Ray ends a driver that lost its cluster's head after 60 s, with no word of ours; the command
# decides itself (RayPool's patience) and stops with one line, its complete trials stored.
os.environ.setdefault("RAY_gcs_rpc_server_reconnect_timeout_s", str(7 * 24 * 3600))
import ray  # noqa: E402 - after the settings above

DRAIN_SECONDS = 1.0
"""How long an actor holds a drain call open waiting for a message."""
LOCAL_OBJECT_STORE = 200 * 1024 * 1024
"""Object store of a Ray instance the command starts itself: results are small."""


class TrialActor:
    """One trial slot on a Ray node: runs trials one at a time and keeps their messages.

    Ray runs its methods in threads (``max_concurrency``), so ``drain`` and ``reply`` answer
    while ``run`` trains.
    """

    def __init__(self, shards: int) -> None:
        import torch

        torch.set_num_threads(1)  # as a local worker: the same results, one core per trial
        self._shards = shards
        self._outbox: queue.Queue[tuple[Any, ...]] = queue.Queue()
        self._replies: queue.Queue[bool] = queue.Queue()

    def ready(self) -> int:
        """The actor's process id, once it is placed and started."""
        return os.getpid()

    def run(self, number: int, spec: TrialSpec) -> None:
        """Train one trial; its messages and result go to the outbox."""

        def progress(step: int, cpu: float) -> None:
            self._outbox.put(("progress", number, (step, cpu)))

        def checkpoint(step: int, value: float) -> bool:
            self._outbox.put(("checkpoint", number, step, value))
            return self._replies.get()

        node = ray.get_runtime_context().get_node_id()
        self._outbox.put(("started", number,
                          {**trial_facts(spec.settings["env"]), RAY_NODE: node}))
        self._outbox.put(("result", number, attempt(spec, self._shards, checkpoint, progress)))

    def drain(self, wait: float) -> list[tuple[Any, ...]]:
        """The messages kept so far, waiting up to ``wait`` seconds for a first one."""
        try:
            out = [self._outbox.get(timeout=wait)]
        except queue.Empty:
            return []
        while True:
            try:
                out.append(self._outbox.get_nowait())
            except queue.Empty:
                return out

    def reply(self, keep_going: bool) -> None:
        """The command's answer to the checkpoint the trial waits on."""
        self._replies.put(keep_going)


@dataclass
class _Slot:
    actor: Any
    ready: Any
    """The actor's ready() call; None once it answered."""
    placed: float | None = None
    """When the cluster was first seen to have given the actor a process (monotonic)."""
    number: int | None = None
    spec: TrialSpec | None = None
    run: Any = None
    drain: Any = None


class ActorTable:
    """Which starting actors the cluster has given a worker process, from Ray's actor table.

    The table is read in a thread of its own, one read at a time: a read waits as long as
    the cluster's head is out of reach, and the command must still notice that silence. A
    read is taken once it has ended; until then nothing new is known.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._reading = False
        self._read: dict[str, bool] | None = None

    def placed(self, actors: list[Any]) -> dict[str, bool] | None:
        """Actor id -> whether it has a worker process, as the last read that ended found it
        (None when no read ended since the last call); starts the next read."""
        with self._lock:
            read, self._read = self._read, None
            if not self._reading and actors:
                self._reading = True
                ids = [a._actor_id.hex() for a in actors]
                threading.Thread(target=self._take, args=(ids,), daemon=True).start()
        return read

    def _take(self, ids: list[str]) -> None:
        found: dict[str, bool] = {}
        try:
            for actor_id in ids:
                found[actor_id] = _has_process(actor_id)
        finally:
            with self._lock:
                self._read, self._reading = found, False


def _has_process(actor_id: str) -> bool:
    """Whether Ray's actor table names a worker process for the actor (placed on a node and
    starting, or started); False while it waits to be placed."""
    try:
        info = ray._private.state.actors(actor_id)
    except Exception:  # noqa: BLE001 - a private table: no answer is no news
        return False
    return bool(info) and int(info.get("Pid") or 0) > 0 and info.get("State") != "DEAD"


class RayPool:
    """Up to ``size`` trial actors on the cluster, started when there is work for them.

    An actor stays between trials (no new process per trial). When a slot's new actor cannot be
    placed (a node was lost and the others are full), an actor whose trial has ended is let go,
    so the cluster's remaining CPUs serve the trials still to run.
    """

    def __init__(self, size: int, shards: int, cpus: int, patience: float,
                 start_seconds: float) -> None:
        self.size = size
        self._actor = ray.remote(TrialActor).options(
            num_cpus=cpus, max_concurrency=3, max_restarts=0, max_task_retries=0)
        self._shards = shards
        self._patience = patience
        self._start_seconds = start_seconds
        self._table = ActorTable()
        self._starting_seen = False
        """Whether the latest read of the actor table found a busy actor starting."""
        self._slots: list[_Slot] = []
        self._silent_since: float | None = None
        self.lost = False
        """Whether the cluster was given up on: nothing more is asked of it."""

    def idle(self) -> int:
        """How many more trials the pool can take now."""
        return self.size - sum(1 for s in self._slots if s.number is not None)

    def submit(self, number: int, spec: TrialSpec) -> None:
        """Run a trial on an idle actor, starting one if needed."""
        slot = next((s for s in self._slots if s.number is None), None)
        if slot is None:
            actor = self._actor.remote(self._shards)
            slot = _Slot(actor, actor.ready.remote())
            self._slots.append(slot)
        slot.number, slot.spec = number, spec
        slot.run, slot.drain = slot.actor.run.remote(number, spec), None

    def running(self) -> dict[int, TrialSpec]:
        """The trials being run, by trial number."""
        return {s.number: s.spec for s in self._slots if s.number is not None and s.spec}

    def events(self, timeout: float) -> list[Event]:
        """What the actors said or did within ``timeout`` seconds.

        Raises:
            ClusterLost: No call has reached the cluster for ``patience`` seconds.
        """
        out: list[Event] = []
        # Idle now, after the runner's claims: no trial was left for them.
        self._let_go_for_unplaced(self._starting(out))
        busy = [s for s in self._slots if s.number is not None]
        for slot in busy:
            if slot.drain is None:
                slot.drain = slot.actor.drain.remote(DRAIN_SECONDS)
        calls = {ref: slot for slot in busy for ref in (slot.drain, slot.run) if ref is not None}
        if not calls:
            return out
        ready, _ = ray.wait(list(calls), num_returns=1, timeout=timeout)
        if ready:
            ready, _ = ray.wait(list(calls), num_returns=len(calls), timeout=0)
        self._note_reach(bool(ready) or self._starting_seen, busy)
        for ref in ready:
            slot = calls[ref]
            if slot not in self._slots or ref not in (slot.drain, slot.run):
                continue  # the slot was let go, or this call ended with its trial
            try:
                got = ray.get(ref)
            except ray.exceptions.RayError as err:
                cannot = _cannot_start(err)
                if cannot is None:
                    self._gone(slot, f"lost on Ray ({type(err).__name__})", out)
                else:
                    self._failed(slot, cannot, out)
                continue
            if ref is slot.run:
                slot.run = None  # the result comes through the outbox
            else:
                slot.drain = None
                self._deliver(slot, got, out)
        return out

    def _deliver(self, slot: _Slot, messages: list[tuple[Any, ...]], out: list[Event]) -> None:
        for message in messages:
            event = as_event(message, slot)
            if event.kind == "result":
                slot.number, slot.spec, slot.run, slot.drain = None, None, None, None
            out.append(event)

    def _gone(self, slot: _Slot, why: str, out: list[Event]) -> None:
        self._slots.remove(slot)
        _kill(slot.actor)
        if slot.number is not None:
            out.append(Event("died", slot.number, (slot.spec, why)))

    def _failed(self, slot: _Slot, why: str, out: list[Event]) -> None:
        """An actor that could not start on its node: its trial fails with the reason (a node
        without the project would fail it again)."""
        self._slots.remove(slot)
        _kill(slot.actor)
        if slot.number is not None:
            out.append(Event("result", slot.number, TrialResult(
                outcome=Outcome.FAILED, env_steps=0, wall_time=0.0,
                failure=failure(Failure.ERROR, why))))

    def _note_reach(self, answered: bool, busy: list[_Slot]) -> None:
        """Stop after ``patience`` seconds in which no trial's actor answered.

        A living actor answers each drain within DRAIN_SECONDS, and one still starting has a
        worker process in the cluster's actor table (read afresh for each call), so silence
        from all of them means the cluster is gone, or has no node left to place them on.
        """
        if answered or not busy:
            self._silent_since = None
            return
        now = time.monotonic()
        self._silent_since = self._silent_since or now
        if now - self._silent_since >= self._patience:
            self.lost = True
            raise ClusterLost(f"no trial actor answered for {self._patience:.0f} s: the Ray "
                              "cluster is lost or has no CPU left for a trial; giving up "
                              "(complete trials are stored; rerun to resume)")

    def _starting(self, out: list[Event]) -> list[_Slot]:
        """The actors that have not answered ready() yet, each marked placed once the
        cluster's actor table names a process for it. One placed for over ``start_seconds``
        is taken as hung in its start: it is let go and its trial runs again."""
        self._starting_seen = False
        starting = [s for s in self._slots if s.ready is not None]
        if not starting:
            return []
        done, _ = ray.wait([s.ready for s in starting], num_returns=len(starting), timeout=0)
        for slot in starting:
            if slot.ready in done:
                slot.ready = None
        starting = [s for s in starting if s.ready is not None]
        placed = self._table.placed([s.actor for s in starting])
        now = time.monotonic()
        for slot in starting:
            if placed is not None and placed.get(slot.actor._actor_id.hex()):
                slot.placed = slot.placed or now
                self._starting_seen |= slot.number is not None
            if slot.placed is not None and now - slot.placed > self._start_seconds:
                self._gone(slot, f"not started after {self._start_seconds:g} s on its node "
                           "(ray.start_seconds)", out)
        return [s for s in starting if s in self._slots]

    def _let_go_for_unplaced(self, starting: list[_Slot]) -> None:
        """Let idle actors go while newer ones wait to be placed (a node was lost and the
        others are full): one idle actor for each actor with no process yet."""
        waiting = [s for s in starting if s.placed is None]
        idle = [s for s in self._slots if s.number is None and s.ready is None]
        for slot in idle[:len(waiting)]:
            self._slots.remove(slot)
            _kill(slot.actor)

    @staticmethod
    def reply(event: Event, keep_going: bool) -> None:
        """Answer a checkpoint: True lets the trial go on, False prunes it."""
        event.slot.actor.reply.remote(keep_going)

    def close(self, terminate: bool = False) -> None:
        """Let every actor go (their trials, if any, stop with them)."""
        if not self.lost:
            for slot in self._slots:
                _kill(slot.actor)
        self._slots.clear()


_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_MISSING = re.compile(r"No module named '([^']+)'")


def _cannot_start(err: Exception) -> str | None:
    """One line for an actor whose creation failed on its node (the project or a package it
    imports is not installed there), naming what is missing and the node; None for any other
    loss (a killed process, a lost node: the trial runs again)."""
    if not (isinstance(err, ray.exceptions.RayActorError) and err.actor_init_failed):
        return None
    lines = [_ANSI.sub("", line).strip() for line in str(err).splitlines()]
    last = next((line for line in reversed(lines) if line.strip("^ ")), type(err).__name__)
    node = _node_of(err.actor_id)
    missing = _MISSING.search(last)
    if missing:
        return (f"Python package {missing[1].split('.')[0]!r} is not installed on Ray node "
                f"{node}: install kraby-study there (docs/guide/clusters.md)")
    return f"a trial cannot start on Ray node {node}: {last}"


def _node_of(actor_id: str | None) -> str:
    """``<ip> (node id <first 8 hex digits>)`` of the node an actor was placed on, as the
    cluster's actor table has it; ``unknown`` when it has no answer."""
    try:
        address = ray._private.state.actors(actor_id)["Address"]
        return f"{address['IPAddress']} (node id {str(address['NodeID'])[:8]})"
    except Exception:  # noqa: BLE001 - a private table: its absence must not hide the error
        return "unknown"


def _kill(actor: Any) -> None:
    try:
        ray.kill(actor, no_restart=True)
    except Exception:  # noqa: BLE001 - already gone, or the cluster is
        pass


@dataclass(frozen=True)
class RayExecutor:
    """Trials as Ray actors on the connected cluster.

    Attributes:
        shards: Processes stepping each trial's legs.
        cpus: CPUs each trial reserves on its node.
        patience: Seconds the cluster may stay out of reach before the command stops.
        start_seconds: Seconds an actor placed on a node may take to start.
    """

    shards: int
    cpus: int
    patience: float
    start_seconds: float

    def workers(self, configured: int | None) -> int:
        """The configured number, or the cluster's CPUs / cpus per trial."""
        if configured is not None:
            return int(configured)
        return max(1, int(ray.cluster_resources().get("CPU", 0)) // self.cpus)

    def pool(self, size: int) -> RayPool:
        """``size`` trial actors, started when there is work for them."""
        return RayPool(size, self.shards, self.cpus, self.patience, self.start_seconds)

    def prestart(self, size: int) -> None:
        """Nothing: actors are placed when a trial needs one."""


def _check_reachable(address: str | None, patience: float) -> None:
    """Fail fast on a ``host:port`` that nothing listens on: Ray itself would wait for it as
    long as it waits for a lost head (see above)."""
    if address is None or ":" not in address or address.startswith("ray://"):
        return
    host, _, port = address.rpartition(":")
    if not port.isdigit():
        raise ConnectionError(f"{address!r} is not host:port")
    deadline = time.monotonic() + patience
    while True:
        try:
            socket.create_connection((host, int(port)), timeout=5.0).close()
            return
        except OSError as err:
            if time.monotonic() >= deadline:
                raise ConnectionError(f"nothing answers at {address} ({first_line(err)})") \
                    from None
            time.sleep(1.0)


@contextmanager
def ray_executor(cfg: DictConfig) -> Iterator[RayExecutor]:
    """Connect to ``ray.address`` (None: a Ray instance of the command's own) for the block.

    Raises:
        ConfigError: The cluster cannot be reached, or no node has cpus_per_trial CPUs.
    """
    address = None if cfg.ray.address is None else str(cfg.ray.address)
    shards = int(cfg.shards or cfg.ray.cpus_per_trial or 1)
    cpus = int(cfg.ray.cpus_per_trial or shards)
    runtime_env = (None if cfg.ray.runtime_env is None
                   else OmegaConf.to_container(cfg.ray.runtime_env, resolve=True))
    options: dict[str, Any] = {"address": address, "runtime_env": runtime_env,
                               "include_dashboard": False, "log_to_driver": False,
                               "logging_level": logging.WARNING}
    if address is None:  # a Ray instance of the command's own, on loopback only
        options.update(object_store_memory=LOCAL_OBJECT_STORE, _node_ip_address="127.0.0.1")
    try:
        _check_reachable(address, float(cfg.db_retry_seconds))
        ray.init(**options)
    except Exception as err:  # noqa: BLE001 - Ray raises several kinds; each is one line here
        where = "a local Ray instance" if address is None else f"the Ray cluster at {address}"
        raise ConfigError(f"cannot start {where}: {first_line(err)}") from None
    try:
        biggest = max((n["Resources"].get("CPU", 0) for n in ray.nodes() if n["Alive"]),
                      default=0)
        if biggest < cpus:
            raise ConfigError(f"no Ray node has {cpus} CPU(s) for a trial (the largest has "
                              f"{biggest:g}); lower ray.cpus_per_trial")
        yield RayExecutor(shards=shards, cpus=cpus, patience=float(cfg.db_retry_seconds),
                          start_seconds=float(cfg.ray.start_seconds))
    finally:
        ray.shutdown()
