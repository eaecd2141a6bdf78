"""The kraby-study command: subcommands and flags become Hydra overrides, then work is done.

main() only wires arguments to the functions that do the work; every check that can fail on
user input runs before anything is written. Each command imports what it needs when it runs,
so ``--help`` and a refused input load no training, database or statistics code.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any

from kraby_study.errors import ClusterLost, ConfigError, DatabaseLost, StoreError, first_line
from kraby_study.run.provenance import note_command

if TYPE_CHECKING:
    from omegaconf import DictConfig

    from kraby_study.answers.standing import StudyStanding
    from kraby_study.plan.preview import Count
    from kraby_study.plan.spec import StudyPlan
    from kraby_study.records.stored import Tally
    from kraby_study.run.executor import Executor
    from kraby_study.run.runner import CommandRun

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
         "confirm.select=RULE: final_score, auc, fastest_equivalent or fastest_tied (default: "
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


def compose_config(overrides: Sequence[str]) -> DictConfig:
    """The command's config (Hydra and the schema are loaded on first use)."""
    from kraby_study.config.compose import compose_config as compose

    return compose(overrides)


def checked_outputs(cfg: DictConfig) -> DictConfig:
    """The config of a training command, once the folders it writes to are known writable."""
    from kraby_study.plan.settings import validate_outputs

    validate_outputs(cfg)
    return cfg


def ended(summary: CommandRun) -> int:
    """A training command's exit code: 130 interrupted, 1 when runs ended in errors (said on
    stderr, counted), else 0; a divergence is a result, not an error."""
    if summary.interrupted:
        return 130
    line = summary.errors_line()
    if line:
        print(f"kraby-study: {line}", file=sys.stderr)
        return 1
    return 0


def open_writer(cfg: DictConfig):  # noqa: ANN201 - a context manager of Store
    """The store a command writes to, with the configured heartbeat timing."""
    from kraby_study.store.store import opened

    return opened(cfg.storage, heartbeat_interval=int(cfg.heartbeat_interval),
                  heartbeat_grace=int(cfg.heartbeat_grace))


def run_options(cfg: DictConfig) -> dict[str, Any]:
    """Heartbeat period and database patience of a running command."""
    return {"heartbeat_seconds": float(cfg.heartbeat_interval),
            "retry_seconds": float(cfg.db_retry_seconds),
            "failed_again": bool(cfg.retry_failed)}


def dry_run(args: argparse.Namespace) -> bool:
    """Whether the command only shows what it would do (``--dry-run`` or ``--cfg job``)."""
    return bool(getattr(args, "dry_run", False) or getattr(args, "cfg", None))


def print_preview(cfg: DictConfig, counts: Sequence[Count],
                  notes: dict[str, list[str]] | None = None) -> int:
    """A dry run's output: the composed config as YAML, the plan and the estimate."""
    from omegaconf import OmegaConf

    from kraby_study.answers.preview import preview_lines
    from kraby_study.config.validate import cores

    workers = (int(cfg.workers) if cfg.workers is not None
               else cores() if str(cfg.executor) == "local" else None)
    from kraby_study.env import adapter_for

    lines = preview_lines(str(cfg.storage), counts, workers, notes)
    print(OmegaConf.to_yaml(cfg), end="")
    print(f"env: {adapter_for(cfg.env).label(cfg.env)}")
    print("\n".join(lines))
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    """Run a study's sweep: every value x seed, resumable."""
    from kraby_study.answers.resumed import resumed
    from kraby_study.answers.winners import StoreWinners
    from kraby_study.config.winner import winners_from
    from kraby_study.plan.sweep import expand_study

    overrides = flag_overrides(args, [STORAGE, WORKERS])
    lookup = StoreWinners()
    with winners_from(lookup):
        cfg = checked_outputs(compose_config(overrides))
    if cfg.campaign is not None:
        if dry_run(args):
            return preview_campaign(cfg, overrides)
        return run_campaign_command(cfg, overrides)
    if cfg.study is not None:
        cfg = resumed(cfg, str(cfg.study.name))
    plan = dataclasses.replace(expand_study(cfg), inputs=[i.stored() for i in lookup.inputs])
    if dry_run(args):
        from kraby_study.plan.preview import plan_count

        return print_preview(cfg, [plan_count(plan)],
                             {plan.name: [f"from other studies: {i.text()}"
                                          for i in lookup.inputs]})
    # Loaded once the input is known to be good: a refused input answers at once.
    from kraby_study.run.executor import executor_for
    from kraby_study.run.study_run import closing_line

    with executor_for(cfg) as executor:
        summary, counts = run_stage(cfg, plan, executor)
    print(closing_line("study", plan, counts))
    return ended(summary)


