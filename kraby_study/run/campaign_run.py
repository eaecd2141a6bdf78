"""Run a campaign: its stages in order, each with every worker, each after its inputs are
selected.

Before any run, every stage whose inputs are already selected is planned and compared with what
the store holds under its name, so a changed stage is refused before anything trains. A
finished stage runs nothing again; a stage left unfinished (interrupted, or runs still held by
another machine that stopped) ends the command, and rerunning it resumes.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from typing import TextIO

from omegaconf import DictConfig

from kraby_study.answers.resumed import resumed_stage
from kraby_study.answers.selected import sweep_selection
from kraby_study.answers.winners import StoreWinners, Unfinished
from kraby_study.decision.comparison import CompareOptions
from kraby_study.errors import StoreError
from kraby_study.plan.campaign import Campaign, Stage
from kraby_study.plan.spec import StudyPlan
from kraby_study.plan.sweep import expand_study
from kraby_study.records.attributes import StudyAttrs
from kraby_study.records.stored import Tally
from kraby_study.records.values import param_name, value_label
from kraby_study.run.runner import CommandRun
from kraby_study.store.store import check_same_definition, opened, study_exists
from kraby_study.store.url import shown_url

RunStage = Callable[[DictConfig, StudyPlan], tuple[CommandRun, Tally]]
"""Runs one stage's plan with the command's workers and store; returns (summary, outcomes)."""


def stage_plan(campaign: Campaign, stage: Stage) -> tuple[DictConfig, StudyPlan]:
    """A stage's config and plan, its earlier stages' winners read from the store."""
    lookup = StoreWinners(names={s.study: s.name for s in campaign.before(stage)},
                          recorders=[s.name for s in campaign.stages])
    cfg = resumed_stage(campaign, stage, lookup)
    inputs = [i.stored() for i in lookup.inputs if i.setting != stage.parameter]
    plan = dataclasses.replace(expand_study(cfg), inputs=inputs,
                               campaign=campaign.record(stage))
    return cfg, plan


def check_stage(campaign: Campaign, stage: Stage, cfg: DictConfig, plan: StudyPlan) -> None:
    """Refuse a stage stored under its name with another definition.

    Raises:
        StoreError: The stored definition differs; the message names the settings.
    """
    if not study_exists(str(cfg.storage), plan.name):
        return
    with opened(str(cfg.storage), create=False, writer=False) as store:
        stored = store.load(plan.name).attrs
    try:
        check_same_definition(plan.name, shown_url(str(cfg.storage)), stored, StudyAttrs(
            definition=plan.definition, fingerprint=plan.fingerprint))
    except StoreError as err:
        raise StoreError(f"campaign {campaign.name}, stage {stage.number} ({stage.study}): "
                         f"{str(err).split('; choose')[0]}; use another campaign.name or "
                         "storage, or the settings it was run with") from None


def check_stored(campaign: Campaign) -> None:
    """Refuse a campaign whose stored stages were defined otherwise, before any work: every
    stage whose inputs are selected is planned and compared with its stored definition.

    Raises:
        StoreError: A stage's definition changed (the message names the settings).
    """
    for stage in campaign.stages:
        try:
            cfg, plan = stage_plan(campaign, stage)
        except Unfinished:
            return
        check_stage(campaign, stage, cfg, plan)


def selected_text(cfg: DictConfig, stage: Stage) -> str:
    """``n_epochs=10 (fastest_equivalent, mean final score -0.5; documented 30)`` from the
    stored stage."""
    with opened(str(cfg.storage), create=False, writer=False) as store:
        chosen = sweep_selection(store.load(stage.name), CompareOptions.of(cfg))
    if chosen is None:
        return "no selectable value"
    documented = ("" if stage.documented is None
                  else f"; documented {value_label(stage.documented)}")
    return (f"{param_name(stage.parameter)}={value_label(chosen.value)} ({chosen.rule}, mean "
            f"final score {chosen.mean:.4g}{documented})")


def run_campaign(campaign: Campaign, run_stage: RunStage, stream: TextIO) -> int:
    """Run every stage in order; returns the exit code (0 when the campaign is finished).

    Raises:
        ConfigError or StoreError: A stage cannot be planned (e.g. an earlier stage selected
            nothing) or was stored with another definition; one line.
    """
    check_stored(campaign)
    total = len(campaign.stages)
    errors = 0
    for stage in campaign.stages:
        cfg, plan = stage_plan(campaign, stage)
        taken = ", ".join(f"{i['setting']}={value_label(i['value'])}" for i in plan.inputs)
        print(f"campaign {campaign.name}, stage {stage.number}/{total}: {plan.name} "
              f"({stage.parameter}, select {stage.select})"
              + (f"; from earlier stages: {taken}" if taken else ""), file=stream, flush=True)
        check_stage(campaign, stage, cfg, plan)
        summary, counts = run_stage(cfg, plan)
        errors += summary.errors
        if summary.interrupted:
            return 130
        # A raced stage plans the runs its race still wants, not every value's every seed.
        runs = counts.planned if plan.racing else len(plan.specs)
        left = runs - counts.ended
        if left > 0:
            print(f"campaign {campaign.name}: stage {plan.name} has {left} run(s) left; rerun "
                  "the same command to continue", file=stream)
            return 1
        print(f"stage {stage.number}/{total} {plan.name}: {counts.complete}/{runs} "
              f"complete, {counts.failed} failed; selected {selected_text(cfg, stage)}",
              file=stream, flush=True)
    print(f"campaign {campaign.name}: {total}/{total} stages finished; `kraby-study best "
          f"--campaign {campaign.name}` writes the settings it ends with", file=stream)
    if errors:
        print(f"kraby-study: {errors} run(s) ended in an error (not a divergence): "
              "`kraby-study list` counts them and the report gives their reasons",
              file=sys.stderr)
        return 1
    return 0
