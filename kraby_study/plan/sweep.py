"""Expand a sweep into trial specifications, one per value and seed: pure, no training, no
database."""

from __future__ import annotations

from omegaconf import DictConfig

from kraby_study.config.validate import (
    RUN_LENGTH,
    to_container,
    validate_env,
    validate_ppo,
    validate_run_length,
)
from kraby_study.errors import ConfigError
from kraby_study.plan.racing import race_rules
from kraby_study.plan.settings import (
    model_path,
    resolved_settings,
    tensorboard_run,
    with_value,
)
from kraby_study.plan.spec import StudyPlan, TrialSpec, seeding_of, with_seeding
from kraby_study.records.attributes import StudyKind
from kraby_study.records.stored import sweep_key
from kraby_study.records.values import param_name, value_key, value_label


def run_seeds(cfg: DictConfig) -> list[int]:
    """Seeds of a study's runs: seed, seed + 1, ... (fixed, so a rerun repeats them)."""
    return [int(cfg.seed) + i for i in range(int(cfg.budget.seeds))]


def expand_study(cfg: DictConfig) -> StudyPlan:
    """One TrialSpec per (value, seed) of the selected study; every trial config validated."""
    if cfg.study is None:
        raise ConfigError("no study selected: add study=NAME (e.g. study=ent_coef)")
    study = cfg.study
    values = list(to_container(study["values"]))
    if not values:
        raise ConfigError(f"study {study.name!r} lists no values")
    if len({value_key(v) for v in values}) != len(values):
        raise ConfigError(f"study {study.name!r} lists a value twice")
    racing = race_rules(cfg, run_seeds(cfg), "budget.seeds")
    scheme = seeding_of(cfg)
    specs = []
    for index, value in enumerate(values):
        trial_cfg = with_value(cfg, study.parameter, value)
        try:
            validate_env(trial_cfg.env, trial_cfg.ppo)
            validate_ppo(trial_cfg.ppo)
        except ConfigError as err:
            raise ConfigError(f"study {study.name}, value {value!r}: {err}") from None
        # Named by its value only where the value sets the run's length.
        validate_run_length(trial_cfg.env, trial_cfg.ppo, int(cfg.budget.steps),
                            where=f"study {study.name}, value {value!r}: "
                            if str(study.parameter) in RUN_LENGTH else "")
        settings = resolved_settings(trial_cfg)
        named = f"{param_name(str(study.parameter))}={value_label(value)}"
        logs = tensorboard_run(cfg, str(study.name), named)
        for seed in run_seeds(cfg):
            key = sweep_key(index, seed)
            specs.append(TrialSpec(
                study=str(study.name), key=key, seed=seed, steps=int(cfg.budget.steps),
                curve_every=int(cfg.budget.curve_every), settings=settings, value=value,
                model_path=model_path(cfg, str(study.name), key),
                label=f"{named} seed {seed}", tensorboard_run=logs, seeding=scheme))
    base = resolved_settings(cfg)
    root, leaf = str(study.parameter).split(".", 1)
    base[root].pop(leaf, None)
    if study.parameter != "ppo.batch_size":
        base["ppo"].pop("batch_size", None)
        base["ppo"]["batch_size_setting"] = to_container(cfg.ppo).get("batch_size")
    definition = {
        "kind": StudyKind.SWEEP.value,
        "parameter": str(study.parameter),
        "values": values,
        "settings": base,
        "steps": int(cfg.budget.steps),
        "curve_every": int(cfg.budget.curve_every),
    }
    if racing is not None:
        definition["racing"] = racing.stored()
    return StudyPlan(name=str(study.name), parameter=str(study.parameter), values=values,
                     specs=specs, definition=with_seeding(definition, scheme),
                     select=str(study.select),
                     racing=racing)


