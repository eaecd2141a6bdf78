"""How fast the command answers: ``--help``, a refused input, ``list``, and the first trial line.

Each command runs as ``python -m kraby_study.cli`` from a checkout (``PYTHONPATH`` puts its
``kraby_study``, ``kraby_envs`` and ``kraby_conf`` first), in a fresh process, ``--repeats``
times; the table gives the median wall time. With ``--baseline DIR`` a second checkout (e.g.
an older commit in a git worktree) is measured in the same run, the two interleaved, and each
row gets the ratio this / baseline.
Usage::

    python benchmarks/bench_startup.py [--repeats 5] [--baseline /tmp/before]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def command(root: Path, *args: str) -> list[str]:
    """The CLI of the checkout at ``root``."""
    return [sys.executable, "-m", "kraby_study.cli", *args]


SHIMS = Path(tempfile.mkdtemp(prefix="kraby-startup-"))
"""Per checkout, a folder of links naming its packages as installed (envs/ is kraby_envs)."""


def environment(root: Path) -> dict[str, str]:
    """This process's environment with the checkout's packages first on the import path."""
    shim = SHIMS / root.name
    if not shim.exists():
        shim.mkdir()
        for name, folder in (("kraby_study", "kraby_study"), ("kraby_envs", "envs"),
                             ("kraby_conf", "conf")):
            (shim / name).symlink_to(root / folder)
    return {**os.environ, "PYTHONPATH": str(shim)}


def timed(root: Path, args: list[str], cwd: Path, code: int | None = 0) -> float:
    """Wall seconds of one command run to its end; checks its exit code."""
    start = time.perf_counter()
    done = subprocess.run(command(root, *args), cwd=cwd, env=environment(root),
                          capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if code is not None and done.returncode != code:
        raise SystemExit(f"{args}: exit {done.returncode}, expected {code}: {done.stderr}")
    return seconds


def first_trial_line(root: Path, store: Path, cwd: Path) -> float:
    """Wall seconds from start to the first line about a trial of a smoke study."""
    store.unlink(missing_ok=True)
    start = time.perf_counter()
    proc = subprocess.Popen(
        command(root, "run", "study=ent_coef", "budget=smoke", "workers=2", "save_models=false",
                f"storage=sqlite:///{store}"),
        cwd=cwd, env=environment(root), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)
    assert proc.stdout is not None
    try:
        for line in proc.stdout:
            if line.startswith(("started", "[")):
                return time.perf_counter() - start
        raise SystemExit(f"no trial line from {root}")
    finally:
        proc.kill()
        proc.wait()


def measure(root: Path, work: Path, repeats: int) -> dict[str, list[float]]:
    """Every measurement of one checkout, ``repeats`` times."""
    small = work / f"small-{root.name}.db"
    if not small.exists():
        subprocess.run(command(root, "run", "study=ent_coef", "budget=smoke", "budget.seeds=1",
                               "save_models=false", "workers=2", f"storage=sqlite:///{small}"),
                       cwd=work, env=environment(root), capture_output=True, check=True)
    rows: dict[str, list[float]] = {}
    for _ in range(repeats):
        rows.setdefault("kraby-study --help", []).append(timed(root, ["--help"], work))
        rows.setdefault("refused input (run ppo.gamma=1.5)", []).append(timed(
            root, ["run", "study=ent_coef", "ppo.gamma=1.5",
                   f"storage=sqlite:///{work / 'refused.db'}"], work, code=2))
        rows.setdefault("list, a store of 5 trials", []).append(
            timed(root, ["list", f"storage=sqlite:///{small}"], work))
        rows.setdefault("run study=ent_coef budget=smoke: first trial line", []).append(
            first_trial_line(root, work / f"first-{root.name}.db", work))
    return rows


def main() -> None:
    """Measure, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--baseline", type=Path, help="another checkout, measured beside")
    args = parser.parse_args()
    roots = [ROOT] + ([args.baseline.resolve()] if args.baseline else [])
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        results: dict[Path, dict[str, list[float]]] = {root: {} for root in roots}
        for _ in range(args.repeats):  # interleaved, so load on the machine hits both alike
            for root in roots:
                for name, values in measure(root, work, 1).items():
                    results[root].setdefault(name, []).extend(values)
    header = "| measurement | this checkout (s) |"
    rule = "|---|---:|"
    if args.baseline:
        header += " baseline (s) | ratio |"
        rule += "---:|---:|"
    print(f"median of {args.repeats} runs each, wall seconds, {os.cpu_count()} cores")
    print(header)
    print(rule)
    for name, values in results[ROOT].items():
        this = statistics.median(values)
        row = f"| {name} | {this:.2f} |"
        if args.baseline:
            before = statistics.median(results[roots[1]][name])
            row += f" {before:.2f} | {this / before:.2f} |"
        print(row)


if __name__ == "__main__":
    main()
