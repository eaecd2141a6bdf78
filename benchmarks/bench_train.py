"""Benchmark: `kraby-study train` against a plain SB3 script, and 1 against 2 workers.

Run: python benchmarks/bench_train.py [--steps 32768] [--skip-workers]
     python benchmarks/bench_train.py --baseline DIR [--repeats 3]

Both trainings use the tuned settings (n_steps 32 x 32 legs, batch 1024, 30 epochs). The plain
script is what a user would write without kraby-study: PPO on a DummyVecEnv of 32 single
environments (one PyBullet client each) wrapped in VecMonitor, with one torch thread like a
kraby-study worker. Each side runs as its own process tree. Peak memory is the largest sum over
the tree of PSS (proportional set size: a page shared by n processes counts 1/n in each, so the
Python, NumPy and PyBullet libraries that several processes map are counted once) and, for
reference, of RSS (which counts them once per process). Speeds are env steps per second of
training (environment and model construction to the end of learning) and of the whole command.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PLAIN_SCRIPT = r"""
import json, sys, time
import torch
torch.set_num_threads(1)
import gymnasium as gym
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor
import kraby_envs

steps = int(sys.argv[1])
t0 = time.perf_counter()
env = VecMonitor(DummyVecEnv([lambda: gym.make("KrabyOneLeg-v0") for _ in range(32)]))
model = PPO("MlpPolicy", env, n_steps=32, batch_size=1024, n_epochs=30, gamma=0.8,
            gae_lambda=0.95, clip_range=0.2, ent_coef=0.01, learning_rate=0.01,
            policy_kwargs={"net_arch": {"pi": [64, 64], "vf": [64, 64]}}, seed=0, device="cpu")
