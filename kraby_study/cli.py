"""The kraby-study command: subcommands and flags become Hydra overrides, then work is done.

Each command is argument parsing, a call of the Python API (`kraby_study.api`) and
printing; every check that can fail on user input runs before anything is written. The API
imports what a call needs when it runs, so ``--help`` and a refused input load no training,
database or statistics code.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from kraby_study import api
from kraby_study.errors import ClusterLost, ConfigError, DatabaseLost, StoreError, first_line
from kraby_study.run.provenance import note_command

if TYPE_CHECKING:
    from kraby_study.api import Best, Config, RunResult, StudyInfo

OVERRIDES_HELP = ("Hydra overrides, e.g. study=ent_coef budget=quick ppo.n_steps=64 workers=2 "
                  "storage=sqlite:///studies/kraby.db")

EPILOG = """\
config groups (conf/): env=leg|gym (env=gym env.id=Pendulum-v1: any registered Gymnasium
id), ppo=start|tuned|zoo (zoo: rl-zoo3's settings for env.id, pip install
'kraby-study[zoo]'), budget=full|quick|smoke|zoo,
study=observation|batch_size|n_steps|n_epochs|gamma|clip_range|learning_rate|gae_lambda|
ent_coef|n_envs, campaign=documented (the nine studies in order, each with the earlier
winners), search=ppo|gym|gym_sde (the Optuna spaces; optuna env=gym takes gym; gym_sde adds
gSDE's log_std_init and sde_sample_freq).
A study file may take a setting from a finished study's selected value: ppo.gamma:
${winner:gamma}.
executor=local|ray: trials run in worker processes here, or as Ray actors on a cluster
(ray.address=auto|host:port; null starts a Ray instance here); the command writes the store.
tensorboard_dir=DIR: each run's SB3 logs in DIR/<study>/<value or trial>-seed<n>, for
tensorboard --logdir DIR (pip install 'kraby-study[tensorboard]').
seeding=streams|offset: how a run's seed gives each env copy (a leg) its stream (streams:
independent children of the seed; offset: seed + i, the scheme before streams); unset, a
stored study keeps its own and a new one takes streams.
compare.margin=F (default 0.2): the smallest difference that matters, F x the best's |IQM|;
each value is best, equivalent (within it), worse (below the best by more) or undecided.
compare.select=RULE: best, report and ${winner:...} apply RULE instead of a study's stored one.
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


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid number: {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
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


def _objective(text: str) -> str:
    """``final_reward,training_time`` (or ``[final_reward,training_time]``) -> the list as an
    override value; one name stays one name."""
    names = [n.strip() for n in text.strip().strip("[]").split(",") if n.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected a reward, or a reward and a cost, got "
                                         f"{text!r}")
    return names[0] if len(names) == 1 else f"[{','.join(names)}]"


def _floor(text: str) -> str:
    """An enqueued ppo config's name as an override value; ``none`` (or null) for no floor."""
    name = text.strip()
    return "null" if name.lower() in ("none", "null") else name


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
    Flag("--cpu-budget", "search.cpu_budget", "CPU seconds the search may spend over all "
         "its trials, as search.cpu_budget=S: it starts no trial once its ended trials, "
         "what its running ones used so far and what asking the sampler cost reach it (the "
         "running ones finish, so it overshoots), so two searches compare at the same budget "
         "(default: none, --trials alone)", "S", _positive_float),
    Flag("--trial-share", "search.trial_share", "with --cpu-budget, the share of it one "
         "trial may use, as search.trial_share=F: a trial projected at a checkpoint to use "
         "more is stopped there and stored as pruned (rl-zoo3's settings and other enqueued "
         "configurations, and rechecks, never are) (default: none)", "F", _positive_float),
    Flag("--recheck", "search.recheck", "before the search ends, retrain its K best trials "
         "on search.recheck_seeds (2) more seeds each, ranking each by all its seeds, and the "
         "next in line when one drops out of the top K, within --cpu-budget (exploring stops "
         "early enough to pay for them, and does not start again; past the budget the best "
         "trial is still rechecked, so the pick always is), as search.recheck=K "
         "(default 0: none; one objective only)", "K", _whole),
    WORKERS, STORAGE,
    Flag("--study-name", "search.name", "name of the search in the store, as search.name=NAME "
         "(default ppo_search)", "NAME"),
    Flag("--objective", "search.objective", "what the search optimises, as "
         "search.objective=...: a reward (final_reward or evaluation; default final_reward), "
         "or a reward and a cost, final_reward,training_time (CPU seconds per seed), for a "
         "front of trials", "NAME[,COST]", _objective),
    Flag("--floor", "search.floor", "with two objectives, the enqueued ppo config a trial must "
         "score at least as well as to be feasible (on the front, among the sampler's good "
         "trials), as search.floor=NAME (default tuned); none for no floor", "NAME|none",
         _floor),
    Flag("--sampler", "search.sampler", "default tpe (seeded; handles one objective or two), "
         "nsga2 for NSGA-II, gp for Optuna's Gaussian-process sampler, as search.sampler=...",
         choices=("tpe", "random", "nsga2", "gp")),
    Flag("--pruner", "search.pruner", "stops bad trials: median and hyperband at env-step "
         "checkpoints, wilcoxon after whole seeds (races a trial's seeds against the best "
         "trial's), as search.pruner=... (default median; none with two objectives, which "
         "Optuna cannot prune, and with --sampler gp, which learns nothing from a pruned "
         "trial)", choices=("median", "hyperband", "wilcoxon", "none")),
    Flag("--seed", "search.seed", "sampler seed, stored with the study, as search.seed=S "
         "(default 0)", "S", _whole),
]
OUT = Flag("--out", "out", "report folder, as out=DIR (default reports)", "DIR")
CONFIRM_FLAGS = [
    Flag("--study-name", "confirm.study", "the search or sweep whose top configurations are "
         "retrained, as confirm.study=NAME (default: none, baselines only)", "NAME"),
    Flag("--top", "confirm.top", "configurations retrained: the search's best complete trials "
         "(of a two-objective search, up to K trials of its front spread along it: the best "
         "score, the cheapest, the rest evenly in cost order) or the sweep's best values, as "
         "confirm.top=K (default 5)", "K", _positive_int),
    Flag("--select", "confirm.select", "the confirm study's selection rule, as "
         "confirm.select=RULE: final_score, auc or fastest_equivalent (default: "
         "fastest_equivalent for a two-objective search, final_score otherwise; a stored "
         "confirm keeps its own)", "RULE"),
    Flag("--seeds", "confirm.seeds", "fresh seeds per configuration, none used by the study, as "
         "confirm.seeds=N (default 10); they start at confirm.seed (default 1000, apart from "
         "the tuning seeds 0, 1, ... of run and optuna)", "N", _at_least_two),
    STORAGE, WORKERS,
]


