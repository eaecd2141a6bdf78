"""Retrain a stored study's top configurations (and baseline ppo configs) on fresh seeds, into
the confirm study ``NAME-confirm``: the tuning seeds chose them, so their scores there
overstate them; fresh seeds test them on data the choice never saw."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, TextIO

from kraby_study.api.config import Config
from kraby_study.api.outcome import RunResult, output, run_result
from kraby_study.api.run import open_writer, run_options

if TYPE_CHECKING:
    from omegaconf import DictConfig

    from kraby_study.plan.spec import StudyPlan


def confirm_plan(config: Config, reading: bool = False) -> tuple[DictConfig, StudyPlan]:
    """The confirm study a config asks for, checked, and its plan.

    Args:
        config: A config composed for ``confirm``.
        reading: Read the source study without ever creating a store (a dry run).
    """
    from kraby_study.answers.configurations import confirmed_study
    from kraby_study.answers.resumed import resumed
    from kraby_study.plan.confirm import baseline_arm, confirm_name, confirm_rule
    from kraby_study.plan.confirm import confirm_plan as plan_of
    from kraby_study.store.store import opened, opened_for_reading

    config.require("confirm")
    cfg = config.cfg
    confirm_rule(cfg, None)  # a rule that is not one is refused before the store is read
    baselines = [baseline_arm(name, config.overrides) for name in cfg.confirm.baselines]
    source = None
    if cfg.confirm.study is not None:
        # A dry run never opens a store that is not there (opening would create the file).
        reader = opened_for_reading if reading else partial(opened, create=False, writer=False)
        with reader(cfg.storage) as store:
            source = confirmed_study(store.load(str(cfg.confirm.study)), int(cfg.confirm.top))
    cfg = resumed(cfg, confirm_name(source.name if source else None,
                                    [arm.label for arm in baselines], cfg.confirm.name))
    return cfg, plan_of(cfg, source, baselines)


def confirm(config: Config, stream: TextIO | None = None) -> RunResult:
    """Retrain the top configurations of ``confirm.study`` (and each ``confirm.baselines``
    ppo config) on ``confirm.seeds`` fresh seeds, resumably.

    Args:
        config: A config composed for ``confirm`` (`kraby_study.compose`; its default
            budget is ``quick``).
        stream: Where progress goes (default: standard output).

    Returns:
        How the confirm study ended (`RunResult`).

    Examples:
        >>> import io
        >>> import kraby_study as ks
        >>> config = ks.compose(["confirm.baselines=[tuned]", "confirm.seeds=2",
        ...                      "budget=smoke", "budget.steps=512", "budget.curve_every=64",
        ...                      "ppo.n_envs=4", "ppo.n_steps=32", "ppo.n_epochs=2",
        ...                      "ppo.net_arch=[8]", "save_models=false", "workers=1",
        ...                      "storage=sqlite:///example.db"], command="confirm")
        >>> result = ks.confirm(config, stream=io.StringIO())
        >>> result.study, result.complete
        ('confirm-ppo=tuned', 2)
    """
    from kraby_study.run.executor import executor_for
    from kraby_study.run.study_run import closing_line, run_plan

    cfg, plan = confirm_plan(config)
    with executor_for(cfg) as executor, open_writer(cfg) as store:
        summary, counts = run_plan(store, plan, executor, executor.workers(cfg.workers),
                                   output(stream), **run_options(cfg))
    planned = counts.planned if plan.racing else len(plan.specs)
    return run_result(plan.name, summary, counts,
               closing_line("confirm", plan, counts)
               + f"; report it with `kraby-study report --study-name {plan.name}`", planned)