model.learn(total_timesteps=steps)
print(json.dumps({"train_seconds": time.perf_counter() - t0, "env_steps": model.num_timesteps}))
"""


def _tree(pid: int) -> list[int]:
    pids = [pid]
    for p in pids:
        task = Path(f"/proc/{p}/task")
        try:
            for thread in task.iterdir():
                pids.extend(int(c) for c in (thread / "children").read_text().split())
        except OSError:
            continue
    return pids


def _rss_mb(pids: list[int]) -> float:
    total = 0
    for pid in pids:
        try:
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1])
        except OSError:
            continue
    return total / 1024


def _pss_mb(pids: list[int]) -> float:
    total = 0
    for pid in pids:
        try:
            for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    total += int(line.split()[1])
        except OSError:
            continue
    return total / 1024


def measure(cmd: list[str], cwd: Path,
            env: dict[str, str] | None = None) -> tuple[float, tuple[float, float], str]:
    """(wall seconds, (peak tree RSS, peak tree PSS) in MB, stdout) of a command.

    RSS is sampled every 50 ms; PSS, which walks every mapping, every 500 ms so that the
    sampling does not take a core from the command measured.
    """
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env=env)
    peak_rss = peak_pss = 0.0
    ticks = 0
    while proc.poll() is None:
        pids = _tree(proc.pid)
        peak_rss = max(peak_rss, _rss_mb(pids))
        if ticks % 10 == 0:
            peak_pss = max(peak_pss, _pss_mb(pids))
        ticks += 1
        time.sleep(0.05)
    out = proc.stdout.read() if proc.stdout else ""
    if proc.returncode != 0:
        raise SystemExit(f"command failed ({proc.returncode}): {' '.join(cmd)}\n{out}")
    return time.perf_counter() - t0, (peak_rss, peak_pss), out


def kraby(*args: str) -> list[str]:
    return [sys.executable, "-m", "kraby_study.cli", *args]


def bench_train(steps: int, work: Path) -> list[str]:
    """Rows of the train-vs-plain table."""
    wall_k, peak_k, out = measure(kraby("train", "ppo=tuned", f"budget.steps={steps}",
                                        "save_models=false", "storage=sqlite:///k.db"), work)
    import optuna

    study = optuna.load_study(study_name=optuna.get_all_study_names(
        "sqlite:///" + str(work / "k.db"))[0], storage="sqlite:///" + str(work / "k.db"))
    trial = study.trials[-1]
    k_steps, k_train = trial.user_attrs["env_steps"], trial.user_attrs["wall_time"]
    script = work / "plain_sb3.py"
    script.write_text(PLAIN_SCRIPT)
    wall_p, peak_p, out_p = measure([sys.executable, str(script), str(steps)], work)
    plain = json.loads(out_p.strip().splitlines()[-1])
    p_steps, p_train = plain["env_steps"], plain["train_seconds"]
    rows = [
        "| run | env steps | training steps/s | command steps/s | peak PSS (MB) | peak RSS (MB) |",
        "|---|---:|---:|---:|---:|---:|",
        f"| plain SB3, DummyVecEnv x 32 | {p_steps} | {p_steps / p_train:,.0f} | "
        f"{p_steps / wall_p:,.0f} | {peak_p[1]:,.0f} | {peak_p[0]:,.0f} |",
        f"| kraby-study train ppo=tuned | {k_steps} | {k_steps / k_train:,.0f} | "
        f"{k_steps / wall_k:,.0f} | {peak_k[1]:,.0f} | {peak_k[0]:,.0f} |",
        f"| ratio kraby / plain | | {(k_steps / k_train) / (p_steps / p_train):.2f}x | "
        f"{(k_steps / wall_k) / (p_steps / wall_p):.2f}x | {peak_k[1] / peak_p[1]:.2f} | "
        f"{peak_k[0] / peak_p[0]:.2f} |",
    ]
    return rows


def bench_against(baseline: Path, steps: int, repeats: int, work: Path) -> list[str]:
    """Rows of the whole-command table: the plain script, ``train`` of this checkout and of
    the ``baseline`` checkout (e.g. an older commit, unpacked with git archive), interleaved in
    rotating order ``repeats`` times, so that each ratio compares runs that saw the same load."""
    import statistics

    from bench_startup import environment

    script = work / "plain_sb3.py"
    script.write_text(PLAIN_SCRIPT)
    here = Path(__file__).resolve().parents[1]
    sides = {"plain": None, "this": here, "baseline": baseline}
    speeds: dict[str, list[float]] = {side: [] for side in sides}
    for repeat in range(repeats):
        order = list(sides)[repeat % 3:] + list(sides)[:repeat % 3]
        for side in order:
            if side == "plain":
                cmd, env = [sys.executable, str(script), str(steps)], None
            else:
                store = work / f"{side}{repeat}.db"
                cmd = kraby("train", "ppo=tuned", f"budget.steps={steps}", "save_models=false",
                            f"storage=sqlite:///{store}")
                env = environment(sides[side])  # type: ignore[arg-type]
            wall, _, _ = measure(cmd, work, env)
            speeds[side].append(steps / wall)
    rows = ["| repeat | plain SB3 | train, this checkout | train, baseline | this / plain | "
            "baseline / plain |", "|---:|---:|---:|---:|---:|---:|"]
    for i in range(repeats):
        plain = speeds["plain"][i]
        rows.append(f"| {i + 1} | {plain:,.0f} | {speeds['this'][i]:,.0f} | "
                    f"{speeds['baseline'][i]:,.0f} | {speeds['this'][i] / plain:.2f}x | "
                    f"{speeds['baseline'][i] / plain:.2f}x |")
    this = statistics.median(t / p for t, p in zip(speeds["this"], speeds["plain"], strict=True))
    base = statistics.median(b / p for b, p in zip(speeds["baseline"], speeds["plain"],
                                                    strict=True))
    rows.append(f"| median | | | | {this:.2f}x | {base:.2f}x |")
    return rows


def bench_workers(work: Path) -> list[str]:
    """Rows of the workers table on a small study (4 values x 2 seeds).

    One worker on one core (shards=1) against two workers is the scaling of the worker pool;
    one worker with the default shards shows what a lone worker gains from the core it would
    otherwise leave idle.
    """
    args = ["run", "study=clip_range", "budget.seeds=2", "budget.steps=16384",
            "budget.curve_every=1024", "save_models=false"]
    runs = {"1 worker, 1 core (shards=1)": ["workers=1", "shards=1"],
            "2 workers": ["workers=2"],
            "1 worker, 2 shards on both cores (default)": ["workers=1"]}
    times = {}
    for index, (label, extra) in enumerate(runs.items()):
        wall, _, _ = measure(kraby(*args, *extra, f"storage=sqlite:///w{index}.db"), work)
        times[label] = wall
    base = next(iter(times.values()))
    return [
        "| run | wall time (s), 8 trials x 16,384 steps | speed-up |",
        "|---|---:|---:|",
        *(f"| {label} | {wall:.1f} | {base / wall:.2f}x |" for label, wall in times.items()),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=32768)
    parser.add_argument("--skip-workers", action="store_true")
    parser.add_argument("--baseline", type=Path,
                        help="another checkout: whole-command env steps/s of its train, this "
                        "checkout's and the plain script's, interleaved (then nothing else)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"cores: {os.cpu_count()}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if args.baseline is not None:
            print("\n".join(bench_against(args.baseline.resolve(), args.steps, args.repeats,
                                           work)))
            return
        print("\n".join(bench_train(args.steps, work)))
        if not args.skip_workers:
            print()
            print("\n".join(bench_workers(work)))
    print("\ngoals: training speed >= 1.3x, memory <= 0.35; 2 workers >= 1.7x")


if __name__ == "__main__":
    main()
