"""What runs the trials: worker processes on this machine, or a Ray cluster.

An executor is chosen by ``executor=local|ray`` and lives for one command. It says how many
trials run at once when ``workers`` is null, and gives the runner a
[`Pool`][kraby_study.run.pool.Pool] of that many slots. Whatever runs the trials, their results come
back to the command's process, which stays the only writer of the store.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Protocol

from omegaconf import DictConfig

from kraby_study.config.validate import cores
from kraby_study.run.pool import Pool, WorkerPool, WorkerSlot, start_worker, stop_workers


class Executor(Protocol):
    """Runs a command's trials; one per command."""

    def workers(self, configured: int | None) -> int:
        """Trials at once: the configured number, or what the machines hold."""

    def pool(self, size: int) -> Pool:
        """A pool of ``size`` trial slots (closed by the runner)."""
        ...

    def prestart(self, size: int) -> None:
        """Start what a pool of ``size`` slots will run on now, ahead of its first trial (the
        command then opens its store meanwhile); a no-op where nothing is gained."""


@dataclass(frozen=True)
class LocalExecutor:
    """Worker processes on this machine.

    Attributes:
        shards: Processes stepping each trial's legs; None gives each trial the cores the
            workers leave idle, so a lone trial uses the whole machine.
    """

    shards: int | None = None
    spares: dict[int, list[WorkerSlot]] = field(default_factory=dict, compare=False)
    """Workers started ahead ([`prestart`][kraby_study.run.executor.LocalExecutor.prestart]), by the
    pool size they were started for."""

    def workers(self, configured: int | None) -> int:
        """The configured number, or one per core."""
        return int(configured) if configured is not None else cores()

    def _shards(self, size: int) -> int:
        return self.shards if self.shards is not None else max(1, cores() // size)

    def pool(self, size: int) -> Pool:
        """``size`` worker processes, started when there is work for them (those started
        ahead for this size first)."""
        return WorkerPool(size, self._shards(size), self.spares.setdefault(size, []))

    def prestart(self, size: int) -> None:
        """Start ``size`` workers now: their imports (torch, SB3, the envs: about 2 s) overlap
        the command's own start (the store); a pool of ``size`` takes them."""
        self.spares.setdefault(size, []).extend(start_worker(self._shards(size))
                                                for _ in range(size))

    def close(self) -> None:
        """Stop the workers started ahead that no pool took."""
        for slots in self.spares.values():
            stop_workers(slots)
            slots.clear()


@contextmanager
def executor_for(cfg: DictConfig) -> Iterator[Executor]:
    """The executor a command's config asks for, connected for the length of the block.

    Raises:
        ConfigError: The Ray cluster cannot be reached or cannot hold one trial (one line).
    """
    if str(cfg.executor) == "ray":
        from kraby_study.run.ray_pool import ray_executor

        with ray_executor(cfg) as executor:
            yield executor
    else:
        local = LocalExecutor(None if cfg.shards is None else int(cfg.shards))
        try:
            yield local
        finally:
            local.close()
