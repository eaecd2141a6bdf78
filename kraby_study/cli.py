"""The kraby-study command: subcommands and flags become Hydra overrides, then work is done.

main() only wires arguments to the functions that do the work; every check that can fail on
user input runs before anything is written.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any

from omegaconf import DictConfig
from sqlalchemy import exc as sa_exc

from kraby_study.compose import compose_config
from kraby_study.config import ConfigError, worker_count
from kraby_study.messages import first_line
from kraby_study.runner import DatabaseLost
from kraby_study.store import StoreError

OVERRIDES_HELP = ("Hydra overrides, e.g. study=ent_coef budget=quick ppo.n_steps=64 workers=2 "
                  "storage=sqlite:///studies/kraby.db")

EPILOG = """\
config groups (conf/): env=leg, ppo=start|tuned, budget=full|quick|smoke,
study=observation|batch_size|n_steps|n_epochs|gamma|clip_range|learning_rate|gae_lambda|
ent_coef|n_envs, search=ppo (the Optuna space).
Any setting can be overridden with key=value (ppo.gamma=0.8).
Your own YAML files in ./conf/<group>/ extend these groups.
"""


def _compose(overrides: Sequence[str]) -> DictConfig:
    return compose_config(list(overrides))


def with_default(overrides: Sequence[str], group: str, option: str) -> list[str]:
    """The overrides, choosing ``group=option`` first unless the user chose that group."""
    chosen = any(o.startswith(f"{group}=") for o in overrides)
    return list(overrides) if chosen else [f"{group}={option}", *overrides]


def open_writer(cfg: DictConfig):  # noqa: ANN201 - a context manager of Store
    """The store a command writes to, with the configured heartbeat timing."""
    from kraby_study.store import opened

    return opened(cfg.storage, heartbeat_interval=int(cfg.heartbeat_interval),
                  heartbeat_grace=int(cfg.heartbeat_grace))


def run_options(cfg: DictConfig) -> dict[str, Any]:
    """Heartbeat period, database patience and physics processes of a running command."""
    return {"heartbeat_seconds": float(cfg.heartbeat_interval),
            "retry_seconds": float(cfg.db_retry_seconds),
            "physics_processes": cfg.physics_processes}


def cmd_run(args: argparse.Namespace) -> int:
    """Run a study's sweep: every value x seed, resumable."""
    from kraby_study.plan import expand_study
    from kraby_study.sweep import run_plan

    cfg = _compose(args.overrides)
    plan = expand_study(cfg)
    with open_writer(cfg) as store:
        summary, complete, failed = run_plan(store, plan, worker_count(cfg), sys.stdout,
                                             **run_options(cfg))
    total = len(plan.specs)
    print(f"study {plan.name}: {complete}/{total} complete, {failed} failed"
          + (f", {total - complete - failed} left (rerun the same command to continue)"
             if complete + failed < total else ""))
    return 130 if summary.interrupted else 0


def cmd_train(args: argparse.Namespace) -> int:
    """One training run, stored like a trial, its model saved."""
    from kraby_study.plan import single_run
    from kraby_study.sweep import run_plan

    cfg = _compose(with_default(args.overrides, "ppo", "tuned"))
    plan = single_run(cfg)
    with open_writer(cfg) as store:
        summary, _, _ = run_plan(store, plan, 1, sys.stdout, **run_options(cfg))
        trial = _latest(store, plan.name, plan.specs[0].key)
    if trial is None:
        return 130 if summary.interrupted else 1
    status = trial.user_attrs.get("status", trial.state.name.lower())
    line = f"train {plan.name} seed {cfg.seed}: {status}"
    if trial.value is not None:
        line += f", final score {trial.value:.4g} over {trial.user_attrs.get('env_steps')} steps"
    if trial.user_attrs.get("failure"):
        line += f" ({trial.user_attrs['failure']})"
    print(line)
    if trial.user_attrs.get("model_path") and trial.value is not None:
        print(f"model: {trial.user_attrs['model_path']}")
    if summary.interrupted:
        return 130
    return 0 if trial.value is not None else 1


def _latest(store: object, name: str, key: str) -> object | None:
    from kraby_study.ledger import attempts_by_key

    study = store.load(name)  # type: ignore[attr-defined]
    return attempts_by_key(study.get_trials(deepcopy=False)).get(key)


def cmd_list(args: argparse.Namespace) -> int:
    """The studies in the store with their progress."""
    from kraby_study.ledger import study_progress
    from kraby_study.store import opened

    cfg = _compose(args.overrides)
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


def search_overrides(args: argparse.Namespace) -> list[str]:
    """The optuna command's flags as Hydra overrides, placed before the user's own."""
    flags = [("trials", "search.trials"), ("workers", "workers"), ("storage", "storage"),
             ("study_name", "search.name"), ("sampler", "search.sampler"),
             ("pruner", "search.pruner"), ("seed", "search.seed")]
    overrides = [f"{key}={getattr(args, attr)}" for attr, key in flags
                 if getattr(args, attr) is not None]
    return with_default(overrides + list(args.overrides), "budget", "quick")


