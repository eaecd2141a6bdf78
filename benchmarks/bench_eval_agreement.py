"""Benchmark: this tool's evaluation scores against stable-baselines3's own evaluator, on the same
saved models; and the evaluation's cost as a share of training.

Run: python benchmarks/bench_eval_agreement.py [--folder DIR] [--seeds 6] [--workers 2]
    [--episodes 200] [--tool-episodes N] [--scored] [env=gym env.id=Pendulum-v1 ppo=zoo ...]

1. Trains the settings given (default: rl-zoo3's Pendulum-v1 settings at rl-zoo3's 100,000
   steps, ``ppo=zoo budget=zoo``) with this tool on ``--seeds`` seeds from 0 (``kraby-study
   confirm --baseline ppo=NAME search.objective=evaluation``, models saved): each run is
   scored as the tool scores it, the deterministic policy's mean return over the default
   number of evaluation episodes drawn from the run's own evaluation stream, with the
   standard error of that mean from its episodes.
2. Scores every saved model again with SB3's ``evaluate_policy`` (deterministic, ``--episodes``
   episodes on ``make_vec_env(ID, n_envs=1, seed=SB3_SEED + run seed)``: each model its own
   episodes, so the models' evaluations are independent, as the tool's are; with the model's
   VecNormalize statistics when it has them), the standard error from the episode returns.
   ``--tool-episodes N`` scores the tool's side again on the first N episodes of each run's
   evaluation stream (the stored score is its first ``eval_episodes``); ``--scored`` skips the
   training and scores the store already in ``--folder``.
3. Prints, per model, both scores, their difference and z = difference / sqrt(se_tool^2 +
   se_sb3^2); then the mean over the models of both and the z of that difference (the models'
   evaluations are independent, so its standard error is the root sum of squares over n);
   and the CPU seconds one evaluation takes (one torch thread, as a worker) against the
   trial's CPU seconds (its training and its evaluation).

The last line: ``agreement: mean tool T (se a) vs SB3 S (se b), z Z; max |z| per model M over
N models; evaluation P % of training``. Scores agree when |z| stays below 2 (about 95 % of
differences of two independent unbiased estimates of one mean do).
"""

from __future__ import annotations

import argparse
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SB3_SEED = 987_654_321
"""Seed of SB3's evaluation env, plus the run's seed: its first reset is seeded with it and
later ones continue the env's generator, apart from every training stream (children of
SeedSequence(run seed)) and evaluation stream here. One seed for every model would score them
all on one set of episodes, whose sampling error the mean over models would then share."""


def train(folder: Path, seeds: int, workers: int, overrides: list[str]) -> Path:
    """Train the settings on seeds 0 .. seeds - 1 with the tool's confirm; the store's path."""
    store = folder / "agreement.db"
    baseline = next((o.split("=", 1)[1] for o in overrides if o.startswith("ppo=")), "zoo")
    rest = [o for o in overrides if not o.startswith("ppo=")]
    command = [sys.executable, "-m", "kraby_study.cli", "confirm", "--baseline",
               f"ppo={baseline}", "--seeds", str(seeds), "--workers", str(workers),
               "--storage", f"sqlite:///{store}", "confirm.seed=0",
               "search.objective=evaluation", "save_models=true",
               f"models_dir={folder / 'models'}", *rest]
    print("$", " ".join(command[2:]), flush=True)
    subprocess.run(command, check=True, cwd=folder)
    return store


