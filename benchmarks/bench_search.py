"""Benchmark: the default search against random search at equal CPU cost, on one Gymnasium env.

Run: python benchmarks/bench_search.py --env-id Pendulum-v1 --cpu-budget 1800
         [--sampler-seeds 0 1 2] [--confirm-seeds 5] [--storage URL] [--workers 2]
         [--samplers tpe random] [--tag NAME] [--enqueue [NAME ...]] [--no-zoo] [--cost]
         [--dry-run] [KEY=VALUE ...] [--arm-overrides ARM:KEY=VALUE ...]

For each sampler seed and each sampler, one search (``kraby-study optuna``, evaluation
objective, rl-zoo3's settings for the env as the fixed ones, ``budget=zoo``) runs until it has
used ``--cpu-budget`` CPU seconds (``search.cpu_budget``: no trial starts once the ended trials
and the running ones so far have used it; the running ones finish, so each search overshoots).
Both searches evaluate rl-zoo3's settings first, as the default search does when it trains with them
(``search.enqueue`` null: the command's ppo config), then sample; ``--enqueue NAME ...`` names
other ppo configs, and ``--enqueue`` alone none (a cold start). The search's pick (its best
complete trial; of equal scores the one on more seeds, then the cheaper) is then
retrained by ``kraby-study confirm --top 1`` on ``--confirm-seeds`` fresh seeds, each scored
on its own evaluation episodes, and rl-zoo3's settings are confirmed once on the same fresh
seeds, for reference.

With ``--cost`` each search has two objectives, the evaluation return and CPU seconds per seed
(``--objective evaluation,training_time --floor none``: unpruned, a front), and its pick is what
``confirm --top 1`` takes from the front: the best score, the cheapest among equal scores. The
comparison then also pairs the picks' CPU seconds per run in the confirm.

After the table, one line per search says what its sampler chose after the random start
(the first ``search.startup_trials`` trials, the same for TPE as for random search of the same
seed; for the GP sampler, the trials it modelled): how many trials, how many pruned, and how
many distinct settings of the space's categorical parameters, which shows a sampler drawing
the same few again.

Two searches are compared by what their picks do on the fresh seeds, not by the search's own
best score (the maximum of noisy scores, which overstates its pick: the table shows both). One
sampler seed says little about a sampler, so the comparison is over several: per sampler seed,
the difference of the two picks' confirmed means (paired: same seed of the sampler, same fresh
seeds, same budget), then their mean with a 95 % Student-t interval over the sampler seeds and
an exact one-sided Wilcoxon signed-rank p (scipy) that the default does worse, where there are
at least 2 sampler seeds. Extra ``KEY=VALUE`` overrides go to every command (e.g.
``budget.seeds=2``).

An arm is a sampler's name (``--sampler NAME``: tpe, random, gp, ...) or a racing search
(``--racing``, docs/guide/studies.md "Racing search"): ``racing`` with multivariate TPE,
``racing-random`` and ``racing-gp`` with those samplers. A racing arm's pick is its
incumbent, on all its seeds, which ``confirm --top 1`` retrains; its row gives the
configurations asked and the runs ended in place of the trials, the incumbent's seeds
beside its key, and the IQM over them as its search score. ``--arm-overrides
ARM:KEY=VALUE ...`` go to one arm's commands only (its search and its confirm), after the
common ones, and replace a common override of the same key: a racing arm races on more seeds
(``racing:budget.seeds=8``, its cap) than the other arm's trials get (``budget.seeds=2``).
``--dry-run`` asks each search for its plan (``kraby-study optuna --dry-run``) and stops.

A rerun of the same command continues: each search is the stored one of its name (a search
that has used its budget runs nothing more), and each confirm the stored confirm.

The last line reads ``bench_search: <default> - <other> confirmed mean difference D (95 % t CI
[lo, hi], S sampler seeds); CPU <default> C1 s, <other> C2 s``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import subprocess
import sys
from dataclasses import dataclass

import optuna
from scipy import stats

from kraby_study.answers.racing_search import racing_search
from kraby_study.answers.search_front import search_front
from kraby_study.decision.front import spread
from kraby_study.records.stored import counted, known_number, search_key, spent_cpu
from kraby_study.records.values import best_trial

optuna.logging.set_verbosity(optuna.logging.WARNING)


RACING = "racing"
"""The arm name of a racing search; ``racing-NAME`` races with sampler NAME."""


def sampler_flags(arm: str) -> list[str]:
    """The search's flags for an arm: ``racing`` a racing search with multivariate TPE,
    ``racing-NAME`` one with sampler NAME, any other name that sampler's search."""
    if arm == RACING:
        return ["--racing", "--sampler", "tpe"]
    if arm.startswith(f"{RACING}-"):
        return ["--racing", "--sampler", arm.removeprefix(f"{RACING}-")]
    return ["--sampler", arm]


