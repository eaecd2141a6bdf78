"""A model, not a measurement: the documented set's wall time on N nodes of 2 cores.

Run: python experiments/model_cluster.py --store camp.db --calibration cal.db
         --ray-overhead S --head-ms MS [--stage-start S] [--nodes 1,4,16,64]

Inputs, each measured elsewhere (docs/benchmarks/index.md names the commands):

- Trial times: a run of the documented campaign at a small budget (``--store``: `kraby-study
  run campaign=documented budget=quick budget.steps=8192 budget.seeds=2 workers=1 shards=1`),
  and `kraby-study train shards=1` of ppo=tuned and of the campaign's published settings at
  8,192 and 32,768 steps (``--store`` and ``--calibration``). The two budgets give a run's
  fixed CPU seconds and its seconds per step; each value's run is extrapolated to 250,000
  steps and scaled so that the two configurations land on their CPU seconds per run measured
  at the full budget (``--full-tuned-cpu`` 63.0, ``--full-campaign-cpu`` 86.9,
  docs/results/index.md).
  A run's CPU seconds are taken as its wall time on a core of its own. From the gamma stage
  on, runs are anchored to the published end settings' measured run (``--anchor-from``): the
  small run's own selections (fewer epochs, larger batches) are cheaper than the published
  chain's.
- Ray's cost per trial and slot (``--ray-overhead``) and the head's seconds per stored trial
  (``--head-ms``), from benchmarks/bench_head.py; the time from a stage's start to its first
  trial's start (``--stage-start``: the command's pool, and so its actors, are made per stage),
  from benchmarks/bench_ray_fault.py.

The structure: the nine stages run one after another (each needs the previous one's selected
value); a stage's 10 seeds x its values are its runs, one per slot, 2 slots per node (one CPU
per trial). A slot takes the next queued run as soon as the head has stored its result; the
head stores one result at a time. Runs of one value take the same time (their seeds' spread is
not modelled). The wall time of each stage is simulated event by event.
"""

from __future__ import annotations

import argparse
import heapq
import json
import sqlite3
from collections import defaultdict
from pathlib import Path

STAGES = ("observation", "batch_size", "n_steps", "n_epochs", "gamma", "clip_range",
          "learning_rate", "gae_lambda", "ent_coef")
SEEDS = 10
CORES = 2
STEPS, SMALL, LARGER = 250_000, 8192, 32768


def _connect(store: Path) -> sqlite3.Connection:
    return sqlite3.connect(f"file:{store}?mode=ro", uri=True)


def measured_runs(store: Path) -> dict[str, list[float]]:
    """Each stage's mean CPU seconds per run, value by value, at the store's small budget."""
    rows = _connect(store).execute(
        "SELECT s.study_name, p.param_value, a.value_json FROM trials t "
        "JOIN studies s ON s.study_id = t.study_id "
        "JOIN trial_user_attributes a ON a.trial_id = t.trial_id AND a.key = 'cpu_time' "
        "LEFT JOIN trial_params p ON p.trial_id = t.trial_id "
        "WHERE t.state = 'COMPLETE' AND s.study_name LIKE 'documented-%'").fetchall()
    per_value: dict[str, dict[float, list[float]]] = defaultdict(lambda: defaultdict(list))
    for study, value, cpu in rows:
        per_value[study.removeprefix("documented-")][value].append(float(cpu))
    return {stage: [sum(v) / len(v) for v in per_value[stage].values()] for stage in STAGES}


def train_runs(*stores: Path) -> dict[tuple[int, int], float]:
    """CPU seconds of each ``train`` run in the stores, by (n_epochs, steps): n_epochs tells
    ppo=tuned (30) from the campaign's settings (20)."""
    out: dict[tuple[int, int], float] = {}
    for store in stores:
        for attrs in _connect(store).execute(
                "SELECT group_concat(a.key || '=' || a.value_json, '\x1f') FROM trials t "
                "JOIN studies s ON s.study_id = t.study_id "
                "JOIN trial_user_attributes a ON a.trial_id = t.trial_id "
                "WHERE t.state = 'COMPLETE' AND s.study_name LIKE 'train-%' "
                "GROUP BY t.trial_id").fetchall():
            got = dict(item.split("=", 1) for item in attrs[0].split("\x1f"))
            epochs = int(json.loads(got["settings"])["ppo"]["n_epochs"])
            out[(epochs, int(got["steps"]))] = float(got["cpu_time"])
    return out


def full_budget(small: float, fixed: float) -> float:
    """A run's CPU seconds at the full budget from its seconds at the small one: the fixed
    part stays, the rest grows with the steps."""
    return fixed + (small - fixed) * STEPS / SMALL


