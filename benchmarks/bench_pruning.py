"""Benchmark: env steps spent and best score found, median pruner against no pruner.

Run: python benchmarks/bench_pruning.py [--trials 30] [--seeds 2] [--steps 20480]
     [--sampler tpe|random] [--sampler-seeds 0 1 2] [--jobs 2] [--keep DIR]
     python benchmarks/bench_pruning.py --summarise DIR [--sampler-seeds ...] (stores kept in DIR)

For each sampler seed, two searches share everything but the pruner: the space
(conf/search/ppo.yaml), the seeded sampler (TPE unless --sampler random), the budget (--seeds
seeds of --steps env steps per trial; the default, 2 x 20,480, is the experience of one
quick-budget seed split over two seeds) and the number of trials. Each search has its own
temporary store and one worker with one physics process, so it is sequential: its suggestions
do not depend on which trial happens to finish first, and the run is reproducible. --jobs
searches run at a time.

Two kinds of noise judge "best score within noise": the standard deviation of the objective (a
mean over --seeds seeds) over 5 such trials of one configuration (the tuned settings), and the
spread over sampler seeds of the difference in best score between the two searches of a seed,
which is what the best score of a whole search varies by.

It also prints what a median rule that knew every trial's final score would have saved on the
unpruned search's trials: the most the median pruner can save there without stopping a trial that
would end above the median.
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
from optuna.trial import FrozenTrial, TrialState

PRUNERS = ("none", "median")


def search_command(url: str, name: str, pruner: str, sampler: str, sampler_seed: int,
                   trials: int, seeds: int, steps: int) -> list[str]:
    """One search on one worker and one physics process."""
    return [sys.executable, "-m", "kraby_study.cli", "optuna", "--trials", str(trials),
            "--workers", "1", "--storage", url, "--study-name", name, "--pruner", pruner,
            "--sampler", sampler, "--seed", str(sampler_seed), "budget=quick",
            f"budget.seeds={seeds}", f"budget.steps={steps}", "shards=1",
            "save_models=false"]


def run_all(commands: list[list[str]], jobs: int, cwd: Path) -> None:
    """Run the commands, ``jobs`` at a time; stop at the first that fails."""
    waiting = list(commands)
    running: list[subprocess.Popen[bytes]] = []
    while waiting or running:
        while waiting and len(running) < jobs:
            running.append(subprocess.Popen(waiting.pop(0), cwd=cwd,
                                            stdout=subprocess.DEVNULL))
        time.sleep(1.0)
        for proc in [p for p in running if p.poll() is not None]:
            running.remove(proc)
            if proc.returncode != 0:
                raise SystemExit(f"a search failed ({proc.returncode}): {' '.join(proc.args)}")


def noise_command(url: str, seeds: int, steps: int) -> list[str]:
    """5 x ``seeds`` seeds of the tuned settings, on one worker, for the noise of the objective."""
    return [sys.executable, "-m", "kraby_study.cli", "run", "study=n_envs", "study.values=[32]",
            "budget=quick", f"budget.seeds={5 * seeds}", f"budget.steps={steps}",
            f"storage={url}", "workers=1", "save_models=false"]


def noise(url: str, seeds: int) -> tuple[float, int] | None:
    """Standard deviation of the objective (a mean over ``seeds`` seeds) at the tuned settings,
    over the groups of ``seeds`` seeds finished (5 when the noise job ran to its end), and how
    many groups; None with fewer than 2 (a run stopped before or during its noise job)."""
    try:
        study = optuna.load_study(study_name="n_envs", storage=url)
    except KeyError:
        return None
    scores = sorted((t.user_attrs["seed"], t.value) for t in study.trials if t.value is not None)
    values = np.array([v for _, v in scores])
    if len(values) < 2 * seeds:
        return None
    means = values[: len(values) // seeds * seeds].reshape(-1, seeds).mean(axis=1)
    return float(np.std(means, ddof=1)), len(means)


def finished(url: str, name: str) -> list[FrozenTrial]:
    """A search's trials in order, up to the first that has not finished."""
    out: list[FrozenTrial] = []
    for trial in sorted(optuna.load_study(study_name=name, storage=url).trials,
                        key=lambda t: t.number):
        if trial.state not in (TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL):
            break
        out.append(trial)
    return out


def summarise(trials: list[FrozenTrial]) -> tuple[int, int, int, int, float]:
    """(complete, pruned, failed, env steps, best score) of a search's trials."""
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    return (len(complete), sum(t.state == TrialState.PRUNED for t in trials),
            sum(t.state == TrialState.FAIL for t in trials),
            sum(int(t.user_attrs.get("env_steps", 0)) for t in trials),
            max(float(t.value) for t in complete))


