"""``<study>/reproducibility.md``: how a study's numbers were made, checklist by checklist.

It follows the reporting checklist of Eimer et al. (ICML 2023) for hyperparameter studies in RL:
the tuning seeds apart from the test seeds, what was compared (values or search space), the
budget in env steps and CPU seconds, the hardware, and the package and code versions. Each
trial stores what made it ([`kraby_study.run.provenance`][]); where the trials of one study differ
in a field that can move the numbers, a warning names the field and counts each value.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from kraby_study.answers.study_data import StudyData
from kraby_study.records.attributes import RAY_NODE, Placement, StudyKind, TrialAttrs
from kraby_study.records.definition import (
    SEEDING_TEXT,
    UNRECORDED_SEEDING,
    scored_by_evaluation,
    seed_text,
    stored_eval_set,
    stored_seeding,
)
from kraby_study.records.stored import Outcome, StoredTrial, offset_leg_seeds, outcome, trial_seeds
from kraby_study.report.document import Block, Heading, Items, Table, Text, to_markdown
from kraby_study.run.provenance import ENV_FIELDS, PACKAGES

FILE = "reproducibility.md"

HARDWARE = ("cpu", "cpu_capability", "cores", "platform", "hostname")
SOFTWARE = ("kraby_study", "python", *PACKAGES, "git_commit", "git_dirty")
CHECKED = ("cpu", "cpu_capability", "cores", "platform", "kraby_study", "python", *PACKAGES,
           "git_commit", "git_dirty", *ENV_FIELDS)
"""Fields that can move a trial's numbers: trials that differ in one are warned about (the
hostname, the Ray node, the folder and the command line may differ freely)."""
CPU_MODELS = ("; the same settings and seed give the same numbers bit for bit only on one CPU "
              "model with the same software, so a run of this study repeated on another of "
              "these CPU models agrees in distribution, not to the bit "
              "(docs/reference/reproducibility.md)")
"""What the warning on trials of several CPU models adds."""
EXPLAINED = {"cpu": CPU_MODELS,
             "cpu_capability": "; torch's kernels then sum in another order, so the same seed "
                               "gives other numbers (docs/reference/reproducibility.md)"}
"""What a warning on a field adds: what the difference does to the seeds' numbers."""


def started(trials: Sequence[StoredTrial]) -> list[StoredTrial]:
    """The trials that ran (complete, failed or pruned): those provenance describes."""
    return [t for t in trials if outcome(t) != Outcome.PENDING]


def field_counts(trials: Sequence[StoredTrial], records: dict[str, dict[str, str]],
                 name: str) -> Counter[str]:
    """How many trials have each value of one provenance field (``not recorded`` for trials
    without a record)."""
    counts: Counter[str] = Counter()
    for trial in trials:
        record = records.get(str(trial.user_attrs.get("provenance")))
        counts[record.get(name, "not recorded") if record else "not recorded"] += 1
    return counts


def counted_text(counts: Counter[str]) -> str:
    """``value`` when all trials agree, else ``a (n trials), b (m trials)``, most first (ties
    in text order)."""
    if len(counts) == 1:
        return next(iter(counts))
    return ", ".join(f"{value} ({n} trial{'s' if n != 1 else ''})"
                     for value, n in sorted(counts.items(), key=lambda c: (-c[1], c[0])))


def warnings(trials: Sequence[StoredTrial], records: dict[str, dict[str, str]]) -> list[str]:
    """One line per field in which the trials differ, a missing record, or a dirty checkout."""
    lines: list[str] = []
    missing = sum(1 for t in trials if str(t.user_attrs.get("provenance")) not in records)
    if missing:
        lines.append(f"{missing} of {len(trials)} trials have no provenance record (trained "
                     "before kraby-study stored it, or by another tool)")
    recorded = [t for t in trials if str(t.user_attrs.get("provenance")) in records]
    for name in CHECKED:
        counts = field_counts(recorded, records, name)
        if len(counts) > 1:
            lines.append(f"trials differ in {name}: {counted_text(counts)}"
                         + EXPLAINED.get(name, ""))
    dirty = field_counts(recorded, records, "git_dirty").get("yes", 0)
    if dirty:
        lines.append(f"{dirty} trial{'s' if dirty != 1 else ''} ran from a git checkout with "
                     "uncommitted changes: the commit alone does not give its code")
    return lines


