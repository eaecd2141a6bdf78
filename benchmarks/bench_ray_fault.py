"""Benchmark: what a lost Ray node and a lost head command cost, against a run without fault.

Run: python benchmarks/bench_ray_fault.py [--steps 16384] [--seeds 2] [--after 8]

Three one-CPU Ray nodes on loopback (each run on a fresh cluster, stopped at its end), the
clip_range sweep (4 values x --seeds seeds, models not saved), 3 workers, each run in a fresh
SQLite store:

1. no fault;
2. the third node killed (its raylet and every process below it, SIGKILL) --after seconds
   after trial actors run on all three nodes;
3. the command itself killed with SIGKILL once 3 trials are complete, then the same command
   run again on the same cluster and store.

It prints each run's wall time, the trials run again, and whether every run's score and curve
equal the fault-free run's to the bit; for 3, which trials the second command ran.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bench_head import kill_marked

from kraby_study.store.store import opened

# Reading a cluster's processes from /proc is a test fixture (tests/processes.py), shared here.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from processes import cmdline, descendants  # noqa: E402

RAY = str(Path(sys.executable).with_name("ray"))
# Trial actors at the command's own priority, as the product sets for a Ray of its own.
ENV = dict(os.environ, RAY_USAGE_STATS_ENABLED="0", RAY_AUTH_MODE="disabled",
           RAY_worker_niceness="0", PYTHONUNBUFFERED="1")


class Cluster:
    """One-CPU nodes on loopback in a folder of their own."""

    def __init__(self, run: int) -> None:
        self.folder = Path(f"/tmp/krf{os.getpid()}-{run}")
        self.port = 6600 + (os.getpid() + run) % 900
        self.address = f"127.0.0.1:{self.port}"
        self.raylets: list[int] = []

    def start(self, nodes: int) -> None:
        for index in range(nodes):
            where = (["--head", f"--port={self.port}", "--include-dashboard=false",
                      f"--temp-dir={self.folder}"] if index == 0
                     else [f"--address={self.address}"])
            before = set(self._raylets())
            subprocess.run([RAY, "start", *where, "--num-cpus=1", "--node-ip-address=127.0.0.1",
                            "--object-store-memory=100000000"], check=True, env=ENV,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            (raylet,) = set(self._raylets()) - before
            self.raylets.append(raylet)

    def _raylets(self) -> list[int]:
        return [int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit()
                and str(self.folder).encode() in cmdline(int(p.name))
                and b"raylet/raylet" in cmdline(int(p.name))]

    def has_actor(self, raylet: int) -> bool:
        return any(cmdline(p).startswith(b"ray::Trial") for p in descendants([raylet]))

    def stop(self) -> None:
        kill_marked(str(self.folder))
        subprocess.run(["rm", "-rf", str(self.folder)], check=False)


@contextmanager
def cluster(run: int, nodes: int = 3) -> Iterator[Cluster]:
    made = Cluster(run)
    try:
        made.start(nodes)
        yield made
    finally:
        made.stop()


def command(args: argparse.Namespace, address: str, db: Path) -> list[str]:
    return [sys.executable, "-m", "kraby_study.cli", "run", "study=clip_range",
            f"budget.steps={args.steps}", f"budget.seeds={args.seeds}", "budget.curve_every=1024",
            "save_models=false", "workers=3", "executor=ray", f"ray.address={address}",
            f"storage=sqlite:///{db}"]


def results(db: Path) -> dict[str, tuple[float, list[float]]]:
    """Score and curve of each complete trial, by key."""
    with opened(f"sqlite:///{db}", create=False, writer=False) as store:
        ledger = store.load("clip_range")
        done = {t.number: t for t in ledger.trials() if t.value is not None}
        curves = ledger.curves(list(done))
    return {str(t.user_attrs["key"]): (float(t.value),
                                       curves[curves.number == n].mean_reward.tolist())
            for n, t in done.items()}


def reruns(out: str) -> int:
    return sum(1 for line in out.splitlines() if re.search(r"\), rerun", line))


def launch(args: argparse.Namespace, address: str, db: Path) -> subprocess.Popen[str]:
    """The study's command on the cluster at ``address`` into ``db``, started in ``db``'s
    folder, its output (stderr with it) read as text."""
    return subprocess.Popen(command(args, address, db), cwd=db.parent, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=16384)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--after", type=float, default=8.0)
    args = parser.parse_args()
    trials = 4 * args.seeds
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        # 1. No fault.
        with cluster(1) as made:
            db = folder / "clean.db"
            t0 = time.perf_counter()
            proc = launch(args, made.address, db)
            assert proc.stdout is not None
            first_start = None
            lines = []
            for line in proc.stdout:
                lines.append(line)
                if first_start is None and line.startswith("started"):
                    first_start = time.perf_counter() - t0
            proc.wait()
            clean_wall = time.perf_counter() - t0
            assert proc.returncode == 0, "".join(lines)
        clean = results(db)
        assert len(clean) == trials
        print(f"1. no fault: {clean_wall:.1f} s, {trials} trials complete; the first trial "
              f"started {first_start:.1f} s after the command (start-up, Ray connection, "
              "actor placed and started)", flush=True)

        # 2. The third node lost mid-study.
        with cluster(2) as made:
            db = folder / "lost_node.db"
            t0 = time.perf_counter()
            proc = launch(args, made.address, db)
            while not all(made.has_actor(r) for r in made.raylets):
                assert proc.poll() is None, proc.communicate()[0]
                time.sleep(0.2)
            time.sleep(args.after)
            victim = made.raylets[2]
            killed_at = time.perf_counter() - t0
            for pid in [victim, *descendants([victim])]:
                try:
                    os.kill(pid, 9)
                except ProcessLookupError:
                    pass
            out, _ = proc.communicate()
            lost_wall = time.perf_counter() - t0
            assert proc.returncode == 0, out
        lost = results(db)
        print(f"2. node lost at {killed_at:.1f} s: {lost_wall:.1f} s "
              f"({lost_wall / clean_wall:.2f}x, {lost_wall - clean_wall:+.1f} s), "
              f"{reruns(out)} trial(s) run again, {len(lost)} complete, "
              f"scores and curves equal to 1 to the bit: {lost == clean}", flush=True)

        # 3. The head's command killed once 3 trials are complete, then run again.
        with cluster(3) as made:
            db = folder / "lost_head.db"
            t0 = time.perf_counter()
            proc = launch(args, made.address, db)
            assert proc.stdout is not None
            ended = 0
            for line in proc.stdout:
                if re.match(r"\[\d+/\d+\] .*: complete", line):
                    ended += 1
                    if ended == 3:
                        break
            proc.kill()
            proc.wait()
            first_wall = time.perf_counter() - t0
            before = results(db)
            t1 = time.perf_counter()
            again = subprocess.run(command(args, made.address, db), cwd=folder, env=ENV,
                                   capture_output=True, text=True)
            second_wall = time.perf_counter() - t1
            assert again.returncode == 0, again.stdout + again.stderr
        after = results(db)
        ran = [line for line in again.stdout.splitlines() if re.match(r"\[\d+/\d+\] ", line)]
        head = again.stdout.splitlines()[0] if again.stdout else ""
        kept = all(after[k] == v for k, v in before.items())
        print(f"3. head killed after {len(before)} complete trials at {first_wall:.1f} s; "
              f"the command again: {second_wall:.1f} s, ran {len(ran)} trial(s) "
              f"({head!r}); together {first_wall + second_wall:.1f} s "
              f"({(first_wall + second_wall) / clean_wall:.2f}x); complete trials kept as they "
              f"were: {kept}; all {len(after)} equal to 1 to the bit: {after == clean}",
              flush=True)


if __name__ == "__main__":
    main()