def run_stage(cfg: DictConfig, plan: StudyPlan, executor: Executor) -> tuple[CommandRun, Tally]:
    """Run a plan on the command's store and executor: (what this command ran, the plan's
    outcomes)."""
    from kraby_study.run.study_run import run_plan

    with open_writer(cfg) as store:
        return run_plan(store, plan, executor, executor.workers(cfg.workers), sys.stdout,
                        **run_options(cfg))


def run_campaign_command(cfg: DictConfig, overrides: Sequence[str]) -> int:
    """``run campaign=NAME``: every stage in order, resumable."""
    from kraby_study.plan.campaign import campaign_of
    from kraby_study.run.campaign_run import run_campaign
    from kraby_study.run.executor import executor_for

    campaign = campaign_of(cfg, overrides)
    with executor_for(cfg) as executor:
        return run_campaign(campaign, lambda stage_cfg, plan: run_stage(stage_cfg, plan, executor),
                            sys.stdout)


def preview_campaign(cfg: DictConfig, overrides: Sequence[str]) -> int:
    """``run campaign=NAME --dry-run``: each stage's trials, and its inputs from earlier
    stages (named, not guessed, while those are not selected)."""
    from kraby_study.answers.preview import campaign_preview
    from kraby_study.plan.campaign import campaign_of

    stages = campaign_preview(campaign_of(cfg, overrides))
    return print_preview(cfg, [s.count for s in stages], {
        s.count.study: [f"stage {s.stage.number}/{len(stages)} ({s.stage.parameter}, select "
                        f"{s.stage.select})"] + [f"from earlier stages: {i}" for i in s.inputs]
        for s in stages})


def cmd_train(args: argparse.Namespace) -> int:
    """One training run, stored like a trial, its model saved."""
    from kraby_study.plan.train import train_plan
    from kraby_study.run.executor import executor_for
    from kraby_study.run.study_run import run_plan, train_outcome

    cfg = checked_outputs(compose_config(with_default(flag_overrides(args, [STORAGE]), "ppo",
                                                      "tuned")))
    if cfg.racing.enabled:
        raise ConfigError("racing is for run and confirm: train makes one run")
    plan = train_plan(cfg)
    with executor_for(cfg) as executor:
        # One run: its worker starts importing torch and SB3 while the store opens.
        executor.prestart(1)
        with open_writer(cfg) as store:
            summary, _ = run_plan(store, plan, executor, 1, sys.stdout, **run_options(cfg))
            return train_outcome(store, plan, summary, int(cfg.seed), sys.stdout)


def cmd_list(args: argparse.Namespace) -> int:
    """The studies in the store with their progress."""
    from kraby_study.answers.standing import store_standings
    from kraby_study.config.storage import plain_storage

    overrides = flag_overrides(args, [STORAGE])
    # A plain storage=URL (or none) needs no composed config: Hydra would cost a third of
    # the command.
    url = plain_storage(overrides) or str(compose_config(overrides).storage)
    rows = store_standings(url)
    if not rows:
        print(f"no studies in {url}")
        return 0
    for line in standings_table(rows):
        print(line)
    for line in filter(None, (row.retry_line() for row in rows)):
        print(line)
    return 0


