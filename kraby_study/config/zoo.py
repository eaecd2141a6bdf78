"""``ppo=zoo`` and ``budget=zoo``: the PPO settings rl-zoo3 publishes for ``env.id``, as data.

rl-zoo3's ``hyperparams/ppo.yml`` (package ``rl-zoo3``, extra ``kraby-study[zoo]``) is read as
YAML from the installed package's files; rl_zoo3 itself is never imported, and its strings
(``lin_0.001``, ``policy_kwargs: "dict(...)"``, ``normalize: "{...}"``) are parsed, never
evaluated: [`translate`][kraby_study.config.zoo.translate] is the one translation into this
project's schema, and [`to_entry`][kraby_study.config.zoo.to_entry] the one translation back (``best
--format zoo``), both reading the same tables of keys. Keys an entry leaves out keep the defaults
rl-zoo3 leaves in force (SB3's PPO defaults, one env). An entry that uses what the schema cannot
express is refused, naming it.

The resolver ``${zoo:KEY}`` (conf/ppo/zoo.yaml, conf/budget/zoo.yaml) reads ``env.id`` from
the config being composed.
"""

from __future__ import annotations

import ast
import importlib.util
from dataclasses import dataclass
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import Any

import yaml
from omegaconf import DictConfig, OmegaConf

from kraby_study.errors import ConfigError

NAME = "zoo"
EXTRA = "kraby-study[zoo]"

SB3_DEFAULTS: dict[str, Any] = {
    "n_envs": 1, "n_steps": 2048, "batch_size": 64, "n_epochs": 10, "gamma": 0.99,
    "gae_lambda": 0.95, "clip_range": 0.2, "ent_coef": 0.0, "vf_coef": 0.5,
    "max_grad_norm": 0.5, "learning_rate": 3e-4, "learning_rate_schedule": "constant",
    "clip_range_schedule": "constant", "net_arch": [64, 64], "activation": "tanh",
    "ortho_init": True, "log_std_init": 0.0, "use_sde": False, "sde_sample_freq": -1,
}
"""What an entry's missing keys mean: stable-baselines3's PPO and MlpPolicy defaults, and
rl-zoo3's one env."""

NUMBERS = ("n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda", "ent_coef", "vf_coef",
           "max_grad_norm", "n_envs", "sde_sample_freq")
SCHEDULED = ("learning_rate", "clip_range")
"""Settings rl-zoo3 writes as a number (constant) or ``lin_<number>`` (linear to 0)."""
ACTIVATIONS = {"Tanh": "tanh", "ReLU": "relu"}
"""``nn.NAME`` of policy_kwargs' activation_fn -> the setting ``activation``."""
POLICY_KWARGS = {"log_std_init": "log_std_init", "ortho_init": "ortho_init",
                 "activation_fn": "activation", "net_arch": "net_arch"}
"""policy_kwargs' keys read and written, in rl-zoo3's order -> the setting each one is."""
NORM_REWARD_OFF = "{'norm_obs': True, 'norm_reward': False}"
"""rl-zoo3's normalize for observations only (``env.normalize_reward: false``)."""
CURVE_POINTS = 50
"""Learning-curve points of budget=zoo: its curve bin is n_timesteps / 50."""
BUDGET_SEEDS = 10


