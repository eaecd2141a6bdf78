"""Benchmark: how long a trial actor takes to start on a Ray node, idle and under load.

Run: python benchmarks/bench_actor_start.py [--actors 5] [--load 2] [--cold]

A Ray instance of this process (one CPU per actor slot, on loopback) starts the product's
TrialActor ``--actors`` times, one after another, each in a fresh worker process (a fresh
interpreter: Ray, the project, torch and SB3 imported anew). For each it measures, from the
creation call: when Ray's actor table first names a worker process for it (placed; read every
0.1 s), and when its ready() answers (started: its imports and torch's set-up done).

With --load N, N training runs (`kraby-study train`, long enough to outlast the measurement)
run beside it on the same cores, as trials of another command would on a loaded node; they
are stopped at the end. With --cold, every file of this environment's site-packages and of
the project is dropped from the page cache before each actor (posix_fadvise DONTNEED), so its
imports read them from the disk, as a node does on its first trial. The default of
ray.start_seconds is set from the slowest start measured, with room for a node slower than
this one (docs/guide/clusters.md).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("RAY_AUTH_MODE", "disabled")


def load(runs: int, folder: Path) -> list[subprocess.Popen[bytes]]:
    """``runs`` training runs of the leg, each long enough to outlast the measurement."""
    procs = []
    for i in range(runs):
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "kraby_study.cli", "train", "budget=smoke",
             "budget.steps=5000000", "save_models=false", "workers=1", f"seed={i}",
             f"storage=sqlite:///{folder}/load{i}.db"],
            cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
    return procs


def evict(folders: list[Path]) -> int:
    """Drop the files under ``folders`` from the page cache; returns how many."""
    count = 0
    for folder in folders:
        for path in folder.rglob("*"):
            try:
                if not path.is_file() or path.is_symlink():
                    continue
                fd = os.open(path, os.O_RDONLY)
            except OSError:
                continue
            try:
                os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
                count += 1
            finally:
                os.close(fd)
    return count


def measure(actors: int, cold: bool) -> list[tuple[float, float]]:
    """(placed, started) seconds of ``actors`` trial actors started one after another."""
    import sysconfig

    import kraby_study
    from kraby_study.run import ray_pool

    ray = ray_pool.ray
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False,
             object_store_memory=ray_pool.LOCAL_OBJECT_STORE, _node_ip_address="127.0.0.1")
    remote = ray.remote(ray_pool.TrialActor).options(num_cpus=1, max_concurrency=3,
                                                     max_restarts=0)
    out = []
    folders = [Path(sysconfig.get_paths()["purelib"]), Path(kraby_study.__file__).parent]
    try:
        for _ in range(actors):
            if cold:
                evict(folders)
            began = time.monotonic()
            actor = remote.remote(1)
            ready = actor.ready.remote()
            placed = None
            while True:
                done, _ = ray.wait([ready], timeout=0.1)
                now = time.monotonic() - began
                if placed is None and ray_pool._has_process(actor._actor_id.hex()):
                    placed = now
                if done:
                    ray.get(ready)
                    out.append((placed if placed is not None else now, now))
                    break
            ray.kill(actor, no_restart=True)
            time.sleep(1.0)  # its CPU back before the next one is placed
    finally:
        ray.shutdown()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actors", type=int, default=5)
    parser.add_argument("--load", type=int, default=0, help="training runs beside it")
    parser.add_argument("--cold", action="store_true", help="imports read from the disk")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        procs = load(args.load, Path(folder))
        try:
            if procs:
                time.sleep(20.0)  # the runs past their own start, training
            times = measure(args.actors, args.cold)
        finally:
            for proc in procs:
                proc.kill()
                proc.wait()
    print(f"{os.cpu_count()} cores, {args.load} training run(s) beside it, "
          f"{'cold' if args.cold else 'warm'} page cache, "
          f"load average {os.getloadavg()[0]:.1f}")
    for i, (placed, started) in enumerate(times, 1):
        print(f"actor {i}: placed after {placed:.2f} s, started after {started:.2f} s")
    starts = [s for _, s in times]
    print(f"started: median {statistics.median(starts):.2f} s, max {max(starts):.2f} s")


if __name__ == "__main__":
    main()
