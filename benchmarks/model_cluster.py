"""A model, not a measurement: the documented set's wall time on N nodes of 2 cores.

Run: python benchmarks/model_cluster.py --store camp.db --full-tuned-cpu 63.0
         --ray-overhead S --head-ms MS [--stage-start S] [--nodes 1,4,16,64]

Inputs, each measured elsewhere (docs/benchmarks.md names the commands):

- Trial times: a run of the documented campaign at a small budget (``--store``: `kraby-study
  run campaign=documented budget=quick budget.steps=8192 budget.seeds=2 workers=1 shards=1`,
  then `kraby-study train ppo=tuned` at the same steps into the same store). Each value's CPU
  seconds per run there, times the factor that takes ppo=tuned's run to its measured CPU
  seconds at the full budget (``--full-tuned-cpu``, docs/results.md), is that value's run time
  at the full budget on one core of its own.
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
import sqlite3
from collections import defaultdict
from pathlib import Path

STAGES = ("observation", "batch_size", "n_steps", "n_epochs", "gamma", "clip_range",
          "learning_rate", "gae_lambda", "ent_coef")
SEEDS = 10
CORES = 2


def measured_runs(store: Path) -> tuple[dict[str, list[float]], float]:
    """Each stage's mean CPU seconds per run, value by value, and ppo=tuned's, at the small
    budget of the store."""
    db = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    rows = db.execute(
        "SELECT s.study_name, p.param_value, a.value_json FROM trials t "
        "JOIN studies s ON s.study_id = t.study_id "
        "JOIN trial_user_attributes a ON a.trial_id = t.trial_id AND a.key = 'cpu_time' "
        "LEFT JOIN trial_params p ON p.trial_id = t.trial_id "
        "WHERE t.state = 'COMPLETE'").fetchall()
    per_value: dict[str, dict[float, list[float]]] = defaultdict(lambda: defaultdict(list))
    tuned: list[float] = []
    for study, value, cpu in rows:
        if study.startswith("documented-"):
            per_value[study.removeprefix("documented-")][value].append(float(cpu))
        elif study.startswith("train"):
            tuned.append(float(cpu))
    stages = {stage: [sum(v) / len(v) for v in per_value[stage].values()] for stage in STAGES}
    assert tuned, "no train run of ppo=tuned in the store"
    return stages, sum(tuned) / len(tuned)


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
    parser.add_argument("--full-tuned-cpu", type=float, required=True)
    parser.add_argument("--ray-overhead", type=float, required=True)
    parser.add_argument("--head-ms", type=float, required=True)
    parser.add_argument("--stage-start", type=float, default=10.0)
    parser.add_argument("--nodes", default="1,4,16,64")
    args = parser.parse_args()
    small, tuned_small = measured_runs(args.store)
    scale = args.full_tuned_cpu / tuned_small
    full = {stage: [scale * t for t in values] for stage, values in small.items()}
    runs = {stage: [t for t in values for _ in range(SEEDS)] for stage, values in full.items()}
    total = sum(sum(r) for r in runs.values())
    print(f"ppo=tuned: {tuned_small:.2f} CPU s per run in the store, {args.full_tuned_cpu} at "
          f"the full budget: factor {scale:.1f}")
    print(f"{sum(len(r) for r in runs.values())} runs, {total / 3600:.1f} CPU hours at the "
          "full budget (model)")
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
