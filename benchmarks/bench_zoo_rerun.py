"""Benchmark: a stranger's rerun of a handed-back rl-zoo3 file, against rl-zoo3's own settings.

Run: python benchmarks/bench_zoo_rerun.py FILE [--env ID] [--seeds S ...] [--steps N]
         [--episodes E] [--fail-below X] [--alternative greater|less|two-sided]
         [--storage URL --confirm NAME] [--out CSV] [--folder DIR] [--jobs J] [--smoke]

FILE is an rl-zoo3 hyperparameter file as ``kraby-study best --format zoo`` writes it. Both
its settings for the id and rl-zoo3's own (its installed ``hyperparams/ppo.yml``) are trained
by rl-zoo3's own trainer, as a user of rl-zoo3 would: ``python -m rl_zoo3.train --algo ppo
--env ID --seed S [-conf FILE] [-n N] --eval-freq -1 --vec-env dummy --num-threads 1 -f DIR``,
one subprocess a run, each in its own folder, on seeds the project never used (600-619 by
default), the two settings alternating seed by seed. A run's CPU seconds are the child's
resource usage (user + system, from ``os.wait4``): Python's start-up and imports included, a
few seconds a run alike for both settings. A run whose folder already holds its model and its
record for the same command is not trained again, so an interrupted rerun resumes.

Every saved model is scored with stable-baselines3's ``evaluate_policy`` on E fresh episodes
(200 by default, deterministic actions) on 10 envs stepped together, seeded 1,000,000 + 100 x
the training seed + 0 to 9, so no episode starts where a training env did, and both settings
of a seed meet the same episodes; with the VecNormalize statistics rl-zoo3 saved when the
settings normalise (frozen, rewards unnormalised). A run's score is the mean return of its
episodes.

Per setting: n, mean, interquartile mean (IQM: scipy's 25 % trimmed mean, the project's
``decision.intervals.iqm``) with its 95 % percentile bootstrap interval (scipy.stats.bootstrap,
9,999 resamples), seeds scoring below ``--fail-below`` (when given) and the mean CPU seconds a
run. Then the file's IQM minus rl-zoo3's with its 95 % percentile bootstrap interval (each
setting's seeds resampled apart), and Yuen's test of trimmed means (scipy.stats.ttest_ind,
trim 0.25, Welch's degrees of freedom), one-sided by ``--alternative`` (greater: the file's
settings score higher), at alpha 0.05, with both n.

With ``--storage URL --confirm NAME`` the rows of the project's own confirm of the same
settings are set beside the rerun's: the confirm's configurations whose stored settings equal
the file's and rl-zoo3's (read through the project's answers layer, compared setting by
setting, the whole rollout standing for an oversized minibatch), with the same columns from
their stored final scores and CPU seconds. A confirm that does not hold the file's settings
is refused before anything trains; one without rl-zoo3's is said so under the table.

Every run's row (the confirm's too) goes to ``--out`` (default zoo_rerun.csv). The last line
reads ``bench_zoo_rerun: IQM difference D [lo, hi]; Yuen p P (n A and B)``.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import math
import os
import shutil
import subprocess
import sys
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import yaml
from scipy import stats

from kraby_study.decision.intervals import iqm
from kraby_study.errors import ConfigError, StoreError

EVAL_SEED_OFFSET = 1_000_000
EVAL_ENVS = 10
"""A model is scored on EVAL_ENVS envs stepped together, the i-th seeded EVAL_SEED_OFFSET +
100 x (training seed) + i: apart from every training env (rl-zoo3 seeds S, S + 1, ... for
seed S) and from other seeds' evaluation envs, and the same for both settings of a seed."""
SEEDS = list(range(600, 620))
"""Default seeds: 20 the project's studies do not train by default (its runs start at seed 0,
its confirms at 1000). Not 500-513: the first such rerun (issue 83) trained those with
rl-zoo3's trainer, which repeats a run from its seed on one machine, so they would give its
runs again rather than new evidence."""
RESAMPLES = 9_999
LEVEL = 0.95
ALPHA = 0.05
SMOKE = {"seeds": [500], "steps": 300, "episodes": 3}
"""--smoke: one seed, a few hundred steps (SB3 still collects one whole rollout), 3 episodes."""


