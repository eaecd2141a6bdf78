"""What runs the trials: worker processes on this machine, or a Ray cluster.

An executor is chosen by ``executor=local|ray`` and lives for one command. It says how many
trials run at once when ``workers`` is null, and gives the runner a :class:`Pool` of that many
slots. Whatever runs the trials, their results come back to the command's process, which stays
the only writer of the store.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Protocol

from omegaconf import DictConfig

from kraby_study.config.validate import cores
from kraby_study.run.pool import Pool, WorkerPool


class Executor(Protocol):
    """Runs a command's trials; one per command."""

    def workers(self, configured: int | None) -> int:
        """Trials at once: the configured number, or what the machines hold."""

    def pool(self, size: int) -> Pool:
        """A pool of ``size`` trial slots (closed by the runner)."""


@dataclass(frozen=True)
class LocalExecutor:
    """Worker processes on this machine.

    Attributes:
        shards: Processes stepping each trial's legs; None gives each trial the cores the
            workers leave idle, so a lone trial uses the whole machine.
    """

    shards: int | None = None

    def workers(self, configured: int | None) -> int:
        """The configured number, or one per core."""
        return int(configured) if configured is not None else cores()

    def pool(self, size: int) -> Pool:
        """``size`` worker processes, started when there is work for them."""
        shards = self.shards if self.shards is not None else max(1, cores() // size)
        return WorkerPool(size, shards)


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
        yield LocalExecutor(None if cfg.shards is None else int(cfg.shards))
