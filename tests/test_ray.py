"""executor=ray: the same results as the local executor, trials run again when a Ray worker or
node dies, and bad input in one line. Each test starts its own Ray processes on loopback and
stops every one of them."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from importlib import metadata
from pathlib import Path

import pytest
from conftest import (
    SERVER,
    TINY,
    fresh_database,
    load,
    run_cli,
    spawn_cli,
    sqlite_url,
    tiny_with_steps,
    wait_for,
)
from optuna.trial import TrialState
from processes import cmdline, descendants

from kraby_study.errors import StoreError
from kraby_study.records.attributes import PROVENANCE_PREFIX, RAY_NODE
from kraby_study.store.rows import reading
from kraby_study.store.store import opened

pytest.importorskip("ray")
# One xdist worker runs every Ray test in turn: they count the machine's Ray processes.
pytestmark = pytest.mark.xdist_group("ray")

RAY = str(Path(sys.executable).with_name("ray"))
# Test clusters live on loopback, for one test each: no token to share between the nodes.
os.environ.setdefault("RAY_AUTH_MODE", "disabled")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

SLOWER = tiny_with_steps(32768)


def outcomes(db: Path, name: str) -> dict[str, list[TrialState]]:
    """Each planned run's attempts, by key, in order."""
    out: dict[str, list[TrialState]] = {}
    for trial in load(db, name).get_trials():
        out.setdefault(str(trial.user_attrs["key"]), []).append(trial.state)
    return out


def scores(db: Path, name: str) -> dict[str, tuple[float, list[float]]]:
    """The final score and learning curve of each complete run, by key."""
    with opened(sqlite_url(db), create=False, writer=False) as store:
        ledger = store.load(name)
        trials = {t.number: t for t in ledger.trials() if t.state == TrialState.COMPLETE}
        curves = ledger.curves(list(trials))
    return {str(t.user_attrs["key"]): (t.value, curves[curves.number == n].mean_reward.tolist())
            for n, t in trials.items()}


def ray_processes(marker: str) -> list[int]:
    """Processes whose command line holds ``marker`` (a cluster's own temporary folder)."""
    return [int(p.name) for p in Path("/proc").iterdir()
            if p.name.isdigit() and marker.encode() in cmdline(int(p.name))]


def kill_all(pids: list[int]) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


class Cluster:
    """A Ray cluster of one-CPU nodes on loopback, in its own temporary folder."""

    def __init__(self, folder: Path, port: int) -> None:
        self.folder, self.port = folder, port
        self.address = f"127.0.0.1:{port}"

    def start(self, head: bool, cpus: int = 1, python: str | None = None) -> int:
        """Start a node of ``cpus`` CPUs (its workers run ``python``, by default this
        interpreter); returns its raylet's process id."""
        before = set(self.raylets())
        where = (["--head", f"--port={self.port}", "--include-dashboard=false",
                  f"--temp-dir={self.folder}"] if head else [f"--address={self.address}"])
        ray = [RAY] if python is None else [
            python, "-c", "from ray.scripts.scripts import main; main()"]
        subprocess.run([*ray, "start", *where, f"--num-cpus={cpus}",
                        "--node-ip-address=127.0.0.1", "--object-store-memory=100000000"],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        (raylet,) = set(self.raylets()) - before
        return raylet

    @staticmethod
    def node_id(raylet: int) -> str:
        """The Ray node id of a node, from its raylet's command line."""
        (node,) = [arg.split(b"=", 1)[1].decode() for arg in cmdline(raylet).split(b"\0")
                   if arg.startswith(b"--node_id=")]
        return node

    def raylets(self) -> list[int]:
        return [p for p in ray_processes(str(self.folder)) if b"raylet/raylet" in cmdline(p)]

    def client_servers(self) -> list[int]:
        """The Ray client servers the head starts: they leave its process tree, and their
        command line names the head's port (``--address=IP:PORT``), not the cluster's folder."""
        port = f":{self.port}\0".encode()
        return [p for p in ray_processes("ray.util.client.server")
                if b"--address=" in cmdline(p) and port in cmdline(p)]

    def stop(self, patience: float = 20.0) -> None:
        """SIGKILL every process of the cluster and everything they started, until none is
        left (or ``patience`` seconds have passed): a SIGKILL takes effect asynchronously, and
        a head being killed may still start a client server, so one pass can miss one."""
        deadline = time.monotonic() + patience
        while own := ray_processes(str(self.folder)) + self.client_servers():
            kill_all(own + descendants(own))
            if time.monotonic() > deadline:
                return
            time.sleep(0.2)


@pytest.fixture
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cluster]:
    # Ray's socket paths must stay short: a folder of its own right under /tmp.
    folder = Path(f"/tmp/kr{os.getpid()}")
    made = Cluster(folder, 6400 + os.getpid() % 1000)
    try:
        yield made
    finally:
        made.stop()
        subprocess.run(["rm", "-rf", str(folder)], check=False)
    assert not made.client_servers()  # nothing of the cluster outlives the test


