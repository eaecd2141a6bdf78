"""Benchmark: which tuning method finds the best leg settings per CPU second.

Run:  python benchmarks/bench_methods.py --cpu-budget B [--seeds METHOD=SEEDS ...]
          [--storage URL] [--workers N] [--confirm-seeds 10] [--out methods.csv]
          [--set METHOD:KEY=VALUE ...] [KEY=VALUE ...]
      ... --campaign-cpu      (the campaign's repetitions only; prints their CPU s)
      ... --plan              (every command it would run, with the CPU it expects)
      ... --table [--margin F] [--alpha A]
      ... --full-budget M1 M2 [--full-repetitions R ...]

Four methods tune PPO on the leg (``env=leg``) at one reduced budget, given as the
``KEY=VALUE`` overrides every command gets (on top of ``budget=quick``; the plan uses
``budget.steps=20480 budget.seeds=2 budget.curve_every=1024``):

- ``campaign``: ``kraby-study run campaign=documented``, the nine documented one-at-a-time
  sweeps, each fixing the earlier stages' winners (conf/campaign/documented.yaml);
- ``random``: ``kraby-study optuna search.sampler=random``;
- ``tpe``: ``kraby-study optuna``, today's default search (TPE, its default pruner);
- ``racing``: ``kraby-study optuna --racing`` (the racing search), with any overrides given
  as ``--set racing:KEY=VALUE``: its seed cap ``budget.seeds`` must be at least
  ``racing.min_seeds`` (4), e.g. ``--set racing:budget.seeds=10`` (refused before any work
  otherwise).

Every search may use ``--cpu-budget`` B CPU seconds (``search.cpu_budget``); the plan sets B
to the CPU the campaign's first repetition used, which ``--campaign-cpu`` runs and prints
(read from the store: every attempt's ``cpu_time``, and a search's ``suggest_cpu``, as
``benchmarks/bench_search.py`` reads them). Every search starts from the documented starting
point only, ``search.enqueue=[start]``, where the campaign starts: the default enqueues
``tuned`` too, the hand-tuned result, which would hand the searches the documented answer.

Repetition r of a method is its own set of studies in one store: a search's is its sampler
seed r (``search.seed=r``) and tuning seeds 100 r, 100 r + 1, ... (``seed=100r``), stored as
``TAG-METHOD-rR``; a campaign's trains seeds 100 r, ... as campaign ``TAG-campaign-rR``
(``campaign.name``), its stages ``TAG-campaign-rR-STUDY``. ``racing`` and ``random`` of the same
r are a pair (the same sampler seed and tuning seeds). Each repetition's pick is retrained on
``--confirm-seeds`` fresh seeds at the same budget, ``kraby-study confirm --study-name NAME
--top 1``: the search's best trial, or the campaign's last stage's top value, whose settings
carry every earlier stage's winner (the harness checks that they are the settings
``kraby-study best --campaign`` gives). Every confirm trains the same fresh seeds (1000 on;
checked), so two picks are compared seed by seed.

Resumable: each step reads the store first. A repetition whose confirm is finished is skipped;
otherwise its tuning command runs again (a finished search or campaign starts nothing, a killed
one continues where it stopped), then its confirm (likewise). After each confirm the CSV
``--out`` is written again from the store: one row per method and repetition (CPU s of the
tuning, the configurations it trained and its env steps, the pick and its settings, its search
score, the confirmed IQM with its 95 % Tukey-McLaughlin trimmed-t interval, failed runs and
seeds, CPU s per confirm run).

``--table`` prints one markdown table: per method and repetition, the tuning's CPU s, the
configurations it trained (distinct settings: a campaign's values over its stages, each
stage's earlier winner once; a search's trials; a racing search's configurations whatever
their seeds) and its env steps (every attempt's), the pick,
its confirmed IQM [interval] and its answer against the campaign's pick of the same
repetition (``ks.compare`` on the two picks' confirmed seed scores at ``--margin``, default
``compare.margin`` 0.2, and ``--alpha``: better, equivalent, worse or undecided), then per
method the mean CPU s and the answers counted, losses included. Then the planned test, fixed
before the first run: racing against random search, paired by repetition, the exact one-sided
Wilcoxon signed-rank test (scipy, ``alternative='greater'``, zero differences dropped) on the
confirmed IQMs, alpha 0.05, n the complete pairs; and the same test of each other search
method against random search where pairs exist, labelled exploratory. Last, the plan's second
test: the search method with the highest mean confirmed IQM against the campaign, paired by
repetition, one-sided Student t (scipy ``ttest_1samp``, ``alternative='greater'``) that the
mean IQM difference is above ``-margin x |the campaign's mean confirmed IQM|``
(non-inferiority), with both methods' mean CPU s. ``--asked SETTING=VALUE`` (with
``--table``) adds per method and repetition how many configurations had that setting, of all
the tuning trained, and the mean CPU s of a run with it and with other values.

``--full-budget M1 M2`` (its own invocation, after the reduced-budget runs) retrains the picks
of two methods at the full budget (``budget=full`` then the invocation's overrides: 250,000
steps) on ``--confirm-seeds`` fresh seeds, each as ``confirm --baseline ppo=pick_M_rR`` into
study ``TAG-full-M-rR`` (the pick written as ./conf/ppo/pick_M_rR.yaml in the working folder,
its settings checked equal to the confirmed ones), every repetition with a finished confirm
unless ``--full-repetitions`` names some; resumable like the rest. ``--table`` then adds their
IQMs and M1's answer against M2's pick of the same repetition.

The last line reads ``bench_methods: racing - random confirmed IQM, ...`` (the planned test).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import shlex
import statistics
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).parent))
import optuna  # noqa: E402
from bench_search import signed_rank  # noqa: E402

import kraby_study as ks  # noqa: E402
from kraby_study.answers.study_data import load_study  # noqa: E402
from kraby_study.answers.sweep_evidence import build_sweep  # noqa: E402
from kraby_study.config.ppo_file import write_ppo_config  # noqa: E402
from kraby_study.decision.intervals import iqm_interval_name  # noqa: E402
from kraby_study.errors import ConfigError, StoreError  # noqa: E402
from kraby_study.plan.campaign import campaign_of, stage_file  # noqa: E402
from kraby_study.plan.confirm import TEST_SEED  # noqa: E402
from kraby_study.plan.settings import settings_with_ppo  # noqa: E402
from kraby_study.records.stored import counted, spent_cpu  # noqa: E402
from kraby_study.store.store import opened_for_reading  # noqa: E402

optuna.logging.set_verbosity(optuna.logging.WARNING)

METHODS = ("campaign", "random", "tpe", "racing")
SEARCHES = ("random", "tpe", "racing")
PLANNED = ("racing", "random")
"""The planned test: the first method against the second, paired by repetition."""
PLANNED_ALPHA = 0.05
DEFAULT_SEEDS = {"campaign": "0-4", "random": "0-9", "tpe": "0-4", "racing": "0-9"}
SEED_STRIDE = 100
"""Repetition r trains tuning seeds from SEED_STRIDE x r: apart from every other repetition's
and, up to r = 9, from the confirms' fresh seeds (1000 on)."""
CAMPAIGN = "documented"
SHORT = [("env", "observation", "obs"), ("ppo", "n_steps", "n_steps"),
         ("ppo", "batch_size", "batch"), ("ppo", "n_epochs", "epochs"),
         ("ppo", "gamma", "gamma"), ("ppo", "clip_range", "clip"),
         ("ppo", "learning_rate", "lr"), ("ppo", "gae_lambda", "lambda"),
         ("ppo", "ent_coef", "ent")]
