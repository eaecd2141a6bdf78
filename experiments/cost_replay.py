"""Replay a cost cap on stored searches: would stopping dear trials early free the budget?

Run: python experiments/cost_replay.py URL STUDY [STUDY ...] (--cap C | --share F) [--good X]

A search's samplers do not see what a trial costs, and a CPU budget can go to a few dear
trials. A cost cap would stop a trial at a checkpoint once its CPU seconds per env step pass C
times those of the search's first complete trial (with ``ppo=zoo``, rl-zoo3's settings); TPE,
which ranks pruned trials below complete ones, would learn where such trials lie, and random
search would not. This script asks, before any such cap is built, what one would have done
to stored searches. A trial's CPU seconds per env step are read as its whole
run's (its stored CPU seconds over its env steps, its evaluations included), and the
reference is the search's first complete trial by number, as the search reads it once that
trial has ended. A trial above the cap is taken as stopped at its first checkpoint (a quarter
of its first seed with 4 checkpoints), having used its rate times those env steps. Pruned
trials count too, when they ran past that checkpoint; a recheck reports no checkpoint, so no
cap stops it. What the search would have sampled with the CPU seconds a stop saves is not
known, so it is not replayed: the script says how much of a budget the cap frees and whether it
stops a setting that ends well, not what the search would have picked.

``--share F`` replays the cap the search has since been given (``search.trial_share``): a
trial projected to use more than F times the search's CPU budget (its stored
``cpu_budget``) is stopped. Its projection at the first checkpoint is read as its whole
run's rate times the env steps of all its seeds; the configurations the search evaluated
first (``enqueued``) are spared, as the search spares them.

Per search: the reference's CPU s per env step, the trials the cap stops (and their rates as
multiples of the reference), the CPU seconds they used and would have used, how many of them
ended at ``--good`` or better, and whether the search's pick (its best complete trial) is
among them. The last line reads ``cost_replay: N searches at cap C (or share F); it stops S
of T trials; they used U of the V CPU s the searches used, W up to their first checkpoint; G
of them ended at X or better; P of the N picks among them`` (``1 search`` for one).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import optuna
from omegaconf import OmegaConf
from optuna.trial import TrialState

from kraby_study.plan.space import checkpoint_every
from kraby_study.records.attributes import TrialAttrs
from kraby_study.records.stored import counted, spent_cpu

optuna.logging.set_verbosity(optuna.logging.WARNING)


@dataclass(frozen=True)
class Stop:
    """A trial the cap stops: its number, rate as a multiple of the reference's, the CPU
    seconds it used, those it would have used up to its first checkpoint, and its value (None
    for a pruned one)."""

    number: int
    times: float
    used: float
    capped: float
    value: float | None


def first_pace(trials: list[optuna.trial.FrozenTrial]) -> float | None:
    """CPU seconds per env step of a search's first complete trial (by number; a recheck is
    not one), or None while none has both measured."""
    for trial in sorted(trials, key=lambda t: t.number):
        attrs = TrialAttrs.of(trial)
        if (trial.state == TrialState.COMPLETE and attrs.recheck_of is None
                and attrs.cpu_time and attrs.env_steps):
            return float(attrs.cpu_time) / int(attrs.env_steps)
    return None


def past_rate(limit: float, rate: float, attrs: TrialAttrs) -> bool:
    """``--cap``: its CPU s per env step pass ``limit``."""
    return rate > limit


def past_share(limit: float, total: int, rate: float, attrs: TrialAttrs) -> bool:
    """``--share``: at its rate, its ``total`` env steps would use more than ``limit`` CPU s,
    and it is not a configuration the search evaluated first."""
    return attrs.enqueued is None and rate * total > limit


def stops(trials: list[optuna.trial.FrozenTrial], dear: Callable[[float, TrialAttrs], bool],
          first: int, reference: float) -> list[Stop]:
    """The ended trials a cap stops at their first checkpoint (``first`` env steps): those
    whose CPU s per env step ``dear`` calls too dear; their rates as multiples of
    ``reference``, the first complete trial's."""
    out = []
    for trial in trials:
        attrs = TrialAttrs.of(trial)
        if (trial.state not in (TrialState.COMPLETE, TrialState.PRUNED)
                or attrs.recheck_of is not None or not attrs.cpu_time or not attrs.env_steps
                or int(attrs.env_steps) <= first):
            continue
        rate = float(attrs.cpu_time) / int(attrs.env_steps)
        if dear(rate, attrs):
            value = float(trial.value) if trial.state == TrialState.COMPLETE else None
            out.append(Stop(trial.number, rate / reference, float(attrs.cpu_time),
                            rate * first, value))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("storage")
    parser.add_argument("studies", nargs="+")
    rule = parser.add_mutually_exclusive_group(required=True)
    rule.add_argument("--cap", type=float,
                      help="the cap: a multiple of the first complete trial's CPU s per step")
    rule.add_argument("--share", type=float,
                      help="the cap: a share of the search's CPU budget one trial may use")
    parser.add_argument("--good", type=float, default=None,
                        help="a final value counted as ending well (default: the pick's)")
    args = parser.parse_args(argv)
    if args.cap is not None and not args.cap > 0:
        parser.error(f"--cap must be positive, got {args.cap:g}")
    if args.share is not None and not 0 < args.share <= 1:
        parser.error(f"--share must be in (0, 1], got {args.share:g}")
    searches = []
    for name in args.studies:  # every one checked before any is replayed
        try:
            study = optuna.load_study(study_name=name, storage=args.storage)
        except KeyError:
            parser.error(f"no search {name!r} in {args.storage}")
        definition = study.user_attrs["kraby_definition"]
        trials = [t for t in study.trials if t.state != TrialState.WAITING]
        reference = first_pace(trials)
        if reference is None:
            parser.error(f"{name} has no complete trial with its CPU seconds and env steps")
        first = checkpoint_every(OmegaConf.create({"budget": {"steps": definition["steps"]},
                                                   "search": definition["search"]}))
        if args.cap is not None:
            dear = partial(past_rate, args.cap * reference)
        else:
            budget = study.user_attrs.get("kraby_cpu_budget")
            if budget is None:
                parser.error(f"{name} has no CPU budget to share")
            dear = partial(past_share, args.share * float(budget),
                           int(definition["steps"]) * int(definition["seeds"]))
        searches.append((name, trials, first, reference, dear))
    totals = {"trials": 0, "stops": 0, "cpu": 0.0, "used": 0.0, "capped": 0.0, "well": 0,
              "picks": 0}
    print("| search | reference CPU s per step | stopped (x reference) | their CPU s: used, "
          "to the first checkpoint | of the search's CPU s | ended well | pick stopped |")
    print("|---|---:|---|---|---:|---:|---|")
    for name, trials, first, reference, dear in searches:
        stopped = stops(trials, dear, first, reference)
        # The pick as the search makes it: each trial by its latest attempt (a rechecked one
        # by all its seeds); every attempt's CPU seconds count towards the search's.
        complete = [t for t in counted(trials) if t.state == TrialState.COMPLETE]
        pick = max(complete, key=lambda t: float(t.value))  # type: ignore[arg-type]
        good = float(pick.value) if args.good is None else args.good  # type: ignore[arg-type]
        well = sum(1 for s in stopped if s.value is not None and s.value >= good)
        used, capped = sum(s.used for s in stopped), sum(s.capped for s in stopped)
        cpu = spent_cpu(trials)
        listed = ", ".join(f"t{s.number} ({s.times:.1f})" for s in stopped)
        picked = any(s.number == pick.number for s in stopped)
        print(f"| {name} | {reference:.3g} | {len(stopped)}"
              f"{': ' + listed if listed else ''} | {used:,.0f}, {capped:,.0f} | {cpu:,.0f} | "
              f"{well} | {'yes' if picked else 'no'} (t{pick.number}) |")
        totals["trials"] += sum(1 for t in trials
                                if t.state in (TrialState.COMPLETE, TrialState.PRUNED))
        totals["stops"] += len(stopped)
        totals["cpu"] += cpu
        totals["used"] += used
        totals["capped"] += capped
        totals["well"] += well
        totals["picks"] += int(picked)
    threshold = "the pick's score" if args.good is None else f"{args.good:g}"
    n = len(searches)
    rule = f"cap {args.cap:g}" if args.cap is not None else f"share {args.share:g}"
    print(f"cost_replay: {n} search{'' if n == 1 else 'es'} at {rule}; it stops "
          f"{totals['stops']} of {totals['trials']} trials; they used {totals['used']:,.0f} of "
          f"the {totals['cpu']:,.0f} CPU s the search{'' if n == 1 else 'es'} used, "
          f"{totals['capped']:,.0f} up to their first "
          f"checkpoint; {totals['well']} of them ended at {threshold} or better; "
          f"{totals['picks']} of the {n} pick{'' if n == 1 else 's'} among them")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