def local_ray_processes(before: set[int], patience: float = 30.0) -> set[int]:
    """Ray processes started since ``before`` (a command's own local Ray instance) that are
    still there after up to ``patience`` seconds: ray.shutdown kills the raylet and the GCS
    without waiting, and their workers and agents exit on their own a moment later."""
    deadline = time.monotonic() + patience
    while True:
        left = {p for p in ray_processes("ray/") if p not in before}
        if not left or time.monotonic() >= deadline:
            return left
        time.sleep(0.2)


def test_a_ray_sweep_gives_the_local_executors_exact_scores(workdir: Path) -> None:
    before = set(ray_processes("ray/"))
    common = ["study=gamma", *TINY, "study.values=[0.8,0.99]", "workers=2"]
    assert run_cli("run", *common, f"storage={sqlite_url(workdir / 'local.db')}") == 0
    # With TensorBoard logs on Ray too: they land at DIR and change no result.
    proc = spawn_cli("run", *common, f"storage={sqlite_url(workdir / 'ray.db')}",
                     "executor=ray", "tensorboard_dir=tb", cwd=workdir)
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out
    local, on_ray = scores(workdir / "local.db", "gamma"), scores(workdir / "ray.db", "gamma")
    assert len(local) == 4 and on_ray == local  # bit for bit: scores and every curve point
    # Each Ray trial stores what made it, as its actor saw it (here the same machine).
    study = load(workdir / "ray.db", "gamma")
    made = [study.user_attrs[PROVENANCE_PREFIX + t.user_attrs["provenance"]]
            for t in study.trials]
    assert {r["hostname"] for r in made} == {socket.gethostname()}
    assert {r["torch"] for r in made} == {metadata.version("torch")}
    assert all("executor=ray" in r["command"] for r in made)
    assert not local_ray_processes(before)  # the command stopped its own Ray instance
    assert sorted(p.name for p in (workdir / "tb" / "gamma").iterdir()) == [
        "gamma=0.8-seed0", "gamma=0.8-seed1", "gamma=0.99-seed0", "gamma=0.99-seed1"]