"""The settings the search space and the campaign vary, as a pick's short form writes them."""
COLUMNS = ["method", "repetition", "budget_steps", "tuning", "cpu_s", "configurations",
           "env_steps", "pick",
           "settings", "search_score", "confirm", "seeds", "confirmed_iqm", "iqm_low",
           "iqm_high", "interval", "failed_runs", "failed_seeds", "confirm_cpu_per_run"]


def key_of(override: str) -> str:
    """The setting an override sets (``budget`` for ``budget=smoke``)."""
    return override.split("=", 1)[0].lstrip("+~")


def merged(*lists: Sequence[str]) -> list[str]:
    """Overrides in order, a later one replacing an earlier one of the same setting (Hydra
    refuses a setting given twice)."""
    out: dict[str, str] = {}
    for overrides in lists:
        for override in overrides:
            out.pop(key_of(override), None)
            out[key_of(override)] = override
    return list(out.values())


def parse_seeds(given: Sequence[str]) -> dict[str, list[int]]:
    """``METHOD=0-9`` or ``METHOD=0,3,4`` per method; ConfigError on anything else."""
    seeds: dict[str, list[int]] = {}
    for item in given:
        method, _, text = item.partition("=")
        if method not in METHODS or not text:
            raise ConfigError(f"--seeds {item!r}: use METHOD=FIRST-LAST or METHOD=R,R,... "
                              f"with METHOD one of {', '.join(METHODS)}")
        try:
            if "-" in text:
                first, last = (int(part) for part in text.split("-", 1))
                found = list(range(first, last + 1))
            else:
                found = [int(part) for part in text.split(",")]
        except ValueError:
            raise ConfigError(f"--seeds {item!r}: repetitions are whole numbers") from None
        if not found or len(set(found)) != len(found) or not all(0 <= r < 10 for r in found):
            raise ConfigError(f"--seeds {item!r}: distinct repetitions from 0 to 9 (repetition "
                              f"r trains seeds from {SEED_STRIDE} r, below the fresh seeds "
                              f"{TEST_SEED} on)")
        seeds[method] = found
    return seeds


def parse_sets(given: Sequence[str]) -> dict[str, list[str]]:
    """``METHOD:KEY=VALUE`` overrides of one method's tuning command."""
    sets: dict[str, list[str]] = {m: [] for m in METHODS}
    for item in given:
        method, _, override = item.partition(":")
        if method not in METHODS or "=" not in override:
            raise ConfigError(f"--set {item!r}: use METHOD:KEY=VALUE with METHOD one of "
                              f"{', '.join(METHODS)}")
        sets[method].append(override)
    return sets


def racing_available() -> bool:
    """Whether this install's ``kraby-study optuna`` has the racing search (``--racing``)."""
    done = subprocess.run([sys.executable, "-m", "kraby_study.cli", "optuna", "--help"],
                          capture_output=True, text=True)
    return done.returncode == 0 and "--racing" in done.stdout


@dataclass(frozen=True)
class Arm:
    """One repetition of one method: its tuning studies, its pick's confirm, and its pick at
    the full budget."""

    method: str
    repetition: int
    tag: str
    stages: tuple[str, ...]
    """The campaign's stage studies, in order (the study names after ``TAG-campaign-rR-``)."""

    @property
    def tuning(self) -> str:
        """The search's name, or the campaign's."""
        return f"{self.tag}-{self.method}-r{self.repetition}"

    @property
    def studies(self) -> list[str]:
        """The stored studies the tuning made."""
        if self.method == "campaign":
            return [f"{self.tuning}-{stage}" for stage in self.stages]
        return [self.tuning]

    @property
    def picked(self) -> str:
        """The study whose top configuration is the pick: the search, or the last stage."""
        return self.studies[-1]

    @property
    def confirm(self) -> str:
        """The pick's confirm at the tuning budget (confirm's own name for it)."""
        return f"{self.picked}-confirm"

    @property
    def full(self) -> str:
        """The pick's confirm at the full budget."""
        return f"{self.tag}-full-{self.method}-r{self.repetition}"

    @property
    def ppo_name(self) -> str:
        """The pick as a ppo config (./conf/ppo/NAME.yaml) for the full budget."""
        return f"pick_{self.method}_r{self.repetition}"

    def __str__(self) -> str:
        return f"{self.method} r{self.repetition}"


