"""Shared helpers: tiny study settings, a CLI runner, and a look into the store."""

from __future__ import annotations

import hashlib
import math
import os
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import optuna
import pytest
import sqlalchemy as sa

from kraby_study.cli import main
from kraby_study.store.store import study_exists

# Tiny nets and budgets: a trial takes about a second.
TINY = ["budget=smoke", "budget.steps=512", "budget.curve_every=64", "ppo.n_envs=4",
        "ppo.n_steps=32", "ppo.n_epochs=2", "ppo.net_arch=[8]", "save_models=false"]

TINY_SEARCH = """\
name: tiny
sampler: random
pruner: none
seed: 3
startup_trials: 1
checkpoints: 4
objective: final_reward
trials: 3
enqueue: []
params:
  learning_rate: {path: ppo.learning_rate, type: float, low: 1.0e-4, high: 1.0e-2, log: true}
  gamma: {path: ppo.gamma, type: float, low: 0.5, high: 0.99}
"""
"""A search space of two parameters: 3 trials, random, unpruned, nothing enqueued (write it
as conf/search/tiny.yaml and run with search=tiny)."""

FAST_HEARTBEAT = ["heartbeat_interval=1", "heartbeat_grace=4"]
"""A server notices a stopped command's trials within seconds."""


def tiny_with_steps(steps: int) -> list[str]:
    """TINY with longer runs, for tests that must catch a trial while it runs."""
    return [a if not a.startswith("budget.steps") else f"budget.steps={steps}" for a in TINY]


optuna.logging.set_verbosity(optuna.logging.WARNING)


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh working directory: the default store lands in it."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def run_cli(*args: str) -> int:
    """Run the CLI in this process; returns its exit code."""
    return main(list(args))