@pytest.mark.parametrize("args,message", [
    (["executor=dask"], "executor must be one of local, ray, got 'dask'"),
    (["executor=ray", "ray.cpus_per_trial=0"], "ray.cpus_per_trial must be at least 1"),
    (["executor=ray", "ray.cpus_per_trial=64"], "no Ray node has 64 CPU(s) for a trial"),
])
def test_bad_executor_input_is_one_line_and_writes_nothing(
        workdir: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str) -> None:
    assert run_cli("run", "study=gamma", *TINY, *args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (workdir / "studies").exists()


def test_executor_ray_without_ray_names_the_extra(
        workdir: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "ray" else real(name, *a))
    assert run_cli("run", "study=gamma", *TINY, "executor=ray") == 2
    err = capsys.readouterr().err.strip()
    assert err == ("kraby-study: error: executor=ray needs Ray, which is not installed: pip "
                   "install 'kraby-study[ray]'")
    assert not (workdir / "studies").exists()


def test_an_unreachable_cluster_is_one_line_and_writes_nothing(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("run", "study=gamma", *TINY, "executor=ray", "ray.address=127.0.0.1:1",
                   "db_retry_seconds=2") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cannot start the Ray cluster at 127.0.0.1:1" in err
    assert not (workdir / "studies").exists()


def actors() -> list[int]:
    """Every trial actor's process on this machine."""
    return [p for p in ray_processes("ray::TrialActor") if cmdline(p).startswith(b"ray::Trial")]


def started_trials(db: Path) -> int:
    """Trials whose actor said they started (their provenance stored)."""
    if not db.exists():
        return 0
    try:
        with reading(sqlite_url(db)) as reader:
            return sum("provenance" in t.user_attrs for study in reader.studies()
                       for t in study.trials)
    except StoreError:  # the command is still creating the store
        return 0


def killed_midway(workdir: Path, args: list[str], ready: Callable[[], bool],
                  victims: Callable[[], list[int]]) -> tuple[int, str]:
    """Run a command, SIGKILL ``victims()`` once ``ready()`` holds (both trials started:
    training, each for many seconds more); (exit code, output) of the command."""
    proc = spawn_cli("run", "study=clip_range", *SLOWER, "budget.seeds=1", "workers=2",
                     "executor=ray", *args, cwd=workdir)
    try:
        wait_for(ready, proc=proc)
        kill_all(victims())
        out, _ = proc.communicate(timeout=600)
    finally:
        proc.kill()
    return proc.returncode, out


def each_run_complete_once(db: Path) -> None:
    """One trial per planned run of the 4, each complete: a killed one ran again under its
    number."""
    runs = outcomes(db, "clip_range")
    assert sorted(runs) == [f"v{i}-s0" for i in range(4)]
    assert all(states == [TrialState.COMPLETE] for states in runs.values()), runs


@pytest.mark.slow
def test_a_killed_ray_worker_has_its_trial_run_again(workdir: Path) -> None:
    db = workdir / "ray.db"
    before = set(ray_processes("ray/"))
    code, out = killed_midway(workdir, [f"storage={sqlite_url(db)}"],
                              ready=lambda: len(actors()) == 2 and started_trials(db) == 2,
                              victims=lambda: actors()[:1])
    assert code == 0, out
    assert "(worker lost on Ray (ActorDiedError)), rerun" in out
    each_run_complete_once(db)
    assert not local_ray_processes(before)


@pytest.mark.slow
def test_a_lost_node_has_its_trials_run_on_the_others(workdir: Path, cluster: Cluster) -> None:
    head = cluster.node_id(cluster.start(head=True))
    second = cluster.start(head=False)
    lost = cluster.node_id(second)
    db = workdir / "ray.db"

    def on_both_nodes() -> bool:  # each node has a trial that started (its record stored)
        if not db.exists():
            return False
        try:
            with reading(sqlite_url(db)) as reader:
                return {r.get(RAY_NODE) for study in reader.studies()
                        for r in study.provenance.values()} == {head, lost}
        except StoreError:  # the command is still creating the store
            return False

    code, out = killed_midway(workdir, [f"ray.address={cluster.address}",
                                        f"storage={sqlite_url(db)}"],
                              ready=on_both_nodes,
                              victims=lambda: [second, *descendants([second])])
    assert code == 0, out
    assert "worker lost on Ray" in out
    each_run_complete_once(db)
    # Each trial stores the node that ran it: trials started on both nodes (the study keeps
    # the lost node's record), and each trial the lost node held ran again on the head.
    study = load(db, "clip_range")
    records = {k[len(PROVENANCE_PREFIX):]: v for k, v in study.user_attrs.items()
               if k.startswith(PROVENANCE_PREFIX)}
    assert {r[RAY_NODE] for r in records.values()} == {head, lost}
    node = {f"clip_range={t.params['clip_range']} seed 0":
            records[t.user_attrs["provenance"]][RAY_NODE] for t in study.trials}
    rerun = [line.split(":")[0] for line in out.splitlines()
             if "(worker lost on Ray (" in line and "), rerun" in line]
    assert rerun and all(node[label] == head for label in rerun), (rerun, node)
    # list counts both nodes.
    listed = subprocess.run([sys.executable, "-m", "kraby_study.cli", "list",
                             f"storage={sqlite_url(db)}"], capture_output=True, text=True,
                            check=True, cwd=workdir).stdout
    assert " 2 nodes " in listed, listed


@pytest.mark.slow
def test_a_node_without_the_project_fails_its_trial_in_one_line(
        workdir: Path, cluster: Cluster) -> None:
    import sysconfig

    site = sysconfig.get_paths()["purelib"]
    if Path(__import__("kraby_study").__file__).is_relative_to(site):
        pytest.skip("kraby-study is installed into site-packages, not editable")
    # A node whose Python has Ray and every dependency (this environment's site-packages),
    # but not kraby-study: an editable install's finder is only read from a site folder.
    bare = workdir / "bare"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(bare)], check=True)
    (bare_site,) = bare.glob("lib/python*/site-packages")
    (bare_site / "deps.pth").write_text(site + "\n")
    cluster.start(head=True, cpus=0)  # every trial goes to the bare node
    node = cluster.node_id(cluster.start(head=False, python=str(bare / "bin" / "python")))
    db = workdir / "ray.db"
    proc = spawn_cli("run", "study=clip_range", *TINY, "study.values=[0.2]", "budget.seeds=1",
                     "executor=ray", f"ray.address={cluster.address}",
                     f"storage={sqlite_url(db)}", cwd=workdir)
    out, _ = proc.communicate(timeout=300)
    assert proc.returncode == 1, out
    (trial,) = load(db, "clip_range").get_trials()
    assert trial.state == TrialState.FAIL
    reason = str(trial.user_attrs["failure"])
    assert reason.startswith("error: Python package 'kraby_study' is not installed on Ray node ")
    assert f"(node id {node[:8]}): install kraby-study there (docs/guide/clusters.md)" in reason
    assert len(reason.splitlines()) == 1
    # The node fixed (the project installed there: this environment's editable install) and
    # the cluster started again: the failed trial runs again, on purpose, with its seed and
    # settings.
    cluster.stop()
    for installed in Path(site).glob("__editable__*kraby_study*"):
        shutil.copy(installed, bare_site)
    fixed = Cluster(Path(f"{cluster.folder}-fixed"), cluster.port + 1)
    try:
        fixed.start(head=True, cpus=0)
        now = fixed.node_id(fixed.start(head=False, python=str(bare / "bin" / "python")))
        listed = subprocess.run([sys.executable, "-m", "kraby_study.cli", "list",
                                 f"storage={sqlite_url(db)}"], capture_output=True, text=True,
                                check=True, cwd=workdir).stdout
        # No trial of it started, so no command is stored to quote.
        assert ("clip_range: 1 run(s) failed with an error; to run them again with the same "
                "seeds and settings: its command with --retry-failed") in listed
        proc = spawn_cli("run", "study=clip_range", *TINY, "study.values=[0.2]",
                         "budget.seeds=1", "executor=ray", f"ray.address={fixed.address}",
                         f"storage={sqlite_url(db)}", "--retry-failed", cwd=workdir)
        out, _ = proc.communicate(timeout=300)
    finally:
        fixed.stop()
        subprocess.run(["rm", "-rf", str(fixed.folder)], check=False)
    assert proc.returncode == 0, out
    study = load(db, "clip_range")
    first, again = study.get_trials()
    assert (again.state, again.user_attrs["retry_of"]) == (TrialState.COMPLETE, first.number)
    assert again.params == first.params and again.user_attrs["seed"] == first.user_attrs["seed"]
    record = study.user_attrs[PROVENANCE_PREFIX + again.user_attrs["provenance"]]
    assert record[RAY_NODE] == now != node
    assert record["retried_failure"] == reason and record["retry_of"] == str(first.number)