def tuning_command(ctx: Context, arm: Arm, cpu_budget: float | None,
                   sets: dict[str, list[str]]) -> list[str]:
    """The command (after ``kraby-study``) that tunes one repetition: the common overrides,
    then the repetition's and the method's own (``--set``), each replacing an earlier one of
    the same setting (the racing search's seed cap, ``budget.seeds``, is one)."""
    seed = f"seed={SEED_STRIDE * arm.repetition}"
    if arm.method == "campaign":
        return ["run", *merged(ctx.common, [f"campaign={CAMPAIGN}",
                                            f"campaign.name={arm.tuning}", seed],
                               sets["campaign"])]
    assert cpu_budget is not None
    search = [f"search.name={arm.tuning}", f"search.seed={arm.repetition}", seed,
              "search.enqueue=[start]", f"search.cpu_budget={cpu_budget:g}",
              "search.trials=100000"]
    method = {"random": ["search.sampler=random"], "tpe": [], "racing": ["--racing"]}
    flags = [a for a in method[arm.method] if a.startswith("--")]
    own = [a for a in method[arm.method] if not a.startswith("--")]
    return ["optuna", *flags, *merged(ctx.common, own, search, sets[arm.method])]


@dataclass
class Context:
    """What every step needs: the store, the common overrides and the command options."""

    storage: str
    workers: int
    overrides: list[str]
    """The reduced budget's overrides, on top of budget=quick and save_models=false."""
    given: list[str]
    """The invocation's own overrides."""
    confirm_seeds: int
    tag: str

    @property
    def common(self) -> list[str]:
        return [*self.overrides, f"storage={self.storage}", f"workers={self.workers}"]


def kraby(args: Sequence[str]) -> None:
    """Run one kraby-study command in its own process, its output shown as it comes; stop
    the benchmark (exit 1) if it fails: rerunning continues from what the store holds."""
    print("$ kraby-study " + shlex.join(args), flush=True)
    done = subprocess.run([sys.executable, "-m", "kraby_study.cli", *args])
    if done.returncode != 0:
        raise SystemExit(f"bench_methods: the command ended with code {done.returncode}; rerun "
                         "bench_methods.py with the same arguments to continue (what is stored "
                         "is kept)")


def standings(url: str) -> dict[str, ks.StudyInfo]:
    """Every stored study's progress by name (none when there is no store yet)."""
    try:
        return {s.name: s for s in ks.open_store(url).studies()}
    except StoreError:
        return {}


def finished(info: ks.StudyInfo | None) -> bool:
    """A stored study with every planned run ended and none running."""
    return (info is not None and info.running == 0 and info.planned > 0
            and info.complete + info.failed + info.pruned >= info.planned)


@dataclass(frozen=True)
class Cost:
    """What a tuning spent."""

    cpu: float
    """CPU seconds, every attempt's, and asking the sampler."""
    configurations: int
    """Distinct settings it trained (a campaign's values over its stages, each stage's
    earlier winner counted once; a search's trials; a racing search's configurations whatever
    their seeds)."""
    env_steps: int
    """Env steps every attempt trained (a pruned trial's up to where it stopped)."""
    runs: int
    """Counted trials (a sweep's value x seed runs, a search's trials, a racing search's
    runs)."""


def tuning_cost(url: str, studies: Sequence[str]) -> Cost:
    """What the tuning's studies spent, read from the store."""
    cpu, steps, runs = 0.0, 0, 0
    configurations: set[str] = set()
    for name in studies:
        study = optuna.load_study(study_name=name, storage=url)
        every = [t for t in study.get_trials(deepcopy=False)
                 if t.state != optuna.trial.TrialState.WAITING]
        cpu += spent_cpu(every)
        kept = counted(every)
        runs += len(kept)
        configurations |= {json.dumps(t.user_attrs.get("settings") or [name, t.params],
                                      sort_keys=True, default=str) for t in kept}
        steps += sum(int(t.user_attrs.get("env_steps") or 0) for t in every)
    return Cost(cpu, len(configurations), steps, runs)


@dataclass
class Confirmed:
    """A one-arm confirm study, read from the store."""

    name: str
    label: str
    settings: dict[str, Any]
    source_score: float
    steps: int
    seeds: list[int]
    scores: list[float]
    """The complete runs' scores, in seed order."""
    iqm: float
    low: float
    high: float
    failed_runs: int
    failed_seeds: str
    cpu_per_run: float


def read_confirm(url: str, name: str) -> Confirmed:
    """A confirm's pick, the IQM of its fresh seeds' scores with its interval (as the report
    computes them), its failed runs and seeds, and its CPU s per complete run."""
    with opened_for_reading(url) as store:
        data = load_study(store, name)
        sweep = build_sweep(data)
    row = sweep.rows[0]
    arm = data.definition["arms"][0]
    complete = sorted((r for r in ks.open_store(url).runs(name) if r.outcome == "complete"),
                      key=lambda r: int(r.seed or 0))
    counted_seeds = ("-" if math.isnan(row.failed_seeds)
                     else f"{int(row.failed_seeds)}/{row.complete}")
    cpu = [float(r.cpu_time) for r in complete if r.cpu_time is not None]
    return Confirmed(name=name, label=str(arm["label"]), settings=arm["settings"],
                     source_score=float(arm["source_score"]) if arm.get("source_score")
                     is not None else math.nan, steps=int(data.definition["steps"]),
                     seeds=[int(s) for s in data.definition["seeds"]],
                     scores=[float(r.score) for r in complete if r.score is not None],
                     iqm=float(row.iqm), low=float(row.iqm_low), high=float(row.iqm_high),
                     failed_runs=int(row.failed), failed_seeds=counted_seeds,
                     cpu_per_run=statistics.fmean(cpu) if cpu else math.nan)


def short_settings(settings: dict[str, Any]) -> str:
    """The settings the methods vary, e.g. ``obs=default n_steps=32 ... ent=1e-08``."""
    parts = []
    for root, key, short in SHORT:
        value = settings.get(root, {}).get(key)
        if value is not None:
            parts.append(f"{short}={value:.3g}" if isinstance(value, float) else f"{short}={value}")
    return " ".join(parts)


@dataclass
class Result:
    """One repetition's tuning and its confirmed pick."""

    arm: Arm
    cost: Cost
    confirmed: Confirmed

    @property
    def cpu(self) -> float:
        """The tuning's CPU seconds."""
        return self.cost.cpu