def stage_wall(runs: list[float], slots: int, overhead: float, head: float,
               start: float) -> float:
    """Seconds from a stage's start to its last result stored."""
    queue = list(runs)
    ends: list[float] = []
    for _ in range(min(slots, len(queue))):
        heapq.heappush(ends, start + queue.pop(0) + overhead)
    head_free = 0.0
    last = 0.0
    while ends:
        end = heapq.heappop(ends)
        stored = max(end, head_free) + head
        head_free = last = stored
        if queue:
            heapq.heappush(ends, stored + queue.pop(0) + overhead)
    return last


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--store", type=Path, required=True)
    parser.add_argument("--calibration", type=Path, required=True)
    parser.add_argument("--full-tuned-cpu", type=float, default=63.0)
    parser.add_argument("--full-campaign-cpu", type=float, default=86.9)
    parser.add_argument("--ray-overhead", type=float, required=True)
    parser.add_argument("--head-ms", type=float, required=True)
    parser.add_argument("--stage-start", type=float, default=10.0)
    parser.add_argument("--nodes", default="1,4,16,64")
    parser.add_argument("--anchor-from", default="gamma", choices=STAGES)
    args = parser.parse_args()
    small = measured_runs(args.store)
    trains = train_runs(args.store, args.calibration)
    # Each configuration's two budgets give its fixed CPU seconds per run and its seconds per
    # step; the model takes the fixed part from ppo=tuned and calibrates the extrapolation to
    # the CPU seconds measured at the full budget (the mean ratio of the two configurations).
    ratios = []
    fixed = 0.0
    for name, epochs, measured in (("ppo=tuned", 30, args.full_tuned_cpu),
                                   ("campaign_documented", 20, args.full_campaign_cpu)):
        low, high = trains[(epochs, SMALL)], trains[(epochs, LARGER)]
        per_step = (high - low) / (LARGER - SMALL)
        own_fixed = low - per_step * SMALL
        fixed = fixed or own_fixed
        predicted = full_budget(low, own_fixed)
        ratios.append(measured / predicted)
        print(f"{name}: {low:.2f} CPU s at {SMALL:,} steps, {high:.2f} at {LARGER:,}: fixed "
              f"{own_fixed:.2f} s, {1000 * per_step:.3f} ms per step; extrapolated to "
              f"{STEPS:,} steps {predicted:.1f} s, measured {measured} (ratio "
              f"{measured / predicted:.2f})")
    calibration = sum(ratios) / len(ratios)
    print(f"calibration: x{calibration:.2f}; fixed part {fixed:.2f} s per run")
    full = {stage: [calibration * full_budget(t, fixed) for t in values]
            for stage, values in small.items()}
    # From the gamma stage on, the published chain trains at about the settings it ends with
    # (n_epochs 20, batch 128), whose run measured --full-campaign-cpu; the small run selected
    # cheaper ones (its own n_epochs and batch size). Those stages keep their measured spread
    # from value to value, scaled so that the last stage's mean is that measured run.
    later = STAGES[STAGES.index(args.anchor_from):]
    last = full[STAGES[-1]]
    anchor = args.full_campaign_cpu / (sum(last) / len(last))
    print(f"stages {', '.join(later)}: x{anchor:.2f} (the small run's last stage averaged "
          f"{sum(last) / len(last):.1f} s per run at the full budget, the published settings "
          f"{args.full_campaign_cpu})")
    for stage in later:
        full[stage] = [anchor * t for t in full[stage]]
    runs = {stage: [t for t in values for _ in range(SEEDS)] for stage, values in full.items()}
    total = sum(sum(r) for r in runs.values())
    print(f"{sum(len(r) for r in runs.values())} runs, {total / 3600:.1f} CPU hours at the "
          f"full budget (model): {total / 3600 / CORES:.1f} h on one node of {CORES} cores")
    print("| stage | runs | slowest run (s) | mean run (s) |")
    print("|---|---:|---:|---:|")
    for stage in STAGES:
        print(f"| {stage} | {len(runs[stage])} | {max(full[stage]):.0f} | "
              f"{sum(full[stage]) / len(full[stage]):.0f} |")
    critical = sum(max(values) for values in full.values())
    print(f"critical path (the slowest run of each stage, one after another): "
          f"{critical / 60:.1f} min")
    head = args.head_ms / 1000
    print("| nodes | slots | documented set (h) | (min) | speed-up | slowest-run floor (min) |")
    print("|---:|---:|---:|---:|---:|---:|")
    base = None
    for nodes in (int(n) for n in args.nodes.split(",")):
        slots = CORES * nodes
        wall = sum(stage_wall(runs[s], slots, args.ray_overhead, head, args.stage_start)
                   for s in STAGES)
        base = base or wall
        print(f"| {nodes} | {slots} | {wall / 3600:.2f} | {wall / 60:.0f} | "
              f"{base / wall:.1f}x | {critical / 60:.0f} |")


if __name__ == "__main__":
    main()