def override_key(override: str) -> str:
    """The key a Hydra ``KEY=VALUE`` override sets."""
    return override.split("=", 1)[0].lstrip("+~")


def arm_overrides(items: list[str], arms: list[str]) -> dict[str, list[str]]:
    """``ARM:KEY=VALUE`` items by arm; a ValueError names the first item that is not one of
    an arm in ``arms``."""
    found: dict[str, list[str]] = {arm: [] for arm in arms}
    for item in items:
        arm, colon, override = item.partition(":")
        if not colon or "=" in arm or "=" not in override:
            raise ValueError(f"--arm-overrides takes ARM:KEY=VALUE, not {item!r} (give the "
                             "overrides of every arm before --arm-overrides)")
        if arm not in found:
            raise ValueError(f"--arm-overrides names arm {arm!r}, not one of --samplers "
                             f"{' '.join(arms)}")
        found[arm].append(override)
    return found


def with_own(common: list[str], own: list[str]) -> list[str]:
    """The common overrides, less those whose key an arm's own set, then the arm's own."""
    keys = {override_key(o) for o in own}
    return [o for o in common if override_key(o) not in keys] + own


@dataclass
class Arm:
    """One search and its confirmed pick."""

    sampler: str
    """The arm's name: a sampler, or ``racing``, ``racing-NAME`` for a racing search."""
    seed: int
    study: str
    overrides: list[str] | None = None
    """Its search's and confirm's Hydra overrides (common and its own)."""
    trials: str = ""
    cpu: float = math.nan
    pick: str = ""
    search_score: float = math.nan
    after_start: str = ""
    confirmed: list[float] | None = None
    confirm_cpu: float = math.nan

    @property
    def mean(self) -> float:
        return statistics.fmean(self.confirmed) if self.confirmed else math.nan

    @property
    def racing(self) -> bool:
        """Whether it is a racing search."""
        return sampler_flags(self.sampler)[0] == "--racing"


def kraby(*args: str, plan: bool = False) -> None:
    """Run one kraby-study command; stop the benchmark if it fails. Its last 3 lines are
    printed, or with ``plan`` (a dry run) its plan, from the line that begins it."""
    command = [sys.executable, "-m", "kraby_study.cli", *args]
    print("$ kraby-study " + " ".join(args), flush=True)
    done = subprocess.run(command, text=True, capture_output=True)
    if done.returncode != 0:
        sys.exit(f"bench_search: a command failed ({done.returncode}):\n{done.stdout}"
                 f"{done.stderr}")
    lines = done.stdout.strip().splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith("plan")), -3)
    for line in lines[start if plan else -3:]:
        print("  " + line)


def read_racing(study: optuna.Study, arm: Arm) -> None:
    """A racing search's configurations asked, runs ended, CPU seconds used and pick (its
    incumbent, with its seeds and their IQM), replayed from the store as ``confirm`` reads
    it."""
    every = [t for t in study.trials if t.state != optuna.trial.TrialState.WAITING]
    found = racing_search(study.user_attrs["kraby_definition"], study.trials)
    incumbent = found.incumbent if found is not None else None
    if found is None or incumbent is None:
        sys.exit(f"bench_search: {arm.study} has no incumbent to confirm")
    runs = sum(c.seeds for c in found.configurations)
    arm.trials = f"{len(found.configurations)} configurations, {runs} runs"
    arm.cpu = spent_cpu(every)
    arm.pick = f"{incumbent.key} ({incumbent.seeds} seeds)"
    arm.search_score = incumbent.iqm
    arm.after_start = found.summary()