@dataclass(frozen=True)
class Setting:
    """One of the two settings retrained: the file's or rl-zoo3's own."""

    label: str
    conf: Path | None
    """The hyperparameter file; None for rl-zoo3's own ppo.yml."""
    entry: dict[str, Any]
    """Its entry for the env id, in rl-zoo3's keys."""


@dataclass
class Run:
    """One trained and scored run (a confirm's run: score and CPU from the store)."""

    setting: str
    source: str
    seed: int
    score: float
    cpu: float
    status: str = "ok"
    episodes: int = 0
    episode_sd: float = math.nan
    folder: str = ""


def fail(message: str) -> NoReturn:
    """Stop on bad input: one line, exit code 2."""
    print(f"bench_zoo_rerun: {message}", file=sys.stderr)
    raise SystemExit(2)


def read_entry(path: Path, env_id: str | None) -> tuple[str, dict[str, Any]]:
    """The env id and its entry in an rl-zoo3 hyperparameter file (the file's only id when
    ``env_id`` is None)."""
    try:
        table = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        fail(f"cannot read {path}: {str(error).splitlines()[0]}")
    if not isinstance(table, dict) or not table:
        fail(f"{path} is not an rl-zoo3 hyperparameter file (a mapping of env ids to settings)")
    if env_id is None:
        if len(table) != 1:
            fail(f"{path} holds {len(table)} ids ({', '.join(map(str, table))}): name one "
                 "with --env")
        env_id = str(next(iter(table)))
    if env_id not in table:
        fail(f"{path} has no entry for {env_id} (it has {', '.join(map(str, table))})")
    import gymnasium

    if env_id not in gymnasium.registry:
        fail(f"{env_id} is not a registered Gymnasium id")
    return env_id, dict(table[env_id])


def zoo_entry(env_id: str) -> tuple[str, dict[str, Any]]:
    """rl-zoo3's own entry for the id and the installed version, read as rl-zoo3 reads it."""
    from kraby_study.config.zoo import entries, zoo_version

    try:
        table = entries()
    except (ConfigError, StoreError) as error:
        fail(str(error))
    if env_id not in table:
        fail(f"rl-zoo3 {zoo_version()} publishes no PPO settings for {env_id}")
    return zoo_version(), dict(table[env_id])


def command(setting: Setting, env_id: str, seed: int, steps: int | None, folder: Path,
            threads: int) -> list[str]:
    """rl-zoo3's train command for one run, its log folder ``folder``."""
    args = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", env_id,
            "--seed", str(seed), "--eval-freq", "-1", "--vec-env", "dummy", "--num-threads",
            str(threads), "--log-interval", "-2", "--verbose", "0", "-f", str(folder)]
    if setting.conf is not None:
        args += ["-conf", str(setting.conf)]
    if steps is not None:
        args += ["-n", str(steps)]
    return args


def train(args: list[str], folder: Path) -> tuple[float, str]:
    """Train one run in ``folder`` (kept when it already holds this command's model): its
    CPU seconds (user + system of the child) and its status."""
    record = folder / "run.json"
    if record.is_file():
        held = json.loads(record.read_text())
        if held.get("command") == args[1:] and list(folder.rglob("*.zip")):
            return float(held["cpu"]), str(held["status"])
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    with (folder / "train.log").open("w") as log:
        child = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, cwd=folder)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
    cpu = usage.ru_utime + usage.ru_stime
    code = child.returncode
    ended = "ok" if code == 0 else f"error: exit {code} (see {folder / 'train.log'})"
    record.write_text(json.dumps({"command": args[1:], "cpu": cpu, "status": ended}))
    return cpu, ended


