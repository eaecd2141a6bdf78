"""Benchmark: how many trials per second one command (the head) can receive and store.

Run: python benchmarks/bench_head.py [--trials 400] [--slots 64] [--url postgresql+psycopg://...]
         [--ray-nodes 2 --ray-slots 2,8]

The command's own path runs as `kraby-study run` runs it: the config composed, the sweep
expanded (study=gamma at the full budget, budget.seeds raised to give --trials trials), the
store opened, `run_plan` -> `run_trials` -> `PlanSource` -> `StudyLedger`. Only what runs the
trials is a stub, and it lives here, not in the product: every trial returns at once what a
full-budget trial returns, a curve of 122 bins (250,000 steps at curve_every 2,048), its
measures, and the provenance record a Ray actor sends when it starts. So the rate is the
head's ceiling: receiving a trial, recording its provenance, its curve, its attributes and its
Optuna state, and claiming the next one.

Stores: a fresh SQLite file, and a fresh PostgreSQL database when --url (or
KRABY_TEST_POSTGRES_URL) names a server. With --ray-nodes N the same study also runs through
the product's RayPool on a Ray cluster of N one-CPU nodes started on loopback (stopped at the
end), with trial actors whose `run` returns the same result at once (a subclass defined here):
the rate per slot there is Ray's own cost per trial (submit, drain, result), which a real
trial pays once per trial on top of its training.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import os
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import sqlalchemy as sa

from kraby_study.api.run import open_writer, run_options
from kraby_study.config.compose import compose_config
from kraby_study.plan.spec import TrialSpec
from kraby_study.plan.sweep import expand_study
from kraby_study.records.attributes import RAY_NODE, CurvePoint, TrialResult
from kraby_study.records.stored import Outcome
from kraby_study.run.pool import Event
from kraby_study.run.provenance import trial_facts
from kraby_study.run.study_run import run_plan

VALUES = 8  # the gamma study's values
STEPS, CURVE_EVERY = 250_000, 2048


def full_result(seed: int) -> TrialResult:
    """What a complete full-budget trial returns: 122 curve bins and its measures."""
    bins = STEPS // CURVE_EVERY
    curve = [CurvePoint(step=(i + 1) * CURVE_EVERY, mean_reward=-0.5 + i / bins * 0.48 + seed
                        * 1e-6, wall_time=0.8 * (i + 1), episodes=20) for i in range(bins)]
    return TrialResult(outcome=Outcome.COMPLETE, curve=curve, env_steps=STEPS + 1024,
                       wall_time=96.3, cpu_time=63.0, started="2026-11-27T10:00:00+00:00",
                       ended="2026-11-27T10:01:36+00:00", final_score=-0.0191 - seed * 1e-6,
                       train_reward=-0.0191 - seed * 1e-6, scores=[-0.0191 - seed * 1e-6])


class StubPool:
    """A Pool whose every trial returns at once: started (provenance), then the result
    (``result(spec)``; by default what a full-budget trial of the spec's seed returns)."""

    def __init__(self, size: int, facts: dict[str, str],
                 result: Callable[[TrialSpec], TrialResult] | None = None) -> None:
        self.size = size
        self._facts = facts
        self._result = result or (lambda spec: full_result(spec.seed))
        self._running: dict[int, TrialSpec] = {}

    def idle(self) -> int:
        return self.size - len(self._running)

    def submit(self, number: int, spec: TrialSpec) -> None:
        self._running[number] = spec

    def running(self) -> dict[int, TrialSpec]:
        return dict(self._running)

    def events(self, timeout: float) -> list[Event]:
        out: list[Event] = []
        for number, spec in self._running.items():
            out += [Event("started", number, self._facts),
                    Event("result", number, self._result(spec))]
        self._running.clear()
        return out

    def reply(self, event: Event, keep_going: bool) -> None:
        raise AssertionError("a sweep has no checkpoints")

    def close(self, terminate: bool = False) -> None:
        self._running.clear()


@dataclasses.dataclass
class StubExecutor:
    """An executor whose pool is ``make(size)``."""

    make: Any

    def workers(self, configured: int | None) -> int:
        return int(configured or 1)

    def pool(self, size: int) -> Any:
        return self.make(size)

    def prestart(self, size: int) -> None:
        """Nothing to start."""


def run_study(url: str, trials: int, slots: int, executor: StubExecutor,
              folder: Path) -> tuple[float, float]:
    """(wall seconds, CPU seconds of this process) one command takes to receive and store
    ``trials`` trials, ``slots`` at once."""
    seeds = trials // VALUES
    cfg = compose_config(["study=gamma", "budget=full", f"budget.seeds={seeds}",
                          f"storage={url}", "save_models=false"])
    plan = expand_study(cfg)
    assert len(plan.specs) == trials, len(plan.specs)
    here = Path.cwd()
    os.chdir(folder)
    try:
        with open_writer(cfg) as store:
            t0, c0 = time.perf_counter(), time.process_time()
            summary, counts = run_plan(store, plan, executor, slots, io.StringIO(), live=False,
                                       **run_options(cfg))
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        os.chdir(here)
    assert counts.complete == trials, counts
    return wall, cpu


@contextmanager
def postgres_database(server: str) -> Iterator[str]:
    """A fresh database on the server, dropped at the end."""
    admin = sa.create_engine(server, isolation_level="AUTOCOMMIT")
    name = f"kraby_head_{uuid.uuid4().hex[:8]}"
    with admin.connect() as conn:
        conn.execute(sa.text(f"CREATE DATABASE {name}"))
    try:
        yield sa.engine.make_url(server).set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as conn:
            conn.execute(sa.text(f"DROP DATABASE IF EXISTS {name} WITH (FORCE)"))
        admin.dispose()


@contextmanager
def ray_cluster(nodes: int) -> Iterator[str]:
    """``nodes`` one-CPU Ray nodes on loopback in a temporary folder of their own; every one
    of their processes is killed at the end."""
    folder = Path(f"/tmp/krh{os.getpid()}")
    port = 6500 + os.getpid() % 1000
    ray = str(Path(sys.executable).with_name("ray"))
    # Trial actors at the command's own priority, as the product sets for a Ray of its own.
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0", RAY_AUTH_MODE="disabled",
               RAY_worker_niceness="0")
    common = ["--num-cpus=1", "--node-ip-address=127.0.0.1", "--object-store-memory=100000000"]
    try:
        subprocess.run([ray, "start", "--head", f"--port={port}", "--include-dashboard=false",
                        f"--temp-dir={folder}", *common], check=True, env=env,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(nodes - 1):
            subprocess.run([ray, "start", f"--address=127.0.0.1:{port}", *common], check=True,
                           env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        yield f"127.0.0.1:{port}"
    finally:
        kill_marked(str(folder))
        subprocess.run(["rm", "-rf", str(folder)], check=False)


def kill_marked(marker: str) -> None:
    """SIGKILL the processes whose command line holds ``marker``, and all below them."""
    parents: dict[int, list[int]] = {}
    own: list[int] = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) == os.getpid():
            continue
        try:
            ppid = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
            line = (proc / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue
        parents.setdefault(ppid, []).append(int(proc.name))
        if marker.encode() in line:
            own.append(int(proc.name))
    todo, every = list(own), list(own)
    while todo:
        for child in parents.get(todo.pop(), []):
            every.append(child)
            todo.append(child)
    for pid in every:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def ray_executor(address: str) -> StubExecutor:
    """The product's RayPool on the cluster at ``address``, its actors returning at once."""
    import ray

    from kraby_study.run.ray_pool import RayPool, TrialActor

    class InstantActor(TrialActor):
        """A trial actor whose trial returns at once (what it sends is a real trial's)."""

        def run(self, number: int, spec: TrialSpec) -> None:
            node = ray.get_runtime_context().get_node_id()
            self._outbox.put(("started", number,
                              {**trial_facts(spec.settings["env"]), RAY_NODE: node}))
            self._outbox.put(("result", number, full_result(spec.seed)))

    from kraby_study.run import ray_pool

    # Instant trials end while the pool's other actors are still starting (importing torch
    # takes well over 10 s on a loaded machine), which the pool takes for actors waiting on a
    # lost node's CPU, and lets the idle ones go. Real trials outlast any start-up: here the
    # patience is raised so that each slot keeps its actor.
    ray_pool.PLACEMENT_SECONDS = 1e9
    ray.init(address=address, include_dashboard=False, log_to_driver=False,
             logging_level="WARNING")
    cpus = int(ray.cluster_resources()["CPU"])

    def make(size: int) -> RayPool:
        pool = RayPool(size, 1, 1, 60.0)
        # Several actors may share a node's CPU: they only answer, they do not train.
        pool._actor = ray.remote(InstantActor).options(  # noqa: SLF001 - the stub's seam
            num_cpus=cpus / size, max_concurrency=3, max_restarts=0, max_task_retries=0)
        return pool

    return StubExecutor(make)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=400)
    parser.add_argument("--slots", type=int, default=64)
    parser.add_argument("--url", default=os.environ.get("KRABY_TEST_POSTGRES_URL"))
    parser.add_argument("--ray-nodes", type=int, default=0)
    parser.add_argument("--ray-slots", default="2,8")
    parser.add_argument("--skip-local", action="store_true", help="only the Ray rows")
    args = parser.parse_args()
    facts = {**trial_facts({"kind": "leg"}), RAY_NODE: "0" * 56}
    local = StubExecutor(lambda size: StubPool(size, facts))
    print(f"cores: {os.cpu_count()}; {args.trials} trials of the full budget's size "
          f"(122 curve bins, measures, provenance), each returned at once")
    print("| store | trials from | slots | wall (s) | trials/s | ms per trial | head CPU ms "
          "per trial | slot-seconds per trial |")
    print("|---|---|---:|---:|---:|---:|---:|---:|", flush=True)

    def row(store: str, source: str, slots: int, measured: tuple[float, float]) -> None:
        wall, cpu = measured
        print(f"| {store} | {source} | {slots} | {wall:.1f} | {args.trials / wall:.1f} | "
              f"{1000 * wall / args.trials:.1f} | {1000 * cpu / args.trials:.1f} | "
              f"{slots * wall / args.trials:.3f} |", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        # A first study outside the table: imports and the schema's creation.
        run_study(f"sqlite:///{folder / 'warm.db'}", VALUES, 8, local, folder)
        if not args.skip_local:
            row("SQLite file", "stub pool", args.slots,
                run_study(f"sqlite:///{folder / 'head.db'}", args.trials, args.slots, local,
                          folder))
            if args.url:
                with postgres_database(args.url) as url:
                    row("PostgreSQL", "stub pool", args.slots,
                        run_study(url, args.trials, args.slots, local, folder))
        if args.ray_nodes:
            with ray_cluster(args.ray_nodes) as address:
                executor = ray_executor(address)
                for slots in (int(s) for s in args.ray_slots.split(",")):
                    # Twice: a study of one trial per slot and value, and the full count. Each
                    # starts its actors (a pool per study, as per campaign stage); the
                    # difference is the trials' own cost.
                    few = VALUES * slots
                    short, _ = run_study(f"sqlite:///{folder / f'short{slots}.db'}", few,
                                         slots, executor, folder)
                    measured = run_study(f"sqlite:///{folder / f'ray{slots}.db'}", args.trials,
                                         slots, executor, folder)
                    row(f"SQLite file, {args.ray_nodes} Ray nodes", "instant actors", slots,
                        measured)
                    wall = measured[0]
                    per = (wall - short) / (args.trials - few)
                    print(f"  {few} trials: {short:.1f} s; the {args.trials - few} more: "
                          f"{1000 * per:.1f} ms per trial, {slots * per:.3f} slot-seconds "
                          f"per trial; start-up of the pool and its actors about "
                          f"{short - few * per:.1f} s", flush=True)


if __name__ == "__main__":
    main()