def _seeds_block(data: StudyData, trials: Sequence[StoredTrial]) -> list[str]:
    per_trial = int(data.definition.get("seeds", 1)) if data.kind == StudyKind.SEARCH else 1
    own = {seed for t in trials for seed in trial_seeds(t, per_trial)}
    seeding = stored_seeding(data.definition)
    scheme = f"Seeding: {SEEDING_TEXT[seeding]}."
    if data.kind != StudyKind.CONFIRM:
        return [f"Tuning seeds (the seeds this study's runs trained): {seed_text(own)}.",
                scheme, "Test seeds: none in this study; `kraby-study confirm` retrains chosen "
                "settings on fresh seeds."]
    planned = [int(s) for s in data.definition.get("seeds", [])] or sorted(own)
    lines = [f"Test seeds (fresh seeds of this confirm study): {seed_text(planned)}.", scheme]
    source = data.definition.get("source")
    if not source:
        lines.append("No source study (baselines only): no tuning seeds to keep apart.")
    elif data.source_seeds is None:
        lines.append(f"Tuning seeds: those of {source!r}, which is not in this store, so "
                     "disjointness is not checked here.")
    else:
        shared = sorted(set(planned) & set(data.source_seeds))
        lines.append(f"Tuning seeds (of the source study {source!r}): "
                     f"{seed_text(data.source_seeds)}.")
        lines.append("Test and tuning seeds are disjoint." if not shared else
                     f"Warning: test and tuning seeds share {seed_text(shared)}.")
        lines += _shared_streams(data, trials, seeding)
    if scored_by_evaluation(data.definition):
        lines.append(_test_set(data.definition))
    return lines


def _test_set(definition: dict[str, Any]) -> str:
    """Where a confirm scored by evaluation drew its evaluation episodes (its test set)."""
    episodes = definition.get("eval_episodes")
    if stored_eval_set(definition) == "run":
        return (f"Test set: each run's own {episodes} evaluation episodes, drawn from its "
                "seed's evaluation stream (a child of its SeedSequence apart from its training "
                "streams): no test episode is one the source study scored a run on.")
    return (f"Warning: test set reused: every run was scored on the same {episodes} fixed "
            "evaluation episodes as every run of its source (its eval_set is fixed), so the "
            "settings were selected on the episodes they are tested on.")


def _shared_streams(data: StudyData, trials: Sequence[StoredTrial], seeding: str) -> list[str]:
    """Whether test runs reset legs on the streams of tuning runs: only where both studies
    seed by offset (s + i), whose runs share streams with every run less than n_envs apart."""
    if seeding != UNRECORDED_SEEDING or data.source_legs is None:
        return ["Test and tuning runs share no env's stream (one of the two studies seeds by "
                "streams)."]
    reusing = [t for t in trials if offset_leg_seeds(t) & data.source_legs]
    if not reusing:
        return ["Test and tuning runs share no env's stream."]
    return [f"Warning: {len(reusing)} of {len(trials)} test runs reset some of their legs on "
            "the same streams as tuning runs (both studies seed by offset), so their episodes "
            "are partly those the settings were chosen on."]


def _flat(settings: dict[str, Any], prefix: str = "") -> list[str]:
    out: list[str] = []
    for key, value in settings.items():
        if isinstance(value, dict):
            out += _flat(value, f"{prefix}{key}.")
        else:
            out.append(f"{prefix}{key}={value}")
    return out


def _compared_block(data: StudyData) -> list[Block]:
    definition = data.definition
    if data.kind == StudyKind.CONFIRM:
        rows = [[str(arm.get("label")), str(arm.get("origin") or ""),
                 " ".join(_flat(dict(arm.get("settings", {}).get("ppo", {}))))]
                for arm in definition.get("arms", [])]
        return [Text("Configurations retrained (each arm's ppo settings):"),
                Table(["arm", "origin", "ppo settings"], rows)]
    blocks: list[Block] = []
    if data.kind == StudyKind.SWEEP:
        values = ", ".join(str(v) for v in definition.get("values", []))
        blocks.append(Text(f"Values compared: {definition.get('parameter')} = {values}."))
    elif data.kind == StudyKind.SEARCH:
        search = dict(definition.get("search", {}))
        space = search.pop("params", {})
        rows = [[name, " ".join(_flat(dict(p)))] for name, p in space.items()]
        blocks.append(Text("Search space:"))
        blocks.append(Table(["parameter", "definition"], rows))
        blocks.append(Text("Search settings: " + " ".join(_flat(search)) + "."))
    settings = definition.get("settings")
    if isinstance(settings, dict):
        blocks.append(Text("Fixed settings: " + " ".join(_flat(settings)) + "."))
    return blocks


