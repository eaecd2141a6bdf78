"""Benchmark: a trial on three Gymnasium envs against plain SB3 with the same settings.

Run: python benchmarks/bench_gym.py [--env ID ...] [--steps N] [--repeats 3]

Each env (default: Pendulum-v1, MountainCarContinuous-v0 and CartPole-v1) trains rl-zoo3's
own PPO settings for its id on both sides, one torch thread, on the CPU. The kraby side is the
trial a worker runs for ``env=gym env.id=ID ppo=zoo`` (``run.trial.run_trial`` of the spec
``train`` plans: the env seam's stream-seeded DummyVecEnv, VecNormalize where rl-zoo3
normalises, the episode recorder, CPU-time accounting, the score), with the trial modules
loaded first as a worker loads them. The plain side is what a user writes without kraby-study:
``make_vec_env``, ``VecNormalize`` where rl-zoo3's entry says ``normalize``, and
``PPO(...).learn()`` with a callback that stops it where a trial stops (at the budget, inside
the rollout that reaches it, which is not learnt from), so both sides make the same updates.

The plain side's settings are built here from rl-zoo3's ppo.yml entry for the id (read from
the installed package's files), independently of kraby-study's translation, and checked to
equal what the trial passes to SB3's ``PPO`` and its env (SB3's own defaults filled in on both
sides) before anything is timed; any difference stops the benchmark.

Each side runs in a fresh process, the two interleaved, ``--repeats`` times per env; speeds
are env steps per second from the env's construction to the end of learning, and the ratio is
taken within each repeat (so both sides see the same load), then its median per env. Each
side's CPU seconds over the same span (user + system) give a second ratio, of steps per CPU
second, which other work on a shared machine disturbs less than the wall clock.
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import inspect
import json
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

import yaml

STEPS = {"Pendulum-v1": 20480, "MountainCarContinuous-v0": 20000, "CartPole-v1": 20480}
"""Default budget per env: Pendulum 5 rollouts of 4 x 1,024, CartPole 80 of 8 x 32,
MountainCarContinuous its whole rl-zoo3 budget (2,500 rollouts of 8 steps)."""
SEED = 0

PLAIN = r"""
import json, resource, sys, time
import torch
torch.set_num_threads(1)
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecNormalize


class Stop(BaseCallback):
    # A trial stops at its budget inside the rollout that reaches it, which is not learnt from.
    def _on_step(self):
        return self.num_timesteps < steps


def setting(value):
    # rl-zoo3's lin_<number>: linearly from the number to 0 over the run.
    if isinstance(value, dict):
        return LinearSchedule(start=value["linear"], end=0.0, end_fraction=1.0)
    return value


steps, settings = int(sys.argv[1]), json.loads(sys.argv[2])
kwargs = {name: setting(value) for name, value in settings["ppo"].items()}
policy_kwargs = dict(settings["policy_kwargs"])
if "activation_fn" in policy_kwargs:
    policy_kwargs["activation_fn"] = getattr(torch.nn, policy_kwargs["activation_fn"])
def cpu():
    # CPU seconds of this process, as a trial counts them (user + system).
    own = resource.getrusage(resource.RUSAGE_SELF)
    return own.ru_utime + own.ru_stime


t0, cpu0 = time.perf_counter(), cpu()
env = make_vec_env(settings["id"], n_envs=settings["n_envs"], seed=settings["seed"])
if settings["normalize"] is not None:
    env = VecNormalize(env, **settings["normalize"])
model = PPO("MlpPolicy", env, policy_kwargs=policy_kwargs or None, seed=settings["seed"],
            device="cpu", verbose=0, **kwargs)
model.learn(total_timesteps=steps, callback=Stop())
print(json.dumps({"seconds": time.perf_counter() - t0, "cpu": cpu() - cpu0,
                  "steps": model.num_timesteps}))
"""

KRABY = r"""
import json, sys
import torch
torch.set_num_threads(1)
import kraby_study.run.callback  # loaded before the trial, as a worker loads it
from kraby_study.config.compose import compose_config
from kraby_study.plan.train import train_plan
from kraby_study.run.trial import run_trial

steps, env_id = int(sys.argv[1]), sys.argv[2]
cfg = compose_config(["env=gym", f"env.id={env_id}", "ppo=zoo", f"budget.steps={steps}",
                      "save_models=false"])
result = run_trial(train_plan(cfg).specs[0])
print(json.dumps({"seconds": result.wall_time, "cpu": result.cpu_time,
                  "steps": result.env_steps}))
