"""Throughput and peak memory of the Kraby leg environments (a measurement, not a test).

Compares, each in a fresh spawned process so the memory peaks stay separate:

- one ``KrabyOneLeg-v0`` environment (``gym.make``);
- SB3's ``DummyVecEnv`` of ``n_envs`` such environments (one PyBullet client each);
- ``make_batched(n_envs)``: all legs in one PyBullet world.

Peak memory is ``ru_maxrss`` after the run; the increment subtracts a process that made
the same imports and nothing else. Usage::

    python benchmarks/bench_env.py [--steps 1000] [--n-envs 32] [--repeats 1]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import resource
import time
from collections.abc import Callable
from dataclasses import dataclass

CONFIGS = ("baseline", "single", "dummy_vec_env", "batched")


@dataclass(frozen=True)
class Measurement:
    """One configuration's result."""

    config: str
    n_envs: int
    steps_per_second: float
    steps_per_cpu_second: float
    peak_rss_mb: float


def _peak_rss_mb() -> float:
    # Linux reports ru_maxrss in kibibytes.
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _timed(step: Callable[[], None], steps: int, warmup: int = 10) -> tuple[float, float]:
    """Wall and CPU seconds of ``steps`` calls; CPU time is steadier on a shared machine."""
    for _ in range(warmup):
        step()
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        step()
    return time.perf_counter() - wall, time.process_time() - cpu


def _measure(config: str, steps: int, n_envs: int) -> Measurement:
    # Identical imports in every configuration, so the baseline subtracts them all.
    import gymnasium as gym
    import numpy as np
    from stable_baselines3.common.vec_env import DummyVecEnv

    import kraby_envs

    rng = np.random.default_rng(0)
    if config == "baseline":
        return Measurement(config, 0, 0.0, 0.0, _peak_rss_mb())
    if config == "single":
        env = gym.make(kraby_envs.ENV_ID)
        env.reset(seed=0)

        def step() -> None:
            _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 3).astype(np.float32))
            if terminated or truncated:
                env.reset()

        wall, cpu = _timed(step, steps)
        env.close()
        return Measurement(config, 1, steps / wall, steps / cpu, _peak_rss_mb())
    if config == "dummy_vec_env":
        venv = DummyVecEnv([lambda: gym.make(kraby_envs.ENV_ID) for _ in range(n_envs)])
        venv.seed(0)
    elif config == "batched":
        venv = kraby_envs.make_batched(n_envs=n_envs, seed=0)
    else:
        raise ValueError(f"config must be one of {CONFIGS}, got {config!r}")
    venv.reset()

    def vec_step() -> None:
        venv.step(rng.uniform(-1, 1, (n_envs, 3)).astype(np.float32))

    wall, cpu = _timed(vec_step, steps)
    venv.close()
    transitions = steps * n_envs
    return Measurement(config, n_envs, transitions / wall, transitions / cpu, _peak_rss_mb())


def run_isolated(config: str, steps: int, n_envs: int) -> Measurement:
    """Runs one configuration in a freshly spawned interpreter."""
    with mp.get_context("spawn").Pool(1) as pool:
        return pool.apply(_measure, (config, steps, n_envs))


def main() -> None:
    # One BLAS/OpenMP thread everywhere: helper threads would compete with the stepping
    # thread on small machines. Set before the children spawn, so they inherit it.
    for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(variable, "1")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="steps of each (vector) env")
    parser.add_argument("--n-envs", type=int, default=32, help="legs in the vectorised configs")
    parser.add_argument("--repeats", type=int, default=1,
                        help="runs per config; the run with the best CPU speed is kept")
    args = parser.parse_args()

    results: dict[str, Measurement] = {}
    for _ in range(args.repeats):
        for config in CONFIGS:
            measured = run_isolated(config, args.steps, args.n_envs)
            best = results.get(config)
            if best is None or measured.steps_per_cpu_second > best.steps_per_cpu_second:
                results[config] = measured
    baseline = results.pop("baseline").peak_rss_mb

    print(f"{args.steps} steps per env, {args.n_envs} legs in the vectorised configs, "
          f"baseline RSS (same imports) {baseline:.1f} MB\n")
    print("| configuration | envs | env steps/s | env steps/CPU-s | peak RSS (MB) "
          "| increment (MB) |")
    print("|---|---:|---:|---:|---:|---:|")
    for m in results.values():
        print(f"| {m.config} | {m.n_envs} | {m.steps_per_second:,.0f} "
              f"| {m.steps_per_cpu_second:,.0f} | {m.peak_rss_mb:.1f} "
              f"| {m.peak_rss_mb - baseline:.1f} |")
    dummy, batched = results["dummy_vec_env"], results["batched"]
    speed = batched.steps_per_second / dummy.steps_per_second
    cpu_speed = batched.steps_per_cpu_second / dummy.steps_per_cpu_second
    memory = (batched.peak_rss_mb - baseline) / max(dummy.peak_rss_mb - baseline, 1e-9)
    print(f"\nbatched vs DummyVecEnv: speed x{speed:.2f} wall, x{cpu_speed:.2f} CPU "
          f"(goal >= 1.3); memory increment x{memory:.3f} (goal <= 0.2)")


if __name__ == "__main__":
    main()
