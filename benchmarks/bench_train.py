"""Benchmark: `kraby-study train` against a plain SB3 script, and 1 against 2 workers.

Run: python benchmarks/bench_train.py [--steps 32768] [--skip-workers]

Both trainings use the tuned settings (n_steps 32 x 32 legs, batch 1024, 30 epochs). The plain
script is what a user would write without kraby-study: PPO on a DummyVecEnv of 32 single
environments (one PyBullet client each) wrapped in VecMonitor. Each side runs as its own process
tree; peak memory is the largest sum of RSS over the tree, sampled every 50 ms. Speeds are env
steps per second of training (model construction to the end of learn) and of the whole command.
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


def measure(cmd: list[str], cwd: Path) -> tuple[float, float, str]:
    """(wall seconds, peak tree RSS in MB, stdout) of a command."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    peak = 0.0
    while proc.poll() is None:
        peak = max(peak, _rss_mb(_tree(proc.pid)))
        time.sleep(0.05)
    out = proc.stdout.read() if proc.stdout else ""
    if proc.returncode != 0:
        raise SystemExit(f"command failed ({proc.returncode}): {' '.join(cmd)}\n{out}")
    return time.perf_counter() - t0, peak, out


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
        "| run | env steps | training steps/s | command steps/s | peak memory (MB) |",
        "|---|---:|---:|---:|---:|",
        f"| plain SB3, DummyVecEnv x 32 | {p_steps} | {p_steps / p_train:,.0f} | "
        f"{p_steps / wall_p:,.0f} | {peak_p:,.0f} |",
        f"| kraby-study train ppo=tuned | {k_steps} | {k_steps / k_train:,.0f} | "
        f"{k_steps / wall_k:,.0f} | {peak_k:,.0f} |",
        f"| ratio kraby / plain | | {(k_steps / k_train) / (p_steps / p_train):.2f}x | "
        f"{(k_steps / wall_k) / (p_steps / wall_p):.2f}x | {peak_k / peak_p:.2f} |",
    ]
    return rows


def bench_workers(work: Path) -> list[str]:
    """Rows of the 1-vs-2-workers table on a small study (4 values x 2 seeds)."""
    args = ["run", "study=clip_range", "budget.seeds=2", "budget.steps=16384",
            "budget.curve_every=1024", "save_models=false"]
    times = {}
    for workers in (1, 2):
        wall, _, _ = measure(kraby(*args, f"workers={workers}",
                                   f"storage=sqlite:///w{workers}.db"), work)
        times[workers] = wall
    return [
        "| workers | wall time (s), 8 trials x 16,384 steps | speed-up |",
        "|---:|---:|---:|",
        f"| 1 | {times[1]:.1f} | 1.00x |",
        f"| 2 | {times[2]:.1f} | {times[1] / times[2]:.2f}x |",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=32768)
    parser.add_argument("--skip-workers", action="store_true")
    args = parser.parse_args()
    print(f"cores: {os.cpu_count()}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        print("\n".join(bench_train(args.steps, work)))
        if not args.skip_workers:
            print()
            print("\n".join(bench_workers(work)))
    print("\ngoals: training speed >= 1.3x, memory <= 0.35; 2 workers >= 1.7x")


if __name__ == "__main__":
    main()