"""


# -- the plain side's settings, from rl-zoo3's entry ---------------------------------------

def zoo_entry(env_id: str) -> dict[str, Any]:
    """rl-zoo3's ppo.yml entry for ``env_id``, from the installed package's files."""
    spec = importlib.util.find_spec("rl_zoo3")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("rl-zoo3 is not installed: pip install -e '.[test]'")
    path = Path(next(iter(spec.submodule_search_locations))) / "hyperparams" / "ppo.yml"
    return dict(yaml.safe_load(path.read_text())[env_id])


def _zoo_value(value: Any) -> Any:
    """A number, or rl-zoo3's ``lin_<number>`` as ``{"linear": number}``."""
    if isinstance(value, str) and value.startswith("lin_"):
        return {"linear": float(value[4:])}
    return value


def _keywords(text: str) -> dict[str, Any]:
    """``dict(a=1, activation_fn=nn.ReLU)`` as data (``nn.NAME`` as ``NAME``)."""
    call = ast.parse(text.strip(), mode="eval").body
    assert isinstance(call, ast.Call) and not call.args, text
    out = {}
    for keyword in call.keywords:
        node = keyword.value
        out[keyword.arg] = (node.attr if isinstance(node, ast.Attribute)
                            else ast.literal_eval(node))
    return out


def plain_settings(env_id: str) -> dict[str, Any]:
    """What a user passes to plain SB3 for rl-zoo3's entry of ``env_id`` (as JSON data)."""
    entry = zoo_entry(env_id)
    skip = {"n_envs", "n_timesteps", "policy", "policy_kwargs", "normalize"}
    ppo = {name: _zoo_value(value) for name, value in entry.items() if name not in skip}
    n_envs = int(entry.get("n_envs", 1))
    if "batch_size" in ppo:
        # SB3 trains a minibatch larger than the rollout as the whole rollout (MountainCar's
        # 256 on its 8-step rollout is one minibatch of 8): passed as the size SB3 trains.
        ppo["batch_size"] = min(int(ppo["batch_size"]), int(ppo.get("n_steps", 2048)) * n_envs)
    normalize = entry.get("normalize", False)
    if isinstance(normalize, str):
        normalize = ast.literal_eval(normalize)
    if normalize:
        # rl-zoo3 gives VecNormalize the entry's gamma.
        normalize = {**(normalize if isinstance(normalize, dict) else {}),
                     **({"gamma": entry["gamma"]} if "gamma" in entry else {})}
    return {"id": env_id, "seed": SEED, "n_envs": n_envs,
            "normalize": normalize or None, "ppo": ppo,
            "policy_kwargs": _keywords(entry["policy_kwargs"]) if "policy_kwargs" in entry
            else {}}


# -- the trial's settings, as it passes them to SB3 ------------------------------------------

def trial_settings(env_id: str, steps: int) -> dict[str, Any]:
    """What the trial passes to SB3's ``PPO`` and its env, in :func:`plain_settings`' form."""
    import stable_baselines3
    from stable_baselines3.common.utils import LinearSchedule
    from stable_baselines3.common.vec_env import VecNormalize

    from kraby_study.config.compose import compose_config
    from kraby_study.plan.train import train_plan
    from kraby_study.run import trial

    cfg = compose_config(["env=gym", f"env.id={env_id}", "ppo=zoo", f"budget.steps={steps}",
                          "save_models=false"])
    spec = train_plan(cfg).specs[0]
    passed: dict[str, Any] = {}

    class Capture:  # stands in for PPO: keeps what build_model passes
        def __init__(self, policy: str, env: Any, **kwargs: Any) -> None:
            passed.update(kwargs, policy=policy)

        def set_logger(self, logger: Any) -> None:
            pass

    env = trial.make_env(spec, spec.seed)
    real, stable_baselines3.PPO = stable_baselines3.PPO, Capture
    try:
        trial.build_model(spec, env, spec.seed)
    finally:
        stable_baselines3.PPO = real
        env.close()
    assert passed.pop("policy") == "MlpPolicy" and passed.pop("device") == "cpu"
    assert passed.pop("verbose") == 0
    for name, value in passed.items():
        if isinstance(value, LinearSchedule):
            assert (value.end, value.end_fraction) == (0.0, 1.0), (name, value)
            passed[name] = {"linear": value.start}
    policy_kwargs = dict(passed.pop("policy_kwargs"))
    policy_kwargs["activation_fn"] = policy_kwargs["activation_fn"].__name__
    arch = policy_kwargs["net_arch"]
    if isinstance(arch, dict) and arch["pi"] == arch["vf"]:
        policy_kwargs["net_arch"] = arch["pi"]
    normalize = None
    if isinstance(env, VecNormalize):
        normalize = {"norm_obs": env.norm_obs, "norm_reward": env.norm_reward,
                     "gamma": env.gamma}
    return {"id": env_id, "seed": passed.pop("seed"), "n_envs": env.num_envs,
            "normalize": normalize, "ppo": passed, "policy_kwargs": policy_kwargs}