def refused_before_work(workdir: Path, capsys: pytest.CaptureFixture[str], *args: str) -> str:
    """Run the CLI on bad input in ``workdir``: it must exit 2 with a one-line error and no
    store made. Returns the error."""
    assert run_cli(*args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert not (workdir / "studies").exists()
    return err


def spawn_cli(*args: str, cwd: Path) -> subprocess.Popen[str]:
    """Start the CLI as a separate process (for kill tests)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "kraby_study.cli", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env)


def finished_search(root: Path, name: str, space: str, *args: str) -> Path:
    """``root`` with the search space ``conf/search/<name>.yaml`` written and the CLI run there
    with ``args`` (a search that must succeed); returns ``root``."""
    (root / "conf" / "search").mkdir(parents=True)
    (root / "conf" / "search" / f"{name}.yaml").write_text(space)
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        assert run_cli(*args) == 0
    return root


def sqlite_url(path: Path) -> str:
    """The storage URL of a SQLite file."""
    return f"sqlite:///{path}"


def csv_approx(expected: object) -> object:
    """``pytest.approx`` at the precision of the report's CSV files: a float written with
    CSV_DIGITS (6) significant digits is off by up to half a unit in the last one, 5 x 10^-6
    of its value, more than approx's default 10^-6 allows."""
    from kraby_study.report.document import CSV_DIGITS

    return pytest.approx(expected, rel=10.0 ** (1 - CSV_DIGITS))


def file_digest(path: Path) -> str:
    """Hash of a file's bytes ('' when missing)."""
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.exists() else ""


def load(store: Path | str, name: str) -> optuna.Study:
    """A stored study, from a SQLite file or a database URL (tables never created)."""
    url = sqlite_url(store) if isinstance(store, Path) else store
    storage = optuna.storages.RDBStorage(url, skip_table_creation=True)
    try:
        study = optuna.load_study(study_name=name, storage=storage)
        study.get_trials()  # read while the connection is open
        return study
    finally:
        storage.engine.dispose()


SERVER = os.environ.get("KRABY_TEST_POSTGRES_URL")
"""A PostgreSQL server for the tests that need one (CI starts one: see .ci/postgres.sh)."""


@contextmanager
def fresh_database() -> Iterator[str]:
    """A new, empty database on the test server, dropped afterwards."""
    assert SERVER is not None
    name = f"kraby_{uuid.uuid4().hex[:10]}"
    admin = sa.create_engine(SERVER, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(sa.text(f"CREATE DATABASE {name}"))
    url = sa.engine.make_url(SERVER).set(database=name).render_as_string(hide_password=False)
    try:
        yield url
    finally:
        with admin.connect() as conn:
            conn.execute(sa.text("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                                 "WHERE datname = :n"), {"n": name})
            conn.execute(sa.text(f"DROP DATABASE IF EXISTS {name}"))
        admin.dispose()


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=[
    pytest.mark.postgres,
    pytest.mark.skipif(not SERVER, reason="KRABY_TEST_POSTGRES_URL is not set")])])
def store_url(request: pytest.FixtureRequest, workdir: Path) -> Iterator[str]:
    """The store of a test, once per backend: the default SQLite file of the working
    directory, then a fresh PostgreSQL database."""
    if request.param == "sqlite":
        yield sqlite_url(workdir / "studies" / "kraby.db")
    else:
        with fresh_database() as url:
            yield url


def has_study(url: str, name: str) -> bool:
    """Whether a command has created the study in the store, read without writing anything."""
    return study_exists(url, name)


def children(pid: int, workers_only: bool = True) -> list[int]:
    """Direct child processes of a process (Linux): its trial workers by default."""
    out: list[int] = []
    task = Path(f"/proc/{pid}/task")
    for thread in task.iterdir() if task.exists() else []:
        out.extend(int(c) for c in (thread / "children").read_text().split())
    if workers_only:
        out = [c for c in out if b"kraby_study.run.worker" in _cmdline(c)]
    return out


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def wait_for(predicate: Callable[[], bool], timeout: float = 180.0,
             proc: subprocess.Popen[str] | Sequence[subprocess.Popen[str]] | None = None) -> None:
    """Poll until the predicate holds; fail the test after ``timeout`` seconds, or as soon as
    one of ``proc`` (the commands being watched) has ended, with what it printed."""
    procs = [] if proc is None else [proc] if isinstance(proc, subprocess.Popen) else list(proc)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        for ended in (p for p in procs if p.poll() is not None):
            out = ended.stdout.read() if ended.stdout else ""
            for p in procs:
                p.kill()
            raise AssertionError(f"a command ended first (exit {ended.returncode}):\n{out}")
        time.sleep(0.1)
    for p in procs:
        p.kill()
    raise AssertionError("timed out")


def _signal_all(pids: Sequence[int], signum: int) -> None:
    for pid in pids:
        try:
            os.kill(pid, signum)
        except ProcessLookupError:
            pass


def kill_when(predicate: Callable[[], bool], proc: subprocess.Popen[str],
              victims: Callable[[], list[int]] | None = None, signum: int = signal.SIGKILL,
              timeout: float = 180.0) -> None:
    """Signal a command (SIGKILL by default: it and every process below it; or ``victims()``)
    at a point of its progress, once ``predicate`` (a look at the store) holds.

    Once a look finds it, a second look is taken with the command and its processes stopped
    (SIGSTOP), and the signal is sent only if that one finds it too: what the predicate read
    is then what the signal meets, no trial ending between the look and the kill however
    loaded the machine. A stopped look the writer's lock refuses (SQLite, the command stopped
    mid-commit) lets the command go on and looks again. Fails as :func:`wait_for` does, and
    at once if the command has ended by the time the point is found.
    """
    from processes import descendants

    deadline = time.monotonic() + timeout
    while True:
        wait_for(predicate, timeout=max(deadline - time.monotonic(), 0.0), proc=proc)
        if proc.poll() is not None:  # it ended after the look: the point was passed, not met
            out = proc.stdout.read() if proc.stdout else ""
            raise AssertionError(f"the command ended (exit {proc.returncode}) before it could be "
                                 f"signalled at the point looked for:\n{out}")
        group = [proc.pid, *descendants([proc.pid])]
        _signal_all(group, signal.SIGSTOP)
        try:
            try:
                ready = proc.poll() is None and predicate()
            except (sa.exc.OperationalError, optuna.exceptions.StorageInternalError):
                ready = False
            if ready:
                _signal_all(group if victims is None else victims(), signum)
                if victims is None and signum == signal.SIGKILL:
                    proc.wait()
                return
        finally:
            _signal_all(group, signal.SIGCONT)


def write_study_file(root: Path, name: str, parameter: str, values: str, extra: str = "") -> None:
    """A user's study file in ./conf/study/ of a working directory."""
    folder = root / "conf" / "study"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.yaml").write_text(
        f"# @package _global_\nstudy:\n  name: {name}\n  parameter: {parameter}\n"
        f"  values: {values}\n{extra}")


