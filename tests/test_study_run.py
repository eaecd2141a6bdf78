"""`kraby-study run`, `train` and `list` end to end on a SQLite store."""

from __future__ import annotations

import shutil
import signal
import tempfile
from pathlib import Path

import pytest
import yaml
from conftest import (
    FAST_HEARTBEAT,
    TINY,
    children,
    file_digest,
    has_study,
    kill_when,
    load,
    run_cli,
    spawn_cli,
    sqlite_url,
    tiny_with_steps,
    write_study_file,
)
from optuna.trial import TrialState

from kraby_study.records.stored import is_interrupted, latest_by_key, sweep_key

CONF = Path(__file__).resolve().parents[1] / "conf"


def _complete_keys(db: Path | str, name: str) -> list[str]:
    trials = load(db, name).get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    return sorted(t.user_attrs["key"] for t in trials)


def _planned_keys(study: str, seeds: int) -> list[str]:
    """The keys of a packaged study's runs, from its study file."""
    values = yaml.safe_load((CONF / "study" / f"{study}.yaml").read_text())["study"]["values"]
    return sorted(sweep_key(v, s) for v in range(len(values)) for s in range(seeds))


def test_smoke_study_end_to_end(store_url: str, capsys: pytest.CaptureFixture[str]) -> None:
    db = store_url
    assert run_cli("run", "study=clip_range", "workers=2", f"storage={db}", *TINY) == 0
    study = load(db, "clip_range")
    trials = study.get_trials(deepcopy=False)
    assert len(trials) == 8 and all(t.state == TrialState.COMPLETE for t in trials)
    assert sorted({t.params["clip_range"] for t in trials}) == [0.1, 0.2, 0.3, 0.4]
    assert sorted(t.user_attrs["seed"] for t in trials) == [0, 0, 0, 0, 1, 1, 1, 1]
    for trial in trials:
        attrs = trial.user_attrs
        assert attrs["settings"]["ppo"]["clip_range"] == trial.params["clip_range"]
        assert attrs["env_steps"] == 512 and attrs["wall_time"] > 0
        assert attrs["final_score"] == trial.value < 0
        assert trial.datetime_start is not None and trial.datetime_complete is not None
    out = capsys.readouterr().out
    assert "clip_range: 8/8 complete, 0 failed" in out
    # The curves are queryable, binned every 64 steps: episodes of 32 steps x 4 legs end
    # every 128 steps, so every other bin holds the 4 episodes that ended in it.
    from kraby_study.store.store import opened
    with opened(db, create=False, writer=False) as store:
        points = store.load("clip_range").curves().to_dict("records")
    by_trial: dict[int, list[int]] = {}
    for p in points:
        by_trial.setdefault(p["number"], []).append(p["step"])
    assert len(by_trial) == 8
    assert all(sorted(steps) == [128, 256, 384, 512] for steps in by_trial.values())
    assert all(p["episodes"] == 4 for p in points)
    # Rerunning changes nothing: complete trials are never rerun.
    digest_trials = [(t.number, t.value) for t in trials]
    assert run_cli("run", "study=clip_range", "workers=2", "--storage", db, *TINY) == 0
    assert "0 to run" in capsys.readouterr().out
    assert [(t.number, t.value) for t in load(db, "clip_range").get_trials()] == digest_trials
    # list shows the study's progress and best value.
    assert run_cli("list", "--storage", db) == 0
    listing = capsys.readouterr().out
    assert "clip_range" in listing and "8/8" in listing and "clip_range=" in listing


def test_more_seeds_extend_a_study(workdir: Path) -> None:
    assert run_cli("run", "study=clip_range", "budget.seeds=1", "workers=1", *TINY) == 0
    db = workdir / "studies" / "kraby.db"
    assert len(_complete_keys(db, "clip_range")) == 4
    assert run_cli("run", "study=clip_range", "budget.seeds=2", "workers=1", *TINY) == 0
    assert len(_complete_keys(db, "clip_range")) == 8