def standings_table(rows: Sequence[StudyStanding]) -> list[str]:
    """``list``'s table: one line per study, columns padded to their widest cell."""
    header = ("study", "kind", "complete", "failed", "pruned", "running", "ran on",
              "selected so far")
    table = [header] + [(p.name, p.kind.value, f"{p.tally.complete}/{p.tally.planned}",
                         str(p.tally.failed), str(p.tally.pruned), str(p.tally.running),
                         p.placement.text(), p.selected) for p in rows]
    widths = [max(len(row[i]) for row in table) for i in range(len(header))]
    return ["  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True))
            for row in table]


def cmd_optuna(args: argparse.Namespace) -> int:
    """An Optuna search over conf/search/<space>.yaml, into the same store."""
    from kraby_study.answers.resumed import resumed
    from kraby_study.answers.standing import study_standing
    from kraby_study.config.compose import composed
    from kraby_study.plan.settings import settings_with_ppo
    from kraby_study.plan.space import objectives, validate_search
    from kraby_study.run.executor import executor_for
    from kraby_study.run.search_source import run_search

    overrides = with_default(flag_overrides(args, SEARCH_FLAGS), "budget", "quick")
    if "env=gym" in overrides:
        # The default space searches the leg's observation too; a gym env's space has no env.
        overrides = with_default(overrides, "search", "gym")
    config = composed(overrides)
    cfg = checked_outputs(config.cfg)
    if cfg.racing.enabled:
        raise ConfigError("racing is for run and confirm: a search races its trials' seeds "
                          "with --pruner wilcoxon")
    cfg = resumed(cfg, str(cfg.search.name))
    if cfg.search.enqueue is None:  # a new search starts from the settings it was given
        cfg.search.enqueue = [config.ppo]
    validate_search(cfg)
    starts = [(f"ppo={name}", settings_with_ppo(name, overrides))
              for name in cfg.search.enqueue]
    if dry_run(args):
        from kraby_study.plan.preview import search_count
        from kraby_study.plan.space import method_text

        return print_preview(cfg, [search_count(cfg)], {str(cfg.search.name): [method_text(cfg)]})
    with executor_for(cfg) as executor, open_writer(cfg) as store:
        summary, ledger = run_search(store, cfg, executor, executor.workers(cfg.workers),
                                     sys.stdout, starts=starts)
        state = study_standing(ledger)
    counts = state.tally
    chosen = state.selected if len(objectives(cfg)) == 2 else f"best {state.selected}"
    print(f"search {state.name}: {counts.complete} complete, {counts.pruned} pruned, "
          f"{counts.failed} failed of {counts.planned}; {chosen}")
    return ended(summary)


def cmd_confirm(args: argparse.Namespace) -> int:
    """Retrain a study's top configurations (and baselines) on fresh seeds."""
    from kraby_study.answers.configurations import confirmed_study
    from kraby_study.answers.resumed import resumed
    from kraby_study.plan.confirm import baseline_arm, confirm_name, confirm_plan, confirm_rule
    from kraby_study.run.executor import executor_for
    from kraby_study.run.study_run import closing_line, run_plan
    from kraby_study.store.store import opened, opened_for_reading

    overrides = flag_overrides(args, CONFIRM_FLAGS)
    cfg = checked_outputs(compose_config(with_default(overrides, "budget", "quick")))
    confirm_rule(cfg, None)  # a rule that is not one is refused before the store is read
    baselines = [baseline_arm(name, overrides) for name in cfg.confirm.baselines]
    source = None
    if cfg.confirm.study is not None:
        # A dry run never opens a store that is not there (opening would create the file).
        reader = opened_for_reading if dry_run(args) else partial(opened, create=False,
                                                                   writer=False)
        with reader(cfg.storage) as store:
            source = confirmed_study(store.load(str(cfg.confirm.study)), int(cfg.confirm.top))
    cfg = resumed(cfg, confirm_name(source.name if source else None,
                                    [arm.label for arm in baselines], cfg.confirm.name))
    plan = confirm_plan(cfg, source, baselines)
    if dry_run(args):
        from kraby_study.plan.preview import plan_count

        return print_preview(cfg, [plan_count(plan, arms="configurations")])
    with executor_for(cfg) as executor, open_writer(cfg) as store:
        summary, counts = run_plan(store, plan, executor, executor.workers(cfg.workers),
                                   sys.stdout, **run_options(cfg))
    print(closing_line("confirm", plan, counts)
          + f"; report it with `kraby-study report --study-name {plan.name}`")
    return ended(summary)


