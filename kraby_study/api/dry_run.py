"""What a run, search or confirm would do, without doing it (the command line's ``--dry-run``):
the composed config, the plan (trials, env steps, how many the store already holds) and an
estimate of the wall time from the steps/s measured on the store. Nothing is trained, and no
store is created or written."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from kraby_study.api.config import Config
from kraby_study.errors import ConfigError

if TYPE_CHECKING:
    from omegaconf import DictConfig

    from kraby_study.plan.preview import Count


@dataclass(frozen=True)
class Preview:
    """A planned call, as the command line's ``--dry-run`` prints it.

    Attributes:
        config: The composed config as YAML.
        env: The environment, in a few words.
        lines: The plan and the estimate, one line each.
    """

    config: str
    env: str
    lines: list[str]

    def text(self) -> str:
        """Everything, as ``--dry-run`` prints it."""
        return f"{self.config}env: {self.env}\n" + "\n".join(self.lines)


def preview(config: Config) -> Preview:
    """What `kraby_study.run_sweep`, `kraby_study.search` or `kraby_study.confirm`
    would do with this config (the one it was composed for), checked as the real call.

    Args:
        config: A config composed for ``run``, ``search`` or ``confirm``.

    Returns:
        The `Preview`.

    Examples:
        >>> import kraby_study as ks
        >>> shown = ks.preview(ks.compose(["study=ent_coef", "budget=quick"]))
        >>> shown.lines[1]
        'ent_coef: 15 trials (5 values x 3 seeds), 40,960 env steps each, 614,400 in all'
    """
    from kraby_study.plan.preview import plan_count, search_count

    if config.command == "run":
        if config.cfg.campaign is not None:
            return _campaign(config)
        from kraby_study.api.run import sweep_plan

        cfg, plan = sweep_plan(config)
        return _shown(cfg, [plan_count(plan)], {
            plan.name: [f"from other studies: {i.text()}" for i in config.inputs]})
    if config.command == "search":
        from kraby_study.api.optuna_search import search_plan
        from kraby_study.plan.space import method_text

        cfg = search_plan(config).cfg
        return _shown(cfg, [search_count(cfg)], {str(cfg.search.name): [method_text(cfg)]})
    if config.command == "confirm":
        from kraby_study.api.fresh_seeds import confirm_plan

        cfg, plan = confirm_plan(config, reading=True)
        return _shown(cfg, [plan_count(plan, arms="configurations")])
    raise ConfigError(f"a config composed for {config.command} has nothing to preview: "
                      "compose it for run, search or confirm")


def _campaign(config: Config) -> Preview:
    """Each stage's trials, and its inputs from earlier stages (named, not guessed, while
    those are not selected)."""
    from kraby_study.answers.preview import campaign_preview
    from kraby_study.plan.campaign import campaign_of

    stages = campaign_preview(campaign_of(config.cfg, config.overrides))
    return _shown(config.cfg, [s.count for s in stages], {
        s.count.study: [f"stage {s.stage.number}/{len(stages)} ({s.stage.parameter}, select "
                        f"{s.stage.select})"] + [f"from earlier stages: {i}" for i in s.inputs]
        for s in stages})


def _shown(cfg: DictConfig, counts: Sequence[Count],
           notes: dict[str, list[str]] | None = None) -> Preview:
    from omegaconf import OmegaConf

    from kraby_study.answers.preview import preview_lines
    from kraby_study.config.validate import cores
    from kraby_study.env import adapter_for

    workers = (int(cfg.workers) if cfg.workers is not None
               else cores() if str(cfg.executor) == "local" else None)
    lines = preview_lines(str(cfg.storage), counts, workers, notes)
    return Preview(config=OmegaConf.to_yaml(cfg), env=adapter_for(cfg.env).label(cfg.env),
                   lines=lines)