def cmd_optuna(args: argparse.Namespace) -> int:
    """An Optuna search over conf/search/<space>.yaml, into the same store."""
    from kraby_study.ledger import study_progress
    from kraby_study.search import run_search, validate_search

    cfg = _compose(search_overrides(args))
    validate_search(cfg)
    with open_writer(cfg) as store:
        summary, study = run_search(store, cfg, worker_count(cfg), sys.stdout)
        state = study_progress(study)
    print(f"search {state.name}: {state.complete} complete, {state.pruned} pruned, "
          f"{state.failed} failed of {state.total}; best {state.best}")
    return 130 if summary.interrupted else 0


def cmd_best(args: argparse.Namespace) -> int:
    """Print a study's best settings and write them as a ppo config file."""
    from pathlib import Path

    from kraby_study.best import find_best, write_config
    from kraby_study.compose import USER_CONF_DIR
    from kraby_study.store import opened

    overrides = list(args.overrides)
    if args.storage:
        overrides.insert(0, f"storage={args.storage}")
    cfg = _compose(overrides)
    name = args.study_name or str(cfg.search.name)
    config_name = args.name or f"best_{name}"
    if not config_name.replace("_", "").replace("-", "").isalnum():
        raise ConfigError(f"--name {config_name!r}: use letters, digits, _ and -")
    with opened(cfg.storage, create=False, writer=False) as store:
        best = find_best(store.load(name))
    path = Path(USER_CONF_DIR) / "ppo" / f"{config_name}.yaml"
    write_config(best, path)
    print(f"best: {best.description}")
    print(f"wrote {path}: use it with `kraby-study train ppo={config_name}` or "
          f"`kraby-study run ppo={config_name} study=...`")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Redraw the figures and tables of the stored studies."""
    from kraby_study.report import run_report

    # study=NAME names a stored study here (a search or a renamed sweep too), not the Hydra
    # group of study files, so it is taken out before composing.
    names = [o.split("=", 1)[1] for o in args.overrides if o.startswith("study=")]
    overrides = [o for o in args.overrides if not o.startswith("study=")]
    if len(names) > 1:
        raise ConfigError("report takes one study=NAME (or none for every study)")
    cfg = _compose(overrides)
    return run_report(cfg.storage, cfg.out, study=names[0] if names else None,
                      fmt=args.format, stream=sys.stdout, policy=not args.no_policy)


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
        ("run", cmd_run, "run a documented sweep (study=NAME): values x seeds, resumable"),
        ("train", cmd_train, "one training run (ppo=tuned by default), model saved"),
        ("list", cmd_list, "the studies in the store with their progress"),
        ("optuna", cmd_optuna, "an Optuna search (TPE, pruning) over conf/search/ppo.yaml"),
        ("best", cmd_best, "print a study's best settings and write them as conf/ppo/NAME.yaml"),
        ("report", cmd_report, "redraw every figure and table of the stored studies into out= "
         "(default reports/): study=NAME for one"),
    ]
    parsers = {}
    for name, func, text in commands:
        command = sub.add_parser(name, help=text, description=text, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
        command.add_argument("overrides", nargs="*", metavar="KEY=VALUE", help=OVERRIDES_HELP)
        command.set_defaults(func=func)
        parsers[name] = command
    search = parsers["optuna"]
    search.add_argument("--trials", type=_positive_int, help="total trials of the study: "
                        "rerunning tops it up to this number, so --trials 50 twice gives 50, "
                        "not 100 (default 50)")
    search.add_argument("--workers", type=_positive_int,
                        help="worker processes (default: one per core)")
    search.add_argument("--storage", help="database URL (default sqlite:///studies/kraby.db)")
    search.add_argument("--study-name", help="name of the search in the store (default "
                        "ppo_search)")
    search.add_argument("--sampler", choices=["tpe", "random"], help="default tpe (seeded)")
    search.add_argument("--pruner", choices=["median", "hyperband", "none"],
                        help="stops bad trials at env-step checkpoints (default median)")
    search.add_argument("--seed", type=_whole, help="sampler seed, stored with the study "
                        "(default 0)")
    search.epilog = ("each trial trains budget.seeds seeds of budget.steps env steps (budget=quick "
                     "unless you choose one); the score is the mean over its seeds. The pruner "
                     "sees the mean reward at search.checkpoints equal env-step intervals of the "
                     "first seed, then the mean score after each further seed; it stops no "
                     "trial in the first search.warmup (half) of the first seed.\n\n"
                     + EPILOG)
    best = parsers["best"]
    best.add_argument("--study-name", help="the study (default: the search's name, ppo_search)")
    best.add_argument("--name", help="config name to write (default best_<study>)")
    best.add_argument("--storage", help="database URL (default sqlite:///studies/kraby.db)")
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
    except DatabaseLost as err:
        print(f"kraby-study: error: {err}", file=sys.stderr)
        return 1
    except sa_exc.OperationalError as err:
        # A database that fails outside the retried calls (while a study is being opened).
        print(f"kraby-study: error: database error: {first_line(err)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("kraby-study: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
