"""Benchmark: env steps spent and best score found, median and wilcoxon pruners against none.

Run: python benchmarks/bench_pruning.py [--trials 30] [--seeds 2] [--steps 20480]
     [--sampler tpe|random] [--sampler-seeds 0 1 2] [--pruners median wilcoxon] [--wilcoxon-p P]
     [--jobs 2] [--keep DIR] [--no-noise]
     python benchmarks/bench_pruning.py --summarise DIR [--sampler-seeds ...] (stores kept in DIR)
     python benchmarks/bench_pruning.py --rule [--rule-seeds 3 5 10] [--wilcoxon-p P]

For each sampler seed, searches share everything but the pruner: the space
(conf/search/ppo.yaml), the seeded sampler (TPE unless --sampler random), the budget (--seeds
seeds of --steps env steps per trial; the default, 2 x 20,480, is the experience of one
quick-budget seed split over two seeds) and the number of trials. One search has no pruner, one
search runs per --pruners entry (median: env-step checkpoints in the first seed; wilcoxon: each
seed's score against the best trial's same seeds, which needs --seeds 5 or more at its default
threshold). Each search has its own temporary store and one worker with one physics process, so
it is sequential: its suggestions do not depend on which trial happens to finish first, and the
run is reproducible. --jobs searches run at a time.

Two kinds of noise judge "best score within noise": the standard deviation of the objective (a
mean over --seeds seeds) over 5 such trials of one configuration (the tuned settings; skipped
with --no-noise), and the spread over sampler seeds of the difference in best score between a
pruned search and the unpruned one.

On the unpruned search's trials, taken as they came (pruning changes what TPE samples next, so
these are not the pruned searches' own numbers), it also prints
- what a median rule that knew every trial's final score would have saved: the most the median
  pruner can save there without stopping a trial that would end above the median;
- what the wilcoxon pruner itself (Optuna's, same threshold and startup) would have saved: each
  trial's seed scores are read back from the running means it reported after each seed.

--rule trains nothing: on simulated scores (each seed normal with sd 1, the trial's mean some sds
above or below the best trial's) it prints how often the wilcoxon pruner stops a trial and the
share of its env steps that saves, for each number of seeds per trial.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import optuna
from optuna.study import StudyDirection
from optuna.trial import FrozenTrial, TrialState, create_trial

PRUNED = ("median", "wilcoxon")


def search_command(url: str, name: str, pruner: str, sampler: str, sampler_seed: int,
                   trials: int, seeds: int, steps: int, extra: list[str]) -> list[str]:
    """One search on one worker and one physics process."""
    return [sys.executable, "-m", "kraby_study.cli", "optuna", "--trials", str(trials),
            "--workers", "1", "--storage", url, "--study-name", name, "--pruner", pruner,
            "--sampler", sampler, "--seed", str(sampler_seed), "budget=quick",
            f"budget.seeds={seeds}", f"budget.steps={steps}", "shards=1",
            "save_models=false", *extra]


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


def wilcoxon_config(seeds: int, steps: int, p: float | None) -> object:
    """The config a wilcoxon search of this budget composes (its pruner, its threshold)."""
    from kraby_study.config.compose import compose_config

    return compose_config(["budget=quick", f"budget.seeds={seeds}", f"budget.steps={steps}",
                           "search.pruner=wilcoxon", *wilcoxon_overrides(p)])


def wilcoxon_overrides(p: float | None) -> list[str]:
    return [] if p is None else [f"search.wilcoxon_p={p}"]


def seed_scores(trial: FrozenTrial, seeds: int, steps: int) -> list[float] | None:
    """A complete trial's seed scores, read back from the running means an unpruned (median-style)
    search reports after each seed but the last, and its value, the mean of all: seed k scored
    k m_k - (k - 1) m_(k-1). None when a mean is missing."""
    means = [trial.intermediate_values.get(k * steps) for k in range(1, seeds)]
    if any(m is None for m in means) or trial.value is None:
        return None
    running = [float(m) for m in means if m is not None] + [float(trial.value)]
    return [running[0]] + [(k + 1) * running[k] - k * running[k - 1] for k in range(1, seeds)]


def _seed_values(scores: list[float]) -> dict[int, float]:
    """Seed scores as the wilcoxon search reports them, one step per seed."""
    return {k + 1: score for k, score in enumerate(scores)}


def replayed_wilcoxon(trials: list[FrozenTrial], seeds: int, steps: int,
                      pruner: optuna.pruners.BasePruner) -> tuple[int, list[FrozenTrial]]:
    """(env steps, trials stopped) of the unpruned search's trials, in order, had the wilcoxon
    pruner judged each one's seeds as they ended: a stopped trial spends its seeds up to the
    stop, every other trial what it spent."""
    study = optuna.create_study(direction="maximize")
    spent = 0
    stopped: list[FrozenTrial] = []
    for trial in trials:
        used = int(trial.user_attrs.get("env_steps", 0))
        scores = seed_scores(trial, seeds, steps) if trial.state == TrialState.COMPLETE else None
        if scores is None:
            spent += used
            continue
        cut = next((k for k in range(2, seeds) if pruner.prune(study, create_trial(
            state=TrialState.PRUNED, intermediate_values=_seed_values(scores[:k])))), None)
        if cut is None:
            spent += used
            study.add_trial(create_trial(value=float(np.mean(scores)),
                                         intermediate_values=_seed_values(scores)))
        else:
            spent += round(used * cut / seeds)
            stopped.append(trial)
            study.add_trial(create_trial(state=TrialState.PRUNED,
                                         intermediate_values=_seed_values(scores[:cut])))
    return spent, stopped


def rule(seeds_list: list[int], p: float | None, samples: int) -> None:
    """How often the wilcoxon pruner stops a trial, and the env steps that saves, on simulated
    seed scores (sd 1), the trial's mean this many sds above (+) or below (-) a best trial's."""
    from kraby_study.run.sampling import make_pruner

    shifts = (1.0, 0.5, 0.0, -0.5, -1.0, -2.0, -5.0)
    rng = np.random.default_rng(0)
    print(f"wilcoxon pruner on simulated seed scores (sd 1), {samples} trials per cell: "
          "share stopped / share of env steps saved")
    print("| seeds | threshold | first stop after | "
          + " | ".join(f"{s:+g} sd" if s else "0" for s in shifts) + " |")
    print("|---:|---:|---:|" + "---:|" * len(shifts))
    for seeds in seeds_list:
        cfg = wilcoxon_config(seeds, 1000, p)
        pruner = make_pruner(cfg)
        first = pruner._n_startup_steps  # type: ignore[attr-defined]
        cells = []
        for shift in shifts:
            stops, saved = 0, 0.0
            for _ in range(samples):
                best = rng.normal(0.0, 1.0, seeds)
                trial = rng.normal(shift, 1.0, seeds)
                study = SimpleNamespace(direction=StudyDirection.MAXIMIZE, best_trial=create_trial(
                    value=float(best.mean()), intermediate_values=_seed_values(list(best))))
                cut = next((k for k in range(2, seeds) if pruner.prune(
                    study, create_trial(state=TrialState.PRUNED,  # type: ignore[arg-type]
                                        intermediate_values=_seed_values(list(trial[:k]))))),
                           None)
                if cut is not None:
                    stops += 1
                    saved += (seeds - cut) / seeds
            cells.append(f"{stops / samples:.0%} / {saved / samples:.0%}")
        reach = f"seed {first}" if first < seeds else "never"
        print(f"| {seeds} | {cfg.search.wilcoxon_p:g} | {reach} | " + " | ".join(cells) + " |")
    print("columns: the trial's mean minus the best trial's, in seed sds (+: the trial is "
          "better); the best trial is one fixed draw here, not the best of many, which would "
          "make stops of good trials likelier")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=30)
    parser.add_argument("--seeds", type=int, default=2, help="seeds per trial")
    parser.add_argument("--steps", type=int, default=20480, help="env steps per seed")
    parser.add_argument("--sampler", choices=["tpe", "random"], default="tpe")
    parser.add_argument("--sampler-seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--pruners", nargs="+", choices=PRUNED, default=["median"],
                        help="pruned searches beside the unpruned one (default median)")
    parser.add_argument("--wilcoxon-p", type=float, default=None,
                        help="search.wilcoxon_p of the wilcoxon search (default: the config's)")
    parser.add_argument("--jobs", type=int, default=2, help="searches at a time")
    parser.add_argument("--keep", type=Path, default=None,
                        help="write the stores here and keep them")
    parser.add_argument("--no-noise", action="store_true",
                        help="skip the 5 x --seeds runs of the tuned settings (the noise)")
    parser.add_argument("--summarise", type=Path, default=None, metavar="DIR",
                        help="run nothing: compare the stores kept in DIR (by --keep) on the "
                             "trials every search of a seed has finished")
    parser.add_argument("--rule", action="store_true",
                        help="train nothing: the wilcoxon pruner on simulated seed scores")
    parser.add_argument("--rule-seeds", type=int, nargs="+", default=[3, 5, 10])
    parser.add_argument("--rule-samples", type=int, default=1000)
    args = parser.parse_args()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    if args.rule:
        rule(args.rule_seeds, args.wilcoxon_p, args.rule_samples)
        return
    if args.summarise is not None and not args.summarise.is_dir():
        parser.error(f"--summarise: no directory {args.summarise}")
    pruners = ["none", *dict.fromkeys(args.pruners)]
    if "wilcoxon" in pruners:
        from kraby_study.errors import ConfigError
        from kraby_study.plan.space import validate_search

        try:
            validate_search(wilcoxon_config(args.seeds, args.steps, args.wilcoxon_p))
        except ConfigError as err:
            parser.error(str(err))
    extra = {p: wilcoxon_overrides(args.wilcoxon_p) if p == "wilcoxon" else [] for p in pruners}
    with tempfile.TemporaryDirectory() as tmp:
        cwd = args.summarise or args.keep or Path(tmp)
        cwd.mkdir(parents=True, exist_ok=True)
        stores = {(seed, pruner): (f"sqlite:///{cwd / f'{pruner}_{seed}'}.db",
                                   f"bench_{pruner}_{seed}")
                  for seed in args.sampler_seeds for pruner in pruners}
        noise_url = f"sqlite:///{cwd / 'noise.db'}"
        if args.summarise is None:
            # The slower, unpruned searches first, so the last ones to finish are short.
            order = sorted(stores, key=lambda k: (k[1] != "none", k[0]))
            noise_job = [] if args.no_noise else [noise_command(noise_url, args.seeds,
                                                                args.steps)]
            run_all([*(search_command(*stores[k], k[1], args.sampler, k[0], args.trials,
                                      args.seeds, args.steps, extra[k[1]]) for k in order),
                     *noise_job], args.jobs, cwd)
        done = {k: finished(*stores[k]) for k in stores}
        compared = {seed: min(len(done[seed, p]) for p in pruners) for seed in args.sampler_seeds}
        rows = {k: summarise(done[k][:compared[k[0]]]) for k in stores}
        sd = noise(noise_url, args.seeds) if (cwd / "noise.db").exists() else None
    if any(n < args.trials for n in compared.values()):
        print("compared on the trials every search finished: "
              + ", ".join(f"seed {s}: {n}" for s, n in compared.items()))
    print(f"{args.trials} trials per search, {args.sampler} sampler, {args.seeds} seed(s) x "
          f"{args.steps:,} env steps per trial")
    print("| sampler seed | pruner | complete | pruned | failed | env steps | saved | best score |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    for seed in args.sampler_seeds:
        for pruner in pruners:
            complete, pruned, failed, steps, best = rows[seed, pruner]
            saved = "" if pruner == "none" else f"{1 - steps / rows[seed, 'none'][3]:.0%}"
            print(f"| {seed} | {pruner} | {complete} | {pruned} | {failed} | {steps:,} | "
                  f"{saved} | {best:.4f} |")
    for pruner in pruners[1:]:
        saved = [1 - rows[s, pruner][3] / rows[s, "none"][3] for s in args.sampler_seeds]
        total = 1 - (sum(rows[s, pruner][3] for s in args.sampler_seeds)
                     / sum(rows[s, "none"][3] for s in args.sampler_seeds))
        diffs = np.array([rows[s, pruner][4] - rows[s, "none"][4] for s in args.sampler_seeds])
        print(f"env steps saved by the {pruner} pruner: {total:.0%} over all seeds "
              f"({', '.join(f'{x:.0%}' for x in saved)}; goal >= 40 %)")
        spread = f", sd {np.std(diffs, ddof=1):.4f}" if len(diffs) > 1 else ""
        print(f"best score, {pruner} minus none: mean {diffs.mean():+.4f} "
              f"({', '.join(f'{d:+.4f}' for d in diffs)}{spread})")
    unpruned = {s: done[s, "none"][:compared[s]] for s in args.sampler_seeds}
    first_step, startup = first_prunable_step(args.seeds, args.steps)
    bounds = {s: flawless_median(unpruned[s], first_step, startup) for s in args.sampler_seeds}
    print(f"a median rule that knew every final score (stopping at {first_step:,} env steps "
          f"after {startup} complete trials) would have saved: "
          + ", ".join(f"seed {s}: {1 - spent / rows[s, 'none'][3]:.0%} ({n} stopped)"
                      for s, (spent, n) in bounds.items()))
    if args.seeds > 2:
        from kraby_study.run.sampling import make_pruner

        cfg = wilcoxon_config(args.seeds, args.steps, args.wilcoxon_p)
        parts = []
        for s in args.sampler_seeds:
            spent, stopped = replayed_wilcoxon(unpruned[s], args.seeds, args.steps,
                                               make_pruner(cfg))
            values = [float(t.value) for t in stopped]
            top = f", the best of them ended at {max(values):.4f}" if values else ""
            parts.append(f"seed {s}: {1 - spent / rows[s, 'none'][3]:.0%} ({len(stopped)} "
                         f"stopped{top}; the search's best {rows[s, 'none'][4]:.4f})")
        print(f"the wilcoxon pruner (p < {cfg.search.wilcoxon_p:g}) replayed on the unpruned "
              f"search's trials would have saved: " + ", ".join(parts))
    if sd is not None:
        print(f"noise of the objective (sd, a mean over {args.seeds} seed(s) of {args.steps:,} "
              f"steps, at the tuned settings, {sd[1]} samples): {sd[0]:.4f}")


if __name__ == "__main__":
    main()