def flag_overrides(args: argparse.Namespace, flags: Sequence[Flag]) -> list[str]:
    """The flags given, as key=value overrides, placed before the user's own overrides."""
    out = []
    if getattr(args, "racing", False):
        out.append("racing.enabled=true")
    if getattr(args, "retry_failed", False):
        out.append("retry_failed=true")
    if getattr(args, "baseline", None):
        out.append(f"confirm.baselines=[{','.join(args.baseline)}]")
    for flag in flags:
        value = getattr(args, flag.name.lstrip("-").replace("-", "_"), None)
        if value is not None:
            out.append(f"{flag.key}={value}")
    return out + list(args.overrides)


def stored_study(overrides: Sequence[str]) -> tuple[str | None, list[str]]:
    """``study=NAME`` names a stored study for best and report (a search or a renamed sweep
    too), not the Hydra group of study files: it is taken out before composing."""
    names = [o.split("=", 1)[1] for o in overrides if o.startswith("study=")]
    if len(names) > 1:
        raise ConfigError("give one study=NAME (or --study-name NAME)")
    return (names[0] if names else None), [o for o in overrides if not o.startswith("study=")]


def dry_run(args: argparse.Namespace) -> bool:
    """Whether the command only shows what it would do (``--dry-run`` or ``--cfg job``)."""
    return bool(getattr(args, "dry_run", False) or getattr(args, "cfg", None))