@dataclass(frozen=True)
class ZooSettings:
    """rl-zoo3's settings for one id, in this project's schema."""

    env_id: str
    ppo: dict[str, Any]
    """Every PPOConfig setting."""
    env: dict[str, Any]
    """normalize and normalize_reward."""
    n_timesteps: int
    """The budget rl-zoo3 trains with (its benchmark's)."""
    version: str
    """The rl-zoo3 version read."""

    def value(self, key: str) -> Any:
        """A setting by its dotted name: ppo.NAME, env.NAME, or budget.steps / seeds /
        curve_every (budget=zoo)."""
        root, _, leaf = key.partition(".")
        budget = {"steps": self.n_timesteps, "seeds": BUDGET_SEEDS,
                  "curve_every": max(1, self.n_timesteps // CURVE_POINTS)}
        table = {"ppo": self.ppo, "env": self.env, "budget": budget}.get(root, {})
        if leaf not in table:
            raise ConfigError(f"${{zoo:{key}}} names no setting (ppo.NAME, env.normalize, "
                              "env.normalize_reward, budget.steps, budget.seeds, "
                              "budget.curve_every)")
        return table[leaf]


def hyperparams_file() -> Path:
    """rl-zoo3's ppo.yml in the installed package, found without importing it."""
    spec = importlib.util.find_spec("rl_zoo3")
    if spec is None or not spec.submodule_search_locations:
        raise ConfigError(f"ppo=zoo and budget=zoo read rl-zoo3's published settings, and "
                          f"rl-zoo3 is not installed: pip install '{EXTRA}'")
    path = Path(next(iter(spec.submodule_search_locations))) / "hyperparams" / "ppo.yml"
    if not path.is_file():
        raise ConfigError(f"the installed rl-zoo3 has no {path.name} at {path}")
    return path


def zoo_version() -> str:
    """The installed rl-zoo3's version."""
    try:
        return metadata.version("rl-zoo3")
    except metadata.PackageNotFoundError:
        return "unknown"


@cache
def entries() -> dict[str, Any]:
    """Every entry of rl-zoo3's ppo.yml, by id (plain YAML: no tag of its runs code)."""
    with hyperparams_file().open(encoding="utf-8") as handle:
        return yaml.safe_load(handle)


def zoo_settings(env_id: str) -> ZooSettings:
    """rl-zoo3's PPO settings for ``env_id``, translated; ConfigError in one line when it has
    none or they use what the schema cannot express."""
    table = entries()
    if env_id not in table or env_id in ("default", "atari"):
        raise ConfigError(f"rl-zoo3 {zoo_version()} publishes no PPO settings for {env_id!r} "
                          f"(its ppo.yml has {len(table) - 2} ids, e.g. Pendulum-v1, "
                          "CartPole-v1)")
    return translate(env_id, dict(table[env_id]), zoo_version())


def translate(env_id: str, entry: dict[str, Any], version: str = "unknown") -> ZooSettings:
    """One ppo.yml entry in this project's schema.

    Raises:
        ConfigError: The entry uses something the schema cannot express; the message names it.
    """
    def refuse(what: str) -> ConfigError:
        return ConfigError(f"rl-zoo3's PPO entry for {env_id} uses {what}, which kraby-study's "
                           "schema cannot express")

    ppo = dict(SB3_DEFAULTS)
    env = {"normalize": False, "normalize_reward": True}
    known = {*NUMBERS, *SCHEDULED, "n_timesteps", "policy", "policy_kwargs", "use_sde",
             "normalize"}
    unknown = sorted(set(entry) - known)
    if unknown:
        raise refuse(", ".join(f"{key}: {entry[key]!r}" for key in unknown))
    if str(entry.get("policy", "MlpPolicy")) != "MlpPolicy":
        raise refuse(f"policy {entry['policy']} (the schema trains MlpPolicy)")
    for key in NUMBERS:
        if key in entry:
            ppo[key] = _number(entry[key], key, refuse)
    for key in ("n_envs", "n_steps", "batch_size", "n_epochs", "sde_sample_freq"):
        ppo[key] = int(ppo[key])
    for key in SCHEDULED:
        if key in entry:
            ppo[key], ppo[f"{key}_schedule"] = _scheduled(entry[key], key, refuse)
    if "use_sde" in entry:
        ppo["use_sde"] = bool(entry["use_sde"])
    if "policy_kwargs" in entry:
        ppo.update(_policy_kwargs(str(entry["policy_kwargs"]), refuse))
    if "normalize" in entry:
        env.update(_normalize(entry["normalize"], refuse))
    rollout = ppo["n_steps"] * ppo["n_envs"]
    if ppo["batch_size"] >= rollout:
        # SB3 then trains on the whole rollout as one minibatch, as batch_size null does.
        ppo["batch_size"] = None
    elif rollout % ppo["batch_size"]:
        raise refuse(f"batch_size {ppo['batch_size']}, which does not divide its rollout "
                     f"n_steps x n_envs = {rollout} (SB3 trains a short last minibatch)")
    steps = int(_number(entry.get("n_timesteps", 1e6), "n_timesteps", refuse))
    return ZooSettings(env_id, ppo, env, steps, version)


def to_entry(settings: ZooSettings) -> dict[str, Any]:
    """The inverse of [`translate`][kraby_study.config.zoo.translate]: settings as one ppo.yml
    entry, in rl-zoo3's own keys.

    Every number is written, ``batch_size`` explicitly (null: the whole rollout, n_steps x
    n_envs); a linear schedule as ``lin_<number>``; ``policy_kwargs`` as rl-zoo3 writes it,
    ``"dict(...)"`` of what differs from SB3's defaults (left out when nothing does);
    ``normalize`` when it is on, ``true`` or
    [`NORM_REWARD_OFF`][kraby_study.config.zoo.NORM_REWARD_OFF]. ``translate(env_id, to_entry(s))``
    gives ``s``'s settings back.

    Raises:
        ConfigError: A setting is missing, a schedule is neither constant nor linear, or the
            activation is not one [`ACTIVATIONS`][kraby_study.config.zoo.ACTIVATIONS] names.
    """
    ppo = settings.ppo
    missing = sorted(set(SB3_DEFAULTS) - set(ppo))
    if missing:
        raise ConfigError(f"the settings for {settings.env_id} lack {', '.join(missing)}, "
                          "which an rl-zoo3 entry needs")
    entry: dict[str, Any] = {}
    if settings.env.get("normalize"):
        entry["normalize"] = True if settings.env.get("normalize_reward", True) \
            else NORM_REWARD_OFF
    entry.update({"n_envs": int(ppo["n_envs"]), "n_timesteps": int(settings.n_timesteps),
                  "policy": "MlpPolicy"})
    for key in NUMBERS:
        if key != "sde_sample_freq":
            entry.setdefault(key, ppo[key])
    if ppo["batch_size"] is None:
        entry["batch_size"] = int(ppo["n_steps"]) * int(ppo["n_envs"])
    for key in SCHEDULED:
        schedule = ppo[f"{key}_schedule"]
        if schedule not in ("constant", "linear"):
            raise ConfigError(f"{key}_schedule {schedule!r}: rl-zoo3 writes constant or linear "
                              "schedules only")
        entry[key] = f"lin_{float(ppo[key])!r}" if schedule == "linear" else ppo[key]
    entry.update({"use_sde": bool(ppo["use_sde"]), "sde_sample_freq": ppo["sde_sample_freq"]})
    names = {setting: name for name, setting in ACTIVATIONS.items()}
    if ppo["activation"] not in names:
        raise ConfigError(f"activation {ppo['activation']!r}: rl-zoo3 entries read here take "
                          f"{', '.join(names)}")
    kwargs = []
    for key, setting in POLICY_KWARGS.items():
        value = ppo[setting]
        if value == SB3_DEFAULTS[setting]:
            continue
        text = f"nn.{names[value]}" if setting == "activation" else repr(
            [int(w) for w in value] if setting == "net_arch" else value)
        kwargs.append(f"{key}={text}")
    if kwargs:
        entry["policy_kwargs"] = f"dict({', '.join(kwargs)})"
    return entry


def study_settings(settings: dict[str, Any], steps: int, what: str) -> ZooSettings:
    """A study's stored settings (env and complete ppo, as ``best`` reads them) and budget
    steps, for [`to_entry`][kraby_study.config.zoo.to_entry].

    Raises:
        ConfigError: ``what`` (the study, in words) trained what an rl-zoo3 hyperparameter
            file cannot say: the leg, a time limit of its own or keyword arguments of the id.
    """
    env = settings.get("env", {})
    if "id" not in env:
        raise ConfigError(f"--format zoo writes rl-zoo3 settings for a Gymnasium id, and {what} "
                          "trained the leg (env=leg) in kraby-study's batched world of legs, "
                          "which rl-zoo3 does not build: write it with --format ppo")
    for key, empty in (("kwargs", {}), ("max_episode_steps", None)):
        if env.get(key, empty) != empty:
            raise ConfigError(f"{what} has env.{key}={env[key]!r} for {env['id']}, which an "
                              "rl-zoo3 hyperparameter file that ppo=zoo reads back cannot hold")
    return ZooSettings(str(env["id"]), dict(settings["ppo"]),
                       {"normalize": bool(env.get("normalize", False)),
                        "normalize_reward": bool(env.get("normalize_reward", True))},
                       int(steps), zoo_version())


def train_command(env_id: str, path: Path, packages: list[str] | None = None) -> str:
    """The command that trains an rl-zoo3 hyperparameter file's settings for ``env_id``."""
    return (f"python -m rl_zoo3.train --algo ppo --env {env_id} -conf {path}"
            + (f" --gym-packages {' '.join(packages)}" if packages else ""))


def write_hyperparams(settings: ZooSettings, description: str, path: Path,
                      packages: list[str] | None = None) -> dict[str, Any]:
    """An rl-zoo3 hyperparameter file, ``{env id: entry}``, for
    [`train_command`][kraby_study.config.zoo.train_command] (with ``--gym-packages`` for an id the
    ``packages`` register); the entry written."""
    entry = to_entry(settings)
    text = (f"# Written by kraby-study best --format zoo: {description}.\n"
            f"# Train: {train_command(settings.env_id, path, packages)}\n"
            + yaml.safe_dump({settings.env_id: entry}, sort_keys=False))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return entry


def _number(value: Any, key: str, refuse: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise refuse(f"{key}: {value!r} (a number is expected)")
    return value


def _scheduled(value: Any, key: str, refuse: Any) -> tuple[float, str]:
    """``0.001`` -> (0.001, constant); ``lin_0.001`` -> (0.001, linear)."""
    if isinstance(value, str):
        if not value.startswith("lin_"):
            raise refuse(f"{key}: {value!r} (a number or lin_<number> is expected)")
        try:
            return float(value[4:]), "linear"
        except ValueError:
            raise refuse(f"{key}: {value!r} (a number or lin_<number> is expected)") from None
    return float(_number(value, key, refuse)), "constant"


def _literal(node: ast.AST, refuse: Any, where: str) -> Any:
    """A parsed value: numbers, booleans, lists, ``dict(...)`` and ``{...}`` of them, and
    ``nn.NAME`` (as the name); anything else is refused."""
    if isinstance(node, ast.Constant) and isinstance(node.value, int | float | bool | str):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        inner = _literal(node.operand, refuse, where)
        if isinstance(inner, int | float) and not isinstance(inner, bool):
            return -inner if isinstance(node.op, ast.USub) else inner
    if isinstance(node, ast.List | ast.Tuple):
        return [_literal(item, refuse, where) for item in node.elts]
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id == "dict" and not node.args
            and all(k.arg is not None for k in node.keywords)):
        return {k.arg: _literal(k.value, refuse, where) for k in node.keywords}
    if isinstance(node, ast.Dict) and all(k is not None for k in node.keys):
        return {_literal(k, refuse, where): _literal(v, refuse, where)  # type: ignore[arg-type]
                for k, v in zip(node.keys, node.values, strict=True)}
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
            and node.value.id == "nn":
        return f"nn.{node.attr}"
    raise refuse(f"{where} {ast.unparse(node)!r} (only numbers, booleans, lists, dicts and "
                 "nn.NAME are read)")


def _parsed(text: str, refuse: Any, where: str) -> Any:
    """A string of ppo.yml parsed as a Python expression's syntax tree, then read as data."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError:
        raise refuse(f"{where} {text!r} (not an expression)") from None
    return _literal(tree.body, refuse, where)


def _policy_kwargs(text: str, refuse: Any) -> dict[str, Any]:
    """``dict(log_std_init=-2, ortho_init=False, activation_fn=nn.ReLU, net_arch=...)``."""
    given = _parsed(text, refuse, "policy_kwargs")
    if not isinstance(given, dict):
        raise refuse(f"policy_kwargs {text!r} (a dict is expected)")
    out: dict[str, Any] = {}
    for key, value in given.items():
        if key == "log_std_init" and isinstance(value, int | float) \
                and not isinstance(value, bool):
            out[POLICY_KWARGS[key]] = float(value)
        elif key == "ortho_init" and isinstance(value, bool):
            out[POLICY_KWARGS[key]] = value
        elif key == "activation_fn" and isinstance(value, str) \
                and value.removeprefix("nn.") in ACTIVATIONS:
            out[POLICY_KWARGS[key]] = ACTIVATIONS[value.removeprefix("nn.")]
        elif key == "net_arch":
            out[POLICY_KWARGS[key]] = _net_arch(value, refuse)
        else:
            raise refuse(f"policy_kwargs {key}={value!r}")
    return out


def _net_arch(value: Any, refuse: Any) -> list[int]:
    """A list of widths, or ``dict(pi=L, vf=L)`` with the same L (the schema's networks have
    one shape)."""
    if isinstance(value, dict) and set(value) == {"pi", "vf"} and value["pi"] == value["vf"]:
        value = value["pi"]
    if isinstance(value, list) and value and all(
            isinstance(w, int) and not isinstance(w, bool) and w >= 1 for w in value):
        return [int(w) for w in value]
    raise refuse(f"policy_kwargs net_arch={value!r} (one list of widths for both networks)")


def _normalize(value: Any, refuse: Any) -> dict[str, bool]:
    """``true``, or ``"{'norm_obs': True, 'norm_reward': False}"``."""
    if isinstance(value, bool):
        return {"normalize": value, "normalize_reward": True}
    given = _parsed(str(value), refuse, "normalize") if isinstance(value, str) else value
    if not isinstance(given, dict) or set(given) - {"norm_obs", "norm_reward"}:
        raise refuse(f"normalize: {value!r}")
    if not given.get("norm_obs", True):
        raise refuse(f"normalize: {value!r} (rewards normalised without the observations)")
    return {"normalize": True, "normalize_reward": bool(given.get("norm_reward", True))}


def _resolve(key: str, *, _root_: DictConfig) -> Any:
    env = _root_.get("env")
    if env is None or "id" not in env:
        raise ConfigError(f"${{zoo:{key}}} (ppo=zoo, budget=zoo) reads rl-zoo3's settings for a "
                          "Gymnasium id: choose env=gym env.id=ID")
    if OmegaConf.is_missing(env, "id"):
        raise ConfigError("ppo=zoo and budget=zoo need env.id=ID (e.g. env.id=Pendulum-v1)")
    return zoo_settings(str(env.id)).value(str(key).strip())


def register() -> None:
    """Register the ``zoo`` resolver with OmegaConf (idempotent)."""
    if not OmegaConf.has_resolver(NAME):
        OmegaConf.register_new_resolver(NAME, _resolve)