def first_prunable_step(seeds: int, steps: int) -> tuple[int, int]:
    """(first env step at which the searches' median pruner may stop a trial, complete trials
    it needs first), from the same config the searches composed."""
    from kraby_study.config.compose import compose_config
    from kraby_study.plan.space import checkpoint_every, warmup_steps

    cfg = compose_config(["budget=quick", f"budget.seeds={seeds}", f"budget.steps={steps}"])
    every = checkpoint_every(cfg)
    return -(-warmup_steps(cfg) // every) * every, int(cfg.search.pruner_startup_trials)


def flawless_median(trials: list[FrozenTrial], first_step: int, startup: int) -> tuple[int, int]:
    """(env steps, trials stopped) of the unpruned search's trials under a median rule that knows
    each trial's final score: after ``startup`` complete trials, a trial that would end below the
    median of the trials kept so far is stopped at ``first_step``; every other trial, and every
    failed one, spends what it spent. What the median pruner could save on these trials without
    ever stopping one that would end above the median (taking TPE's choices as they were, though
    pruning changes them)."""
    kept: list[float] = []
    spent = stopped = 0
    for trial in trials:
        steps = int(trial.user_attrs.get("env_steps", 0))
        if trial.state != TrialState.COMPLETE:
            spent += steps
        elif len(kept) >= startup and float(trial.value) < float(np.median(kept)):
            spent += min(first_step, steps)
            stopped += 1
        else:
            spent += steps
            kept.append(float(trial.value))
    return spent, stopped


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--seeds", type=int, default=2, help="seeds per trial")
    parser.add_argument("--steps", type=int, default=20480, help="env steps per seed")
    parser.add_argument("--sampler", choices=["tpe", "random"], default="tpe")
    parser.add_argument("--sampler-seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--jobs", type=int, default=2, help="searches at a time")
    parser.add_argument("--keep", type=Path, default=None,
                        help="write the stores here and keep them")
    parser.add_argument("--summarise", type=Path, default=None, metavar="DIR",
                        help="run nothing: compare the stores kept in DIR (by --keep) on the "
                             "trials both searches of a seed have finished")
    args = parser.parse_args()
    if args.summarise is not None and not args.summarise.is_dir():
        parser.error(f"--summarise: no directory {args.summarise}")
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        cwd = args.summarise or args.keep or Path(tmp)
        cwd.mkdir(parents=True, exist_ok=True)
        stores = {(seed, pruner): (f"sqlite:///{cwd / f'{pruner}_{seed}'}.db",
                                   f"bench_{pruner}_{seed}")
                  for seed in args.sampler_seeds for pruner in PRUNERS}
        noise_url = f"sqlite:///{cwd / 'noise.db'}"
        if args.summarise is None:
            # The slower, unpruned searches first, so the last ones to finish are short.
            order = sorted(stores, key=lambda k: (k[1] != "none", k[0]))
            run_all([*(search_command(*stores[k], k[1], args.sampler, k[0], args.trials,
                                      args.seeds, args.steps) for k in order),
                     noise_command(noise_url, args.seeds, args.steps)], args.jobs, cwd)
        done = {k: finished(*stores[k]) for k in stores}
        compared = {seed: min(len(done[seed, p]) for p in PRUNERS) for seed in args.sampler_seeds}
        rows = {k: summarise(done[k][:compared[k[0]]]) for k in stores}
        sd = noise(noise_url, args.seeds) if (cwd / "noise.db").exists() else None
    if any(n < args.trials for n in compared.values()):
        print("compared on the trials both searches finished: "
              + ", ".join(f"seed {s}: {n}" for s, n in compared.items()))
    print(f"{args.trials} trials per search, {args.sampler} sampler, {args.seeds} seed(s) x "
          f"{args.steps:,} env steps per trial")
    print("| sampler seed | pruner | complete | pruned | failed | env steps | best score |")
    print("|---:|---|---:|---:|---:|---:|---:|")
    for seed in args.sampler_seeds:
        for pruner in PRUNERS:
            complete, pruned, failed, steps, best = rows[seed, pruner]
            print(f"| {seed} | {pruner} | {complete} | {pruned} | {failed} | {steps:,} | "
                  f"{best:.4f} |")
    saved = [1 - rows[s, "median"][3] / rows[s, "none"][3] for s in args.sampler_seeds]
    total = 1 - (sum(rows[s, "median"][3] for s in args.sampler_seeds)
                 / sum(rows[s, "none"][3] for s in args.sampler_seeds))
    diffs = np.array([rows[s, "median"][4] - rows[s, "none"][4] for s in args.sampler_seeds])
    print(f"env steps saved by the median pruner: {total:.0%} over all seeds "
          f"({', '.join(f'{x:.0%}' for x in saved)}; goal >= 40 %)")
    spread = f", sd {np.std(diffs, ddof=1):.4f}" if len(diffs) > 1 else ""
    print(f"best score, median minus none: mean {diffs.mean():+.4f} "
          f"({', '.join(f'{d:+.4f}' for d in diffs)}{spread})")
    first_step, startup = first_prunable_step(args.seeds, args.steps)
    bounds = {s: flawless_median(done[s, "none"][:compared[s]], first_step, startup)
              for s in args.sampler_seeds}
    print(f"a median rule that knew every final score (stopping at {first_step:,} env steps "
          f"after {startup} complete trials) would have saved: "
          + ", ".join(f"seed {s}: {1 - spent / rows[s, 'none'][3]:.0%} ({n} stopped)"
                      for s, (spent, n) in bounds.items()))
    if sd is not None:
        print(f"noise of the objective (sd, a mean over {args.seeds} seed(s) of {args.steps:,} "
              f"steps, at the tuned settings, {sd[1]} samples): {sd[0]:.4f}")


if __name__ == "__main__":
    main()