def _complete(settings: dict[str, Any]) -> dict[str, Any]:
    """Settings with SB3's own defaults (PPO, MlpPolicy, VecNormalize) in every gap."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.vec_env import VecNormalize

    def defaults(call: Any, names: Any) -> dict[str, Any]:
        parameters = inspect.signature(call).parameters
        return {n: parameters[n].default for n in names}

    ppo = defaults(PPO.__init__, ["n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda",
                                  "clip_range", "ent_coef", "vf_coef", "max_grad_norm",
                                  "learning_rate", "use_sde", "sde_sample_freq"])
    policy = defaults(ActorCriticPolicy.__init__, ["ortho_init", "log_std_init"])
    policy.update(net_arch=[64, 64], activation_fn="Tanh")  # MlpPolicy's net_arch=None
    normalize = settings["normalize"]
    if normalize is not None:
        normalize = {**defaults(VecNormalize.__init__, ["norm_obs", "norm_reward", "gamma"]),
                     **normalize}
    return {**settings, "normalize": normalize, "ppo": {**ppo, **settings["ppo"]},
            "policy_kwargs": {**policy, **settings["policy_kwargs"]}}


def check_same(env_id: str, plain: dict[str, Any], steps: int) -> None:
    """Stop unless the plain side's settings are the trial's."""
    mine, theirs = _complete(plain), _complete(trial_settings(env_id, steps))
    if mine != theirs:
        differ = {key: (mine[key], theirs[key]) for key in mine if mine[key] != theirs[key]}
        sys.exit(f"{env_id}: the plain side's settings differ from the trial's "
                 f"(plain, trial): {differ}")


# -- timing -----------------------------------------------------------------------------------

def measure(script: str, *args: str) -> tuple[float, float]:
    """Env steps per second of one side, in a fresh process, and per CPU second."""
    done = subprocess.run([sys.executable, "-c", script, *args], capture_output=True,
                          text=True, check=True)
    numbers = json.loads(done.stdout.strip().splitlines()[-1])
    return numbers["steps"] / numbers["seconds"], numbers["steps"] / numbers["cpu"]


def bench(env_id: str, steps: int, repeats: int) -> float:
    """Print the env's table; its median ratio."""
    plain = plain_settings(env_id)
    check_same(env_id, plain, steps)
    arguments = {"plain": (PLAIN, str(steps), json.dumps(plain)),
                 "kraby": (KRABY, str(steps), env_id)}
    rows, ratios, cpu_ratios = [], [], []
    for repeat in range(repeats):
        # Alternate which side goes first, so a drift in the machine's load favours neither.
        order = ("plain", "kraby") if repeat % 2 == 0 else ("kraby", "plain")
        speed = {side: measure(*arguments[side]) for side in order}
        ratios.append(speed["kraby"][0] / speed["plain"][0])
        cpu_ratios.append(speed["kraby"][1] / speed["plain"][1])
        rows.append(f"| {repeat + 1} | {speed['plain'][0]:,.0f} | {speed['kraby'][0]:,.0f} | "
                    f"{ratios[-1]:.3f} | {speed['plain'][1]:,.0f} | {speed['kraby'][1]:,.0f} | "
                    f"{cpu_ratios[-1]:.3f} |")
    print(f"\n{env_id}, {steps:,} steps, settings: {json.dumps(plain)}\n")
    print("| repeat | plain SB3 steps/s | kraby-study trial steps/s | ratio "
          "| plain steps/CPU s | trial steps/CPU s | CPU ratio |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))
    print(f"\nmedian CPU ratio {statistics.median(cpu_ratios):.3f}", flush=True)
    return statistics.median(ratios)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", action="append", dest="envs", metavar="ID",
                        help="a Gymnasium id rl-zoo3 has PPO settings for (repeatable; "
                             "default: the three of STEPS)")
    parser.add_argument("--steps", type=int, default=None,
                        help="env steps per run (default per env: " + ", ".join(
                            f"{env} {steps}" for env, steps in STEPS.items()) + "; else 20480)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    medians = {env: bench(env, args.steps or STEPS.get(env, 20480), args.repeats)
               for env in args.envs or list(STEPS)}
    print()
    for env, median in medians.items():
        print(f"{env}: median ratio {median:.3f} (goal: at least 0.95)")


if __name__ == "__main__":
    main()
