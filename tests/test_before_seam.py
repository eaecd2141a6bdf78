"""The env seam changes no result of the leg: a sweep run by the code just before the seam
(commit 1920c9c, taken from this clone's history) and by this checkout store the same
definition and the same scores and curves, to the bit, on this machine."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import TINY, load, run_cli, sqlite_url
from optuna.trial import TrialState

BEFORE = "1920c9c"
"""main's last commit before the env seam (issue 36) was merged."""

ROOT = Path(__file__).resolve().parents[1]
ARGS = ["run", "study=clip_range", "workers=2", *TINY]


def _has_commit() -> bool:
    found = subprocess.run(["git", "-C", str(ROOT), "cat-file", "-e", f"{BEFORE}^{{commit}}"],
                           capture_output=True, check=False)
    return found.returncode == 0


def _old_checkout(root: Path) -> Path:
    """The packages of commit BEFORE under ``root/pkgs``, importable by their installed names."""
    src, pkgs = root / "src", root / "pkgs"
    src.mkdir(parents=True)
    pkgs.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", BEFORE, "kraby_study", "envs",
                              "conf"], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    for name, folder in (("kraby_study", "kraby_study"), ("kraby_envs", "envs"),
                         ("kraby_conf", "conf")):
        (pkgs / name).symlink_to(src / folder)
    return pkgs


def _runs(db: Path) -> tuple[dict, dict[str, tuple[float, object]]]:
    """The study's stored definition, and each complete run's score and curve by its key."""
    study = load(db, "clip_range")
    trials = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    return study.user_attrs["kraby_definition"], {
        t.user_attrs["key"]: (float(t.value), t.intermediate_values) for t in trials}


@pytest.mark.slow
@pytest.mark.skipif(not _has_commit(), reason=f"commit {BEFORE} is not in this clone")
def test_the_leg_stores_the_same_results_before_and_after_the_seam(workdir: Path) -> None:
    pkgs = _old_checkout(workdir / "before")
    old_db, new_db = workdir / "old.db", workdir / "new.db"
    code = ("import sys, kraby_study; print(kraby_study.__file__); "
            "from kraby_study.cli import main; sys.exit(main(sys.argv[1:]))")
    env = dict(os.environ, PYTHONPATH=str(pkgs))
    old = subprocess.run([sys.executable, "-c", code, *ARGS, f"storage={sqlite_url(old_db)}"],
                         cwd=workdir, env=env, capture_output=True, text=True, check=False)
    assert old.returncode == 0, old.stdout + old.stderr
    assert old.stdout.splitlines()[0].startswith(str(pkgs))  # the old code ran, not this one
    assert run_cli(*ARGS, f"storage={sqlite_url(new_db)}") == 0
    old_definition, old_runs = _runs(old_db)
    new_definition, new_runs = _runs(new_db)
    assert new_definition == old_definition
    assert len(new_runs) == 8 and new_runs == old_runs