@pytest.fixture(scope="module")
def one_seed_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store holding a finished one-seed clip_range study (built once for the module)."""
    root = tmp_path_factory.mktemp("store")
    db = root / "kraby.db"
    assert run_cli("run", "study=clip_range", "budget.seeds=1", "workers=1",
                   f"storage={sqlite_url(db)}", *TINY) == 0
    return db


@pytest.fixture
def stored(workdir: Path, one_seed_store: Path) -> Path:
    """A copy of the one-seed store at the default place of the working directory."""
    db = workdir / "studies" / "kraby.db"
    db.parent.mkdir()
    shutil.copy(one_seed_store, db)
    return db


def test_changed_definition_is_refused_and_store_untouched(
        stored: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = stored
    before = file_digest(db)
    capsys.readouterr()
    assert run_cli("run", "study=clip_range", "budget.seeds=1", "workers=1", *TINY,
                   "ppo.gamma=0.5") == 2
    err = capsys.readouterr().err
    assert "defined differently" in err and "gamma" in err and err.count("\n") == 1
    assert file_digest(db) == before


@pytest.mark.parametrize("bad", [
    ["ppo.ent_coeff=0.1"], ["ppo.n_steps=abc"], ["ppo.learning_rate=-1"], ["ppo.gamma=1.5"],
    ["ppo.batch_size=100"], ["workers=0"], ["shards=0"], ["study=unknown"],
    ["budget=nope"],
])
def test_bad_input_exits_non_zero_and_leaves_the_store_byte_for_byte(
        stored: Path, capsys: pytest.CaptureFixture[str], bad: list[str]) -> None:
    db = stored
    before = file_digest(db)
    capsys.readouterr()
    args = [a for a in ["study=clip_range", *TINY] if a.split("=")[0] not in
            {b.split("=")[0] for b in bad}]
    assert run_cli("run", *args, *bad) == 2
    err = capsys.readouterr().err
    assert err.startswith("kraby-study: error: ") and err.count("\n") == 1
    assert file_digest(db) == before


def test_bad_input_creates_no_store(workdir: Path) -> None:
    assert run_cli("run", "study=clip_range", "workers=0", *TINY) == 2
    assert not (workdir / "studies").exists()


def test_diverging_trial_is_recorded_and_the_study_goes_on(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_study_file(workdir, "lr_blowup", "ppo.learning_rate", "[0.001, 1.0e+12]")
    assert run_cli("run", "study=lr_blowup", "budget.seeds=1", "workers=1", *TINY) == 0
    study = load(workdir / "studies" / "kraby.db", "lr_blowup")
    by_lr = {t.params["learning_rate"]: t for t in study.get_trials()}
    assert by_lr[0.001].state == TrialState.COMPLETE
    assert by_lr[1e12].state == TrialState.FAIL
    assert by_lr[1e12].user_attrs["failure"].startswith("diverged")
    assert "1/2 complete, 1 failed" in capsys.readouterr().out


def test_train_stores_one_run_and_saves_its_model(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = [a for a in TINY if not a.startswith("save_models")]
    assert run_cli("train", "seed=3", *args) == 0
    out = capsys.readouterr().out
    assert "final score" in out
    model = Path(out.split("model: ")[1].strip())
    assert model.is_file() and model.suffix == ".zip"
    from stable_baselines3 import PPO
    assert PPO.load(model, device="cpu").policy is not None


def test_training_leaves_no_folder_per_run_in_the_temporary_folder(
        workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # stable-baselines3's default logger makes an empty SB3-<time> folder per model there.
    # (torch keeps one cache folder per user there, shared by every run: that one may stay.)
    tmp = workdir / "tmp"
    tmp.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp))
    monkeypatch.setattr(tempfile, "tempdir", None)
    assert run_cli("run", "study=clip_range", "study.values=[0.2]", "budget.seeds=1", *TINY) == 0
    assert [p.name for p in tmp.iterdir() if not p.name.startswith("torchinductor_")] == []


def test_same_seed_gives_the_same_curve_with_any_number_of_shards(
        workdir: Path) -> None:
    from kraby_study.store.store import opened

    curves, scores = [], []
    for name, processes in (("a.db", 1), ("b.db", 1), ("c.db", 3)):
        url = sqlite_url(workdir / name)
        assert run_cli("train", "seed=7", f"storage={url}", f"shards={processes}",
                       *TINY) == 0
        with opened(url, create=False, writer=False) as store:
            ledger = store.load(store.study_names()[0])
            curves.append(list(ledger.curves()[["step", "mean_reward"]].itertuples(index=False,
                                                                                  name=None)))
            scores.append(ledger.trials()[0].value)
    assert curves[0] == curves[1] == curves[2] and len(curves[0]) == 4
    assert scores[0] == scores[1] == scores[2]


def test_a_second_command_on_a_busy_sqlite_store_is_refused(workdir: Path) -> None:
    from kraby_study.errors import StoreError
    from kraby_study.store.store import Store

    url = sqlite_url(workdir / "k.db")
    first = Store(url)
    try:
        with pytest.raises(StoreError, match="in use by another kraby-study command"):
            Store(url)
    finally:
        first.close()
    Store(url).close()


def _url(db: Path | str) -> str:
    return sqlite_url(db) if isinstance(db, Path) else db


def _complete_count(db: Path | str, name: str) -> int:
    return len(_complete_keys(db, name)) if has_study(_url(db), name) else 0


def _running_trials(db: Path | str, name: str) -> int:
    if not has_study(_url(db), name):
        return 0
    return len(load(db, name).get_trials(deepcopy=False, states=(TrialState.RUNNING,)))


SLOWER = tiny_with_steps(4096)


@pytest.mark.slow
def test_killing_a_worker_mid_study_loses_and_duplicates_nothing(workdir: Path,
                                                                 store_url: str) -> None:
    db = store_url
    proc = spawn_cli("run", "study=clip_range", "workers=2", f"storage={db}", *SLOWER,
                     *FAST_HEARTBEAT, cwd=workdir)
    # One worker killed while the store shows both trials running (and so both workers busy).
    kill_when(lambda: _running_trials(db, "clip_range") == 2 and len(children(proc.pid)) == 2,
              proc, victims=lambda: children(proc.pid)[:1])
    out, _ = proc.communicate(timeout=300)
    assert proc.returncode == 0, out
    assert "interrupted (worker exit code -9), rerun" in out
    trials = load(db, "clip_range").get_trials()
    assert len(trials) == 8 and all(t.state == TrialState.COMPLETE for t in trials)
    assert _complete_keys(db, "clip_range") == _planned_keys("clip_range", seeds=2)


@pytest.mark.slow
def test_resume_after_the_command_is_killed(workdir: Path, store_url: str) -> None:
    db = store_url
    args = ["run", "study=clip_range", "workers=2", f"storage={db}", *SLOWER, *FAST_HEARTBEAT]
    proc = spawn_cli(*args, cwd=workdir)
    kill_when(lambda: _complete_count(db, "clip_range") >= 2
              and _running_trials(db, "clip_range") >= 1, proc)
    done_before = _complete_keys(db, "clip_range")
    assert 2 <= len(done_before) < 8
    # On a server the rerun takes the killed command's trials over once their heartbeat is
    # stale (heartbeat_grace): it waits for that itself.
    proc = spawn_cli(*args, cwd=workdir)
    out, _ = proc.communicate(timeout=300)
    assert proc.returncode == 0, out
    if db.startswith("sqlite"):  # a server's stale trials may come back only while it runs
        assert "left running by a stopped command will run again" in out
    study = load(db, "clip_range")
    assert _complete_keys(db, "clip_range") == _planned_keys("clip_range", seeds=2)
    latest = latest_by_key(study.get_trials())
    assert all(t.state == TrialState.COMPLETE for t in latest.values())
    retried = [t for t in study.get_trials() if t.state == TrialState.FAIL]
    # Interruptions, not results: given back by the command (SQLite, "interrupted: ...") or
    # failed by a server's heartbeat check (PostgreSQL, no reason).
    assert retried and all(is_interrupted(t) for t in retried)
    assert sorted(t.number for t in retried) == sorted(
        t.user_attrs["retry_of"] for t in study.get_trials() if "retry_of" in t.user_attrs)


@pytest.mark.slow
def test_ctrl_c_stops_cleanly_and_the_rerun_completes(workdir: Path) -> None:
    import subprocess
    import sys

    db = workdir / "studies" / "kraby.db"
    proc = subprocess.Popen([sys.executable, "-m", "kraby_study.cli", "run", "study=clip_range",
                             "workers=2", *SLOWER], cwd=workdir, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    # What a terminal's Ctrl-C sends: SIGINT to the whole process group.
    kill_when(lambda: _complete_count(db, "clip_range") >= 1
              and _running_trials(db, "clip_range") >= 1, proc,
              victims=lambda: [-proc.pid], signum=signal.SIGINT)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 130, out
    assert "interrupted, queued for the next run" in out
    assert _running_trials(db, "clip_range") == 0
    kept = _complete_keys(db, "clip_range")
    assert kept
    assert run_cli("run", "study=clip_range", "workers=2", *SLOWER) == 0
    final = _complete_keys(db, "clip_range")
    assert set(kept) <= set(final)
    assert final == _planned_keys("clip_range", seeds=2)


@pytest.mark.parametrize("command", ["list", "run", "train"])
def test_a_file_that_is_not_a_store_is_refused_in_one_line_and_kept(
        workdir: Path, capsys: pytest.CaptureFixture[str], command: str) -> None:
    db = workdir / "studies" / "kraby.db"
    db.parent.mkdir()
    db.write_text("not a database\n")
    args = ["study=clip_range", *TINY] if command == "run" else (TINY if command == "train"
                                                                  else [])
    assert run_cli(command, *args) == 2
    err = capsys.readouterr().err
    assert err == ("kraby-study: error: cannot open the store sqlite:///studies/kraby.db: "
                   "file is not a database\n")
    assert db.read_text() == "not a database\n"
