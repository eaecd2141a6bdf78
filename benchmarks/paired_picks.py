"""Benchmark analysis: two searches' confirmed picks, paired by sampler seed, tested.

Run: python benchmarks/paired_picks.py --seeds 0 1 2 3 4
         (--first NAME | --first-means M ...) (--second NAME | --second-means M ...)
         [--storage URL] [--alternative greater|less] [--decimals D]

Each arm is either the stored confirms of ``bench_search.py`` (``--first mccnp-tpe`` reads
the studies ``mccnp-tpe-s0-confirm``, ``mccnp-tpe-s1-confirm``, ... in ``--storage``: the mean
of each pick's fresh seeds) or a list of confirmed means as published, one per sampler seed
(``--first-means 73.2 49.4 64.7``), for an arm whose store is gone. A mean read from a store is
taken to 0.1, the precision the results publish, so two searches that picked the same setting
differ by exactly 0 whichever way their means were obtained; ``--decimals D`` sets that
precision for scores on another scale (the leg's IQMs are published to 4 decimals).

Per sampler seed, the first arm's mean minus the second's; then the differences' median, mean
with its 95 % Student-t interval over the sampler seeds, and the exact one-sided Wilcoxon
signed-rank p (scipy, zero differences dropped) that the first arm does better
(``--alternative greater``, the default) or worse (``less``). With ``--margin M`` it also tests
that the first arm is not worse by more than M (the same test on the differences plus M).

With both arms stored it also prints what the same work cost in each arm's search: when the
two searches of a sampler seed began with the same trial 0 (the same settings and seeds,
scored alike to the bit, as with ``--enqueue zoo``), its CPU seconds in each, and the first
over the second. A CPU budget buys more trials where a CPU second does more work, so a ratio
far from 1 says the pair's arms did not get equal budgets in work. It then compares the
picks' CPU seconds a run in their confirms: the first over the second, geometric mean over the
pairs, and the exact one-sided Wilcoxon signed-rank p that the first's are cheaper (on the log
ratios; a pair whose two picks are the same settings is a tie).

The last line reads ``paired_picks: first - second D (median m; 95 % t CI [lo, hi]); Wilcoxon
p P (n N, Z zero)``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import optuna  # noqa: E402
from bench_search import read_confirm, signed_rank, t_interval  # noqa: E402


def arm_means(storage: str, name: str, seeds: list[int], decimals: int = 1) -> list[float]:
    """The confirmed mean of arm NAME's pick at each sampler seed, to ``decimals``."""
    means = []
    for seed in seeds:
        confirm = f"{name}-s{seed}-confirm"
        try:
            scores, _ = read_confirm(storage, confirm)  # stops on a confirm still training
        except KeyError:
            raise SystemExit(f"paired_picks: no study {confirm!r} in {storage}") from None
        if not scores:
            raise SystemExit(f"paired_picks: {confirm} has no complete run")
        means.append(round(statistics.fmean(scores), decimals))
    return means


def arm_costs(storage: str, name: str, seeds: list[int]) -> list[tuple[float, str]]:
    """Arm NAME's pick at each sampler seed: its confirm's mean CPU s a run, and its settings
    (as the confirm's first run stored them), which tell two arms' same pick."""
    costs = []
    for seed in seeds:
        confirm = f"{name}-s{seed}-confirm"
        _, cpu = read_confirm(storage, confirm)
        study = optuna.load_study(study_name=confirm, storage=storage)
        settings = next((t.user_attrs.get("settings") for t in study.get_trials(deepcopy=False)),
                        None)
        costs.append((cpu, json.dumps(settings, sort_keys=True)))
    return costs


def print_costs(seeds: list[int], first: list[tuple[float, str]],
                second: list[tuple[float, str]]) -> None:
    """The picks' CPU s a run in each pair, the first over the second (geometric mean), and
    the exact one-sided Wilcoxon signed-rank p that the first's picks are cheaper (on the
    log of each ratio; a pair that picked the same settings is a tie, dropped)."""
    ratios = [a / b for (a, _), (b, _) in zip(first, second, strict=True)]
    logs = [0.0 if same_a == same_b else math.log(r)
            for r, (_, same_a), (_, same_b) in zip(ratios, first, second, strict=True)]
    pairs = ", ".join(f"seed {seed} {a:.1f} / {b:.1f}"
                      for seed, (a, _), (b, _) in zip(seeds, first, second, strict=True))
    p, n = signed_rank(logs, "less")
    print(f"The picks' CPU s a run, first / second: {pairs}; first over second: geometric "
          f"mean {statistics.geometric_mean(ratios):.2f}; exact one-sided Wilcoxon "
          f"signed-rank p {p:.3g} that the first's are cheaper (n {n}, "
          f"{len(logs) - n} same pick)")


