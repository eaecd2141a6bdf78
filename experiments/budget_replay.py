"""Replay stored budgeted searches under the rule that counts running trials' CPU.

Run: python experiments/budget_replay.py URL [URL ...]

Since 2026-11-29 a search under ``--cpu-budget`` starts no trial once its ended trials' CPU
seconds and what its running trials have used so far reach the budget; before, it counted
ended trials only, so it kept starting trials while the running ones had already spent the
rest. This script reads every search stored with a CPU budget in the given stores (none of
its trials still running) and applies the new rule to its stored schedule: trials in the
order they started, a running trial's CPU so far taken as its elapsed wall time times its
own CPU seconds per wall second (one worker trains on one core). The first trial the rule
would not have started is dropped, and every later one (the budget only fills up). What
the dropped trials would have been replaced by is nothing: the budget was used.

It prints one row per search (CPU s used as stored, under the rule, trials dropped), and a
last line ``budget_replay: N searches; overshoot of the budget mean A % -> B %, largest
C % -> D %; T trials fewer``.
"""

from __future__ import annotations

import argparse
import statistics
from dataclasses import dataclass

import optuna

optuna.logging.set_verbosity(optuna.logging.WARNING)


@dataclass(frozen=True)
class Span:
    """One stored trial: when it started and ended (seconds) and the CPU seconds it used."""

    start: float
    end: float
    cpu: float

    def used_at(self, moment: float) -> float:
        """CPU seconds it had used at ``moment`` (all of it once ended)."""
        if moment >= self.end:
            return self.cpu
        if moment <= self.start:
            return 0.0
        return self.cpu * (moment - self.start) / (self.end - self.start)


def kept(spans: list[Span], budget: float) -> list[Span]:
    """The trials a search would have run had it counted its running trials' CPU so far: in
    the order they started, until one starts when the kept ones have used the budget."""
    out: list[Span] = []
    for span in sorted(spans, key=lambda s: s.start):
        if sum(k.used_at(span.start) for k in out) >= budget:
            break
        out.append(span)
    return out


def spans_of(study: optuna.Study) -> list[Span] | None:
    """The study's ended trials as spans, or None while any is still running."""
    trials = study.trials
    if any(t.state == optuna.trial.TrialState.RUNNING for t in trials):
        return None
    return [Span(t.datetime_start.timestamp(), t.datetime_complete.timestamp(),
                 float(t.user_attrs["cpu_time"]))
            for t in trials if t.datetime_start is not None and t.datetime_complete is not None
            and t.user_attrs.get("cpu_time") is not None]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("storages", nargs="+", metavar="URL")
    args = parser.parse_args(argv)
    rows: list[tuple[str, float, float, float, int]] = []
    for url in args.storages:
        for summary in optuna.study.get_all_study_summaries(url):
            budget = summary.user_attrs.get("kraby_cpu_budget")
            if not budget:
                continue
            spans = spans_of(optuna.load_study(study_name=summary.study_name, storage=url))
            if not spans:
                continue
            left = kept(spans, float(budget))
            rows.append((summary.study_name, float(budget), sum(s.cpu for s in spans),
                         sum(s.cpu for s in left), len(spans) - len(left)))
    if not rows:
        parser.error("no finished search with a CPU budget in these stores")
    print("| search | budget | CPU s used | under the rule | trials dropped |")
    print("|---|---:|---:|---:|---:|")
    for name, budget, used, rule, dropped in rows:
        print(f"| {name} | {budget:,.0f} | {used:,.0f} | {rule:,.0f} | {dropped} |")
    before = [used / budget - 1 for _, budget, used, _, _ in rows]
    after = [rule / budget - 1 for _, budget, _, rule, _ in rows]
    print(f"budget_replay: {len(rows)} searches; overshoot of the budget mean "
          f"{100 * statistics.fmean(before):.1f} % -> {100 * statistics.fmean(after):.1f} %, "
          f"largest {100 * max(before):.1f} % -> {100 * max(after):.1f} %; "
          f"{sum(r[4] for r in rows)} trials fewer")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
