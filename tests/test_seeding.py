"""Seeding schemes through the commands: new studies seed each leg from its own stream, studies
stored before streams existed resume with theirs, bit for bit, and confirm's test seeds stay
apart from the tuning seeds."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import TINY, file_digest, load, run_cli, sqlite_url
from optuna.trial import TrialState

DEFINITION = "kraby_definition"


def scores(db: Path, name: str) -> dict[str, float]:
    """Each complete run's final score by its key (value and seed)."""
    trials = load(db, name).get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    return {t.user_attrs["key"]: float(t.value) for t in trials}


def sweep(db: Path, *args: str) -> int:
    return run_cli("run", "study=clip_range", "workers=2", f"storage={sqlite_url(db)}",
                   "save_models=false", *TINY, *args)


@pytest.fixture(scope="module")
def offset_full(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2-seed clip_range study stored with the scheme before streams (seeding=offset)."""
    db = tmp_path_factory.mktemp("offset") / "kraby.db"
    assert sweep(db, "seeding=offset") == 0
    return db


def test_an_offset_study_is_the_study_stored_before_streams(offset_full: Path) -> None:
    # Offset stores no seeding key: a study stored before streams has this very definition
    # and fingerprint, so the commands below treat it as one of those.
    assert "seeding" not in load(offset_full, "clip_range").user_attrs[DEFINITION]


def test_an_old_scheme_study_resumes_bit_identical(
        workdir: Path, offset_full: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = workdir / "resumed.db"
    assert sweep(db, "budget.seeds=1", "seeding=offset") == 0
    # Resumed with no seeding given, seed 1 runs with the stored scheme, equal to the bit to
    # the same runs of a study run whole with it.
    capsys.readouterr()
    assert sweep(db, "budget.seeds=2", "--dry-run") == 0
    assert "seeding offset: env i of the run with seed s is seeded with s + i" in (
        capsys.readouterr().out)
    assert sweep(db, "budget.seeds=2") == 0
    assert scores(db, "clip_range") == scores(offset_full, "clip_range")
    assert "seeding" not in load(db, "clip_range").user_attrs[DEFINITION]
    # Streams asked for on it is a changed definition: refused in one line, store untouched.
    before = file_digest(db)
    capsys.readouterr()
    assert sweep(db, "budget.seeds=2", "seeding=streams") == 2
    err = capsys.readouterr().err
    assert "defined differently" in err and "seeding" in err and err.count("\n") == 1
    assert file_digest(db) == before


def test_a_new_study_seeds_by_streams_and_repeats_itself(
        workdir: Path, offset_full: Path, capsys: pytest.CaptureFixture[str]) -> None:
    first, again = workdir / "first.db", workdir / "again.db"
    assert sweep(first, "--dry-run") == 0
    streams = ("streams: env i of the run with seed s (one of its ppo.n_envs environments) "
               "draws from child i")
    assert f"seeding {streams}" in capsys.readouterr().out
    assert sweep(first) == 0 and sweep(again) == 0
    assert load(first, "clip_range").user_attrs[DEFINITION]["seeding"] == "streams"
    # A run is a function of its settings and seed: the same scores to the bit.
    new = scores(first, "clip_range")
    assert new == scores(again, "clip_range")
    # The scheme changes the episodes, so every run differs from its offset twin.
    old = scores(offset_full, "clip_range")
    assert new.keys() == old.keys() and all(new[k] != old[k] for k in new)
    # The report names the scheme.
    assert run_cli("report", f"storage={sqlite_url(first)}", "--no-policy",
                   f"out={workdir / 'reports'}") == 0
    page = (workdir / "reports" / "clip_range" / "reproducibility.md").read_text()
    assert f"Seeding: {streams}" in page


def test_an_old_confirm_study_resumes_with_its_seeds(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A confirm stored before test seeds moved to 1000 began at seed 0, under offset.
    url = sqlite_url(workdir / "confirm.db")
    args = ["confirm", "--baseline", "ppo=tuned", "--seeds", "2", "--workers", "2",
            "--storage", url, "save_models=false", *TINY]
    assert run_cli(*args, "confirm.seed=0", "seeding=offset") == 0
    definition = load(url, "confirm-ppo=tuned").user_attrs[DEFINITION]
    assert definition["seeds"] == [0, 1] and "seeding" not in definition
    capsys.readouterr()
    assert run_cli(*args) == 0
    assert "0 to run" in capsys.readouterr().out
    # A new confirm study starts at 1000 with streams.
    assert run_cli(*args, "--baseline", "ppo=start", "--dry-run") == 0
    out = capsys.readouterr().out
    assert "seeds 1000-1001 (2 seeds)" in out and "seeding streams" in out


@pytest.mark.parametrize(("bad", "message"), [
    (["seeding=sequential"], "seeding must be one of streams, offset"),
    (["seeding=1"], "seeding must be one of streams, offset"),
    (["confirm.seed=-1"], "confirm.seed must be >= 0"),
])
def test_bad_seeding_is_refused_in_one_line_before_any_store(
        workdir: Path, capsys: pytest.CaptureFixture[str], bad: list[str],
        message: str) -> None:
    db = workdir / "none.db"
    command = (["confirm", "--baseline", "ppo=tuned"] if bad[0].startswith("confirm.")
               else ["run", "study=clip_range"])
    assert run_cli(*command, f"storage={sqlite_url(db)}", *TINY, *bad) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not db.exists()