def read_search(storage: str, arm: Arm) -> None:
    """The search's trials (each by its latest attempt: a rechecked trial by its recheck), CPU
    seconds used (every attempt's, and asking the sampler for each) and pick (its best
    complete trial; a racing search's incumbent)."""
    study = optuna.load_study(study_name=arm.study, storage=storage)
    if arm.racing:
        read_racing(study, arm)
        return
    two = len(study.directions) == 2
    every = [t for t in study.trials if t.state != optuna.trial.TrialState.WAITING]
    trials = counted(every)
    states = [t.state for t in trials]
    complete = [t for t in trials if t.state == optuna.trial.TrialState.COMPLETE]
    rechecked = sum(1 for t in complete if "recheck_of" in t.user_attrs)
    arm.trials = (f"{len(complete)}/{states.count(optuna.trial.TrialState.PRUNED)}/"
                  f"{states.count(optuna.trial.TrialState.FAIL)}"
                  + (f" ({rechecked} rechecked)" if rechecked else ""))
    arm.cpu = spent_cpu(every)
    arm.after_start = after_start(study, trials)
    if two:
        # The front's best score, as confirm --top 1 takes it (no floor: the searches have none).
        number = spread(search_front(complete).front, 1)[0].key
        best = next(t for t in complete if known_number(t) == number)
    else:
        best = best_trial(complete)
        if best is None:
            sys.exit(f"bench_search: {arm.study} has no complete trial to confirm")
    arm.pick = str(best.user_attrs.get("key", search_key(best.number)))
    arm.search_score = float(best.values[0])


def after_start(study: optuna.Study, trials: list[optuna.trial.FrozenTrial]) -> str:
    """What the sampler chose after its random start (the first ``startup_trials`` trials,
    which a seeded TPE draws as random search of the same seed does): trials, pruned, and
    distinct settings of the space's categorical parameters among them, the sign of a sampler
    that keeps drawing the same few (random search draws them nearly all different).

    The GP sampler's start is its first ``startup_trials`` *complete* trials, so which trial
    it models first depends on when trials ended; its own trials are the ones Optuna marks
    with the GP's relative parameters (``gp:relative_params:...``)."""
    search = study.user_attrs["kraby_definition"]["search"]
    start = int(search["startup_trials"])
    if search.get("sampler") == "gp":
        own = [t for t in trials
               if any(key.startswith("gp:relative_params") for key in t.system_attrs)]
    else:
        own = [t for t in trials if t.number >= start]
    own = [t for t in own if "recheck_of" not in t.user_attrs]
    pruned = sum(1 for t in own if t.state == optuna.trial.TrialState.PRUNED)
    kinds = {name: d for t in own for name, d in t.distributions.items()}
    names = sorted(n for n, d in kinds.items()
                   if isinstance(d, optuna.distributions.CategoricalDistribution))
    distinct = len({tuple(t.params.get(n) for n in names) for t in own})
    return (f"{len(own)} trial{'s' if len(own) != 1 else ''}, {pruned} pruned, {distinct} distinct "
            f"setting{'s' if distinct != 1 else ''} of "
            f"{', '.join(names) or 'no categorical parameter'}")


def read_confirm(storage: str, name: str) -> tuple[list[float], float]:
    """A one-arm confirm's scores by fresh seed (in seed order) and its mean CPU s per run;
    the benchmark stops if a run of it has not ended (a confirm still training)."""
    study = optuna.load_study(study_name=name, storage=storage)
    runs = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    if any(not t.state.is_finished() for t in study.trials):
        sys.exit(f"{name} is not finished ({len(runs)} of {len(study.trials)} runs complete)")
    runs.sort(key=lambda t: int(t.user_attrs["seed"]))
    scores = [float(t.user_attrs["final_score"]) for t in runs]
    cpu = statistics.fmean(float(t.user_attrs["cpu_time"]) for t in runs) if runs else math.nan
    return scores, cpu


def signed_rank(differences: list[float], alternative: str) -> tuple[float, int]:
    """Exact one-sided Wilcoxon signed-rank p of the differences, zeros dropped, and how many
    were left (p 1 when none is)."""
    left = [d for d in differences if d != 0]
    if not left:
        return 1.0, 0
    return float(stats.wilcoxon(left, alternative=alternative, method="exact").pvalue), len(left)


def t_interval(values: list[float]) -> tuple[float, float]:
    """95 % Student-t interval of the mean (nan below 2 values)."""
    if len(values) < 2:
        return math.nan, math.nan
    half = stats.t.ppf(0.975, len(values) - 1) * statistics.stdev(values) / math.sqrt(len(values))
    mean = statistics.fmean(values)
    return mean - half, mean + half


