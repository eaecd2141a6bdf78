"""The evaluation measure of a stored study's saved models: each complete trial's model (and
its VecNormalize statistics, if saved) run by its env's adapter, deterministic actions, over
the evaluation episodes of its seed's own evaluation stream (apart from its training streams),
beside the trial's training score; then the mean and standard deviation of both per value (a
confirm study's configuration, a sweep's value).

Run: python experiments/eval_models.py --storage sqlite:///studies/kraby.db --study-name NAME
[--episodes 10]

This is the measure rl-zoo3's benchmark table publishes (its evaluation's mean return), for
studies whose runs were scored on training episodes (sweeps and confirm studies).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import optuna
from stable_baselines3 import PPO

from kraby_study.env import adapter_for, saved_normalizer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--storage", required=True)
    parser.add_argument("--study-name", required=True)
    parser.add_argument("--episodes", type=int, default=10)
    args = parser.parse_args()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.load_study(study_name=args.study_name, storage=args.storage)
    rows = []
    for trial in study.trials:
        attrs = trial.user_attrs
        path = attrs.get("model_path")
        if trial.state != optuna.trial.TrialState.COMPLETE or not path or not Path(path).is_file():
            continue
        env = attrs["settings"]["env"]
        normalizer = saved_normalizer(path)
        score = adapter_for(env).evaluate(PPO.load(path, device="cpu"), env, args.episodes,
                                          normalizer, seed=attrs.get("seed")).mean
        group = ", ".join(f"{k}={v}" for k, v in trial.params.items()) or "all"
        rows.append((group, attrs.get("final_score"), score))
        print(f"{attrs.get('key')} ({group}): training score {attrs.get('final_score'):.1f}, "
              f"evaluation {score:.1f}")
    for group in dict.fromkeys(r[0] for r in rows):
        mine = [r for r in rows if r[0] == group]
        if len(mine) < 2:
            continue
        for name, column in (("training score", 1), ("evaluation", 2)):
            values = [r[column] for r in mine]
            print(f"{group}: {name} mean {statistics.mean(values):.1f}, sd "
                  f"{statistics.stdev(values):.1f} over {len(values)} runs")


if __name__ == "__main__":
    main()
