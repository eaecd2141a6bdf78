"""What made a trial: the machine that trained it and the command that ran it.

Two halves, gathered where they are true.
[`machine_facts`][kraby_study.run.provenance.machine_facts] runs in the worker (a local worker
process or a Ray actor), so a trial trained on another machine carries that machine's hostname, CPU
and package versions. [`command_facts`][kraby_study.run.provenance.command_facts] runs in the
command that writes the store: its command line (passwords hidden) and the git state of the folder
it ran in. The store keeps each distinct record once per study
([`note_provenance`][kraby_study.store.ledger.StudyLedger.note_provenance]).
"""

from __future__ import annotations

import json
import os
import platform
import re
import shlex
import socket
import subprocess
import sys
from collections.abc import Mapping, Sequence
from functools import cache
from importlib import metadata
from pathlib import Path

ENV_FIELDS = ("env_id", "env_package", "env_version")
"""What a Gymnasium env's trials also store: its id and the package (and version) that
registers it; the leg's trials store none (it is part of kraby-study)."""
PACKAGES = ("stable-baselines3", "torch", "pybullet", "gymnasium", "optuna", "numpy")
"""The packages whose versions decide a trial's numbers, stored with every trial."""

_USERINFO = re.compile(r"(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*://)(?P<user>[^:@/\s]*):[^@/\s]*@")
_command: list[str] | None = None


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not installed"


def cpu_model() -> str:
    """The CPU's model name (Linux: /proc/cpuinfo), else what the platform says."""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def _cpu_capability() -> str:
    """The instruction set torch's own kernels use here (AVX512, AVX2, DEFAULT, ...): it
    decides the order of their sums, so another one gives other numbers for the same seed."""
    try:
        import torch

        return str(torch.backends.cpu.get_cpu_capability())
    except Exception:  # noqa: BLE001 - an older or odd torch: the field says so
        return "unknown"


@cache
def machine_facts() -> dict[str, str]:
    """The machine and software a trial trains with, as text (gathered once per process)."""
    facts = {
        "kraby_study": _version("kraby-study"),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu": cpu_model(),
        "cpu_capability": _cpu_capability(),
        "cores": str(os.cpu_count() or 0),
        "hostname": socket.gethostname(),
    }
    facts.update({package: _version(package) for package in PACKAGES})
    return facts


def trial_facts(env: Mapping[str, object]) -> dict[str, str]:
    """[`machine_facts`][kraby_study.run.provenance.machine_facts], and the env's own facts
    ([`ENV_FIELDS`][kraby_study.run.provenance.ENV_FIELDS]) for a Gymnasium env: what a worker
    stores when a trial starts."""
    return {**machine_facts(), **_env_facts(json.dumps(dict(env), sort_keys=True, default=str))}


@cache
def _env_facts(env_json: str) -> dict[str, str]:
    from kraby_study.env import adapter_for

    env = json.loads(env_json)
    return adapter_for(env).describe(env)


def hide_passwords(text: str) -> str:
    """``text`` with the password of every ``scheme://user:password@`` in it replaced by ***
    (storage URLs, Ray client addresses), as the report shows a storage URL."""
    return _USERINFO.sub(lambda m: f"{m['scheme']}{m['user']}:***@", text)


def note_command(argv: Sequence[str]) -> None:
    """Remember this process's command line (the CLI calls it with its arguments)."""
    global _command
    _command = ["kraby-study", *argv]
    command_facts.cache_clear()


def _git(folder: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(folder), *args], capture_output=True, text=True,
                              timeout=10, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def git_state(folder: Path) -> dict[str, str]:
    """The commit checked out in ``folder`` and whether tracked files had uncommitted changes;
    "not a git checkout" when it is none (or git is missing)."""
    commit = _git(folder, "rev-parse", "HEAD")
    if commit is None:
        return {"git_commit": "not a git checkout", "git_dirty": "unknown"}
    changes = _git(folder, "status", "--porcelain", "--untracked-files=no")
    dirty = "unknown" if changes is None else ("yes" if changes else "no")
    return {"git_commit": commit, "git_dirty": dirty}


@cache
def command_facts() -> dict[str, str]:
    """The command writing the store: its command line, passwords hidden, and the git state
    of the folder it runs in (gathered once per command)."""
    argv = _command if _command is not None else ["kraby-study", *sys.argv[1:]]
    facts = {"command": hide_passwords(shlex.join(argv)), "folder": str(Path.cwd())}
    facts.update(git_state(Path.cwd()))
    return facts
