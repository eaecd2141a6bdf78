"""Benchmark: what a sampler's suggestions cost, replayed on stored searches.

Run: python experiments/sampler_cost.py --storage URL STUDY [STUDY ...]
         [--samplers gp tpe random] [--startup 5]

A search's sampler runs in the command's own process, so its CPU seconds are not in a trial's
cpu_time; a search now stores them on each trial (``suggest_cpu``) and counts them in its CPU
budget, but a search stored before did not, and one sampler's searches say nothing of what
another would have cost on the same trials. For each stored search, each of its trials from
the ``--startup``-th on is suggested again by each sampler, from the trials that had ended
before that trial was asked for (their parameters, states and values, in an in-memory study;
trials still running then are left out, so GP's account of them is not replayed), and the
suggestion's CPU seconds (this process's, every thread) are measured. Printed per search and
sampler: the suggestions replayed, the median and the total CPU seconds, and the total as a
share of the search's stored trial CPU seconds. The samplers are built as a search builds them
(``make_sampler``, with the search's seed), so the ratios gp / tpe are measured on the same
trials in the same run.

The last line reads ``sampler_cost: gp S1 CPU s, tpe S2 CPU s, random S3 CPU s over N
suggestions; gp / tpe R`` (the samplers named, in order).
"""

from __future__ import annotations

import argparse
import statistics
import time

import optuna
from optuna.trial import TrialState

from kraby_study.config.compose import compose_config
from kraby_study.records.stored import counted
from kraby_study.run.sampling import make_sampler

optuna.logging.set_verbosity(optuna.logging.ERROR)


def replay(study: optuna.Study, sampler_name: str, startup: int) -> list[float]:
    """CPU seconds of each suggestion the named sampler makes for the stored study's trials
    from ``startup`` on, each from the trials ended before that trial started."""
    trials = [t for t in counted(list(study.trials)) if t.datetime_start is not None]
    trials.sort(key=lambda t: t.number)
    seed = int(study.user_attrs.get("sampler_seed", 0))
    cfg = compose_config([f"search.sampler={sampler_name}", f"search.seed={seed}",
                          f"search.startup_trials={startup}"])
    costs = []
    for trial in trials[startup:]:
        ended = [t for t in trials if t.datetime_complete is not None
                 and t.datetime_complete <= trial.datetime_start
                 and t.state in (TrialState.COMPLETE, TrialState.PRUNED, TrialState.FAIL)]
        replayed = optuna.create_study(directions=study.directions,
                                       sampler=make_sampler(cfg))
        replayed.add_trials(ended)
        start = time.process_time()
        replayed.ask(fixed_distributions=trial.distributions)
        costs.append(time.process_time() - start)
    return costs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("studies", nargs="+", help="stored searches' names")
    parser.add_argument("--storage", required=True)
    parser.add_argument("--samplers", nargs="+", default=["gp", "tpe", "random"],
                        choices=["gp", "tpe", "random"])
    parser.add_argument("--startup", type=int, default=5,
                        help="trials drawn at random before a sampler models (default 5)")
    args = parser.parse_args(argv)
    if args.startup < 1:
        parser.error("--startup must be at least 1")
    totals = dict.fromkeys(args.samplers, 0.0)
    suggestions = 0
    for name in args.studies:
        try:
            study = optuna.load_study(study_name=name, storage=args.storage)
        except KeyError:
            parser.exit(2, f"sampler_cost: no study {name!r} in {args.storage}\n")
        trial_cpu = sum(float(t.user_attrs.get("cpu_time") or 0.0) for t in study.trials)
        for sampler_name in args.samplers:
            costs = replay(study, sampler_name, args.startup)
            totals[sampler_name] += sum(costs)
            share = sum(costs) / trial_cpu if trial_cpu else float("nan")
            print(f"{name} {sampler_name}: {len(costs)} suggestions, median "
                  f"{statistics.median(costs) if costs else 0:.3f} CPU s, total {sum(costs):.1f} "
                  f"CPU s, {100 * share:.1f} % of its trials' {trial_cpu:,.0f} CPU s")
        suggestions += len(costs)
    ratio = (f"; gp / tpe {totals['gp'] / totals['tpe']:.1f}"
             if "gp" in totals and "tpe" in totals and totals["tpe"] > 0 else "")
    print("sampler_cost: " + ", ".join(f"{n} {c:.1f} CPU s" for n, c in totals.items())
          + f" over {suggestions} suggestions{ratio}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