def finish(result: RunResult) -> int:
    """Print how a training command ended and return its exit code: 130 interrupted, 1 when
    runs ended in errors (said on stderr, counted), else 0; a divergence is a result, not an
    error."""
    if result.message is not None:
        print(result.message)
    if result.warning is not None and not result.interrupted:
        print(f"kraby-study: {result.warning}", file=sys.stderr)
    return result.exit_code


def run_or_preview(args: argparse.Namespace, config: Config,
                   work: Callable[[Config], RunResult]) -> int:
    """``--dry-run``: print what the command would do; else do it."""
    if dry_run(args):
        print(api.preview(config).text())
        return 0
    return finish(work(config))


def cmd_run(args: argparse.Namespace) -> int:
    """Run a study's sweep (every value x seed) or a campaign's stages, resumable."""
    config = api.compose(flag_overrides(args, [STORAGE, WORKERS]), command="run")
    return run_or_preview(args, config, api.run_sweep)


def cmd_train(args: argparse.Namespace) -> int:
    """One training run, stored like a trial, its model saved."""
    return finish(api.train(api.compose(flag_overrides(args, [STORAGE]), command="train")))


def cmd_list(args: argparse.Namespace) -> int:
    """The studies in the store with their progress."""
    from kraby_study.config.storage import plain_storage

    overrides = flag_overrides(args, [STORAGE])
    # A plain storage=URL (or none) needs no composed config: Hydra would cost a third of
    # the command.
    url = plain_storage(overrides) or str(api.compose(overrides, command="list").cfg.storage)
    rows = api.open_store(url).studies()
    if not rows:
        print(f"no studies in {url}")
        return 0
    for line in standings_table(rows):
        print(line)
    for line in filter(None, (row.retry for row in rows)):
        print(line)
    return 0