def check_fresh_seeds(results: Sequence[Result]) -> None:
    """Every pick is retrained on the same fresh seeds, so picks pair seed by seed."""
    first = results[0].confirmed if results else None
    for result in results:
        if first is not None and result.confirmed.seeds != first.seeds:
            raise SystemExit(f"bench_methods: {result.confirmed.name} trained seeds "
                             f"{result.confirmed.seeds}, {first.name} {first.seeds}: every "
                             "pick must be retrained on the same fresh seeds")


def read_result(ctx: Context, arm: Arm) -> Result:
    """One repetition's tuning cost and confirmed pick, checked."""
    cost = tuning_cost(ctx.storage, arm.studies)
    confirmed = read_confirm(ctx.storage, arm.confirm)
    if arm.method == "campaign":
        check_campaign_pick(ctx, arm, confirmed)
    return Result(arm, cost, confirmed)


def check_campaign_pick(ctx: Context, arm: Arm, confirmed: Confirmed) -> None:
    """The campaign's confirmed pick (its last stage's top value) must be the settings the
    campaign ends with (``kraby-study best --campaign``: the last stage's selected value,
    with every earlier winner)."""
    chosen = ks.best(ks.compose([f"storage={ctx.storage}"], command="best"),
                     campaign=arm.tuning)
    if json.dumps(chosen.settings, sort_keys=True) != json.dumps(confirmed.settings,
                                                                sort_keys=True):
        raise SystemExit(f"bench_methods: {arm.confirm} retrained {confirmed.label}, not the "
                         f"settings campaign {arm.tuning} ends with ({chosen.description})")


def check_campaign_top(ctx: Context, arm: Arm) -> None:
    """Before the campaign's confirm: its last stage's top value by IQM, which ``confirm --top
    1`` retrains, must be the value the stage selected. They part only when a value with
    fewer complete seeds than ``report.min_seeds`` (its other runs failed) ranks first: it is
    never selected."""
    found = ks.open_store(ctx.storage).answers(arm.picked)
    top = max((v for v in found.values if v.seeds), key=lambda v: v.iqm)  # first on ties
    if top.value != found.selected:
        raise SystemExit(f"bench_methods: {arm.picked}'s top value by IQM is {top.value} "
                         f"({top.seeds} complete seed(s)), not its selected {found.selected}: "
                         "confirm --top 1 would retrain another pick than the campaign's; rerun "
                         "the stage's failed runs (run ... --retry-failed) first")


def run_arm(ctx: Context, arm: Arm, cpu_budget: float | None,
            sets: dict[str, list[str]], confirm: bool = True) -> None:
    """Tune one repetition and confirm its pick, each step skipped when the store holds it."""
    known = standings(ctx.storage)
    if confirm and finished(known.get(arm.confirm)):
        print(f"{arm}: tuned and confirmed ({arm.confirm})", flush=True)
        return
    kraby(tuning_command(ctx, arm, cpu_budget, sets))
    if not confirm:
        return
    if arm.method == "campaign":
        check_campaign_top(ctx, arm)
    kraby(["confirm", "--study-name", arm.picked, "--top", "1", "--seeds",
           str(ctx.confirm_seeds), *ctx.common])


def stored(ctx: Context, stages: tuple[str, ...]) -> tuple[list[Result], list[Result]]:
    """Every repetition of every method whose confirm is finished, and every pick retrained
    at the full budget, read from the store (whatever invocation ran them)."""
    known = standings(ctx.storage)
    every = [Arm(m, r, ctx.tag, stages) for m in METHODS for r in range(10)]
    rows = [read_result(ctx, arm) for arm in every if finished(known.get(arm.confirm))]
    full = []
    for arm in every:
        if finished(known.get(arm.full)):
            untuned = Cost(math.nan, 0, 0, 0)  # a full-budget retrain tunes nothing
            full.append(Result(arm, untuned, read_confirm(ctx.storage, arm.full)))
    check_fresh_seeds([*rows, *full])
    return rows, full


def write_csv(path: Path, rows: Sequence[Result], full: Sequence[Result]) -> None:
    """One row per method and repetition (and per pick retrained at the full budget, its
    tuning columns empty)."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(COLUMNS)
        for result, tuned in [*((r, True) for r in rows), *((r, False) for r in full)]:
            c = result.confirmed
            writer.writerow([
                result.arm.method, result.arm.repetition, c.steps,
                result.arm.tuning if tuned else "", f"{result.cpu:.1f}" if tuned else "",
                result.cost.configurations if tuned else "",
                result.cost.env_steps if tuned else "", c.label, short_settings(c.settings),
                f"{c.source_score:.6g}", c.name, len(c.scores), f"{c.iqm:.6g}",
                f"{c.low:.6g}", f"{c.high:.6g}", iqm_interval_name(), c.failed_runs,
                c.failed_seeds, f"{c.cpu_per_run:.2f}"])


def against(scores: Sequence[float], reference: Sequence[float], margin: float,
            alpha: float) -> str:
    """A pick's answer against a reference pick by the project's one decision
    (``ks.compare``): better, equivalent, worse, undecided (or too few seeds)."""
    found = ks.compare({"pick": list(scores), "reference": list(reference)}, margin=margin,
                       alpha=alpha)
    mine = found.answer("pick")
    if mine != "best":
        return mine
    other = found.answer("reference")
    return {"worse": "better", "equivalent": "equivalent"}.get(other, other)


def interval_text(c: Confirmed) -> str:
    low = "-" if math.isnan(c.low) else f"{c.low:.4g}"
    high = "-" if math.isnan(c.high) else f"{c.high:.4g}"
    return f"{c.iqm:.4g} [{low}, {high}]"


def paired_test(rows: Sequence[Result], first: str, second: str) -> tuple[float, int, int, float]:
    """(p, complete pairs, pairs left after zero differences, mean difference) of the exact
    one-sided Wilcoxon signed-rank test that ``first``'s confirmed IQMs are higher than
    ``second``'s of the same repetition."""
    by = {(r.arm.method, r.arm.repetition): r.confirmed.iqm for r in rows}
    reps = sorted(rep for method, rep in by if method == first and (second, rep) in by)
    differences = [by[(first, rep)] - by[(second, rep)] for rep in reps]
    if not differences:
        return math.nan, 0, 0, math.nan
    p, left = signed_rank(differences, "greater")
    return p, len(differences), left, statistics.fmean(differences)


