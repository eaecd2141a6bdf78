"""Benchmark: a Pendulum-v1 trial against plain stable-baselines3 with the same settings.

Run: python benchmarks/bench_gym.py [--steps 20480] [--repeats 3]

Both sides train rl-zoo3's Pendulum-v1 settings (``ppo=zoo``: 4 envs x 1024 steps, batch 64,
10 epochs, gSDE every 4 steps, learning rate 1e-3), one torch thread, on the CPU. The plain
side is what a user writes without kraby-study: ``make_vec_env`` and ``PPO(...).learn()``,
with a callback that stops it where a trial stops (at the budget, inside the rollout that
reaches it, which is not learnt from), so both sides do the same updates.
The kraby side is the trial a worker runs (``run.trial.run_trial`` of the spec ``train``
plans: the env seam's stream-seeded DummyVecEnv, the episode recorder, CPU-time accounting,
the score). Each side runs in a fresh process, the two interleaved, ``--repeats`` times;
speeds are env steps per second from the env's construction to the end of learning, and the
ratio is taken within each repeat (so both sides see the same load), then its median.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys

PLAIN = r"""
import json, sys, time
import torch
torch.set_num_threads(1)
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env


class Stop(BaseCallback):
    # A trial stops at its budget inside the rollout that reaches it, which is not learnt from.
    def _on_step(self):
        return self.num_timesteps < steps


steps = int(sys.argv[1])
t0 = time.perf_counter()
env = make_vec_env("Pendulum-v1", n_envs=4, seed=0)
model = PPO("MlpPolicy", env, n_steps=1024, batch_size=64, n_epochs=10, gamma=0.9,
            gae_lambda=0.95, clip_range=0.2, ent_coef=0.0, vf_coef=0.5, max_grad_norm=0.5,
            learning_rate=1e-3, use_sde=True, sde_sample_freq=4, seed=0, device="cpu",
            verbose=0)
model.learn(total_timesteps=steps, callback=Stop())
print(json.dumps({"seconds": time.perf_counter() - t0, "steps": model.num_timesteps}))
"""

KRABY = r"""
import json, sys
import torch
torch.set_num_threads(1)
from kraby_study.config.compose import compose_config
from kraby_study.plan.train import train_plan
from kraby_study.run.trial import run_trial

steps = int(sys.argv[1])
cfg = compose_config(["env=gym", "env.id=Pendulum-v1", "ppo=zoo", f"budget.steps={steps}",
                      "save_models=false"])
result = run_trial(train_plan(cfg).specs[0])
print(json.dumps({"seconds": result.wall_time, "steps": result.env_steps}))
"""


def measure(script: str, steps: int) -> float:
    """Env steps per second of one side, in a fresh process."""
    done = subprocess.run([sys.executable, "-c", script, str(steps)], capture_output=True,
                          text=True, check=True)
    numbers = json.loads(done.stdout.strip().splitlines()[-1])
    return numbers["steps"] / numbers["seconds"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20480)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    rows, ratios = [], []
    for repeat in range(args.repeats):
        # Alternate which side goes first, so a drift in the machine's load favours neither.
        order = ("plain", "kraby") if repeat % 2 == 0 else ("kraby", "plain")
        speed = {side: measure(PLAIN if side == "plain" else KRABY, args.steps)
                 for side in order}
        ratios.append(speed["kraby"] / speed["plain"])
        rows.append(f"| {repeat + 1} | {speed['plain']:,.0f} | {speed['kraby']:,.0f} | "
                    f"{ratios[-1]:.3f} |")
    print("| repeat | plain SB3 steps/s | kraby-study trial steps/s | ratio |")
    print("|---:|---:|---:|---:|")
    print("\n".join(rows))
    print(f"\nmedian ratio {statistics.median(ratios):.3f} (goal: at least 0.95)")


if __name__ == "__main__":
    main()