def score(folder: Path, env_id: str, seed: int, episodes: int) -> tuple[float, float]:
    """Mean and sd of the episode returns of a run's saved model: deterministic actions on
    ``episodes`` episodes of the evaluation envs of ``seed`` (:data:`EVAL_ENVS`; SB3 gives each
    env an equal share of the episodes, so short episodes are not favoured), observations
    normalised with the run's frozen VecNormalize statistics when rl-zoo3 saved them."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(1)
    models = sorted(folder.rglob(f"{env_id}.zip"))
    if not models:
        raise FileNotFoundError(f"no saved model {env_id}.zip under {folder}")
    env = make_vec_env(env_id, n_envs=min(EVAL_ENVS, episodes),
                       seed=EVAL_SEED_OFFSET + 100 * seed)
    saved = sorted(folder.rglob("vecnormalize.pkl"))
    if saved:
        env = VecNormalize.load(str(saved[0]), env)
        env.training, env.norm_reward = False, False
    # Schedules are pickled closures; they are not needed to act (as rl-zoo3's enjoy loads).
    model = PPO.load(models[0], device="cpu", custom_objects={
        "learning_rate": 0.0, "lr_schedule": lambda _: 0.0, "clip_range": lambda _: 0.0})
    returns, _ = evaluate_policy(model, env, n_eval_episodes=episodes, deterministic=True,
                                 return_episode_rewards=True)
    env.close()
    values = np.asarray(returns, dtype=float)
    return float(values.mean()), float(values.std(ddof=1)) if len(values) > 1 else math.nan


def canonical(ppo: dict[str, Any]) -> dict[str, Any]:
    """Settings as they train: a minibatch at least the rollout is the whole rollout."""
    rollout = int(ppo["n_steps"]) * int(ppo["n_envs"])
    size = ppo.get("batch_size")
    return {**ppo, "batch_size": rollout if size is None or int(size) >= rollout else int(size)}


def same(first: Any, second: Any) -> bool:
    """Two setting values equal, floats to a relative 1e-9 (a YAML round trip)."""
    if isinstance(first, bool) or isinstance(second, bool) or first is None or second is None:
        return first == second
    if isinstance(first, int | float) and isinstance(second, int | float):
        return math.isclose(first, second, rel_tol=1e-9, abs_tol=1e-12)
    if isinstance(first, list | tuple) and isinstance(second, list | tuple):
        return len(first) == len(second) and all(map(same, first, second))
    return first == second


def confirm_runs(url: str, name: str, env_id: str,
                 settings: dict[str, dict[str, Any]]) -> tuple[list[Run], dict[str, str]]:
    """The stored runs of confirm ``name`` whose settings are each of ``settings`` (label ->
    rl-zoo3 entry), read through the project's answers layer, and the configuration of each
    label the confirm holds (a label it does not hold is left out of both)."""
    from kraby_study.answers.seed_scores import swept_values
    from kraby_study.answers.study_data import load_study
    from kraby_study.config.zoo import translate
    from kraby_study.plan.spec import OPTIONAL_PPO
    from kraby_study.records.attributes import StudyKind, TrialAttrs
    from kraby_study.records.stored import Outcome, outcome
    from kraby_study.records.values import swept_value, value_key, value_label
    from kraby_study.store.store import opened_for_reading

    try:
        wanted = {label: translate(env_id, entry) for label, entry in settings.items()}
        with opened_for_reading(url) as store:
            if name not in store.study_names():
                fail(f"no study named {name!r} in {url}")
            data = load_study(store, name)
    except (ConfigError, StoreError) as error:
        fail(str(error).splitlines()[0])
    if data.kind != StudyKind.CONFIRM:
        fail(f"{name!r} is a {data.kind} study, not a confirm")
    parameter, values = swept_values(data.kind, data.definition, data.trials)
    by_value: dict[Any, list[Any]] = {}
    for trial in data.trials:
        by_value.setdefault(value_key(swept_value(trial, parameter, values)), []).append(trial)
    runs: list[Run] = []
    found: dict[str, str] = {}
    for label, zoo in wanted.items():
        ppo = canonical(zoo.ppo)
        for value in values:
            trials = by_value.get(value_key(value), [])
            kept = trials[0].user_attrs.get("settings", {}) if trials else {}
            env = kept.get("env", {})
            trained = canonical({**OPTIONAL_PPO, **kept.get("ppo", {})})
            if (env.get("id") == env_id and all(same(ppo[k], trained.get(k)) for k in ppo)
                    and all(same(v, env.get(k, v if k == "normalize_reward" else False))
                            for k, v in zoo.env.items())):
                found[label] = value_label(value)
                source = f"confirm {name!r}: {found[label]}"
                for trial in trials:
                    if outcome(trial) == Outcome.COMPLETE and trial.value is not None:
                        held = TrialAttrs.of(trial)
                        cpu = math.nan if held.cpu_time is None else float(held.cpu_time)
                        runs.append(Run(label, source, int(held.seed or 0), float(trial.value),
                                        cpu))
                break
    return runs, found


def interval(statistic: Any, samples: Sequence[np.ndarray]) -> tuple[float, float]:
    """95 % percentile bootstrap interval (each sample resampled apart); NaN below 2 values
    in a sample."""
    if any(len(x) < 2 for x in samples):
        return math.nan, math.nan
    result = stats.bootstrap(tuple(samples), statistic, n_resamples=RESAMPLES,
                             confidence_level=LEVEL, method="percentile", vectorized=True,
                             rng=np.random.default_rng(0))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def trimmed(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """The IQM along an axis, for the bootstrap (the same trimmed mean as ``iqm``)."""
    return stats.trim_mean(x, 0.25, axis=axis)


def number(value: float, digits: int = 1) -> str:
    """A number for the table; '-' for NaN."""
    return "-" if not math.isfinite(value) else f"{value:,.{digits}f}"


def p_text(p: float) -> str:
    """A p-value to 3 decimals, '< 0.001' below; '-' for NaN."""
    return "-" if not math.isfinite(p) else "< 0.001" if p < 0.001 else f"{p:.3f}"


def row(label: str, source: str, runs: list[Run], fail_below: float | None) -> list[str]:
    """A setting's table row from its runs."""
    scored = np.asarray([r.score for r in runs if math.isfinite(r.score)], dtype=float)
    errors = sum(1 for r in runs if not math.isfinite(r.score))
    low, high = interval(trimmed, [scored])
    failed = ("-" if fail_below is None or not len(scored)
              else f"{int(np.sum(scored < fail_below))} of {len(scored)}")
    cpu = [r.cpu for r in runs if math.isfinite(r.cpu)]
    return [label, source, str(len(scored)) + (f" ({errors} errors)" if errors else ""),
            number(float(scored.mean())) if len(scored) else "-",
            f"{number(iqm(scored))} [{number(low)}, {number(high)}]" if len(scored) else "-",
            failed, number(float(np.mean(cpu))) if cpu else "-"]