def standings_table(rows: Sequence[StudyInfo]) -> list[str]:
    """``list``'s table: one line per study, columns padded to their widest cell."""
    header = ("study", "kind", "complete", "failed", "pruned", "running", "ran on",
              "selected so far")
    table = [header] + [(p.name, p.kind, f"{p.complete}/{p.planned}", str(p.failed),
                         str(p.pruned), str(p.running), p.ran_on, p.selected) for p in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    return ["  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True))
            for row in table]


def cmd_optuna(args: argparse.Namespace) -> int:
    """An Optuna search over conf/search/<space>.yaml, into the same store."""
    config = api.compose(flag_overrides(args, SEARCH_FLAGS), command="search")
    return run_or_preview(args, config, api.search)


def cmd_confirm(args: argparse.Namespace) -> int:
    """Retrain a study's top configurations (and baselines) on fresh seeds."""
    config = api.compose(flag_overrides(args, CONFIRM_FLAGS), command="confirm")
    return run_or_preview(args, config, api.confirm)


def cmd_best(args: argparse.Namespace) -> int:
    """Print a study's selected settings and write them as a ppo config file, or as an rl-zoo3
    hyperparameter file (``--format zoo``)."""
    from kraby_study.api.settings_files import (
        checked_name,
        default_name,
        save_ppo_config,
        save_zoo_file,
    )

    chosen, overrides = stored_study(flag_overrides(args, [STORAGE, BEST_OF]))
    if args.zoo:
        if chosen or args.campaign:
            raise ConfigError("--zoo writes rl-zoo3's settings, not a study's: drop "
                              "--study-name and --campaign")
        return write_zoo(overrides, args.name, args.format)
    if chosen and args.campaign:
        raise ConfigError("give --campaign NAME or --study-name NAME, not both")
    config = api.compose(overrides, command="best")
    name = checked_name(args.name or default_name(config, chosen, args.campaign))
    found = api.best(config, study=chosen, campaign=args.campaign)
    if args.format == "zoo":
        written = save_zoo_file(found, name)
        print_best(found)
        print(f"wrote {written.path}: train it with `{written.train_command}`")
        return 0
    path = save_ppo_config(found, name)
    print_best(found)
    print(f"wrote {path}: use it with `kraby-study train ppo={name}` or "
          f"`kraby-study run ppo={name} study=...`")
    return 0


def print_best(found: Best) -> None:
    """``best``'s lines: a two-objective search's front, then what was selected."""
    for line in found.front:
        print(line)
    print(f"best: {found.description}")


def write_zoo(overrides: Sequence[str], name: str | None, fmt: str = "ppo") -> int:
    """``best --zoo env=gym env.id=ID``: write the settings ppo=zoo reads for the id (with the
    command's own ppo overrides) as ./conf/ppo/NAME.yaml, so they can be read and changed, or
    (``--format zoo``) back as an rl-zoo3 file at budget.steps (default budget=zoo, its own
    n_timesteps)."""
    from kraby_study.api.settings_files import save_ppo_config, save_zoo_file, zoo_best

    found = zoo_best(overrides, fmt)
    if fmt == "zoo":
        written = save_zoo_file(found, name)
        print(f"wrote {written.path}: train it with `{written.train_command}`")
        return 0
    path = save_ppo_config(found, name)
    print(f"wrote {path}: use it with `kraby-study train env=gym "
          f"env.id={found.settings['env']['id']} ppo={path.stem}`")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Redraw the figures and tables of the stored studies."""
    chosen, overrides = stored_study(flag_overrides(args, [STORAGE, REPORTED, OUT]))
    written = api.write_report(api.compose(overrides, command="report"), study=chosen,
                         fmt=args.format, policy=not args.no_policy)
    for line in written.lines():
        print(line)
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser; only commands that exist are listed."""
    parser = _Parser(
        prog="kraby-study", description="Declarative PPO hyperparameter studies on the "
        "simulated Kraby hexapod leg or any Gymnasium environment, stored in SQLite or "
        "PostgreSQL.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                parser_class=_Parser)
    commands: list[tuple[str, Callable[[argparse.Namespace], int], str]] = [
        ("run", cmd_run, "run a documented sweep (study=NAME) or a chain of them "
         "(campaign=NAME): values x seeds, resumable"),
        ("train", cmd_train, "one training run (ppo=tuned by default), model saved"),
        ("list", cmd_list, "the studies in the store with their progress"),
        ("optuna", cmd_optuna, "an Optuna search over conf/search/ppo.yaml: TPE with pruning, "
         "or score and cost together (--objective)"),
        ("confirm", cmd_confirm, "retrain a search's top configurations (or a sweep's top "
         "values, or baselines) on fresh seeds, into study NAME-confirm"),
        ("best", cmd_best, "print a study's selected settings (or a campaign's, --campaign) and "
         "write them as ./conf/ppo/NAME.yaml (--format zoo: as an rl-zoo3 hyperparameter file "
         "./zoo/NAME.yml)"),
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
        "first seed. --pruner wilcoxon sees each seed's final score instead, and stops a "
        "trial's remaining seeds once its finished ones are worse than the best trial's same "
        "seeds by a one-sided Wilcoxon signed-rank test, p < search.wilcoxon_p (0.1: from its "
        "4th seed on, so budget.seeds=5 or more; budget=full has 10).\n\n"
        "--objective final_reward,training_time (search.objective=[final_reward,"
        "training_time]) searches for score and cost at once: the cost is the trial's CPU "
        "seconds per seed, the study has two directions, TPE (or --sampler nsga2 or gp) samples "
        "for both, and no pruner runs (Optuna cannot prune a trial of several objectives; "
        "--pruner other than none is refused). A trial scoring below the --floor "
        "configuration (ppo=tuned unless you choose; it is enqueued) is infeasible: off the "
        "front and out of the sampler's good trials, so the search looks for settings as good "
        "as the floor at less cost. list, best and the report show the front; "
        "best writes its cheapest trial shown equivalent to the best score (within "
        "compare.margin), and confirm --study-name "
        "retrains --top trials spread along it.\n\n" + EPILOG)
    for name in ("run", "optuna", "confirm"):
        parsers[name].add_argument(
            "--dry-run", action="store_true",
            help="compose and check as the real command, then print the config as YAML, the "
            "plan (trials, env steps, how many the store already holds) and an estimate of "
            "the wall time from the steps/s measured on this store; nothing is trained or "
            "written")
        parsers[name].add_argument("--cfg", choices=("job",),
                                   help="--cfg job is Hydra's spelling of --dry-run")
        parsers[name].add_argument(
            "--retry-failed", action="store_true",
            help="queue the study's runs that failed with an error again, with the same seeds "
            "and settings, before running (complete and diverged runs are left alone), as "
            "retry_failed=true")
    for name in ("run", "confirm"):
        parsers[name].add_argument(
            "--racing", action="store_true",
            help="run seeds in rounds; a value leaves once shown worse than the best by more "
            "than compare.margin, or shown equivalent to it (stored with the race; margin 0: "
            "only values shown worse leave) "
            "(as racing.enabled=true; racing.min_seeds, default 4, racing.alpha, default "
            "0.05, and racing.paired, default false, tune it); budget.seeds (confirm: --seeds) "
            "is the most any value gets")
    parsers["optuna"].add_argument(
        "--racing", action="store_true",
        help="a racing search (as racing.enabled=true): each configuration the sampler asks "
        "for trains racing.min_seeds (4) seeds side by side, then one at a time against the "
        "incumbent; it leaves once shown worse by more than compare.margin (or equivalent and "
        "not cheaper), replaces the incumbent once shown better (or equivalent and cheaper in "
        "CPU s per run), or, undecided at the incumbent's seed count, if its IQM on the common "
        "seeds is higher; the incumbent earns a seed whenever no challenger wants one, up to "
        "budget.seeds. Ends at --cpu-budget or --trials configurations; the pick is the "
        "incumbent. One objective, no --pruner, --recheck or --trial-share; TPE is "
        "multivariate")
    parsers["confirm"].add_argument(
        "--baseline", action="append", type=_baseline, metavar="ppo=NAME",
        help="add a ppo config's settings as one more configuration (repeatable), e.g. "
        "--baseline ppo=tuned; with no --study-name, only these are retrained")
    parsers["confirm"].epilog = (
        "each configuration trains --seeds runs at the study's budget (steps and curve bins; "
        "budget=quick for baselines alone), with seeds no trial of the study used. The study "
        "NAME-confirm (confirm-<baselines> for baselines alone; confirm.name=NAME names it) "
        "is resumable like run; report it, then `kraby-study best --study-name "
        "NAME-confirm` writes the confirmed winner's settings, selected by --select (of a "
        "two-objective search's front by default fastest_equivalent: the cheapest in CPU "
        "seconds among the best arm and those shown equivalent to it). `kraby-study best "
        "--study-name NAME-confirm compare.select=RULE` re-selects a stored confirm by another "
        "rule without retraining.\n\n" + EPILOG)
    parsers["best"].add_argument("--name", help="config name to write in ./conf/ppo/ (./zoo/ "
                                 "with --format zoo; default best_<study>, or campaign_<NAME>)")
    parsers["best"].add_argument("--zoo", action="store_true",
                                 help="write rl-zoo3's published PPO settings for env.id "
                                 "(ppo=zoo, needs env=gym env.id=ID and the [zoo] extra) "
                                 "instead of a study's (default name zoo_<id>)")
    parsers["best"].add_argument(
        "--format", choices=("ppo", "zoo"), default="ppo",
        help="ppo (default): a ppo config file in ./conf/ppo/; zoo: an rl-zoo3 hyperparameter "
        "file ./zoo/NAME.yml for the settings' Gymnasium id, in rl-zoo3's keys, n_timesteps "
        "the study's budget steps, for python -m rl_zoo3.train --algo ppo --env ID -conf FILE "
        "(an env=gym study's; with --zoo, rl-zoo3's settings written back)")
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
    note_command(sys.argv[1:] if argv is None else argv)
    try:
        return int(args.func(args))
    except (ConfigError, StoreError) as err:
        print(f"kraby-study: error: {err}", file=sys.stderr)
        return 2
    except (DatabaseLost, ClusterLost) as err:
        print(f"kraby-study: error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("kraby-study: interrupted", file=sys.stderr)
        return 130
    except Exception as err:
        if not _lost_database(err):
            raise
        # A database that fails outside the retried calls (while a study is being opened).
        print(f"kraby-study: error: database error: {first_line(err)}", file=sys.stderr)
        return 1


def _lost_database(err: Exception) -> bool:
    """A database out of reach; only a command that opened a store (so loaded it) has one."""
    if "kraby_study.store.store" not in sys.modules:
        return False
    from kraby_study.store.store import LOST_DATABASE

    return isinstance(err, LOST_DATABASE)


if __name__ == "__main__":
    sys.exit(main())