@pytest.mark.slow
def test_a_lost_cluster_stops_the_command_in_one_line(workdir: Path, cluster: Cluster) -> None:
    cluster.start(head=True)
    db = workdir / "ray.db"
    proc = spawn_cli("run", "study=clip_range", *tiny_with_steps(40960), "budget.seeds=1",
                     "workers=1", "executor=ray", f"ray.address={cluster.address}",
                     "db_retry_seconds=5", f"storage={sqlite_url(db)}", cwd=workdir)
    try:
        wait_for(lambda: db.exists() and bool(actors()), proc=proc)
        cluster.stop()
        out, _ = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == 1, out
    assert out.strip().splitlines()[-1] == (
        "kraby-study: error: no trial actor answered for 5 s: the Ray cluster is lost or has "
        "no CPU left for a trial; giving up (complete trials are stored; rerun to resume)")
    # Nothing is left marked running: the trial that ran is queued again for the next run.
    trials = load(db, "clip_range").get_trials()
    assert not [t for t in trials if t.state == TrialState.RUNNING]
    lost = [t for t in trials if "the cluster running it was lost" in
            str(t.user_attrs.get("failure"))]
    assert len(lost) == 1, [t.user_attrs for t in trials]


@pytest.mark.slow
def test_a_search_on_ray_answers_its_checkpoints_as_a_local_one(workdir: Path) -> None:
    from test_search import TINY_SPACE

    (workdir / "conf" / "search").mkdir(parents=True)
    (workdir / "conf" / "search" / "tiny.yaml").write_text(TINY_SPACE)
    common = ["optuna", "--trials", "3", "search=tiny", "--workers", "1", *TINY,
              "budget.seeds=2"]
    assert run_cli(*common, f"storage={sqlite_url(workdir / 'local.db')}") == 0
    proc = spawn_cli(*common, f"storage={sqlite_url(workdir / 'ray.db')}", "executor=ray",
                     cwd=workdir)
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out

    def trials(db: Path) -> list[tuple]:
        return [(t.state, t.params, t.value, t.intermediate_values)
                for t in load(db, "tiny").get_trials()]

    local = trials(workdir / "local.db")
    assert len(local) == 3 and all(len(t[3]) >= 2 for t in local)
    assert trials(workdir / "ray.db") == local


