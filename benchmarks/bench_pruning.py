"""Benchmark: env steps spent and best score found, median pruner against no pruner.

Run: python benchmarks/bench_pruning.py [--trials 30] [--seeds 1] [--steps 40960] [--workers 2]

Both searches use the same space (conf/search/ppo.yaml), the same seeded TPE sampler, the same
budget (--seeds seeds of --steps env steps per trial; the default is the quick budget's 40,960
steps, one seed) and the same number of trials, in one temporary store. The noise
of the score is the standard deviation over seeds of one configuration (the tuned settings), so
"best score within noise" can be judged.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import optuna
from optuna.trial import TrialState


def search(url: str, name: str, pruner: str, trials: int, seeds: int, steps: int,
           workers: int, cwd: Path) -> float:
    """Run one search; returns its wall time."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "kraby_study.cli", "optuna", "--trials", str(trials),
                    "--workers", str(workers), "--storage", url, "--study-name", name,
                    "--pruner", pruner, "--seed", "0", "budget=quick",
                    f"budget.seeds={seeds}", f"budget.steps={steps}", "save_models=false"],
                   cwd=cwd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def noise(url: str, seeds: int, steps: int, workers: int, cwd: Path) -> float:
    """Standard deviation of the final score over seeds at the tuned settings."""
    subprocess.run([sys.executable, "-m", "kraby_study.cli", "run", "study=n_envs",
                    "study.values=[32]", f"budget.seeds={seeds}", "budget=quick",
                    f"budget.steps={steps}",
                    f"workers={workers}", f"storage={url}", "save_models=false"],
                   cwd=cwd, check=True, stdout=subprocess.DEVNULL)
    study = optuna.load_study(study_name="n_envs", storage=url)
    return float(np.std([t.value for t in study.trials if t.value is not None], ddof=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--seeds", type=int, default=1, help="seeds per trial")
    parser.add_argument("--steps", type=int, default=40960, help="env steps per seed")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cwd = Path(tmp)
        url = f"sqlite:///{cwd / 'bench.db'}"
        for pruner in ("none", "median"):
            wall = search(url, f"bench_{pruner}", pruner, args.trials, args.seeds,
                          args.steps, args.workers, cwd)
            trials = optuna.load_study(study_name=f"bench_{pruner}", storage=url).trials
            steps = sum(int(t.user_attrs.get("env_steps", 0)) for t in trials)
            complete = [t for t in trials if t.state == TrialState.COMPLETE]
            pruned = sum(t.state == TrialState.PRUNED for t in trials)
            failed = sum(t.state == TrialState.FAIL for t in trials)
            best = max(float(t.value) for t in complete)
            rows.append((pruner, len(trials), len(complete), pruned, failed, steps, best, wall))
        sd = noise(url, 5, args.steps * args.seeds, args.workers, cwd)
    print(f"{args.trials} trials, TPE seed 0, {args.seeds} seed(s) x {args.steps:,} env steps "
          "per trial")
    print("| pruner | trials | complete | pruned | failed | env steps | best score | wall (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for pruner, n, complete, pruned, failed, steps, best, wall in rows:
        print(f"| {pruner} | {n} | {complete} | {pruned} | {failed} | {steps:,} | {best:.4f} | "
              f"{wall:.0f} |")
    (_, *_, steps_none, best_none, _), (_, *_, steps_median, best_median, _) = rows
    print(f"env steps saved by the median pruner: {1 - steps_median / steps_none:.0%} "
          f"(goal >= 40 %)")
    print(f"best score difference: {best_median - best_none:+.4f}; seed noise (sd of the final "
          f"score over 5 seeds at the tuned settings, {args.steps * args.seeds:,} steps): "
          f"{sd:.4f}")


if __name__ == "__main__":
    main()
