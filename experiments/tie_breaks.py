"""Benchmark analysis: which of a search's trials tied at its top score confirm best.

Run: python experiments/tie_breaks.py --storage URL --arms NAME [NAME] --seeds 0 1 2

Where a reward has a ceiling (CartPole-v1's 500), many trials of a search reach it on their
search seeds; the pick among them was the first by trial number (Optuna's best trial), and is
now the cheapest (``best`` and ``confirm --top 1``: ``kraby_study.records.values.ranking``).
This reads, per arm and sampler seed, the search ``NAME-sS`` and a
confirm of every distinct trial tied at its top score, ``NAME-sS-ties`` (made by
``kraby-study confirm --study-name NAME-sS --top N confirm.name=NAME-sS-ties``, N the number
tied), and prints each tied trial's confirmed mean (over the confirm's fresh seeds, to 0.1)
beside what three tie-breaks would pick:

- ``first``: the lowest trial number (the pick before);
- ``curve``: the highest mean of the trial's stored intermediate values (the scores the
  pruner saw along training: the area under its learning curve), then the lowest number;
- ``cheapest``: the fewest CPU seconds per search seed, then the lowest number (the pick
  now).

With two arms it prints, per tie-break, the first arm's confirmed mean minus the second's at
each sampler seed, and the means as ``--first-means``/``--second-means`` for
``paired_picks.py``, which tests them.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import optuna  # noqa: E402
from paired_picks import signed  # noqa: E402

from kraby_study.records.stored import search_key  # noqa: E402
from kraby_study.records.values import ranking, value_key  # noqa: E402

RULES: dict[str, Callable[[optuna.trial.FrozenTrial], tuple[float, ...]]] = {
    "first": lambda t: (0.0, t.number),
    "curve": lambda t: (-statistics.fmean(t.intermediate_values.values()), t.number),
    "cheapest": lambda t: ranking(t)[1:],
}
"""Each tie-break as a sort key over the tied trials: the smallest is picked."""


@dataclass
class Ties:
    """A search's trials tied at its top score, and their confirmed means by trial key."""

    search: str
    top: float
    trials: list[optuna.trial.FrozenTrial]
    confirmed: dict[str, float]

    def pick(self, rule: str) -> optuna.trial.FrozenTrial:
        """The tied trial a tie-break picks."""
        return min(self.trials, key=RULES[rule])

    def mean_of(self, trial: optuna.trial.FrozenTrial) -> float:
        """A tied trial's confirmed mean."""
        return self.confirmed[key_of(trial)]


def key_of(trial: optuna.trial.FrozenTrial) -> str:
    """A search trial's key, as its confirm names the configuration."""
    return str(trial.user_attrs.get("key", search_key(trial.number)))


def loaded(storage: str, name: str) -> optuna.Study:
    """A stored study; the analysis stops in one line if there is none of that name."""
    try:
        return optuna.load_study(study_name=name, storage=storage)
    except KeyError:
        raise SystemExit(f"tie_breaks: no study {name!r} in {storage}") from None


def tied_trials(storage: str, search: str) -> tuple[float, list[optuna.trial.FrozenTrial]]:
    """A search's top score and its complete trials at it, one per distinct setting (the
    first by number, by confirm's own equality of settings), as ``confirm --top`` takes
    them."""
    done = [t for t in loaded(storage, search).trials if t.state == optuna.trial.TrialState.COMPLETE
            and "recheck_of" not in t.user_attrs]
    if not done:
        raise SystemExit(f"tie_breaks: {search} has no complete trial")
    top = max(float(t.values[0]) for t in done)
    seen: set[object] = set()
    tied = []
    for trial in sorted(done, key=lambda t: t.number):
        setting = value_key(trial.user_attrs.get("settings"))
        if float(trial.values[0]) == top and setting not in seen:
            seen.add(setting)
            tied.append(trial)
    return top, tied


def confirmed_means(storage: str, name: str) -> dict[str, float]:
    """A confirm's mean score per configuration (over its fresh seeds, to 0.1); the analysis
    stops if a run of it has not ended."""
    study = loaded(storage, name)
    if any(not t.state.is_finished() for t in study.trials):
        raise SystemExit(f"tie_breaks: {name} is not finished")
    scores: dict[str, list[float]] = {}
    for trial in study.trials:
        if trial.state == optuna.trial.TrialState.COMPLETE:
            scores.setdefault(str(trial.params["config"]), []).append(
                float(trial.user_attrs["final_score"]))
    return {key: round(statistics.fmean(values), 1) for key, values in scores.items()}


def read_ties(storage: str, search: str) -> Ties:
    """A search's ties and their confirm; stops if the confirm lacks a tied trial."""
    top, trials = tied_trials(storage, search)
    confirmed = confirmed_means(storage, f"{search}-ties")
    missing = [key_of(t) for t in trials if key_of(t) not in confirmed]
    if missing:
        raise SystemExit(f"tie_breaks: {search}-ties has no complete run of "
                         f"{', '.join(missing)}")
    return Ties(search, top, trials, confirmed)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--storage", required=True)
    parser.add_argument("--arms", nargs="+", required=True,
                        help="one or two arms: their searches' names before -sN")
    parser.add_argument("--seeds", type=int, nargs="+", required=True, help="sampler seeds")
    args = parser.parse_args(argv)
    if len(args.arms) > 2:
        parser.error("--arms takes one or two arms")
    ties = {(arm, seed): read_ties(args.storage, f"{arm}-s{seed}")
            for arm in args.arms for seed in args.seeds}

    print("| search | top score | tied | confirmed: mean of the ties [min, max] | "
          + " | ".join(RULES) + " |")
    print("|---|---:|---:|---|" + "---|" * len(RULES))
    for tie in ties.values():
        means = [tie.mean_of(t) for t in tie.trials]
        picks = [f"{key_of(pick)}: {tie.mean_of(pick):.1f}"
                 for pick in map(tie.pick, RULES)]
        print(f"| {tie.search} | {tie.top:.1f} | {len(tie.trials)} | "
              f"{statistics.fmean(means):.1f} [{min(means):.1f}, {max(means):.1f}] | "
              + " | ".join(picks) + " |")
    if len(args.arms) == 1:
        return 0
    first, second = args.arms
    for rule in RULES:
        a = [ties[(first, s)].mean_of(ties[(first, s)].pick(rule)) for s in args.seeds]
        b = [ties[(second, s)].mean_of(ties[(second, s)].pick(rule)) for s in args.seeds]
        differences = [signed(round(x - y, 1)) for x, y in zip(a, b, strict=True)]
        print(f"tie_breaks {rule}: {first} - {second} {' '.join(differences)}; "
              f"--first-means {' '.join(f'{x:.1f}' for x in a)} "
              f"--second-means {' '.join(f'{y:.1f}' for y in b)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
