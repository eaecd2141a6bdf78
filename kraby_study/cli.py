"""The kraby-study command: subcommands and flags become Hydra overrides, then work is done.

main() only wires arguments to the functions that do the work; every check that can fail on
user input runs before anything is written.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from omegaconf import DictConfig

from kraby_study.compose import compose_config
from kraby_study.config import ConfigError, worker_count
from kraby_study.store import StoreError

OVERRIDES_HELP = ("Hydra overrides, e.g. study=ent_coef budget=quick ppo.n_steps=64 workers=2 "
                  "storage=sqlite:///studies/kraby.db")

EPILOG = """\
config groups (conf/): env=leg, ppo=start|tuned, budget=full|quick|smoke,
study=observation|batch_size|n_steps|n_epochs|gamma|clip_range|learning_rate|gae_lambda|
ent_coef|n_envs. Any setting can be overridden with key=value (ppo.gamma=0.8).
Your own YAML files in ./conf/<group>/ extend these groups.
"""


def _compose(overrides: Sequence[str]) -> DictConfig:
    return compose_config(list(overrides))


def cmd_run(args: argparse.Namespace) -> int:
    """Run a study's sweep: every value x seed, resumable."""
    from kraby_study.plan import expand_study
    from kraby_study.store import opened
    from kraby_study.sweep import run_plan

    cfg = _compose(args.overrides)
    plan = expand_study(cfg)
    with opened(cfg.storage) as store:
        summary, complete, failed = run_plan(store, plan, worker_count(cfg), sys.stdout)
    total = len(plan.specs)
    print(f"study {plan.name}: {complete}/{total} complete, {failed} failed"
          + (f", {total - complete - failed} left (rerun the same command to continue)"
             if complete + failed < total else ""))
    return 130 if summary.interrupted else 0


def cmd_train(args: argparse.Namespace) -> int:
    """One training run, stored like a trial, its model saved."""
    from kraby_study.plan import single_run
    from kraby_study.store import opened
    from kraby_study.sweep import run_plan

    overrides = list(args.overrides)
    if not any(o.startswith("ppo=") for o in overrides):
        overrides.insert(0, "ppo=tuned")
    cfg = _compose(overrides)
    plan = single_run(cfg)
    with opened(cfg.storage) as store:
        summary, _, _ = run_plan(store, plan, 1, sys.stdout)
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


def build_parser() -> argparse.ArgumentParser:
    """The argument parser; only commands that exist are listed."""
    parser = argparse.ArgumentParser(
        prog="kraby-study", description="Declarative PPO hyperparameter studies on the "
        "simulated Kraby hexapod leg, stored in SQLite or PostgreSQL.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands: list[tuple[str, Callable[[argparse.Namespace], int], str]] = [
        ("run", cmd_run, "run a documented sweep (study=NAME): values x seeds, resumable"),
        ("train", cmd_train, "one training run (ppo=tuned by default), model saved"),
        ("list", cmd_list, "the studies in the store with their progress"),
    ]
    for name, func, text in commands:
        command = sub.add_parser(name, help=text, description=text, epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
        command.add_argument("overrides", nargs="*", metavar="KEY=VALUE", help=OVERRIDES_HELP)
        command.set_defaults(func=func)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        return int(args.func(args))
    except (ConfigError, StoreError) as err:
        print(f"kraby-study: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("kraby-study: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
