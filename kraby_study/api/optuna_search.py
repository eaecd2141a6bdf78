"""Run an Optuna search over a search space (``conf/search/<space>.yaml``) into the store.

The sampler, pruner and objectives are the config's ``search`` section; a new search first
evaluates the settings it was composed with (``search.enqueue``), and a stored one resumes
with its own, topped up to ``search.trials`` trials.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TextIO

from kraby_study.api.config import Config
from kraby_study.api.outcome import RunResult, output, run_result
from kraby_study.api.run import open_writer
from kraby_study.errors import ConfigError

if TYPE_CHECKING:
    from omegaconf import DictConfig


@dataclass(frozen=True)
class SearchPlan:
    """A search's config, resumed from the store, and the configurations it starts from."""

    cfg: DictConfig
    starts: list[tuple[str, dict[str, Any]]]
    """(``ppo=NAME``, its resolved settings) for each enqueued configuration."""


def search_plan(config: Config) -> SearchPlan:
    """The search a config asks for, checked: its stored settings taken where the config
    leaves them open, the configurations it starts from composed."""
    from kraby_study.answers.resumed import resumed
    from kraby_study.plan.settings import settings_with_ppo
    from kraby_study.plan.space import validate_search

    config.require("search")
    cfg = resumed(config.cfg, str(config.cfg.search.name))
    if cfg.search.enqueue is None:  # a new search starts from the settings it was given
        if "ppo" not in config.choices:
            raise ConfigError("the config chooses no ppo config in its defaults")
        cfg.search.enqueue = [config.choices["ppo"]]
    validate_search(cfg)
    starts = [(f"ppo={name}", settings_with_ppo(name, config.overrides))
              for name in cfg.search.enqueue]
    return SearchPlan(cfg, starts)


def search(config: Config, stream: TextIO | None = None) -> RunResult:
    """Run (or resume) an Optuna search until its study holds ``search.trials`` trials; with
    ``racing.enabled`` a racing search instead (configurations raced over seeds against an
    incumbent, until ``search.cpu_budget`` is used or ``search.trials`` configurations are
    decided; docs/guide/studies.md).

    Args:
        config: A config composed for ``search`` (`kraby_study.compose`; its default
            budget is ``quick``).
        stream: Where progress goes (default: standard output).

    Returns:
        How it ended; ``message`` names the best trial, or the front of a two-objective
        search (`RunResult`).

    Examples:
        >>> import io
        >>> import kraby_study as ks
        >>> config = ks.compose(["search.trials=1", "budget=smoke", "budget.steps=512",
        ...                      "budget.curve_every=64", "budget.seeds=1", "ppo.n_envs=8",
        ...                      "ppo.n_steps=32", "ppo.n_epochs=2", "ppo.net_arch=[8]",
        ...                      "save_models=false", "workers=1",
        ...                      "storage=sqlite:///example.db"], command="search")
        >>> result = ks.search(config, stream=io.StringIO())  # the enqueued ppo=tuned first
        >>> result.study, result.complete
        ('ppo_search', 1)
    """
    from kraby_study.answers.standing import study_standing
    from kraby_study.plan.space import objectives, racing
    from kraby_study.run.executor import executor_for
    from kraby_study.run.racing_search import run_racing_search
    from kraby_study.run.search_source import run_search

    found = search_plan(config)
    cfg = found.cfg
    run = run_racing_search if racing(cfg) else run_search
    with executor_for(cfg) as executor, open_writer(cfg) as store:
        summary, ledger = run(store, cfg, executor, executor.workers(cfg.workers),
                              output(stream), starts=found.starts)
        state = study_standing(ledger)
    counts = state.tally
    chosen = state.selected if len(objectives(cfg)) == 2 else f"best {state.selected}"
    if racing(cfg):
        return run_result(state.name, summary, counts,
                          f"search {state.name}: {counts.complete} complete and "
                          f"{counts.failed} failed runs; picked {state.selected}")
    return run_result(state.name, summary, counts,
               f"search {state.name}: {counts.complete} complete, {counts.pruned} pruned, "
               f"{counts.failed} failed of {counts.planned}; {chosen}")