def parse(argv: list[str] | None) -> argparse.Namespace:
    """The benchmark's arguments; bad ones stop it (exit 2) before anything runs."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env-id", required=True)
    parser.add_argument("--cpu-budget", type=float, required=True,
                        help="CPU seconds each search may use")
    parser.add_argument("--sampler-seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--samplers", nargs="+", default=["tpe", "random"],
                        help="the default's arm, then the one it is compared with (one arm: "
                             "its searches alone, no comparison); an arm is a sampler (tpe, "
                             "random, gp, ...) or a racing search: racing (multivariate TPE), "
                             "racing-random, racing-gp")
    parser.add_argument("--arm-overrides", nargs="+", action="extend", default=[],
                        metavar="ARM:KEY=VALUE",
                        help="overrides for one arm's commands only, after the common ones "
                             "(a common override of the same key is replaced), e.g. "
                             "racing:budget.seeds=8")
    parser.add_argument("--tag", default=None,
                        help="first word of the study names (default: the env's name)")
    parser.add_argument("--enqueue", nargs="*", default=None,
                        help="ppo configs every search evaluates first (search.enqueue); "
                             "default: the search's own default, rl-zoo3's settings; "
                             "none named: a cold start")
    parser.add_argument("--no-zoo", action="store_true",
                        help="do not confirm rl-zoo3's settings")
    parser.add_argument("--cost", action="store_true",
                        help="two objectives: the evaluation return and CPU s per seed")
    parser.add_argument("--confirm-seeds", type=int, default=5)
    parser.add_argument("--storage", default="sqlite:///bench_search.db")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--dry-run", action="store_true",
                        help="print each search's plan (kraby-study optuna --dry-run) and stop")
    parser.add_argument("overrides", nargs="*", help="KEY=VALUE for every command")
    args = parser.parse_intermixed_args(argv)
    if stray := next((a for a in args.samplers if "=" in a), None):
        parser.error(f"--samplers takes arm names, not {stray!r}: give the KEY=VALUE overrides "
                     "before --samplers")
    if (args.cpu_budget <= 0 or args.confirm_seeds < 2 or not args.sampler_seeds
            or len(args.samplers) > 2):
        parser.error("--cpu-budget must be positive, --confirm-seeds at least 2, "
                     "--sampler-seeds not empty and --samplers one or two")
    if len(set(args.samplers)) != len(args.samplers):
        parser.error(f"--samplers names {args.samplers[0]} twice: name two arms")
    if args.cost and any(sampler_flags(a)[0] == "--racing" for a in args.samplers):
        parser.error("--cost searches on two objectives, which a racing search does not race")
    try:
        args.own = arm_overrides(args.arm_overrides, args.samplers)
    except ValueError as error:
        parser.error(str(error))
    return args


def study_tag(args: argparse.Namespace) -> str:
    """The first word of the study names: ``--tag``, else the env's name (``pendulum``)."""
    return str(args.tag or args.env_id.split("-")[0].lower())


def common_overrides(args: argparse.Namespace) -> list[str]:
    """The Hydra overrides of every command: the env, rl-zoo3's settings and budget, and the
    command line's own."""
    return ["env=gym", f"env.id={args.env_id}", "ppo=zoo", "budget=zoo", *args.overrides]


def plan_arms(args: argparse.Namespace) -> list[Arm]:
    """The searches, by sampler seed then arm, each with its study name and overrides."""
    common = common_overrides(args)
    return [Arm(sampler, seed, f"{study_tag(args)}-{sampler}-s{seed}",
                with_own(common, args.own[sampler]))
            for seed in args.sampler_seeds for sampler in args.samplers]


def search_command(args: argparse.Namespace, arm: Arm) -> list[str]:
    """The arm's ``kraby-study optuna`` arguments."""
    objective = (["--objective", "evaluation,training_time", "--floor", "none"]
                 if args.cost else ["--objective", "evaluation"])
    queue = [] if args.enqueue is None else [f"search.enqueue=[{','.join(args.enqueue)}]"]
    return ["optuna", *objective, *sampler_flags(arm.sampler), "--seed", str(arm.seed),
            "--cpu-budget", f"{args.cpu_budget:g}", "--trials", "100000", "--study-name",
            arm.study, *queue, *common_flags(args), *(arm.overrides or [])]


