"""Replay the median pruner on stored searches that ran without one.

Run: python experiments/pruner_replay.py URL STUDY [STUDY ...] [--good X]

A search run with ``search.pruner=none`` trains every trial to its end and still stores its
intermediate values (the mean training reward at each checkpoint). This script asks what the
default median pruner would have stopped: Optuna's own ``MedianPruner``, built as a search
builds it (``search.pruner_startup_trials`` complete trials first, no stop before
``search.warmup`` of the first seed), judges each complete trial at each of its checkpoints
against the trials complete by then. When a checkpoint was reached is read as the trial's
start plus its elapsed time in proportion to its env steps. A trial the replay stops is
taken out of the trials later ones are judged against, as a live pruner would have. What the
search would have sampled with the CPU a stop saves is not known, so it is not replayed: the
script says how often the pruner stops a setting that ends well, not what the search would
have picked.

Per search: complete trials, how many the replay stops (and at which env step), how many of
those ended at ``--good`` or better, and whether the search's pick (its best trial) is among
them. The last line reads ``pruner_replay: N searches; the median pruner stops S of C complete
trials; G of them ended at X or better; P of the N picks among them`` (``1 search`` for one).
"""

from __future__ import annotations

import argparse
import datetime
from dataclasses import dataclass

import optuna
from omegaconf import OmegaConf
from optuna.trial import TrialState, create_trial

from kraby_study.run.sampling import make_pruner

optuna.logging.set_verbosity(optuna.logging.WARNING)


@dataclass(frozen=True)
class Ran:
    """A complete trial as it ran: when it started and ended, its env steps (all its seeds),
    the values it reported at its checkpoints, and its final value."""

    number: int
    start: datetime.datetime
    end: datetime.datetime
    steps: int
    checkpoints: dict[int, float]
    value: float

    def reached(self, step: int) -> datetime.datetime:
        """When it reached ``step`` env steps (its elapsed time in proportion)."""
        return self.start + (self.end - self.start) * (step / self.steps)


def stopped_at(ran: list[Ran], pruner: optuna.pruners.BasePruner) -> dict[int, int]:
    """Each trial the pruner stops and the step at which it does, judged in the order the
    trials started against those complete (and not stopped) before each checkpoint."""
    stops: dict[int, int] = {}
    for trial in sorted(ran, key=lambda r: r.start):
        for step in sorted(trial.checkpoints):
            moment = trial.reached(step)
            study = optuna.create_study(direction="maximize")
            for other in ran:
                if other is not trial and other.number not in stops and other.end <= moment:
                    study.add_trial(create_trial(value=other.value,
                                                 intermediate_values=other.checkpoints))
            running = create_trial(state=TrialState.RUNNING, intermediate_values={
                s: v for s, v in trial.checkpoints.items() if s <= step})
            if pruner.prune(study, running):
                stops[trial.number] = step
                break
    return stops


def ran_of(study: optuna.Study, steps: int) -> list[Ran]:
    """The study's complete trials as they ran; ``steps``: a trial's env steps, all seeds."""
    out = []
    for t in study.trials:
        if t.state != TrialState.COMPLETE or not t.intermediate_values:
            continue
        assert t.datetime_start is not None and t.datetime_complete is not None
        out.append(Ran(t.number, t.datetime_start, t.datetime_complete,
                       steps, dict(t.intermediate_values), float(t.value)))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("storage")
    parser.add_argument("studies", nargs="+")
    parser.add_argument("--good", type=float, default=None,
                        help="a final value counted as ending well (default: the pick's)")
    args = parser.parse_args(argv)
    searches = []
    for name in args.studies:  # every one checked before any is replayed
        try:
            study = optuna.load_study(study_name=name, storage=args.storage)
        except KeyError:
            parser.error(f"no search {name!r} in {args.storage}")
        definition = study.user_attrs["kraby_definition"]
        if definition["search"]["pruner"] != "none":
            parser.error(f"{name} ran with the {definition['search']['pruner']} pruner: "
                         "replay searches run with search.pruner=none")
        ran = ran_of(study, int(definition["steps"]) * int(definition["seeds"]))
        if not ran:
            parser.error(f"{name} has no complete trial")
        searches.append((name, definition, ran))
    totals = [0, 0, 0, 0]
    print("| search | complete | stopped (at env step) | of them ended well | pick stopped |")
    print("|---|---:|---|---:|---|")
    for name, definition, ran in searches:
        # The median pruner the search would have built, had it run with one.
        cfg = OmegaConf.create({"search": {**definition["search"], "pruner": "median"},
                                "budget": {"steps": definition["steps"],
                                           "seeds": definition["seeds"]}})
        stops = stopped_at(ran, make_pruner(cfg))
        pick = max(ran, key=lambda r: r.value)
        good = pick.value if args.good is None else args.good
        ended_well = sum(1 for r in ran if r.number in stops and r.value >= good)
        steps = ", ".join(f"t{n} ({s:,})" for n, s in sorted(stops.items()))
        print(f"| {name} | {len(ran)} | {len(stops)}{': ' + steps if steps else ''} | "
              f"{ended_well} | {'yes' if pick.number in stops else 'no'} (t{pick.number}) |")
        for i, count in enumerate((len(ran), len(stops), ended_well, pick.number in stops)):
            totals[i] += int(count)
    threshold = "the pick's score" if args.good is None else f"{args.good:g}"
    n = len(args.studies)
    print(f"pruner_replay: {n} search{'' if n == 1 else 'es'}; the median pruner stops "
          f"{totals[1]} of {totals[0]} complete trials; {totals[2]} of them ended at {threshold} "
          f"or better; {totals[3]} of the {n} pick{'' if n == 1 else 's'} among them")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
