"""The kraby-study command: subcommands and flags become Hydra overrides, then work is done.

main() only wires arguments to the functions that do the work; every check that can fail on
user input runs before anything is written.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from omegaconf import DictConfig

from kraby_study.config.compose import compose_config
from kraby_study.errors import ClusterLost, ConfigError, DatabaseLost, StoreError, first_line
from kraby_study.run.executor import executor_for
from kraby_study.store.connection import LOST_DATABASE

if TYPE_CHECKING:
    from kraby_study.run.executor import Executor

OVERRIDES_HELP = ("Hydra overrides, e.g. study=ent_coef budget=quick ppo.n_steps=64 workers=2 "
                  "storage=sqlite:///studies/kraby.db")

EPILOG = """\
config groups (conf/): env=leg, ppo=start|tuned, budget=full|quick|smoke,
study=observation|batch_size|n_steps|n_epochs|gamma|clip_range|learning_rate|gae_lambda|
ent_coef|n_envs, campaign=documented (the nine studies in order, each with the earlier
winners), search=ppo (the Optuna space).
A study file may take a setting from a finished study's selected value: ppo.gamma:
${winner:gamma}.
executor=local|ray: trials run in worker processes here, or as Ray actors on a cluster
(ray.address=auto|host:port; null starts a Ray instance here); the command writes the store.
Any setting can be overridden with key=value (ppo.gamma=0.8); a flag such as --storage URL is
the same as its key=value form (storage=URL), on every command that takes it.
Your own YAML files in ./conf/<group>/ extend these groups and win over packaged files of the
same name.
"""


@dataclass(frozen=True)
class Flag:
    """A command-line flag that is another spelling of one setting."""

    name: str
    """The flag, e.g. --storage."""
    key: str
    """The setting it sets, e.g. storage (search.trials for --trials)."""
    help: str
    metavar: str | None = None
    kind: Callable[[str], Any] = str
    choices: tuple[str, ...] | None = None


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid whole number: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid whole number: {text!r}") from None


def _baseline(text: str) -> str:
    """``ppo=NAME`` -> NAME (a baseline is a ppo config)."""
    group, sep, name = text.partition("=")
    if group != "ppo" or not sep or not name.replace("_", "").replace("-", "").isalnum():
        raise argparse.ArgumentTypeError(f"expected ppo=NAME (a config in conf/ppo/), got "
                                         f"{text!r}")
    return name


def _at_least_two(text: str) -> int:
    value = _positive_int(text)
    if value < 2:
        raise argparse.ArgumentTypeError(f"must be at least 2, got {value}")
    return value


STORAGE = Flag("--storage", "storage", "database URL, as storage=URL (default "
               "sqlite:///studies/kraby.db)", "URL")
WORKERS = Flag("--workers", "workers", "trials at once, each in its own worker process (or Ray "
               "actor), as workers=N (default: one per core; executor=ray: the cluster's CPUs "
               "/ ray.cpus_per_trial)", "N", _positive_int)
BEST_OF = Flag("--study-name", "study", "the stored study, as study=NAME (default: the "
               "search's name, ppo_search)", "NAME")
REPORTED = Flag("--study-name", "study", "report this stored study only, as study=NAME "
                "(default: every study)", "NAME")
SEARCH_FLAGS = [
    Flag("--trials", "search.trials", "total trials of the study, as search.trials=N: "
         "rerunning tops it up to this number, so --trials 50 twice gives 50, not 100 "
         "(default 50)", "N", _positive_int),
    WORKERS, STORAGE,
    Flag("--study-name", "search.name", "name of the search in the store, as search.name=NAME "
         "(default ppo_search)", "NAME"),
    Flag("--sampler", "search.sampler", "default tpe (seeded), as search.sampler=...",
         choices=("tpe", "random")),
    Flag("--pruner", "search.pruner", "stops bad trials at env-step checkpoints, as "
         "search.pruner=... (default median)", choices=("median", "hyperband", "none")),
    Flag("--seed", "search.seed", "sampler seed, stored with the study, as search.seed=S "
         "(default 0)", "S", _whole),
]
OUT = Flag("--out", "out", "report folder, as out=DIR (default reports)", "DIR")
CONFIRM_FLAGS = [
    Flag("--study-name", "confirm.study", "the search or sweep whose top configurations are "
         "retrained, as confirm.study=NAME (default: none, baselines only)", "NAME"),
    Flag("--top", "confirm.top", "configurations retrained: the search's best complete trials "
         "or the sweep's best values, as confirm.top=K (default 5)", "K", _positive_int),
    Flag("--seeds", "confirm.seeds", "fresh seeds per configuration, none used by the study, as "
         "confirm.seeds=N (default 10)", "N", _at_least_two),
    STORAGE, WORKERS,
]


def flag_overrides(args: argparse.Namespace, flags: Sequence[Flag]) -> list[str]:
    """The flags given, as key=value overrides, placed before the user's own overrides."""
    out = []
    if getattr(args, "baseline", None):
        out.append(f"confirm.baselines=[{','.join(args.baseline)}]")
    for flag in flags:
        value = getattr(args, flag.name.lstrip("-").replace("-", "_"), None)
        if value is not None:
            out.append(f"{flag.key}={value}")
    return out + list(args.overrides)