def newcombe_bounds(estimate: float, m: int, n: int, z: float = 1.959963984540054) -> tuple[
        float, float]:
    """Newcombe's (2006, method 5) interval of P(X > Y) by another route than the package's
    root search: every solution of (estimate - t)^2 = z^2 V(t) is a root of the quartic
    (estimate - t)^2 (2 - t)(1 + t) m n
        - z^2 t (1 - t) [(2 - t)(1 + t) + (N* - 1)(1 - t)(1 + t) + (N* - 1) t (2 - t)],
    N* = (m + n) / 2; the bounds are the extreme roots in [0, 1]."""
    from numpy.polynomial import Polynomial as P

    t, half = P([0.0, 1.0]), (m + n) / 2
    left = (estimate - t) ** 2 * (2 - t) * (1 + t) * (m * n)
    right = z ** 2 * t * (1 - t) * ((2 - t) * (1 + t) + (half - 1) * (1 - t) * (1 + t)
                                    + (half - 1) * t * (2 - t))
    roots = [r.real for r in (left - right).roots()
             if abs(r.imag) < 1e-9 and -1e-9 <= r.real <= 1 + 1e-9]
    return max(0.0, min(roots)), min(1.0, max(roots))


def hall_bounds(values: list[float], level: float = 0.95) -> tuple[float, float, float]:
    """Hall's (1992) skewness-corrected t interval of a mean by another route than the
    package's closed-form inverse: g(T) = T + b T^2 + (b^2 / 3) T^3 + b / 2 = v is solved for T
    as the real root of the cubic by ``numpy.roots``, with b = gamma / (3 sqrt(n)) and gamma
    ``scipy.stats.skew(bias=True)``; the bounds are mean - T(q) s / sqrt(n) and
    mean - T(-q) s / sqrt(n), q = t(0.5 + level / 2, n - 1). Returns (mean, low, high)."""
    import numpy as np
    from scipy import stats as sps

    x = np.asarray(values, dtype=float)
    n, mean, se = len(x), float(x.mean()), float(x.std(ddof=1)) / math.sqrt(len(x))
    b = float(sps.skew(x, bias=True)) / (3 * math.sqrt(n))
    q = float(sps.t.ppf(0.5 + level / 2, n - 1))

    def solve(v: float) -> float:
        roots = np.roots([b * b / 3, b, 1.0, b / 2 - v])  # leading zeros dropped when b = 0
        real = [r.real for r in roots if abs(r.imag) < 1e-7]
        assert len(real) >= 1
        return real[0] if len(real) == 1 else min(real, key=lambda r: abs(r - v))

    return mean, mean - solve(q) * se, mean - solve(-q) * se


def bootstrap_t_reference(values: list[float], level: float = 0.95,
                          resamples: int = 2000) -> tuple[float, float]:
    """The bootstrap-t interval of a mean, slowly: the package's resamples of the sorted sample
    (``stats._resample_plan``), each resample's t = (mean* - mean) / (sd* / sqrt(n)) computed
    one at a time on the raw values with ``np.std(ddof=1)`` (+-inf, or 0 on the mean, when the
    resample has one value), then the interval [mean - t_hi se, mean - t_lo se] from
    ``np.quantile`` at (1 -+ level) / 2."""
    import numpy as np

    from kraby_study.decision.intervals import BOOTSTRAP_SEED, _resample_plan

    x = np.sort(np.asarray(values, dtype=float))
    n, mean = len(x), float(np.mean(x))
    ts = []
    for row in _resample_plan(x, resamples, BOOTSTRAP_SEED):
        draw = x[row]
        if len(set(draw.tolist())) == 1:
            gap = float(draw[0]) - mean
            ts.append(0.0 if gap == 0 else math.copysign(math.inf, gap))
        else:
            ts.append((float(np.mean(draw)) - mean) / (float(np.std(draw, ddof=1)) / math.sqrt(n)))
    t_low, t_high = np.quantile(np.array(ts), [(1 - level) / 2, (1 + level) / 2])
    se = float(np.std(x, ddof=1)) / math.sqrt(n)
    return mean - float(t_high) * se, mean - float(t_low) * se