def print_table(rows: list[list[str]], fail_below: float | None) -> None:
    """The settings' table, in markdown."""
    below = f"failed (below {fail_below:g})" if fail_below is not None else "failed"
    header = ["setting", "source", "n", "mean", "IQM [95 % percentile bootstrap CI]", below,
              "CPU s a run"]
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join(["---"] * 2 + ["---:"] * 5) + "|")
    for cells in rows:
        print("| " + " | ".join(cells) + " |")


def compare(first: list[Run], second: list[Run], names: tuple[str, str],
            alternative: str) -> str:
    """The difference of IQMs with its interval, Yuen's test, and the CPU ratio; the summary
    line."""
    a = np.asarray([r.score for r in first if math.isfinite(r.score)], dtype=float)
    b = np.asarray([r.score for r in second if math.isfinite(r.score)], dtype=float)
    difference = iqm(a) - iqm(b) if len(a) and len(b) else math.nan
    low, high = interval(lambda x, y, axis=-1: trimmed(x, axis) - trimmed(y, axis), [a, b])
    p = (float(stats.ttest_ind(a, b, equal_var=False, trim=0.25, alternative=alternative).pvalue)
         if len(a) >= 2 and len(b) >= 2 else math.nan)
    said = {"greater": f"{names[0]} scores higher", "less": f"{names[0]} scores lower",
            "two-sided": "the two differ"}[alternative]
    print(f"\nIQM difference, {names[0]} - {names[1]}: {number(difference)} "
          f"[{number(low)}, {number(high)}] (95 % percentile bootstrap, {RESAMPLES:,} "
          "resamples, each setting's seeds resampled apart)")
    answer = ("-" if not math.isfinite(p)
              else "shown" if p < ALPHA else "not shown")
    trim = ("25 % trimmed from each end, Welch's df" if min(len(a), len(b)) >= 4
            else "below 4 seeds nothing is trimmed, so it is Welch's t-test")
    print(f"test: Yuen's trimmed-mean t-test (scipy.stats.ttest_ind trim=0.25, "
          f"equal_var=False; {trim}), alternative {alternative} ({said}): "
          f"p {p_text(p)}; alpha {ALPHA}: {answer}; n {len(a)} and {len(b)}")
    cpu = [np.mean([r.cpu for r in runs]) if runs else math.nan for runs in (first, second)]
    print(f"CPU s a run, {names[0]} / {names[1]}: {number(cpu[0] / cpu[1], 2)}")
    return (f"bench_zoo_rerun: IQM difference {number(difference)} [{number(low)}, "
            f"{number(high)}]; Yuen p {p_text(p)} (n {len(a)} and {len(b)})")