def with_default(overrides: Sequence[str], group: str, option: str) -> list[str]:
    """The overrides, choosing ``group=option`` first unless the user chose that group."""
    chosen = any(o.startswith(f"{group}=") for o in overrides)
    return list(overrides) if chosen else [f"{group}={option}", *overrides]


def stored_study(overrides: Sequence[str]) -> tuple[str | None, list[str]]:
    """``study=NAME`` names a stored study for best and report (a search or a renamed sweep
    too), not the Hydra group of study files: it is taken out before composing."""
    names = [o.split("=", 1)[1] for o in overrides if o.startswith("study=")]
    if len(names) > 1:
        raise ConfigError("give one study=NAME (or --study-name NAME)")
    return (names[0] if names else None), [o for o in overrides if not o.startswith("study=")]


def open_writer(cfg: DictConfig):  # noqa: ANN201 - a context manager of Store
    """The store a command writes to, with the configured heartbeat timing."""
    from kraby_study.store.connection import opened

    return opened(cfg.storage, heartbeat_interval=int(cfg.heartbeat_interval),
                  heartbeat_grace=int(cfg.heartbeat_grace))


def run_options(cfg: DictConfig) -> dict[str, Any]:
    """Heartbeat period and database patience of a running command."""
    return {"heartbeat_seconds": float(cfg.heartbeat_interval),
            "retry_seconds": float(cfg.db_retry_seconds)}


def cmd_run(args: argparse.Namespace) -> int:
    """Run a study's sweep: every value x seed, resumable."""
    from kraby_study.config.winner import winners_from
    from kraby_study.plan.sweep import expand_study
    from kraby_study.winners import StoreWinners

    overrides = flag_overrides(args, [STORAGE, WORKERS])
    lookup = StoreWinners()
    with winners_from(lookup):
        cfg = compose_config(overrides)
    if cfg.campaign is not None:
        return run_campaign_command(cfg, overrides)
    plan = dataclasses.replace(expand_study(cfg), inputs=[i.stored() for i in lookup.inputs])
    with executor_for(cfg) as executor:
        summary, counts = run_stage(cfg, plan, executor)
    total = len(plan.specs)
    print(f"study {plan.name}: {counts.complete}/{total} complete, {counts.failed} failed"
          + (f", {total - counts.ended} left (rerun the same command to continue)"
             if counts.ended < total else ""))
    return 130 if summary.interrupted else 0


def run_stage(cfg: DictConfig, plan: Any, executor: Executor) -> tuple[Any, Any]:
    """Run a sweep's plan on the command's store and executor: (RunSummary, Tally)."""
    from kraby_study.run.sweep_source import run_plan

    with open_writer(cfg) as store:
        return run_plan(store, plan, executor, executor.workers(cfg.workers), sys.stdout,
                        **run_options(cfg))


