"""Benchmark: 1, 2 and 4 worker processes on one PostgreSQL study, and database writes per trial.

Run: python benchmarks/bench_postgres.py --url postgresql+psycopg://user@host/db
     (or set KRABY_TEST_POSTGRES_URL; .ci/postgres.sh starts a throwaway server)

Each worker process is a separate `kraby-study run ... workers=1` command, as one machine would
start it. All of them join one sweep (clip_range: 4 values x 2 seeds, 8,192 steps per run) in a
fresh database per configuration. Writes are the database's committed transactions
(pg_stat_database.xact_commit) during the run, divided by the number of trials. ``--smoke``
runs 1 and 2 processes at 1,024 steps per run, for the test suite.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import sqlalchemy as sa

from kraby_study.store.store import Store

STUDY = ["study=clip_range", "budget.seeds=2", "budget.steps=8192", "budget.curve_every=1024",
         "save_models=false", "workers=1"]
TRIALS = 8
SMOKE = ["budget.steps=1024", "budget.curve_every=512"]
"""Overrides of ``--smoke``: the same sweep at the leg's shortest budget that can be scored."""


def commits(admin: sa.Engine, name: str) -> int:
    with admin.connect() as conn:
        conn.execute(sa.text("SELECT pg_stat_clear_snapshot()"))
        return int(conn.execute(sa.text("SELECT xact_commit FROM pg_stat_database WHERE "
                                        "datname = :n"), {"n": name}).scalar() or 0)


def run(server: str, processes: int, cwd: Path, extra: list[str]) -> tuple[float, float]:
    """(wall seconds, commits per trial) of one configuration."""
    admin = sa.create_engine(server, isolation_level="AUTOCOMMIT")
    name = f"kraby_bench_{uuid.uuid4().hex[:8]}"
    with admin.connect() as conn:
        conn.execute(sa.text(f"CREATE DATABASE {name}"))
    url = sa.engine.make_url(server).set(database=name).render_as_string(hide_password=False)
    try:
        # Create the tables first so the count covers the study, not the schema.
        Store(url).close()
        before = commits(admin, name)
        t0 = time.perf_counter()
        procs = [subprocess.Popen([sys.executable, "-m", "kraby_study.cli", "run", *STUDY,
                                   *extra, f"storage={url}"], cwd=cwd, stdout=subprocess.DEVNULL)
                 for _ in range(processes)]
        for proc in procs:
            if proc.wait() != 0:
                raise SystemExit("a worker command failed")
        wall = time.perf_counter() - t0
        time.sleep(1.0)  # statistics are flushed to the collector with a short delay
        return wall, (commits(admin, name) - before) / TRIALS
    finally:
        with admin.connect() as conn:
            conn.execute(sa.text(f"DROP DATABASE IF EXISTS {name} WITH (FORCE)"))
        admin.dispose()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default=os.environ.get("KRABY_TEST_POSTGRES_URL"))
    parser.add_argument("--smoke", action="store_true",
                        help="1 and 2 processes at 1,024 steps per run (the test suite's run)")
    args = parser.parse_args()
    if not args.url:
        raise SystemExit("give --url or set KRABY_TEST_POSTGRES_URL")
    with tempfile.TemporaryDirectory() as tmp:
        extra, counts = (SMOKE, (1, 2)) if args.smoke else ([], (1, 2, 4))
        results = {n: run(args.url, n, Path(tmp), extra) for n in counts}
    base = results[1][0]
    steps = "1,024" if args.smoke else "8,192"
    print(f"cores: {os.cpu_count()}; {TRIALS} trials of {steps} steps (clip_range, 2 seeds)")
    print("| worker processes | wall time (s) | speed-up | database commits per trial |")
    print("|---:|---:|---:|---:|")
    for n, (wall, per_trial) in results.items():
        print(f"| {n} | {wall:.1f} | {base / wall:.2f}x | {per_trial:.0f} |")


if __name__ == "__main__":
    main()