def first_trial(storage: str, name: str, seed: int) -> optuna.trial.FrozenTrial | None:
    """Trial 0 of arm NAME's search at this sampler seed, if it is stored and complete."""
    try:
        study = optuna.load_study(study_name=f"{name}-s{seed}", storage=storage)
    except KeyError:  # only the confirm is stored
        return None
    trials = [t for t in study.get_trials(deepcopy=False) if t.number == 0]
    if not trials or trials[0].state != optuna.trial.TrialState.COMPLETE:
        return None
    return trials[0]


def same_work(a: optuna.trial.FrozenTrial, b: optuna.trial.FrozenTrial) -> bool:
    """Whether two trials ran the same work: the same settings and seed, scored alike."""
    keys = ("settings", "seed", "scores")
    return all(a.user_attrs.get(k) == b.user_attrs.get(k) is not None for k in keys)


def work_rates(storage: str, first: str, second: str,
               seeds: list[int]) -> list[tuple[int, float, float]]:
    """(sampler seed, first's CPU s, second's CPU s) of each pair whose searches' trial 0 is
    the same work."""
    rows = []
    for seed in seeds:
        a, b = first_trial(storage, first, seed), first_trial(storage, second, seed)
        if a is not None and b is not None and same_work(a, b):
            rows.append((seed, float(a.user_attrs["cpu_time"]),
                         float(b.user_attrs["cpu_time"])))
    return rows


def print_work_rates(rows: list[tuple[int, float, float]]) -> None:
    """The same work's CPU s in each arm, and the first over the second."""
    if not rows:
        print("Trial 0 is not the same work in any pair's two searches")
        return
    pairs = ", ".join(f"seed {seed} {a:.0f} / {b:.0f}" for seed, a, b in rows)
    ratios = [a / b for _, a, b in rows]
    print(f"The same work (trial 0) in each pair's searches, CPU s first / second: {pairs}; "
          f"first over second: geometric mean {statistics.geometric_mean(ratios):.2f} "
          f"({min(ratios):.2f} to {max(ratios):.2f}, {len(rows)} pair{'s' * (len(rows) > 1)})")


def signed(value: float, decimals: int = 1) -> str:
    """A difference to ``decimals`` with its sign; 0 when it rounds to none."""
    text = f"{value:+.{decimals}f}"
    return "0" if float(text) == 0 else text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", required=True, help="sampler seeds")
    for arm in ("first", "second"):
        group = parser.add_mutually_exclusive_group(required=True)
        group.add_argument(f"--{arm}", help="stored arm: its studies' names before -sN-confirm")
        group.add_argument(f"--{arm}-means", type=float, nargs="+",
                           help="published confirmed means, one per sampler seed")
    parser.add_argument("--storage", default="sqlite:///bench_search.db")
    parser.add_argument("--alternative", choices=["greater", "less"], default="greater",
                        help="greater: the first arm does better; less: worse")
    parser.add_argument("--margin", type=float, default=None,
                        help="also test: the first arm not worse by more than this")
    parser.add_argument("--decimals", type=int, default=1,
                        help="the precision of the means and their differences (default 1)")
    args = parser.parse_args(argv)
    if len(set(args.seeds)) != len(args.seeds):
        parser.error("--seeds must not repeat a seed")
    for arm in ("first", "second"):
        given = getattr(args, f"{arm}_means")
        if given is not None and len(given) != len(args.seeds):
            parser.error(f"--{arm}-means needs one mean per seed ({len(args.seeds)})")
    if args.margin is not None and not args.margin > 0:
        parser.error("--margin must be positive")
    if not 0 <= args.decimals <= 12:
        parser.error("--decimals must be between 0 and 12")
    places = args.decimals
    first = args.first_means or arm_means(args.storage, args.first, args.seeds, places)
    second = args.second_means or arm_means(args.storage, args.second, args.seeds, places)
    differences = [round(a - b, places) for a, b in zip(first, second, strict=True)]

    print("| sampler seed | first | second | first - second |")
    print("|---:|---:|---:|---:|")
    for seed, a, b, d in zip(args.seeds, first, second, differences, strict=True):
        print(f"| {seed} | {a:.{places}f} | {b:.{places}f} | {signed(d, places)} |")
    if args.first and args.second:
        print_work_rates(work_rates(args.storage, args.first, args.second, args.seeds))
        print_costs(args.seeds, arm_costs(args.storage, args.first, args.seeds),
                    arm_costs(args.storage, args.second, args.seeds))
    if args.margin is not None:
        p_margin, n_margin = signed_rank([d + args.margin for d in differences], "greater")
        print(f"Not worse by more than {args.margin:g}: exact one-sided Wilcoxon signed-rank "
              f"p {p_margin:.3g} (n {n_margin})")
    p, n = signed_rank(differences, args.alternative)
    low, high = t_interval(differences)
    mean, median = statistics.fmean(differences), statistics.median(differences)
    interval = "n/a" if math.isnan(low) else f"[{low:.{places}f}, {high:.{places}f}]"
    print(f"paired_picks: first - second {signed(mean, places)} (median {signed(median, places)}"
          f"; 95 % t CI {interval}); Wilcoxon p {p:.3g} ({args.alternative}, n {n}, "
          f"{len(differences) - n} zero)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