def run_campaign_command(cfg: DictConfig, overrides: Sequence[str]) -> int:
    """``run campaign=NAME``: every stage in order, resumable."""
    from kraby_study.plan.campaign import campaign_of
    from kraby_study.run.campaign_run import run_campaign

    campaign = campaign_of(cfg, overrides)
    with executor_for(cfg) as executor:
        return run_campaign(campaign, lambda stage_cfg, plan: run_stage(stage_cfg, plan, executor),
                            sys.stdout)


def cmd_train(args: argparse.Namespace) -> int:
    """One training run, stored like a trial, its model saved."""
    from kraby_study.plan.sweep import single_run
    from kraby_study.records import Outcome, TrialAttrs, latest_by_key, outcome
    from kraby_study.run.sweep_source import run_plan

    cfg = compose_config(with_default(flag_overrides(args, [STORAGE]), "ppo", "tuned"))
    plan = single_run(cfg)
    with executor_for(cfg) as executor, open_writer(cfg) as store:
        summary, _ = run_plan(store, plan, executor, 1, sys.stdout, **run_options(cfg))
        trial = latest_by_key(store.load(plan.name).trials()).get(plan.specs[0].key)
    if trial is None:
        return 130 if summary.interrupted else 1
    attrs = TrialAttrs.of(trial)
    line = f"train {plan.name} seed {cfg.seed}: {outcome(trial)}"
    if trial.value is not None:
        line += f", final score {trial.value:.4g} over {attrs.env_steps} steps"
    if attrs.failure:
        line += f" ({attrs.failure})"
    print(line)
    if attrs.model_path and trial.value is not None:
        print(f"model: {attrs.model_path}")
    if summary.interrupted:
        return 130
    return 0 if outcome(trial) == Outcome.COMPLETE else 1