def sb3_scores(model: object, env_id: str, episodes: int, normalizer_file: Path | None,
               seed: int) -> np.ndarray:
    """The episode returns of SB3's evaluate_policy on a fresh env seeded ``seed``."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import VecNormalize

    env = make_vec_env(env_id, n_envs=1, seed=seed)
    if normalizer_file is not None and normalizer_file.is_file():
        env = VecNormalize.load(str(normalizer_file), env)
        env.training, env.norm_reward = False, False
    returns, _ = evaluate_policy(model, env, n_eval_episodes=episodes, deterministic=True,
                                 return_episode_rewards=True)
    env.close()
    return np.asarray(returns, dtype=float)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--folder", type=Path, default=None,
                        help="where the store and models go (default: a new temporary folder)")
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--tool-episodes", type=int, default=None,
                        help="score the tool's side on this many episodes of each run's "
                             "stream (default: the stored score's)")
    parser.add_argument("--scored", action="store_true",
                        help="score the store already in --folder, without training")
    parser.add_argument("overrides", nargs="*",
                        default=["env=gym", "env.id=Pendulum-v1", "ppo=zoo", "budget=zoo"])
    args = parser.parse_args()
    folder = args.folder or Path(tempfile.mkdtemp(prefix="agreement-"))
    folder.mkdir(parents=True, exist_ok=True)
    store = (folder / "agreement.db" if args.scored
             else train(folder, args.seeds, args.workers, list(args.overrides)))

    import optuna
    import torch
    from stable_baselines3 import PPO

    from kraby_study.env import adapter_for, normalizer_path, saved_normalizer

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    torch.set_num_threads(1)
    [name] = [s.study_name for s in optuna.get_all_study_summaries(f"sqlite:///{store}")]
    study = optuna.load_study(study_name=name, storage=f"sqlite:///{store}")
    rows = []
    print(f"{'seed':>5} {'tool':>9} {'se':>6} {'SB3':>9} {'se':>6} {'diff':>8} {'z':>6} "
          f"{'eval CPU s':>7} {'trial CPU s':>8}")
    for trial in sorted(study.trials, key=lambda t: t.user_attrs.get("seed", 0)):
        attrs = trial.user_attrs
        if trial.state != optuna.trial.TrialState.COMPLETE or "eval_errors" not in attrs:
            continue
        env = attrs["settings"]["env"]
        path = Path(attrs["model_path"])
        model = PPO.load(str(path), device="cpu")
        stats = normalizer_path(path)
        normalizer = saved_normalizer(path)
        stored = int(study.user_attrs["kraby_definition"]["eval_episodes"])
        episodes = args.tool_episodes or stored
        if not rows:  # imports and first calls are not the evaluation's cost
            adapter_for(env).evaluate(model, env, 2, normalizer, seed=attrs["seed"])
        t0 = time.process_time()
        again = adapter_for(env).evaluate(model, env, episodes, normalizer, seed=attrs["seed"])
        seconds = time.process_time() - t0
        tool, tool_se = again.mean, again.error
        if episodes == stored:
            assert math.isclose(again.mean, float(trial.value), rel_tol=1e-9), (
                "the stored score is not rescored")
        theirs = sb3_scores(model, str(env["id"]), args.episodes, stats,
                            SB3_SEED + int(attrs["seed"]))
        sb3, sb3_se = float(theirs.mean()), float(theirs.std(ddof=1) / math.sqrt(len(theirs)))
        z = (tool - sb3) / math.hypot(tool_se, sb3_se)
        rows.append((tool, tool_se, sb3, sb3_se, z, seconds, float(attrs["cpu_time"])))
        print(f"{attrs['seed']:>5} {tool:>9.1f} {tool_se:>6.1f} {sb3:>9.1f} {sb3_se:>6.1f} "
              f"{tool - sb3:>8.1f} {z:>6.2f} {seconds:>7.2f} {attrs['cpu_time']:>8.1f}")
    n = len(rows)
    tools, tool_ses, sb3s, sb3_ses, zs, evals, trains = (np.array(c) for c in zip(*rows,
                                                                                strict=True))
    mean_tool, mean_sb3 = float(tools.mean()), float(sb3s.mean())
    se_tool = float(math.sqrt(np.sum(tool_ses ** 2)) / n)
    se_sb3 = float(math.sqrt(np.sum(sb3_ses ** 2)) / n)
    z_mean = (mean_tool - mean_sb3) / math.hypot(se_tool, se_sb3)
    share = float(np.median(evals / trains))
    print(f"models: {n}; tool episodes {episodes} per model (own stream), SB3 {args.episodes} "
          f"per model; between-seed sd: tool {statistics.stdev(tools):.1f}, SB3 "
          f"{statistics.stdev(sb3s):.1f}; tool's per-episode sd "
          f"{float(np.sqrt(np.mean(tool_ses ** 2)) * math.sqrt(episodes)):.1f}")
    print(f"agreement: mean tool {mean_tool:.1f} (se {se_tool:.1f}) vs SB3 {mean_sb3:.1f} "
          f"(se {se_sb3:.1f}), z {z_mean:.2f}; max |z| per model {np.max(np.abs(zs)):.2f} over "
          f"{n} models; evaluation {100 * share:.1f} % of training")


if __name__ == "__main__":
    main()