def print_table(rows: Sequence[Result], full: Sequence[Result], margin: float,
                alpha: float) -> None:
    """The comparison's table and tests."""
    campaign = {r.arm.repetition: r.confirmed.scores for r in rows if r.arm.method == "campaign"}
    seeds = max((len(r.confirmed.seeds) for r in rows), default=0)
    print(f"\nEach pick retrained on {seeds} fresh seeds ({TEST_SEED} on) at the tuning budget; "
          f"IQM with its {iqm_interval_name()}. Against the campaign: ks.compare of the two "
          f"picks' seed scores, margin {margin:g} of the best's |IQM|, alpha {alpha:g}.")
    print("| method | repetition | CPU s | configurations | env steps (M) | pick | search score "
          "| confirmed IQM [95 % CI] | failed runs | failed seeds | against the campaign's pick "
          "(same repetition) |")
    print("|---|---:|---:|---:|---:|---|---:|---|---:|---:|---|")
    for method in METHODS:
        mine = [r for r in rows if r.arm.method == method]
        if not mine:
            continue
        answers: list[str] = []
        for r in mine:
            c = r.confirmed
            answer = "-"
            if method != "campaign":
                reference = campaign.get(r.arm.repetition)
                answer = ("no campaign pick" if reference is None
                          else against(c.scores, reference, margin, alpha))
                answers.append(answer)
            print(f"| {method} | {r.arm.repetition} | {r.cpu:,.0f} | {r.cost.configurations} "
                  f"| {r.cost.env_steps / 1e6:.2f} | {c.label}: "
                  f"{short_settings(c.settings)} | {c.source_score:.4g} | {interval_text(c)} "
                  f"| {c.failed_runs} | {c.failed_seeds} | {answer} |")
        tally = ", ".join(f"{answers.count(a)} {a}" for a in dict.fromkeys(answers))
        print(f"| **{method}** | **{len(mine)}** | **{statistics.fmean(r.cpu for r in mine):,.0f}**"
              f" | {statistics.fmean(r.cost.configurations for r in mine):.0f}"
              f" | {statistics.fmean(r.cost.env_steps for r in mine) / 1e6:.2f} | | | mean IQM "
              f"{statistics.fmean(r.confirmed.iqm for r in mine):.4g} | | | {tally or '-'} |")
    if full:
        print_full(full, margin, alpha)
    tests = [(*PLANNED, "planned")] + [(m, "random", "exploratory") for m in SEARCHES
                                       if m not in PLANNED]
    print("\nExact one-sided Wilcoxon signed-rank test (scipy, alternative 'greater', zero "
          "differences dropped) on the confirmed IQMs, paired by repetition (sampler seed):")
    last = ""
    for first, second, kind in tests:
        p, n, left, mean = paired_test(rows, first, second)
        if n == 0:
            line = f"{first} - {second} confirmed IQM: no complete pair ({kind})"
        else:
            verdict = "shown higher" if p < PLANNED_ALPHA else "not shown higher"
            line = (f"{first} - {second} confirmed IQM: mean difference {mean:.4g}, n = {n} "
                    f"complete pairs ({n - left} zero), p = {p:.3g} at alpha {PLANNED_ALPHA:g}: "
                    f"{first} {verdict} ({kind})")
        print(f"- {line}")
        if kind == "planned":
            last = line
    print_against_campaign(rows, margin)
    print(f"bench_methods: {last}")


def against_campaign(rows: Sequence[Result], margin: float
                     ) -> tuple[str, list[float], float, float, float] | None:
    """The plan's second goal: the search method with the highest mean confirmed IQM, its
    IQMs minus the campaign's of the same repetitions, the shift it must stay above
    (``-margin x |the campaign's mean confirmed IQM|``) and the one-sided Student t test's p
    that the mean difference is above it (scipy ``ttest_1samp``, ``alternative='greater'``);
    None without the campaign or a search method paired with it."""
    from scipy import stats

    by = {(r.arm.method, r.arm.repetition): r for r in rows}
    campaign = [r for r in rows if r.arm.method == "campaign"]
    means = {m: statistics.fmean(r.confirmed.iqm for r in rows if r.arm.method == m)
             for m in SEARCHES if any(r.arm.method == m for r in rows)}
    if not campaign or not means:
        return None
    best = max(means, key=lambda m: means[m])
    reps = sorted(r.arm.repetition for r in campaign if (best, r.arm.repetition) in by)
    if not reps:
        return None
    differences = [by[(best, rep)].confirmed.iqm - by[("campaign", rep)].confirmed.iqm
                   for rep in reps]
    shift = -margin * abs(statistics.fmean(r.confirmed.iqm for r in campaign))
    p = (float(stats.ttest_1samp(differences, shift, alternative="greater").pvalue)
         if len(differences) >= 2 else math.nan)
    return best, differences, shift, p, means[best]


def print_against_campaign(rows: Sequence[Result], margin: float) -> None:
    """The second goal's test, planned: the best search method's pick non-inferior to the
    campaign's, at what CPU."""
    found = against_campaign(rows, margin)
    if found is None:
        print("- the best search method against the campaign: no pair yet (planned)")
        return
    best, differences, shift, p, mean = found
    campaign = [r for r in rows if r.arm.method == "campaign"]
    cpu = statistics.fmean(r.cpu for r in rows if r.arm.method == best)
    campaign_cpu = statistics.fmean(r.cpu for r in campaign)
    verdict = ("not tested (one pair)" if math.isnan(p) else
               "non-inferior shown" if p < PLANNED_ALPHA else "non-inferiority not shown")
    print(f"\nThe best search method (highest mean confirmed IQM, {mean:.4g}) is {best}; the "
          f"campaign's mean confirmed IQM is "
          f"{statistics.fmean(r.confirmed.iqm for r in campaign):.4g}. Non-inferiority of "
          f"{best}'s pick to the campaign's (one-sided Student t on the paired IQM "
          f"differences, scipy ttest_1samp, alternative 'greater', against a shift of "
          f"{shift:.4g} = -{margin:g} x |the campaign's mean confirmed IQM|):")
    p_text = "-" if math.isnan(p) else f"{p:.3g}"
    print(f"- {best} - campaign confirmed IQM: mean difference "
          f"{statistics.fmean(differences):.4g}, n = {len(differences)} pairs, p = {p_text} at "
          f"alpha {PLANNED_ALPHA:g}: {verdict} (planned); mean CPU s {cpu:,.0f} against the "
          f"campaign's {campaign_cpu:,.0f} ({cpu / campaign_cpu:.2f} x)")


