"""Benchmark: the same small study with executor=ray against executor=local on this machine.

Run: python benchmarks/bench_ray.py [--rounds 2] [--steps 20480]

Each round runs the clip_range sweep (4 values x 2 seeds, 2 workers, models not saved) once per
executor, in a fresh SQLite store, alternating which goes first. The ray run starts its own
local Ray instance, so its wall time includes Ray's start and stop. Peak memory is the largest
sum of the resident set sizes of the command and every process it started (workers, or Ray's
services and trial actors), sampled every 0.2 s. It prints the ratios ray / local (goal: wall
time <= 1.10) and checks that both executors stored the same scores.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import optuna

STUDY = ["study=clip_range", "budget.seeds=2", "budget.curve_every=1024", "save_models=false",
         "workers=2"]


def tree_rss(root: int) -> int:
    """Resident bytes of a process and all its descendants (Linux /proc)."""
    parents: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            stat = (proc / "stat").read_text().rsplit(")", 1)[1].split()
            parents.setdefault(int(stat[1]), []).append(int(proc.name))
            rss[int(proc.name)] = int(stat[21]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, IndexError, ValueError):
            continue
    total, todo = 0, [root]
    while todo:
        pid = todo.pop()
        total += rss.get(pid, 0)
        todo.extend(parents.get(pid, []))
    return total


def run(executor: str, steps: int, folder: Path) -> tuple[float, int, dict[str, float]]:
    """(wall seconds, peak bytes, scores by key) of one command."""
    db = folder / f"{executor}.db"
    db.unlink(missing_ok=True)
    args = [sys.executable, "-m", "kraby_study.cli", "run", *STUDY, f"budget.steps={steps}",
            f"executor={executor}", f"storage=sqlite:///{db}"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, cwd=folder, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    peak = [0]

    def sample() -> None:
        while proc.poll() is None:
            peak[0] = max(peak[0], tree_rss(proc.pid))
            time.sleep(0.2)

    sampler = threading.Thread(target=sample)
    sampler.start()
    code = proc.wait()
    wall = time.perf_counter() - t0
    sampler.join()
    if code != 0:
        raise SystemExit(f"the {executor} run failed (exit {code})")
    study = optuna.load_study(study_name="clip_range", storage=f"sqlite:///{db}")
    scores = {str(t.user_attrs["key"]): float(t.value) for t in study.get_trials()
              if t.value is not None}
    return wall, peak[0], scores


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--steps", type=int, default=20480)
    args = parser.parse_args()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    results: dict[str, list[tuple[float, int]]] = {"local": [], "ray": []}
    with tempfile.TemporaryDirectory() as tmp:
        for index in range(args.rounds):
            order = ("local", "ray") if index % 2 == 0 else ("ray", "local")
            scores = {}
            for executor in order:
                wall, peak, scores[executor] = run(executor, args.steps, Path(tmp))
                results[executor].append((wall, peak))
                print(f"round {index + 1} {executor}: {wall:.1f} s, peak {peak / 2**20:.0f} MiB",
                      flush=True)
            same = scores["local"] == scores["ray"]
            print(f"round {index + 1}: same scores on both executors: {same}", flush=True)
    local_wall = statistics.median(w for w, _ in results["local"])
    ray_wall = statistics.median(w for w, _ in results["ray"])
    local_peak = max(p for _, p in results["local"])
    ray_peak = max(p for _, p in results["ray"])
    print(f"cores: {os.cpu_count()}; clip_range sweep, 8 trials x {args.steps:,} steps, "
          f"2 workers; median of {args.rounds} rounds")
    print("| executor | wall time (s) | ratio | peak memory (MiB) | ratio |")
    print("|---|---:|---:|---:|---:|")
    print(f"| local | {local_wall:.1f} | 1.00 | {local_peak / 2**20:.0f} | 1.00 |")
    print(f"| ray | {ray_wall:.1f} | {ray_wall / local_wall:.2f} | {ray_peak / 2**20:.0f} | "
          f"{ray_peak / local_peak:.2f} |")


if __name__ == "__main__":
    main()
