"""Shared helpers: tiny study settings, a CLI runner, and a look into the store."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import optuna
import pytest
import sqlalchemy as sa

from kraby_study.cli import main
from kraby_study.config import sqlite_path

# Tiny nets and budgets: a trial takes about a second.
TINY = ["budget=smoke", "budget.steps=512", "budget.curve_every=64", "ppo.n_envs=4",
        "ppo.n_steps=32", "ppo.n_epochs=2", "ppo.net_arch=[8]", "save_models=false"]

optuna.logging.set_verbosity(optuna.logging.WARNING)


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh working directory: the default store lands in it."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def run_cli(*args: str) -> int:
    """Run the CLI in this process; returns its exit code."""
    return main(list(args))


def spawn_cli(*args: str, cwd: Path) -> subprocess.Popen[str]:
    """Start the CLI as a separate process (for kill tests)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "kraby_study.cli", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env)


def sqlite_url(path: Path) -> str:
    """The storage URL of a SQLite file."""
    return f"sqlite:///{path}"


def file_digest(path: Path) -> str:
    """Hash of a file's bytes ('' when missing)."""
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.exists() else ""


def load(path: Path, name: str) -> optuna.Study:
    """A stored study."""
    return optuna.load_study(study_name=name, storage=sqlite_url(path))


def has_study(url: str, name: str) -> bool:
    """Whether a command has created the study in the store, read without writing anything.

    Loading a study through Optuna creates its tables when they are missing: polling a store
    that a command is still creating would race that command's own creation of them. A SQLite
    file is opened read-only, and any error there (no file or table yet) reads as not created.
    """
    path = sqlite_path(url)
    if path is not None:
        if not path.exists():
            return False
        url = f"sqlite:///file:{path}?mode=ro&uri=true"
    engine = sa.create_engine(url, poolclass=sa.pool.NullPool)
    try:
        with engine.connect() as conn:
            return sa.inspect(conn).has_table("studies") and conn.execute(
                sa.text("SELECT 1 FROM studies WHERE study_name = :n"), {"n": name}
            ).first() is not None
    except sa.exc.DBAPIError:
        if path is None:
            raise
        return False
    finally:
        engine.dispose()


def children(pid: int, workers_only: bool = True) -> list[int]:
    """Direct child processes of a process (Linux): its trial workers by default."""
    out: list[int] = []
    task = Path(f"/proc/{pid}/task")
    for thread in task.iterdir() if task.exists() else []:
        out.extend(int(c) for c in (thread / "children").read_text().split())
    if workers_only:
        out = [c for c in out if b"kraby_study.worker" in _cmdline(c)]
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


def write_study_file(root: Path, name: str, parameter: str, values: str, extra: str = "") -> None:
    """A user's study file in ./conf/study/ of a working directory."""
    folder = root / "conf" / "study"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.yaml").write_text(
        f"# @package _global_\nstudy:\n  name: {name}\n  parameter: {parameter}\n"
        f"  values: {values}\n{extra}")