def parse_asked(text: str) -> tuple[str, str, str]:
    """``ppo.n_steps=32`` as (``ppo``, ``n_steps``, ``32``)."""
    path, sep, value = text.partition("=")
    root, dot, key = path.partition(".")
    if not sep or not dot or root not in ("env", "ppo") or not key or not value:
        raise ConfigError(f"--asked takes env.KEY=VALUE or ppo.KEY=VALUE, got {text!r}")
    return root, key, value


@dataclass(frozen=True)
class Asked:
    """How often a tuning trained a setting, and what its runs cost."""

    matching: int
    """Configurations trained with the setting."""
    configurations: int
    cpu_matching: float
    """CPU s per run (budget.steps env steps) of the complete trials with it; NaN for none."""
    cpu_others: float


def asked_in(url: str, studies: Sequence[str], root: str, key: str, value: str) -> Asked:
    """Distinct configurations (by their resolved settings) a tuning's studies trained, those
    with ``root.key == value``, and the CPU s per run of each group's complete trials
    (``cpu_time`` over ``env_steps`` times the trial's ``steps`` a run)."""
    seen: dict[str, bool] = {}
    cpu: dict[bool, list[float]] = {True: [], False: []}
    for name in studies:
        study = optuna.load_study(study_name=name, storage=url)
        for trial in counted(study.get_trials(deepcopy=False)):
            settings = trial.user_attrs.get("settings") or {}
            if not settings:
                continue
            matches = str(settings.get(root, {}).get(key)) == value
            seen[json.dumps(settings, sort_keys=True, default=str)] = matches
            attrs = trial.user_attrs
            if (trial.state == optuna.trial.TrialState.COMPLETE and attrs.get("cpu_time")
                    and attrs.get("env_steps") and attrs.get("steps")):
                cpu[matches].append(float(attrs["cpu_time"]) / int(attrs["env_steps"])
                                    * int(attrs["steps"]))
    return Asked(matching=sum(seen.values()), configurations=len(seen),
                 cpu_matching=statistics.fmean(cpu[True]) if cpu[True] else math.nan,
                 cpu_others=statistics.fmean(cpu[False]) if cpu[False] else math.nan)


