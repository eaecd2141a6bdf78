"""The plan of ``train``: one run at the configured settings and seed; pure."""

from __future__ import annotations

from omegaconf import DictConfig

from kraby_study.config.validate import validate_env, validate_ppo, validate_run_length
from kraby_study.plan.settings import model_path, resolved_settings, tensorboard_run
from kraby_study.plan.spec import StudyPlan, TrialSpec, fingerprint, seeding_of, with_seeding
from kraby_study.records.attributes import StudyKind
from kraby_study.records.stored import train_key


def train_plan(cfg: DictConfig) -> StudyPlan:
    """The plan of ``train``: one run at the configured settings and seed.

    Runs with the same settings, budget and seeding share one study named train-<hash>, one
    trial per seed (``seeding=offset`` finds the runs of a study seeded by offset).
    """
    validate_env(cfg.env, cfg.ppo)
    validate_ppo(cfg.ppo)
    validate_run_length(cfg.env, cfg.ppo, int(cfg.budget.steps))
    settings = resolved_settings(cfg)
    scheme = seeding_of(cfg)
    definition = with_seeding({"kind": StudyKind.TRAIN.value, "settings": settings,
                               "steps": int(cfg.budget.steps),
                               "curve_every": int(cfg.budget.curve_every)}, scheme)
    name = f"train-{fingerprint(definition)[:8]}"
    seed = int(cfg.seed)
    key = train_key(seed)
    spec = TrialSpec(study=name, key=key, seed=seed, steps=int(cfg.budget.steps),
                     curve_every=int(cfg.budget.curve_every), settings=settings,
                     model_path=model_path(cfg, name, key), label=f"seed {seed}",
                     tensorboard_run=tensorboard_run(cfg, name, "train"), seeding=scheme)
    return StudyPlan(name=name, parameter="seed", values=[seed], specs=[spec],
                     definition=definition)
