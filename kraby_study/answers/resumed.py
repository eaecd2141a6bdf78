"""What a stored study fixes for the command that resumes it: the settings the command left
open (null) are taken from the study's stored definition, so a study resumes exactly as it began
whatever today's defaults are; a new study gets today's default.

- ``seeding``: the stored scheme (offset for a definition without one), else streams.
- ``confirm.seed`` (a confirm study): the first of its stored seeds, else 1000.
- ``confirm.select`` (a confirm study): its stored selection rule, else the command's default.
- ``search.eval_set``: the stored evaluation set (fixed for a definition without one), else
  run.
- ``search.eval_episodes``: the stored number, else 200.
- ``search.enqueue``: a stored search's own list, else left null for the command to fill
  with its ppo config ([`cmd_optuna`][kraby_study.cli.cmd_optuna]).

A setting the command gives stays as given: if it differs from the stored study, the store
refuses it as a changed definition, naming the setting.
"""

from __future__ import annotations

from omegaconf import DictConfig, open_dict

from kraby_study.config.winner import Lookup
from kraby_study.plan.campaign import Campaign, Stage, stage_config
from kraby_study.records.attributes import StudyAttrs, StudyKind
from kraby_study.records.definition import (
    EVAL_EPISODES,
    EVAL_SET,
    SEEDING,
    stored_enqueue,
    stored_eval_episodes,
    stored_eval_set,
    stored_seeding,
)
from kraby_study.store.rows import has_store, reading


def stored_attrs(url: str, name: str) -> StudyAttrs | None:
    """The stored attributes of study ``name``; None when the store or the study is not
    there (nothing is created)."""
    if not has_store(url):
        return None
    with reading(url) as reader:
        return reader.study_attrs(name)


def resumed(cfg: DictConfig, name: str) -> DictConfig:
    """``cfg`` with ``seeding``, ``search.eval_set``, ``search.eval_episodes`` and a stored
    search's ``search.enqueue`` (and, for a confirm, ``confirm.seed`` and ``confirm.select``)
    settled for the study named ``name`` in ``cfg.storage``: as given, else as stored, else
    the default. A stored confirm keeps its rule unless one is given, so resuming it never
    changes what it selects."""
    if cfg.seeding is not None and cfg.confirm.seed is not None and (
            cfg.confirm.select is not None and cfg.search.eval_set is not None
            and cfg.search.eval_episodes is not None and cfg.search.enqueue is not None):
        return cfg
    attrs = stored_attrs(str(cfg.storage), name)
    definition = attrs.definition if attrs is not None and attrs.fingerprint else None
    out = cfg.copy()
    with open_dict(out):
        if out.seeding is None:
            out.seeding = stored_seeding(definition) if definition is not None else SEEDING
        if out.search.eval_set is None:
            out.search.eval_set = (stored_eval_set(definition) if definition is not None
                                   else EVAL_SET)
        if out.search.eval_episodes is None:
            stored = stored_eval_episodes(definition) if definition is not None else None
            out.search.eval_episodes = EVAL_EPISODES if stored is None else stored
        if out.search.enqueue is None and definition is not None:
            out.search.enqueue = stored_enqueue(definition)
        if (out.confirm.seed is None and definition is not None
                and definition.get("kind") == StudyKind.CONFIRM.value
                and definition.get("seeds")):
            out.confirm.seed = min(int(s) for s in definition["seeds"])
        if (out.confirm.select is None and definition is not None and attrs is not None
                and definition.get("kind") == StudyKind.CONFIRM.value and attrs.select):
            out.confirm.select = str(attrs.select)
    return out


def resumed_stage(campaign: Campaign, stage: Stage, lookup: Lookup) -> DictConfig:
    """A campaign stage's config ([`stage_config`][kraby_study.plan.campaign.stage_config]), settled
    for its stored study."""
    return resumed(stage_config(campaign, stage, lookup), stage.name)