def print_asked(url: str, rows: Sequence[Result], root: str, key: str, value: str) -> None:
    """Per method and repetition, how often its tuning trained ``root.key=value``."""
    setting = f"{root}.{key}={value}"
    print(f"\nConfigurations each tuning trained with {setting}, of all it trained, and the "
          "mean CPU s of a run (a complete trial's CPU s per env step times its steps a run) "
          "with it and with any other value:")
    print(f"| method | repetition | with {setting} | configurations | CPU s a run, with | CPU s "
          "a run, others |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in rows:
        a = asked_in(url, r.arm.studies, root, key, value)
        with_cpu = "-" if math.isnan(a.cpu_matching) else f"{a.cpu_matching:,.1f}"
        other_cpu = "-" if math.isnan(a.cpu_others) else f"{a.cpu_others:,.1f}"
        print(f"| {r.arm.method} | {r.arm.repetition} | {a.matching} | {a.configurations} "
              f"| {with_cpu} | {other_cpu} |")


def print_full(full: Sequence[Result], margin: float, alpha: float) -> None:
    """The picks retrained at the full budget, each answered against the campaign's pick of
    the same repetition there (or, without the campaign, against the last method's)."""
    methods = list(dict.fromkeys(r.arm.method for r in full))
    reference = "campaign" if "campaign" in methods else methods[-1]
    by = {(r.arm.method, r.arm.repetition): r.confirmed for r in full}
    steps = full[0].confirmed.steps
    print(f"\nAt the full budget ({steps:,} steps a run), the same picks on "
          f"{len(full[0].confirmed.seeds)} fresh seeds:")
    print(f"| method | repetition | confirmed IQM [95 % CI] | failed seeds | CPU s a run | "
          f"against {reference}'s pick (same repetition) |")
    print("|---|---:|---|---:|---:|---|")
    for r in full:
        c = r.confirmed
        other = by.get((reference, r.arm.repetition))
        answer = ("-" if r.arm.method == reference or other is None
                  else against(c.scores, other.scores, margin, alpha))
        print(f"| {r.arm.method} | {r.arm.repetition} | {interval_text(c)} | {c.failed_seeds} "
              f"| {c.cpu_per_run:,.1f} | {answer} |")


def arms_of(seeds: dict[str, list[int]], tag: str, stages: tuple[str, ...]) -> list[Arm]:
    """Every repetition to run, in the order they run: by repetition, then method, so pairs
    complete as the measurement goes."""
    reps = sorted({r for rs in seeds.values() for r in rs})
    return [Arm(m, r, tag, stages) for r in reps for m in METHODS if r in seeds.get(m, [])]


def campaign_runs(ctx: Context, sets: dict[str, list[str]]) -> tuple[tuple[str, ...], int]:
    """The campaign's stage studies and its runs at this budget (values x seeds), checked
    as the real command checks them (its campaign.name override included)."""
    command = tuning_command(ctx, Arm("campaign", 0, ctx.tag, ()), None, sets)
    config = ks.compose(command[1:], command="run")
    campaign = campaign_of(config.cfg, config.overrides)
    runs = sum(len(stage_file(campaign, s).study["values"]) for s in campaign.stages)
    return tuple(s.study for s in campaign.stages), runs * int(config.cfg.budget.seeds)


def check_searches(ctx: Context, arms: Sequence[Arm], sets: dict[str, list[str]],
                   cpu_budget: float | None) -> None:
    """Check one tuning command of each search method as the real command checks it
    (``ks.preview``: composed, its space and a racing search's rules checked against the
    store, nothing written), so bad overrides stop here, before any work; the campaign is
    checked by `campaign_runs`."""
    for method in SEARCHES:
        arm = next((a for a in arms if a.method == method), None)
        if arm is not None:
            command = tuning_command(ctx, arm, cpu_budget, sets)
            overrides = ["racing.enabled=true" if a == "--racing" else a for a in command[1:]]
            ks.preview(ks.compose(overrides, command="search"))


def print_plan(ctx: Context, arms: Sequence[Arm], sets: dict[str, list[str]],
               cpu_budget: float | None, campaign: tuple[tuple[str, ...], int],
               full: Sequence[Arm]) -> None:
    """Every command a run would start, with the CPU it is expected to use: B a search, the
    campaign's measured CPU (or B) a repetition, per run of a confirm the campaign's CPU over
    its runs (a run at the same budget), and per run of a full-budget confirm the pick's own
    CPU a run in its confirm (the campaign's, before that confirm ends) times the steps'
    ratio: a pick's settings can make its runs several times dearer than the average run."""
    stages, runs = campaign
    known = standings(ctx.storage)
    first = next((a for a in arms if a.method == "campaign"), Arm("campaign", 0, ctx.tag, stages))
    measured = None
    if finished(known.get(first.studies[-1])):
        measured = tuning_cost(ctx.storage, first.studies).cpu
    budget = cpu_budget if cpu_budget is not None else measured
    if budget is None:
        raise ConfigError("--plan needs --cpu-budget B, or the campaign's first repetition in "
                          "the store")
    steps = int(ks.compose(ctx.overrides, command="run").cfg.budget.steps)
    campaign_cpu = measured if measured is not None else budget
    per_run = campaign_cpu / runs
    print(f"bench_methods plan: every search {budget:,.0f} CPU s (search.cpu_budget, plus the "
          f"overshoot of its last trials); a campaign repetition {runs} runs x {steps:,} steps, "
          f"~{campaign_cpu:,.0f} CPU s ({'measured' if measured is not None else 'taken as B'}); "
          f"one run at this budget ~{per_run:,.1f} CPU s (campaign CPU / its runs)")
    total = 0.0
    for method in METHODS:
        reps = [a.repetition for a in arms if a.method == method]
        if reps:
            print(f"{method}: {len(reps)} repetition{'s' * (len(reps) > 1)} "
                  f"({', '.join(map(str, reps))}), each "
                  f"tuning ~{campaign_cpu if method == 'campaign' else budget:,.0f} CPU s and "
                  f"a confirm of {ctx.confirm_seeds} runs x {steps:,} steps")
    for arm in arms:
        tune = campaign_cpu if arm.method == "campaign" else budget
        confirm = ctx.confirm_seeds * per_run
        done = finished(known.get(arm.confirm))
        state = "  # done" if done else ""
        if not done:
            total += tune + confirm
        print(f"$ kraby-study {shlex.join(tuning_command(ctx, arm, budget, sets))}"
              f"{state or f'  # ~{tune:,.0f} CPU s'}")
        print(f"$ kraby-study confirm --study-name {arm.picked} --top 1 --seeds "
              f"{ctx.confirm_seeds} {shlex.join(ctx.common)}"
              f"{state or f'  # {ctx.confirm_seeds} runs, ~{confirm:,.0f} CPU s'}")
    if full:
        full_steps = int(ks.compose(["budget=full", *ctx.given], command="confirm")
                         .cfg.budget.steps)
        for arm in full:
            done = finished(known.get(arm.full))
            a_run, at, source = per_run, steps, "the campaign's"
            if finished(known.get(arm.confirm)):
                own = read_confirm(ctx.storage, arm.confirm)
                if math.isfinite(own.cpu_per_run):
                    a_run, at, source = own.cpu_per_run, own.steps, "its confirm's"
            each = ctx.confirm_seeds * a_run * full_steps / at
            if not done:
                total += each
            print(f"$ kraby-study {shlex.join(full_args(ctx, arm))}"
                  + ("  # done" if done else f"  # {ctx.confirm_seeds} runs x {full_steps:,} "
                     f"steps, ~{each:,.0f} CPU s ({source} {a_run:,.1f} CPU s a run at "
                     f"{at:,} steps)"))
    print(f"bench_methods plan: ~{total:,.0f} CPU s left, about {total / ctx.workers / 3600:.1f} "
          f"hours on {ctx.workers} workers (one core each)")


def full_args(ctx: Context, arm: Arm) -> list[str]:
    """The full-budget confirm of one pick, as a baseline ppo config."""
    return ["confirm", "--baseline", f"ppo={arm.ppo_name}", "--seeds", str(ctx.confirm_seeds),
            f"confirm.name={arm.full}", *merged(["budget=full", "save_models=false"], ctx.given),
            f"storage={ctx.storage}", f"workers={ctx.workers}"]


def write_pick(ctx: Context, arm: Arm, settings: dict[str, Any]) -> None:
    """The confirmed pick as ./conf/ppo/pick_M_rR.yaml, checked to compose back to exactly
    its settings under the full-budget command's overrides."""
    path = Path("conf") / "ppo" / f"{arm.ppo_name}.yaml"
    if not path.exists():
        write_ppo_config(settings, sorted(settings.get("env", {})),
                         f"the pick of {arm}, confirmed in {arm.confirm}", path)
    composed = settings_with_ppo(arm.ppo_name, merged(["budget=full"], ctx.given))
    if json.dumps(composed, sort_keys=True) != json.dumps(settings, sort_keys=True):
        differ = sorted(f"{root}.{k}" for root in ("env", "ppo")
                        for k in set(settings.get(root, {})) | set(composed.get(root, {}))
                        if settings.get(root, {}).get(k) != composed.get(root, {}).get(k))
        raise ConfigError(f"{path} with this invocation's overrides is not {arm}'s pick "
                          f"({', '.join(differ)} differ): drop those overrides, or the file")


def run_full(ctx: Context, arms: Sequence[Arm]) -> None:
    """Retrain each pick at the full budget, skipping what the store holds."""
    known = standings(ctx.storage)
    for arm in arms:
        if finished(known.get(arm.full)):
            print(f"{arm}: retrained at the full budget ({arm.full})", flush=True)
            continue
        if not finished(known.get(arm.confirm)):
            print(f"{arm}: not confirmed yet at the tuning budget; left out", flush=True)
            continue
        write_pick(ctx, arm, read_confirm(ctx.storage, arm.confirm).settings)
        kraby(full_args(ctx, arm))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cpu-budget", type=float, default=None,
                        help="CPU seconds every search may use (search.cpu_budget)")
    parser.add_argument("--seeds", nargs="+", default=[],
                        help="repetitions per method, METHOD=FIRST-LAST or METHOD=R,R,... "
                             "(default: " + " ".join(f"{m}={s}" for m, s in
                                                      DEFAULT_SEEDS.items()) + ")")
    parser.add_argument("--set", action="append", default=[], dest="sets",
                        metavar="METHOD:KEY=VALUE",
                        help="an override of one method's tuning command, e.g. "
                             "racing:racing.min_seeds=4 (repeatable)")
    parser.add_argument("--confirm-seeds", type=int, default=10,
                        help="fresh seeds each pick is retrained on")
    parser.add_argument("--storage", default="sqlite:///bench_methods.db")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--tag", default="leg", help="first word of every study's name")
    parser.add_argument("--out", type=Path, default=Path("methods.csv"))
    parser.add_argument("--margin", type=float, default=None,
                        help="ks.compare's margin (default compare.margin, 0.2)")
    parser.add_argument("--alpha", type=float, default=0.05, help="ks.compare's alpha")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--campaign-cpu", action="store_true",
                      help="run only the campaign's repetitions and print their CPU s")
    mode.add_argument("--table", action="store_true", help="print the table from the store")
    mode.add_argument("--full-budget", nargs=2, metavar=("M1", "M2"), default=None,
                      help="retrain two methods' picks at budget=full")
    parser.add_argument("--plan", action="store_true",
                        help="print every command a run (or --full-budget) would start and "
                             "the CPU it is expected to use; run none")
    parser.add_argument("--asked", metavar="SETTING=VALUE", default=None,
                        help="with --table: how many configurations each tuning trained with "
                             "this setting (e.g. ppo.n_steps=32), and the CPU s a run of them "
                             "and of the others")
    parser.add_argument("--full-repetitions", type=int, nargs="+", default=None,
                        help="with --full-budget: these repetitions only (default: every one "
                             "confirmed)")
    parser.add_argument("overrides", nargs="*", help="KEY=VALUE for every command")
    args = parser.parse_intermixed_args(argv)
    try:
        return run(args)
    except (ConfigError, StoreError) as err:
        print(f"bench_methods: {err}", file=sys.stderr)
        return 2