def cmd_list(args: argparse.Namespace) -> int:
    """The studies in the store with their progress."""
    from kraby_study.store.connection import opened
    from kraby_study.summary import study_progress

    cfg = compose_config(flag_overrides(args, [STORAGE]))
    with opened(cfg.storage, create=False, writer=False) as store:
        names = store.study_names()
        if not names:
            print(f"no studies in {cfg.storage}")
            return 0
        rows = [study_progress(store.load(name)) for name in names]
    header = ("study", "kind", "complete", "failed", "pruned", "running", "best so far")
    table = [header] + [(p.name, p.kind, f"{p.complete}/{p.total}", str(p.failed),
                         str(p.pruned), str(p.running), p.best) for p in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    for row in table:
        print("  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True)))
    return 0


def cmd_optuna(args: argparse.Namespace) -> int:
    """An Optuna search over conf/search/<space>.yaml, into the same store."""
    from kraby_study.plan.space import validate_search
    from kraby_study.run.search_source import run_search
    from kraby_study.summary import study_progress

    overrides = with_default(flag_overrides(args, SEARCH_FLAGS), "budget", "quick")
    cfg = compose_config(overrides)
    validate_search(cfg)
    starts = [(f"ppo={name}", settings_with_ppo(name, overrides))
              for name in cfg.search.enqueue]
    with executor_for(cfg) as executor, open_writer(cfg) as store:
        summary, ledger = run_search(store, cfg, executor, executor.workers(cfg.workers),
                                     sys.stdout, starts=starts)
        state = study_progress(ledger)
    print(f"search {state.name}: {state.complete} complete, {state.pruned} pruned, "
          f"{state.failed} failed of {state.total}; best {state.best}")
    return 130 if summary.interrupted else 0


def cmd_confirm(args: argparse.Namespace) -> int:
    """Retrain a study's top configurations (and baselines) on fresh seeds."""
    from kraby_study.best import confirm_source
    from kraby_study.plan.confirm import confirm_plan
    from kraby_study.run.sweep_source import run_plan
    from kraby_study.store.connection import opened

    overrides = flag_overrides(args, CONFIRM_FLAGS)
    cfg = compose_config(with_default(overrides, "budget", "quick"))
    baselines = [baseline_arm(name, overrides) for name in cfg.confirm.baselines]
    source = None
    if cfg.confirm.study is not None:
        with opened(cfg.storage, create=False, writer=False) as store:
            source = confirm_source(store.load(str(cfg.confirm.study)), int(cfg.confirm.top))
    plan = confirm_plan(cfg, source, baselines)
    with executor_for(cfg) as executor, open_writer(cfg) as store:
        summary, counts = run_plan(store, plan, executor, executor.workers(cfg.workers),
                                   sys.stdout, **run_options(cfg))
    total = len(plan.specs)
    print(f"confirm {plan.name}: {counts.complete}/{total} complete, {counts.failed} failed"
          + (f", {total - counts.ended} left (rerun the same command to continue)"
             if counts.ended < total else "")
          + f"; report it with `kraby-study report --study-name {plan.name}`")
    return 130 if summary.interrupted else 0


def settings_with_ppo(name: str, overrides: Sequence[str]) -> dict[str, Any]:
    """The resolved settings of the command's overrides with the ppo config ``NAME`` chosen
    instead of the command's own (a search's warm start, a confirm baseline)."""
    from kraby_study.plan.sweep import resolved_settings

    kept = [o for o in overrides if not o.startswith("ppo=")]
    return resolved_settings(compose_config([*kept, f"ppo={name}"]))


def baseline_arm(name: str, overrides: Sequence[str]):  # noqa: ANN201 - a plan.confirm.Arm
    """A ppo config file as a confirm arm: the command's settings with ``ppo=NAME``."""
    from kraby_study.plan.confirm import Arm

    return Arm(label=f"ppo={name}", settings=settings_with_ppo(name, overrides),
               origin=f"the config ppo={name}")


def cmd_best(args: argparse.Namespace) -> int:
    """Print a study's best settings and write them as a ppo config file."""
    from pathlib import Path

    from kraby_study.best import campaign_best, require_best, write_config
    from kraby_study.config.compose import USER_CONF_DIR
    from kraby_study.store.connection import opened

    chosen, overrides = stored_study(flag_overrides(args, [STORAGE, BEST_OF]))
    if chosen and args.campaign:
        raise ConfigError("give --campaign NAME or --study-name NAME, not both")
    cfg = compose_config(overrides)
    name = chosen or str(cfg.search.name)
    config_name = args.name or (f"campaign_{args.campaign}" if args.campaign else f"best_{name}")
    if not config_name.replace("_", "").replace("-", "").isalnum():
        raise ConfigError(f"--name {config_name!r}: use letters, digits, _ and -")
    with opened(cfg.storage, create=False, writer=False) as store:
        best = (campaign_best(store, args.campaign) if args.campaign
                else require_best(store.load(name)))
    path = Path(USER_CONF_DIR) / "ppo" / f"{config_name}.yaml"
    write_config(best, path)
    print(f"best: {best.description}")
    print(f"wrote {path}: use it with `kraby-study train ppo={config_name}` or "
          f"`kraby-study run ppo={config_name} study=...`")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Redraw the figures and tables of the stored studies."""
    from kraby_study.report import run_report

    chosen, overrides = stored_study(flag_overrides(args, [STORAGE, REPORTED, OUT]))
    cfg = compose_config(overrides)
    return run_report(cfg.storage, cfg.out, study=chosen, fmt=args.format, stream=sys.stdout,
                      policy=not args.no_policy, options=cfg.report)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser; only commands that exist are listed."""
    parser = _Parser(
        prog="kraby-study", description="Declarative PPO hyperparameter studies on the "
        "simulated Kraby hexapod leg, stored in SQLite or PostgreSQL.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                parser_class=_Parser)
    commands: list[tuple[str, Callable[[argparse.Namespace], int], str]] = [
        ("run", cmd_run, "run a documented sweep (study=NAME) or a chain of them "
         "(campaign=NAME): values x seeds, resumable"),
        ("train", cmd_train, "one training run (ppo=tuned by default), model saved"),
        ("list", cmd_list, "the studies in the store with their progress"),
        ("optuna", cmd_optuna, "an Optuna search (TPE, pruning) over conf/search/ppo.yaml"),
        ("confirm", cmd_confirm, "retrain a search's top configurations (or a sweep's top "
         "values, or baselines) on fresh seeds, into study NAME-confirm"),
        ("best", cmd_best, "print a study's selected settings (or a campaign's, --campaign) and "
         "write them as ./conf/ppo/NAME.yaml"),
        ("report", cmd_report, "redraw every figure and table of the stored studies into "
         "--out (default reports/); --study-name NAME for one"),
    ]
    flags: dict[str, list[Flag]] = {
        "run": [STORAGE, WORKERS], "train": [STORAGE], "list": [STORAGE],
        "optuna": SEARCH_FLAGS, "confirm": CONFIRM_FLAGS, "best": [STORAGE, BEST_OF],
        "report": [STORAGE, REPORTED, OUT],
    }
    parsers = {}
    for name, func, text in commands:
        command = sub.add_parser(name, help=text, description=text, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
        command.add_argument("overrides", nargs="*", metavar="KEY=VALUE", help=OVERRIDES_HELP)
        for flag in flags[name]:
            command.add_argument(flag.name, type=flag.kind, choices=flag.choices,
                                 metavar=flag.metavar, help=flag.help)
        command.set_defaults(func=func)
        parsers[name] = command
    parsers["optuna"].epilog = (
        "each trial trains budget.seeds seeds of budget.steps env steps (budget=quick unless you "
        "choose one); the score is the mean over its seeds. The pruner sees the mean reward at "
        "search.checkpoints equal env-step intervals of the first seed, then the mean score "
        "after each further seed; it stops no trial in the first search.warmup (half) of the "
        "first seed.\n\n" + EPILOG)
    parsers["confirm"].add_argument(
        "--baseline", action="append", type=_baseline, metavar="ppo=NAME",
        help="add a ppo config's settings as one more configuration (repeatable), e.g. "
        "--baseline ppo=tuned; with no --study-name, only these are retrained")
    parsers["confirm"].epilog = (
        "each configuration trains --seeds runs at the study's budget (steps and curve bins; "
        "budget=quick for baselines alone), with seeds no trial of the study used. The study "
        "NAME-confirm is resumable like run; report it, then `kraby-study best --study-name "
        "NAME-confirm` writes the confirmed winner's settings.\n\n" + EPILOG)
    parsers["best"].add_argument("--name", help="config name to write in ./conf/ppo/ (default "
                                 "best_<study>, or campaign_<NAME>)")
    parsers["best"].add_argument("--campaign", metavar="NAME",
                                 help="write the settings a finished campaign ends with (its "
                                 "last stage's selected value, with every earlier winner)")
    report = parsers["report"]
    report.add_argument("--format", choices=["png", "svg"], default="png",
                        help="figure format (default png)")
    report.add_argument("--no-policy", action="store_true",
                        help="skip the animated GIF of the best policy")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script."""
    parser = build_parser()
    # Overrides may come after flags (optuna --trials 5 budget=quick): argparse leaves them over.
    args, extras = parser.parse_known_args(argv)
    unknown = [e for e in extras if e.startswith("-")]
    if unknown:
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    args.overrides = list(args.overrides) + extras
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        return int(args.func(args))
    except (ConfigError, StoreError) as err:
        print(f"kraby-study: error: {err}", file=sys.stderr)
        return 2
    except (DatabaseLost, ClusterLost) as err:
        print(f"kraby-study: error: {err}", file=sys.stderr)
        return 1
    except LOST_DATABASE as err:
        # A database that fails outside the retried calls (while a study is being opened).
        print(f"kraby-study: error: database error: {first_line(err)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("kraby-study: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
