"""Run a documented sweep, a campaign of sweeps or one training run into the store.

Each call plans first (a pure expansion of the config, `kraby_study.plan`), then hands
the plan to the runner (`kraby_study.run`) on the configured executor; the calling
process is the store's only writer. A rerun resumes: finished runs are not trained again.
"""

from __future__ import annotations

import dataclasses
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any, TextIO

from kraby_study.api.config import Config
from kraby_study.api.outcome import RunResult, output, run_result

if TYPE_CHECKING:
    from omegaconf import DictConfig

    from kraby_study.plan.spec import StudyPlan
    from kraby_study.records.stored import Tally
    from kraby_study.run.executor import Executor
    from kraby_study.run.runner import CommandRun
    from kraby_study.store.store import Store


def open_writer(cfg: DictConfig) -> AbstractContextManager[Store]:
    """The store a command writes to, with the configured heartbeat timing."""
    from kraby_study.store.store import opened

    return opened(cfg.storage, heartbeat_interval=int(cfg.heartbeat_interval),
                  heartbeat_grace=int(cfg.heartbeat_grace))


def run_options(cfg: DictConfig) -> dict[str, Any]:
    """Heartbeat period and database patience of a running command."""
    return {"heartbeat_seconds": float(cfg.heartbeat_interval),
            "retry_seconds": float(cfg.db_retry_seconds),
            "failed_again": bool(cfg.retry_failed)}


def sweep_plan(config: Config) -> tuple[DictConfig, StudyPlan]:
    """A sweep's config, resumed from its stored definition, and its plan (with the values it
    took from other studies)."""
    from kraby_study.answers.resumed import resumed
    from kraby_study.plan.sweep import expand_study

    cfg = config.cfg
    if cfg.study is not None:
        cfg = resumed(cfg, str(cfg.study.name))
    plan = dataclasses.replace(expand_study(cfg), inputs=[i.stored() for i in config.inputs])
    return cfg, plan


def run_stage(cfg: DictConfig, plan: StudyPlan, executor: Executor, stream: TextIO
              ) -> tuple[CommandRun, Tally]:
    """Run a plan on the config's store and the executor: (what this call ran, the plan's
    outcomes)."""
    from kraby_study.run.study_run import run_plan

    with open_writer(cfg) as store:
        return run_plan(store, plan, executor, executor.workers(cfg.workers), stream,
                        **run_options(cfg))


def run_sweep(config: Config, stream: TextIO | None = None) -> RunResult:
    """Run a sweep (``study=NAME``: every value x seed) or a campaign (``campaign=NAME``: its
    stages in order), resumably, into the configured store.

    Args:
        config: A config composed for ``run`` (`kraby_study.compose`).
        stream: Where progress goes (default: standard output).

    Returns:
        How it ended (`RunResult`).

    Raises:
        ConfigError: The plan cannot be made; one line, before anything runs.
        StoreError: The store holds the study with another definition; one line.

    Examples:
        >>> import io
        >>> import kraby_study as ks
        >>> tiny = ["budget=smoke", "budget.steps=512", "budget.curve_every=64",
        ...         "ppo.n_envs=4", "ppo.n_steps=32", "ppo.n_epochs=2", "ppo.net_arch=[8]",
        ...         "save_models=false", "workers=1", "storage=sqlite:///example.db"]
        >>> config = ks.compose(["study=clip_range", "study.values=[0.1,0.2]",
        ...                      "budget.seeds=2", *tiny])
        >>> result = ks.run_sweep(config, stream=io.StringIO())
        >>> (result.study, result.complete, result.exit_code)
        ('clip_range', 4, 0)
    """
    from kraby_study.run.executor import executor_for
    from kraby_study.run.study_run import closing_line

    config.require("run")
    stream = output(stream)
    if config.cfg.campaign is not None:
        return _run_campaign(config, stream)
    cfg, plan = sweep_plan(config)
    with executor_for(cfg) as executor:
        summary, counts = run_stage(cfg, plan, executor, stream)
    planned = counts.planned if plan.racing else len(plan.specs)
    return run_result(plan.name, summary, counts, closing_line("study", plan, counts), planned)


def _run_campaign(config: Config, stream: TextIO) -> RunResult:
    """Every stage of the config's campaign in order, resumably."""
    from kraby_study.plan.campaign import campaign_of
    from kraby_study.run.campaign_run import run_campaign
    from kraby_study.run.executor import executor_for

    campaign = campaign_of(config.cfg, config.overrides)
    stages: list[tuple[CommandRun, Tally]] = []

    def stage(cfg: DictConfig, plan: StudyPlan) -> tuple[CommandRun, Tally]:
        stages.append(run_stage(cfg, plan, executor, stream))
        return stages[-1]

    with executor_for(config.cfg) as executor:
        code = run_campaign(campaign, stage, stream)
    return RunResult(study=campaign.name,
                     complete=sum(c.complete for _, c in stages),
                     failed=sum(c.failed for _, c in stages),
                     pruned=sum(c.pruned for _, c in stages),
                     planned=sum(c.planned for _, c in stages),
                     interrupted=any(s.interrupted for s, _ in stages),
                     errors=sum(s.errors for s, _ in stages), message=None, warning=None,
                     exit_code=code)


def train(config: Config, stream: TextIO | None = None) -> RunResult:
    """One training run (``ppo=tuned`` unless the overrides choose), stored like a trial,
    its model saved unless ``save_models=false``.

    Args:
        config: A config composed for ``train`` (`kraby_study.compose`).
        stream: Where progress goes (default: standard output).

    Returns:
        How it ended, with its final score and model path (`RunResult`).

    Examples:
        >>> import io
        >>> import kraby_study as ks
        >>> config = ks.compose(["budget=smoke", "budget.steps=512", "budget.curve_every=64",
        ...                      "ppo.n_envs=4", "ppo.n_steps=32", "ppo.n_epochs=2",
        ...                      "ppo.net_arch=[8]", "save_models=false",
        ...                      "storage=sqlite:///example.db"], command="train")
        >>> result = ks.train(config, stream=io.StringIO())
        >>> result.exit_code, result.score is not None
        (0, True)
    """
    from kraby_study.plan.train import train_plan
    from kraby_study.run.executor import executor_for
    from kraby_study.run.study_run import run_plan, train_outcome

    config.require("train")
    cfg = config.cfg
    plan = train_plan(cfg)
    with executor_for(cfg) as executor:
        # One run: its worker starts importing torch and SB3 while the store opens.
        executor.prestart(1)
        with open_writer(cfg) as store:
            summary, counts = run_plan(store, plan, executor, 1, output(stream),
                                       **run_options(cfg))
            ended = train_outcome(store, plan, summary, int(cfg.seed))
    return dataclasses.replace(
        run_result(plan.name, summary, counts, "\n".join(ended.lines) or None, 1),
        warning=None, exit_code=ended.code, score=ended.score, model_path=ended.model_path)