ZOO_DIR = "zoo"
"""Where ``best --format zoo`` writes rl-zoo3 hyperparameter files, in the working folder."""


def cmd_best(args: argparse.Namespace) -> int:
    """Print a study's selected settings and write them as a ppo config file, or as an rl-zoo3
    hyperparameter file (``--format zoo``)."""
    from pathlib import Path

    from kraby_study.answers.campaign import campaign_selection
    from kraby_study.answers.selected import require_selection
    from kraby_study.config.conf_dirs import USER_CONF_DIR
    from kraby_study.config.ppo_file import write_ppo_config
    from kraby_study.decision.comparison import CompareOptions
    from kraby_study.store.store import opened

    chosen, overrides = stored_study(flag_overrides(args, [STORAGE, BEST_OF]))
    if args.zoo:
        if chosen or args.campaign:
            raise ConfigError("--zoo writes rl-zoo3's settings, not a study's: drop "
                              "--study-name and --campaign")
        return write_zoo(overrides, args.name, args.format)
    if chosen and args.campaign:
        raise ConfigError("give --campaign NAME or --study-name NAME, not both")
    cfg = compose_config(overrides)
    name = chosen or str(cfg.search.name)
    config_name = args.name or (f"campaign_{args.campaign}" if args.campaign else f"best_{name}")
    if not config_name.replace("_", "").replace("-", "").isalnum():
        raise ConfigError(f"--name {config_name!r}: use letters, digits, _ and -")
    options = CompareOptions.of(cfg)
    with opened(cfg.storage, create=False, writer=False) as store:
        chosen = (campaign_selection(store, args.campaign, options) if args.campaign
                  else require_selection(store.load(name), options))
    if args.format == "zoo":
        what = f"campaign {args.campaign!r}" if args.campaign else f"study {name!r}"
        if chosen.steps is None:
            raise StoreError(f"{what} stores no budget steps for its selected trial, which an "
                             "rl-zoo3 file needs as n_timesteps")
        for line in chosen.front:
            print(line)
        print(f"best: {chosen.description}")
        return write_hyperparams_file(chosen.settings, chosen.steps, chosen.description,
                                      config_name, what)
    path = Path(USER_CONF_DIR) / "ppo" / f"{config_name}.yaml"
    write_ppo_config(chosen.settings, chosen.env_keys, chosen.description, path)
    for line in chosen.front:
        print(line)
    print(f"best: {chosen.description}")
    print(f"wrote {path}: use it with `kraby-study train ppo={config_name}` or "
          f"`kraby-study run ppo={config_name} study=...`")
    return 0


def write_hyperparams_file(settings: dict[str, Any], steps: int, description: str,
                           config_name: str, what: str) -> int:
    """``best --format zoo``: write stored or composed settings (``env`` and ``ppo``) and a
    budget as ./zoo/NAME.yml, an rl-zoo3 hyperparameter file for their Gymnasium id; refused in
    one line, before anything is written, when they are not a Gymnasium id's."""
    from pathlib import Path

    from kraby_study.config.zoo import study_settings, train_command, write_hyperparams
    from kraby_study.plan.spec import OPTIONAL_PPO

    complete = {"env": settings.get("env", {}),
                "ppo": {**OPTIONAL_PPO, **settings.get("ppo", {})}}
    read = study_settings(complete, steps, what)
    path = Path(ZOO_DIR) / f"{config_name}.yml"
    packages = [str(p) for p in complete["env"].get("packages", [])]
    write_hyperparams(read, description, path, packages)
    print(f"wrote {path}: train it with `{train_command(read.env_id, path, packages)}`")
    return 0


