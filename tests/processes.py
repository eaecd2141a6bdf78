"""The processes of a Ray cluster on this machine, read from /proc (a fixture of the Ray tests
and of benchmarks/bench_ray_fault.py, not part of the package)."""

from __future__ import annotations

from pathlib import Path


def cmdline(pid: int) -> bytes:
    """A process's command line; empty once it is gone."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def descendants(pids: list[int]) -> list[int]:
    """The processes below these (Ray's agents and workers are children of a raylet)."""
    parents: dict[int, list[int]] = {}
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            try:
                ppid = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            parents.setdefault(ppid, []).append(int(proc.name))
    out, todo = [], list(pids)
    while todo:
        for child in parents.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out