def run(args: argparse.Namespace) -> int:
    """The invocation's mode, its input checked before any work."""
    seeds = parse_seeds(args.seeds) if args.seeds else parse_seeds(
        [f"{m}={s}" for m, s in DEFAULT_SEEDS.items()])
    sets = parse_sets(args.sets)
    if args.confirm_seeds < 2 or args.workers < 1:
        raise ConfigError("--confirm-seeds must be at least 2 and --workers at least 1")
    if args.cpu_budget is not None and not args.cpu_budget > 0:
        raise ConfigError("--cpu-budget must be positive")
    if args.campaign_cpu:
        if "campaign" not in seeds:
            raise ConfigError("--campaign-cpu runs the campaign's repetitions: give "
                              "--seeds campaign=...")
        seeds = {"campaign": seeds["campaign"]}
    given = list(args.overrides)
    ctx = Context(storage=args.storage, workers=args.workers,
                  overrides=merged(["budget=quick", "save_models=false"], given), given=given,
                  confirm_seeds=args.confirm_seeds, tag=args.tag)
    stages, runs = campaign_runs(ctx, sets)
    arms = arms_of(seeds, args.tag, stages)
    margin = (float(ks.compose([], command="best").cfg.compare.margin) if args.margin is None
              else args.margin)
    if args.full_budget is not None:
        unknown = [m for m in args.full_budget if m not in METHODS]
        if unknown or args.full_budget[0] == args.full_budget[1]:
            raise ConfigError(f"--full-budget names two of {', '.join(METHODS)}")
    full = [a for m in (args.full_budget or []) for a in arms if a.method == m
            and (args.full_repetitions is None or a.repetition in args.full_repetitions)]
    asked = parse_asked(args.asked) if args.asked is not None else None
    if asked is not None and not args.table:
        raise ConfigError("--asked goes with --table")
    if args.table:
        rows, full = stored(ctx, stages)
        print_table(rows, full, margin, args.alpha)
        if asked is not None:
            print_asked(ctx.storage, rows, *asked)
        return 0
    if args.plan:
        print_plan(ctx, [] if args.full_budget else arms, sets, args.cpu_budget,
                   (stages, runs), full)
        if "racing" in seeds and not racing_available():
            print("bench_methods plan: kraby-study optuna has no --racing on this install: the "
                  "racing repetitions cannot run yet")
        return 0
    if args.full_budget is not None:
        run_full(ctx, full)
        write_csv(args.out, *stored(ctx, stages))
        print_table(*stored(ctx, stages), margin, args.alpha)
        return 0
    searches = [m for m in seeds if m in SEARCHES]
    if searches and args.cpu_budget is None:
        raise ConfigError(f"{', '.join(searches)} need --cpu-budget B (CPU s each search may "
                          "use: the campaign's first repetition's, from --campaign-cpu)")
    if "racing" in seeds and not racing_available():
        raise ConfigError("kraby-study optuna has no --racing on this install (the racing "
                          "search): leave racing out of --seeds")
    check_searches(ctx, arms, sets, args.cpu_budget)
    for arm in arms:
        run_arm(ctx, arm, args.cpu_budget, sets, confirm=not args.campaign_cpu)
        if not args.campaign_cpu:
            write_csv(args.out, *stored(ctx, stages))
    if args.campaign_cpu:
        for arm in arms:
            cost = tuning_cost(ctx.storage, arm.studies)
            print(f"campaign r{arm.repetition}: {cost.cpu:,.1f} CPU s over {cost.runs} runs")
        first = tuning_cost(ctx.storage, arms[0].studies).cpu
        print(f"bench_methods: the campaign's first repetition used {first:,.1f} CPU s: "
              f"--cpu-budget {first:.0f}")
        return 0
    print_table(*stored(ctx, stages), margin, args.alpha)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