def write_rows(path: Path, env_id: str, runs: list[Run]) -> None:
    """Every run as a CSV row."""
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["setting", "source", "env", "seed", "score", "episodes",
                         "episode_sd", "cpu_s", "status", "folder"])
        for r in runs:
            writer.writerow([r.setting, r.source, env_id, r.seed, r.score, r.episodes,
                             r.episode_sd, r.cpu, r.status, r.folder])


def parse(argv: Sequence[str] | None) -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("file", type=Path, help="rl-zoo3 hyperparameter file (best --format "
                        "zoo)")
    parser.add_argument("--env", help="env id (default: the file's only id)")
    parser.add_argument("--seeds", type=int, nargs="+", default=SEEDS,
                        help="training seeds (default 600-619)")
    parser.add_argument("--steps", type=int, help="env steps a run (rl-zoo3's -n; default: "
                        "each setting's n_timesteps)")
    parser.add_argument("--episodes", type=int, default=200, help="evaluation episodes a model")
    parser.add_argument("--fail-below", type=float, help="a seed scoring below this failed")
    parser.add_argument("--alternative", choices=("greater", "less", "two-sided"),
                        default="greater", help="Yuen's test: the file's settings score "
                        "higher (greater), lower (less), or differ")
    parser.add_argument("--storage", help="the store holding --confirm")
    parser.add_argument("--confirm", help="the project's confirm study of the same settings")
    parser.add_argument("--out", type=Path, default=Path("zoo_rerun.csv"), help="per-run CSV")
    parser.add_argument("--folder", type=Path, default=Path("zoo_rerun"),
                        help="where each run's rl-zoo3 log folder goes")
    parser.add_argument("--jobs", type=int, default=1, help="runs trained at once")
    parser.add_argument("--threads", type=int, default=1, help="torch threads a run")
    parser.add_argument("--smoke", action="store_true",
                        help="one seed, 300 steps, 3 episodes: checks the script runs")
    args = parser.parse_args(argv)
    if args.smoke:
        args.seeds, args.steps, args.episodes = SMOKE["seeds"], SMOKE["steps"], SMOKE["episodes"]
    if len(set(args.seeds)) != len(args.seeds) or min(args.seeds) < 0:
        fail("--seeds: give distinct seeds, 0 or more")
    if args.episodes < 1 or args.jobs < 1 or args.threads < 1:
        fail("--episodes, --jobs and --threads take 1 or more")
    if args.steps is not None and args.steps < 1:
        fail("--steps takes 1 or more")
    if (args.storage is None) != (args.confirm is None):
        fail("give --storage and --confirm together")
    if not args.file.is_file():
        fail(f"no file {args.file}")
    if not args.out.parent.is_dir():
        fail(f"--out {args.out}: no folder {args.out.parent}")
    if importlib.util.find_spec("rl_zoo3") is None:
        fail("rl-zoo3 is not installed: pip install 'kraby-study[zoo]'")
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = parse(argv)
    env_id, entry = read_entry(args.file, args.env)
    version, own = zoo_entry(env_id)
    handed = Setting(args.file.name, args.file.resolve(), entry)
    published = Setting(f"rl-zoo3 {version} ppo.yml", None, own)
    confirmed: list[Run] = []
    found: dict[str, str] = {}
    if args.confirm is not None:
        confirmed, found = confirm_runs(args.storage, args.confirm, env_id,
                                        {s.label: s.entry for s in (handed, published)})
        if handed.label not in found:
            fail(f"confirm {args.confirm!r} holds no configuration with the settings of "
                 f"{handed.label} for {env_id}")
    steps = {s.label: args.steps or int(float(s.entry.get("n_timesteps", 0))) or None
             for s in (handed, published)}
    print(f"bench_zoo_rerun: {env_id}, {handed.label} against {published.label}, rl-zoo3's "
          f"trainer; seeds {', '.join(map(str, args.seeds))}; steps a run "
          + ", ".join(f"{label} {n:,}" if n else f"{label} rl-zoo3's"
                      for label, n in steps.items())
          + f"; {args.episodes} deterministic episodes a model (envs seeded "
          f"{EVAL_SEED_OFFSET:,} + 100 x the training seed + 0 to {EVAL_ENVS - 1})", flush=True)

    folder = args.folder.resolve()
    jobs = [(setting, seed, folder / ("file" if setting is handed else "zoo") / f"seed{seed}")
            for seed in args.seeds for setting in (handed, published)]
    runs: list[Run] = []
    with ThreadPoolExecutor(args.jobs) as pool:
        started = [pool.submit(train, command(s, env_id, seed, args.steps, where, args.threads),
                               where) for s, seed, where in jobs]
        for (setting, seed, where), job in zip(jobs, started, strict=True):
            cpu, status = job.result()
            mean = sd = math.nan
            if status == "ok":
                mean, sd = score(where, env_id, seed, args.episodes)
            runs.append(Run(setting.label, "rerun", seed, mean, cpu, status, args.episodes, sd,
                            str(where)))
            print(f"  {setting.label} seed {seed}: score {number(mean)} "
                  f"(sd {number(sd)} over {args.episodes} episodes), {cpu:.1f} CPU s, {status}",
                  flush=True)

    print()
    rows = [row(s.label, "rerun", [r for r in runs if r.setting == s.label], args.fail_below)
            for s in (handed, published)]
    if args.confirm is not None:
        rows += [row(s.label, f"confirm {args.confirm!r}: {found[s.label]}",
                     [r for r in confirmed if r.setting == s.label], args.fail_below)
                 for s in (handed, published) if s.label in found]
    print_table(rows, args.fail_below)
    if args.confirm is not None and published.label not in found:
        print(f"(confirm {args.confirm!r} holds no configuration with {published.label}'s "
              "settings)")
    line = compare([r for r in runs if r.setting == handed.label],
                   [r for r in runs if r.setting == published.label],
                   (handed.label, published.label), args.alternative)
    write_rows(args.out, env_id, runs + confirmed)
    print(f"wrote {args.out} ({len(runs) + len(confirmed)} runs)")
    print(line)


if __name__ == "__main__":
    main()