def common_flags(args: argparse.Namespace) -> list[str]:
    """The storage, workers and model saving of every command."""
    return ["--storage", args.storage, "--workers", str(args.workers), "save_models=false"]


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    common = common_flags(args)
    arms = plan_arms(args)
    if args.dry_run:
        for arm in arms:
            kraby(*search_command(args, arm), "--dry-run", plan=True)
        print(f"bench_search: dry run of {len(arms)} searches; each pick would be confirmed "
              f"on {args.confirm_seeds} fresh seeds")
        return 0
    for arm in arms:
        kraby(*search_command(args, arm))
        read_search(args.storage, arm)
        kraby("confirm", "--study-name", arm.study, "--top", "1", "--seeds",
              str(args.confirm_seeds), *common, *(arm.overrides or []))
        arm.confirmed, arm.confirm_cpu = read_confirm(args.storage, f"{arm.study}-confirm")
    zoo_scores: list[float] = []
    if not args.no_zoo:
        zoo = f"{study_tag(args)}-zoo-confirm"
        kraby("confirm", "--baseline", "ppo=zoo", "--seeds", str(args.confirm_seeds),
              f"confirm.name={zoo}", "search.objective=evaluation", *common,
              *common_overrides(args))
        zoo_scores, zoo_cpu = read_confirm(args.storage, zoo)

    print(f"\n{args.env_id}: each search {args.cpu_budget:,.0f} CPU s; picks retrained on "
          f"{args.confirm_seeds} fresh seeds (mean [95 % t CI over the seeds])")
    print("| sampler | seed | trials c/p/f | CPU s used | pick | search score | confirmed mean "
          "| CPU s per run |")
    print("|---|---:|---:|---:|---|---:|---|---:|")
    for arm in arms:
        low, high = t_interval(arm.confirmed or [])
        print(f"| {arm.sampler} | {arm.seed} | {arm.trials} | {arm.cpu:,.0f} | {arm.pick} | "
              f"{arm.search_score:.1f} | {arm.mean:.1f} [{low:.1f}, {high:.1f}] | "
              f"{arm.confirm_cpu:.1f} |")
    if zoo_scores:
        low, high = t_interval(zoo_scores)
        print(f"| ppo=zoo | - | - | - | - | - | {statistics.fmean(zoo_scores):.1f} "
              f"[{low:.1f}, {high:.1f}] | {zoo_cpu:.1f} |")
    if any(arm.racing for arm in arms):
        print("A racing search's row: configurations asked and runs ended for its trials, its "
              "incumbent with its seeds as its pick, their IQM as its search score.")
    print("After each search's random start (the first search.startup_trials trials"
          + ("; a racing search: its configurations" if any(a.racing for a in arms) else "")
          + "):")
    for arm in arms:
        print(f"- {arm.sampler} seed {arm.seed}: {arm.after_start}")
    if len(args.samplers) == 1:
        return 0

    default, other = args.samplers
    by = {(a.sampler, a.seed): a for a in arms}
    diffs = [by[(default, s)].mean - by[(other, s)].mean for s in args.sampler_seeds]
    low, high = t_interval(diffs)
    if len(diffs) >= 2 and any(d != 0 for d in diffs):
        p, _ = signed_rank(diffs, "less")
        print(f"Wilcoxon signed-rank (exact, one-sided, {default} worse), n={len(diffs)} "
              f"sampler seeds: p = {p:.3g}")
        p, _ = signed_rank(diffs, "greater")
        print(f"Wilcoxon signed-rank (exact, one-sided, {default} better), n={len(diffs)} "
              f"sampler seeds: p = {p:.3g}")
    cpu = {name: statistics.fmean(a.cpu for a in arms if a.sampler == name)
           for name in args.samplers}
    if args.cost:
        ratios = [by[(default, s)].confirm_cpu / by[(other, s)].confirm_cpu
                  for s in args.sampler_seeds]
        print(f"The picks' CPU s per run, {default} / {other} by sampler seed: "
              + ", ".join(f"{r:.2f}" for r in ratios)
              + f" (geometric mean {statistics.geometric_mean(ratios):.2f})")
    print(f"bench_search: {default} - {other} confirmed mean difference "
          f"{statistics.fmean(diffs):.1f} (95 % t CI [{low:.1f}, {high:.1f}], {len(diffs)} "
          f"sampler seeds); CPU {default} {cpu[default]:,.0f} s, {other} {cpu[other]:,.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
