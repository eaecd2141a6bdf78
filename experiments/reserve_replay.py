"""Replay stored rechecked searches: where each rule of the rechecks' reserve ends exploring.

Run: python experiments/reserve_replay.py URL [--recheck 3] [--recheck-seeds 3] [--with-next]
         [--studies NAME ...]

A search under ``--recheck K`` and ``--cpu-budget`` stops exploring once the budget holds what
is spent, what its running trials could still use (each to its last step: at its own pace
once a tenth of it has run, before that at the search's median pace) and the rechecks of its K
leaders (:mod:`kraby_study.run.recheck`). Before 2026-12-03 it held what was spent and the
rechecks only, so a dear trial running beside the last ones could take the rechecks' share.

This script reads each finished search stored with a CPU budget (or the ``--studies``
named) and judges each explored trial's start as the rule would have: the attempts ended by
then, the ones running then (their CPU so far taken as spent evenly over their wall time,
their env steps likewise), the leaders' rechecks as today's code reserves them. The first
explored trial the rule would not have started, and every later one, is cut. With
``--with-next`` the rule also holds one more trial's expected CPU (the mean of the ended
explored attempts), a variant that was tried and dropped.

One row per search: explored trials and their CPU s, what the rule cuts, which of the
search's final top K were found in the cut part, and whether its pick was. Last line:
``reserve_replay: N searches; the rule ends exploring before C of E explored CPU s (P %);
K picks found after it``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import optuna
from optuna.trial import FrozenTrial, TrialState

sys.path.insert(0, str(Path(__file__).parent))
from budget_replay import Span  # noqa: E402

from kraby_study.records.attributes import TrialAttrs  # noqa: E402
from kraby_study.records.stored import spent_cpu  # noqa: E402
from kraby_study.run.recheck import cpu_per_step, leaders, reserve, to_spend  # noqa: E402

optuna.logging.set_verbosity(optuna.logging.WARNING)


def span(trial: FrozenTrial) -> Span:
    """A trial's start, end and CPU seconds (timestamps)."""
    assert trial.datetime_start is not None and trial.datetime_complete is not None
    return Span(trial.datetime_start.timestamp(), trial.datetime_complete.timestamp(),
                float(TrialAttrs.of(trial).cpu_time or 0.0))


def explored_of(trials: list[FrozenTrial]) -> list[FrozenTrial]:
    """The ended attempts that explored (rechecks left out), in the order they started."""
    return sorted((t for t in trials if t.datetime_complete is not None
                   and TrialAttrs.of(t).recheck_of is None), key=lambda t: span(t).start)


def cut(trials: list[FrozenTrial], budget: float, recheck: int, seeds: int, per_trial: int,
        with_next: bool) -> list[FrozenTrial]:
    """The explored trials the rule would not have started: the first such, in start order,
    and every later one (empty: it starts them all). ``per_trial``: a trial's seeds, so its
    env steps are its steps times them."""
    ended_all = [t for t in trials if t.datetime_complete is not None]
    spans = {t.number: span(t) for t in ended_all}
    explored = explored_of(trials)
    for index, trial in enumerate(explored):
        now = spans[trial.number].start
        ended = [t for t in ended_all if spans[t.number].end <= now]
        running = [t for t in ended_all if spans[t.number].start < now < spans[t.number].end]
        rate = cpu_per_step(ended)
        coming = 0.0
        for t in running:
            whole = spans[t.number]
            used = whole.used_at(now)
            total = int(TrialAttrs.of(t).steps or 0) * per_trial
            done = int(total * used / whole.cpu) if whole.cpu > 0 else 0
            coming += used + to_spend(done, total, used, rate)
        if with_next:
            costs = [spans[t.number].cpu for t in ended if TrialAttrs.of(t).recheck_of is None]
            coming += statistics.fmean(costs) if costs else 0.0
        if spent_cpu(ended) + coming + reserve(ended, recheck, seeds) >= budget:
            return explored[index:]
    return []


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("storage", metavar="URL")
    parser.add_argument("--recheck", type=int, default=3, help="leaders rechecked (K)")
    parser.add_argument("--recheck-seeds", type=int, default=3, help="more seeds a recheck")
    parser.add_argument("--with-next", action="store_true",
                        help="also hold one more trial's expected CPU (the dropped variant)")
    parser.add_argument("--studies", nargs="+", default=None, help="these searches only")
    args = parser.parse_args(argv)
    if args.recheck < 1 or args.recheck_seeds < 1:
        parser.error("--recheck and --recheck-seeds must be at least 1")
    summaries = {s.study_name: s for s in optuna.study.get_all_study_summaries(args.storage)}
    names = args.studies or sorted(n for n, s in summaries.items()
                                   if s.user_attrs.get("kraby_cpu_budget"))
    missing = [n for n in names if n not in summaries]
    if missing:
        parser.error(f"no study {missing[0]!r} in {args.storage}")
    print("| search | explored | CPU s | cut | cut CPU s | top found in the cut | pick |")
    print("|---|---:|---:|---:|---:|---|---|")
    total = cut_total = 0.0
    picks = rows = 0
    for name in names:
        budget = summaries[name].user_attrs.get("kraby_cpu_budget")
        study = optuna.load_study(study_name=name, storage=args.storage)
        if not budget or any(t.state == TrialState.RUNNING for t in study.trials):
            continue
        per_trial = int(study.user_attrs["kraby_definition"]["seeds"])
        explored = explored_of(study.trials)
        cuts = cut(study.trials, float(budget), args.recheck, args.recheck_seeds, per_trial,
                   args.with_next)
        keys = {TrialAttrs.of(t).key for t in cuts}
        top = [str(TrialAttrs.of(lead.trial).key) for lead in leaders(study.trials, args.recheck)]
        found = [key for key in top if key in keys]
        pick = f"{top[0]} (in the cut)" if top and top[0] in keys else (top[0] if top else "-")
        used = sum(span(t).cpu for t in explored)
        lost = sum(span(t).cpu for t in cuts)
        total, cut_total = total + used, cut_total + lost
        picks += bool(top) and top[0] in keys
        rows += 1
        print(f"| {name} | {len(explored)} | {used:,.0f} | {len(cuts)} | {lost:,.0f} | "
              f"{', '.join(found) or '-'} | {pick} |")
    if not rows:
        parser.error("no finished search with a CPU budget among these")
    share = 100 * cut_total / total if total else 0.0
    print(f"reserve_replay: {rows} searches; the rule ends exploring before {cut_total:,.0f} "
          f"of {total:,.0f} explored CPU s ({share:.1f} %); {picks} picks found after it")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
