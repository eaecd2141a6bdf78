"""Benchmark: env steps spent and best score found, median pruner against no pruner.

Run: python benchmarks/bench_pruning.py [--trials 30] [--seeds 2] [--steps 20480]
     [--sampler tpe|random] [--keep DIR]

Both searches use the same space (conf/search/ppo.yaml), the same seeded sampler (TPE unless
--sampler random), the same budget (--seeds seeds of --steps env steps per trial; the default,
2 x 20,480, is the experience of one quick-budget seed split over two seeds) and the same
number of trials, each in its own temporary store. They run at the same time, one worker each
with one physics process, so each search is sequential: its suggestions do not depend on which
trial happens to finish first. The noise is the standard deviation of the objective (a mean
over --seeds seeds) over 5 such trials of one configuration (the tuned settings), so "best
score within noise" can be judged.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import optuna
from optuna.trial import TrialState


def start_search(url: str, name: str, pruner: str, sampler: str, trials: int, seeds: int,
                 steps: int, cwd: Path) -> subprocess.Popen[bytes]:
    """Start one search on one worker and one physics process."""
    return subprocess.Popen(
        [sys.executable, "-m", "kraby_study.cli", "optuna", "--trials", str(trials),
         "--workers", "1", "--storage", url, "--study-name", name, "--pruner", pruner,
         "--sampler", sampler, "--seed", "0", "budget=quick", f"budget.seeds={seeds}",
         f"budget.steps={steps}", "physics_processes=1", "save_models=false"],
        cwd=cwd, stdout=subprocess.DEVNULL)


def noise(url: str, seeds: int, steps: int, cwd: Path) -> float:
    """Standard deviation of the objective (a mean over ``seeds`` seeds) at the tuned settings,
    over 5 groups of ``seeds`` seeds."""
    subprocess.run([sys.executable, "-m", "kraby_study.cli", "run", "study=n_envs",
                    "study.values=[32]", "budget=quick", f"budget.seeds={5 * seeds}",
                    f"budget.steps={steps}", f"storage={url}", "save_models=false"],
                   cwd=cwd, check=True, stdout=subprocess.DEVNULL)
    study = optuna.load_study(study_name="n_envs", storage=url)
    scores = sorted((t.user_attrs["seed"], t.value) for t in study.trials if t.value is not None)
    values = np.array([v for _, v in scores])
    means = values[: len(values) // seeds * seeds].reshape(-1, seeds).mean(axis=1)
    return float(np.std(means, ddof=1))


def summarise(url: str, name: str) -> tuple[int, int, int, int, int, float]:
    """(trials, complete, pruned, failed, env steps, best score) of a search."""
    trials = optuna.load_study(study_name=name, storage=url).trials
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    return (len(trials), len(complete), sum(t.state == TrialState.PRUNED for t in trials),
            sum(t.state == TrialState.FAIL for t in trials),
            sum(int(t.user_attrs.get("env_steps", 0)) for t in trials),
            max(float(t.value) for t in complete))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--seeds", type=int, default=2, help="seeds per trial")
    parser.add_argument("--steps", type=int, default=20480, help="env steps per seed")
    parser.add_argument("--sampler", choices=["tpe", "random"], default="tpe")
    parser.add_argument("--keep", type=Path, default=None,
                        help="write the stores (none.db, median.db, noise.db) here and keep them")
    args = parser.parse_args()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        cwd = args.keep or Path(tmp)
        cwd.mkdir(parents=True, exist_ok=True)
        urls = {pruner: f"sqlite:///{cwd / pruner}.db" for pruner in ("none", "median")}
        searches = {pruner: start_search(url, f"bench_{pruner}", pruner, args.sampler,
                                         args.trials, args.seeds, args.steps, cwd)
                    for pruner, url in urls.items()}
        for pruner, proc in searches.items():
            if proc.wait() != 0:
                raise SystemExit(f"the {pruner} search failed ({proc.returncode})")
            rows[pruner] = summarise(urls[pruner], f"bench_{pruner}")
        sd = noise(f"sqlite:///{cwd / 'noise.db'}", args.seeds, args.steps, cwd)
    print(f"{args.trials} trials, {args.sampler} sampler seed 0, {args.seeds} seed(s) x "
          f"{args.steps:,} env steps per trial")
    print("| pruner | trials | complete | pruned | failed | env steps | best score |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for pruner, (n, complete, pruned, failed, steps, best) in rows.items():
        print(f"| {pruner} | {n} | {complete} | {pruned} | {failed} | {steps:,} | {best:.4f} |")
    steps_none, best_none = rows["none"][4:]
    steps_median, best_median = rows["median"][4:]
    print(f"env steps saved by the median pruner: {1 - steps_median / steps_none:.0%} "
          f"(goal >= 40 %)")
    print(f"best score difference: {best_median - best_none:+.4f}; noise (sd of the objective, "
          f"a mean over {args.seeds} seed(s) of {args.steps:,} steps, at the tuned settings, "
          f"5 samples): {sd:.4f}")


if __name__ == "__main__":
    main()