@pytest.mark.slow
@pytest.mark.postgres
@pytest.mark.skipif(not SERVER, reason="KRABY_TEST_POSTGRES_URL is not set")
def test_a_ray_sweep_writes_a_postgresql_store(workdir: Path) -> None:
    with fresh_database() as url:
        proc = spawn_cli("run", "study=gamma", *TINY, "study.values=[0.8,0.99]", "workers=2",
                         "executor=ray", f"storage={url}", cwd=workdir)
        out, _ = proc.communicate(timeout=600)
        assert proc.returncode == 0, out
        states = [t.state for t in load(url, "gamma").get_trials()]
        assert states == [TrialState.COMPLETE] * 4


def started_slowly(monkeypatch: pytest.MonkeyPatch, slow: float, patience: float,
                   start_seconds: float) -> tuple[list, float]:
    """One tiny trial on a one-CPU Ray instance of this process, in an actor whose start
    imports a module for ``slow`` seconds: (the pool's events until the trial ended or its
    actor was let go, how long the import took)."""
    from slow_actor import SlowTrialActor

    from kraby_study.config.compose import compose_config
    from kraby_study.plan.sweep import expand_study
    from kraby_study.run import ray_pool

    tests = str(Path(__file__).resolve().parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [tests, *filter(None, [os.environ.get("PYTHONPATH")])]))
    monkeypatch.setenv("KRABY_TEST_SLOW_IMPORT", str(slow))
    monkeypatch.setattr(ray_pool, "TrialActor", SlowTrialActor)
    spec = expand_study(compose_config(["study=gamma", *TINY, "study.values=[0.9]",
                                        "budget.seeds=1"])).specs[0]
    ray = ray_pool.ray
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False,
             object_store_memory=ray_pool.LOCAL_OBJECT_STORE, _node_ip_address="127.0.0.1")
    try:
        pool = ray_pool.RayPool(1, 1, 1, patience=patience, start_seconds=start_seconds)
        pool.submit(0, spec)
        (slot,) = pool._slots
        events: list = []
        # Progress, not time: the pool is asked until the trial's result or death comes.
        deadline = time.monotonic() + 300
        while not any(e.kind in ("result", "died") for e in events):
            assert time.monotonic() < deadline, events
            events += pool.events(timeout=0.5)
        imported = (ray.get(slot.actor.import_seconds.remote())
                    if events[-1].kind == "result" else slow)
        pool.close()
    finally:
        ray.shutdown()
    return events, imported


@pytest.mark.slow
def test_an_actor_that_starts_slowly_is_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    from kraby_study.records.stored import Outcome

    # Its start lasts four times the patience for a silent cluster: alive, not silent.
    events, imported = started_slowly(monkeypatch, slow=8.0, patience=2.0, start_seconds=600)
    assert imported >= 8.0
    assert [e.kind for e in events if e.kind in ("started", "result", "died")] == [
        "started", "result"]
    assert events[-1].payload.outcome == Outcome.COMPLETE


@pytest.mark.slow
def test_an_actor_whose_start_outlasts_ray_start_seconds_is_let_go(
        monkeypatch: pytest.MonkeyPatch) -> None:
    events, _ = started_slowly(monkeypatch, slow=60.0, patience=2.0, start_seconds=3)
    (died,) = [e for e in events if e.kind == "died"]
    assert died.payload[1] == "not started after 3 s on its node (ray.start_seconds)"
    assert not [e for e in events if e.kind in ("started", "result")]