def _budget_block(data: StudyData, trials: Sequence[StoredTrial]) -> list[str]:
    attrs = [TrialAttrs.of(t) for t in trials]
    steps = data.definition.get("steps")
    env_steps = sum(a.env_steps or 0 for a in attrs)
    cpu = [a.cpu_time for a in attrs if a.cpu_time is not None]
    wall = sum(a.wall_time or 0.0 for a in attrs)
    lines = [f"Env steps per run: {int(steps):,}." if steps else "Env steps per run: not "
             "stored.",
             f"Runs that trained: {len(trials)}; env steps trained in all: {env_steps:,}."]
    if cpu:
        note = "" if len(cpu) == len(attrs) else (
            f" ({len(attrs) - len(cpu)} trials recorded no CPU time)")
        lines.append(f"CPU seconds in all (user + system, worker and leg processes): "
                     f"{sum(cpu):,.0f}; training wall-clock seconds summed over runs: "
                     f"{wall:,.0f}{note}.")
        asked = sum(a.suggest_cpu or 0.0 for a in attrs)
        if asked:
            lines.append(f"CPU seconds the search's sampler spent choosing the trials (the "
                         f"command's process, counted in a CPU budget): {asked:,.1f}.")
    else:
        lines.append(f"CPU seconds: not recorded; training wall-clock seconds summed over "
                     f"runs: {wall:,.0f}.")
    return lines


def _facts_table(trials: Sequence[StoredTrial], records: dict[str, dict[str, str]],
                 names: Sequence[str]) -> Table:
    rows = [[name, counted_text(field_counts(trials, records, name))] for name in names]
    return Table(["field", "value (trials, when they differ)"], rows)


def _env_block(trials: Sequence[StoredTrial], records: dict[str, dict[str, str]]) -> Block:
    """The env's id, package and version when the trials recorded them (a Gymnasium env);
    else the leg, which is part of kraby-study."""
    if any(record.get("env_id") for record in records.values()):
        return _facts_table(trials, records, ENV_FIELDS)
    return Text("The Kraby leg (KrabyOneLeg-v0 of kraby_envs, which is part of kraby-study: "
                "its version and commit are below).")


def _hardware(records: dict[str, dict[str, str]]) -> tuple[str, ...]:
    """The hardware fields, with the Ray node when any trial ran on Ray."""
    ray = any(record.get(RAY_NODE) for record in records.values())
    return (*HARDWARE, RAY_NODE) if ray else HARDWARE


def _placement_line(records: dict[str, dict[str, str]]) -> str:
    """How many nodes and CPU models ran the study, every attempt counted (a lost node's
    too)."""
    placement = Placement.of(records.values())
    if not placement.nodes:
        return "Nodes: none recorded."
    models = "; ".join(placement.cpus)
    return (f"Nodes that ran its trials (every attempt, a lost node's too; a Ray node by its "
            f"node id, else a host by its name): {placement.nodes}. CPU models: "
            f"{len(placement.cpus)} ({models}).")


def reproducibility_blocks(data: StudyData) -> list[Block]:
    """The page's blocks."""
    trials = started(data.trials)
    records = data.provenance
    commands = field_counts(trials, records, "command")
    commands.pop("not recorded", None)
    blocks: list[Block] = [
        Heading(f"Reproducibility: {data.name}", 1),
        Text(f"A {data.kind} study; {len(trials)} of its {len(data.trials)} counted trials "
             "ran. Each trial stores the machine that trained it and the command that ran it "
             "when it starts. Checklist: Eimer et al., ICML 2023."),
    ]
    found = warnings(trials, records)
    if found:
        blocks += [Heading("Warnings", 2), Items([f"Warning: {line}." for line in found])]
    blocks += [Heading("Seeds", 2), Items(_seeds_block(data, trials)),
               Heading("What was compared", 2), *_compared_block(data),
               Heading("Budget", 2), Items(_budget_block(data, trials)),
               Heading("Environment", 2), _env_block(trials, records),
               Heading("Hardware", 2), Items([_placement_line(records)]),
               _facts_table(trials, records, _hardware(records)),
               Heading("Software and code", 2), _facts_table(trials, records, SOFTWARE),
               Heading("Commands", 2),
               Items([f"`{c}` ({n} trial{'s' if n != 1 else ''})"
                      for c, n in commands.most_common()] or ["none recorded"])]
    return blocks


def write_reproducibility(data: StudyData, folder: Path) -> Path:
    """Write ``folder/reproducibility.md``; returns its path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / FILE
    path.write_text(to_markdown(reproducibility_blocks(data)), encoding="utf-8")
    return path
