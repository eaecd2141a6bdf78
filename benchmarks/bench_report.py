"""Time ``write_report`` and ``list`` on a large synthetic store (a measurement, not a test).

The store holds sweeps of 10 values x 10 seeds plus one Optuna search, ``--trials`` trials in
all, each with ``--points`` learning-curve points, written through Optuna and
``kraby_study.store`` like real runs (no training). Goals: under 30 s for 500 trials x 250 points,
under 40 s for 5,000 trials x 250 points.
With ``--list N``, ``kraby-study list`` on the same store is timed N times in fresh processes
(median; goal under 2 s at 5,000 trials), and with ``--baseline DIR`` the same command of
another checkout beside it, interleaved, as ``bench_startup.py`` does.
Usage::

    python benchmarks/bench_report.py [--trials 500] [--points 250] [--format png] [--keep DIR]
        [--list N] [--baseline DIR]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import optuna

from kraby_study.report import write_report
from kraby_study.store.store import Store

ROOT = Path(__file__).resolve().parents[1]
# The synthetic stores are a test fixture (tests/synthetic.py), shared with this benchmark.
sys.path.insert(0, str(ROOT / "tests"))
from synthetic import add_search, add_sweep, sweep_runs  # noqa: E402

SWEEPS = [
    ("ent_coef", "ppo.ent_coef", [1e-8, 1e-6, 1e-4, 1e-3, 3e-3, 0.01, 0.03, 0.1, 0.3, 1.0]),
    ("gamma", "ppo.gamma", [0.2, 0.4, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 0.98, 0.9999]),
    ("n_steps", "ppo.n_steps", [8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096]),
    ("gae_lambda", "ppo.gae_lambda", [0.8, 0.85, 0.9, 0.92, 0.95, 0.97, 0.98, 0.99, 0.995, 1.0]),
    ("learning_rate", "ppo.learning_rate",
     [1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 1.0]),
]
SEEDS = 10
STEPS = 250_000


def build_store(url: str, trials: int, points: int) -> int:
    """Write sweeps of 100 runs while they fit, then a search with the remaining trials."""
    rng = np.random.default_rng(0)
    written = 0
    with_store = Store(url)
    try:
        for name, parameter, values in SWEEPS:
            if trials - written < len(values) * SEEDS + 20:
                break
            runs = sweep_runs(values, SEEDS, points, STEPS, rng, failed=2)
            add_sweep(with_store, name, parameter, values, runs, steps=STEPS,
                      curve_every=STEPS // points)
            written += len(runs)
        if trials > written:
            add_search(with_store, "search", trials - written, rng, steps=STEPS, points=points)
            written = trials
    finally:
        with_store.close()
    return written


def time_list(url: str, roots: list[Path], repeats: int, cwd: Path) -> dict[Path, list[float]]:
    """Wall seconds of ``kraby-study list`` on the store, per checkout, in fresh processes."""
    from bench_startup import timed  # the same fresh-process timing as the start-up table

    seconds: dict[Path, list[float]] = {root: [] for root in roots}
    for _ in range(repeats):  # interleaved, so load on the machine hits both alike
        for root in roots:
            seconds[root].append(timed(root, ["list", f"storage={url}"], cwd))
    return seconds


def main() -> None:
    """Build the store, report it, print the timings."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=500)
    parser.add_argument("--points", type=int, default=250)
    parser.add_argument("--format", default="png", choices=["png", "svg"])
    parser.add_argument("--keep", type=Path, default=None,
                        help="write the store and report here instead of a temporary folder")
    parser.add_argument("--list", type=int, default=0, metavar="N",
                        help="also time `kraby-study list` on the store N times (median)")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another checkout whose `list` is timed beside (with --list)")
    args = parser.parse_args()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        url = f"sqlite:///{root / 'bench.db'}"
        start = time.perf_counter()
        trials = build_store(url, args.trials, args.points)
        built = time.perf_counter() - start
        start = time.perf_counter()
        index = write_report(url, root / "report", fmt=args.format)
        seconds = time.perf_counter() - start
        roots = [ROOT] + ([args.baseline.resolve()] if args.baseline else [])
        listed = time_list(url, roots, args.list, root) if args.list else {}
    print(f"store: {trials} trials x {args.points} curve points, "
          f"{len(index.studies)} studies (built in {built:.1f} s)")
    goal = 30 if trials <= 500 else 40
    print(f"write_report: {seconds:.2f} s for {len(index.files)} files "
          f"({'under' if seconds < goal else 'OVER'} the {goal} s goal for this size)")
    if listed:
        this = statistics.median(listed[ROOT])
        line = (f"list: {this:.2f} s, median of {args.list} fresh processes "
                f"({'under' if this < 2 else 'OVER'} the 2 s goal)")
        if args.baseline:
            before = statistics.median(listed[roots[1]])
            line += f"; baseline {before:.2f} s, ratio {this / before:.2f}"
        print(line)


if __name__ == "__main__":
    main()