def write_zoo(overrides: Sequence[str], name: str | None, fmt: str = "ppo") -> int:
    """``best --zoo env=gym env.id=ID``: write the settings ppo=zoo reads for the id (with the
    command's own ppo overrides) as ./conf/ppo/NAME.yaml, so they can be read and changed, or
    (``--format zoo``) back as an rl-zoo3 file at budget.steps (default budget=zoo, its own
    n_timesteps)."""
    import re
    from pathlib import Path

    from kraby_study.config.conf_dirs import USER_CONF_DIR
    from kraby_study.config.ppo_file import write_ppo_config
    from kraby_study.config.validate import to_container
    from kraby_study.config.zoo import zoo_settings

    chosen = [*(o for o in overrides if not o.startswith("ppo=")), "ppo=zoo"]
    cfg = compose_config(with_default(chosen, "budget", "zoo") if fmt == "zoo" else chosen)
    read = zoo_settings(str(cfg.env.id))
    config_name = name or "zoo_" + re.sub(r"[^A-Za-z0-9_-]+", "_", read.env_id)
    if not config_name.replace("_", "").replace("-", "").isalnum():
        raise ConfigError(f"--name {config_name!r}: use letters, digits, _ and -")
    settings = {"env": to_container(cfg.env), "ppo": to_container(cfg.ppo)}
    if fmt == "zoo":
        return write_hyperparams_file(
            settings, int(cfg.budget.steps),
            f"rl-zoo3 {read.version}'s PPO settings for {read.env_id}, as ppo=zoo reads them",
            config_name, f"ppo=zoo for {read.env_id}")
    path = Path(USER_CONF_DIR) / "ppo" / f"{config_name}.yaml"
    write_ppo_config(settings, [],
                     f"rl-zoo3 {read.version}'s PPO settings for {read.env_id} (its budget, "
                     f"n_timesteps {read.n_timesteps:,}, is budget=zoo)", path)
    print(f"wrote {path}: use it with `kraby-study train env=gym env.id={read.env_id} "
          f"ppo={config_name}`")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Redraw the figures and tables of the stored studies."""
    from types import SimpleNamespace

    from omegaconf import OmegaConf

    from kraby_study.report import run_report

    chosen, overrides = stored_study(flag_overrides(args, [STORAGE, REPORTED, OUT]))
    cfg = compose_config(overrides)
    # The report's options with the comparison's: a report may re-analyse any study at any
    # margin, and read another rule than the stored one (compare.select).
    options = SimpleNamespace(**OmegaConf.to_container(cfg.report), margin=cfg.compare.margin,
                              select=cfg.compare.select)
    return run_report(cfg.storage, cfg.out, study=chosen, fmt=args.format, stream=sys.stdout,
                      policy=not args.no_policy, options=options)


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
        "compare.margin; a search stored before keeps fastest_tied), and confirm --study-name "
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
            help="queue the study's failed runs again, with the same seeds and settings, "
            "before running (complete runs are left alone), as retry_failed=true")
    for name in ("run", "confirm"):
        parsers[name].add_argument(
            "--racing", action="store_true",
            help="run seeds in rounds; a value leaves once shown worse than the best by more "
            "than compare.margin, or shown equivalent to it (stored with the race; margin 0: "
            "only values shown worse leave) "
            "(as racing.enabled=true; racing.min_seeds, default 4, racing.alpha, default "
            "0.05, and racing.paired, default false, tune it); budget.seeds (confirm: --seeds) "
            "is the most any value gets")
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
    if args.command == "optuna" and any(e.partition("=")[0] == "--racing" for e in unknown):
        parser.error("--racing races a sweep's seeds; a search races its trials' seeds with "
                     "--pruner wilcoxon")
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
