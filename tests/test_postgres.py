"""Several commands on one PostgreSQL study; a killed one's trial comes back; a lost database.

These need a server: set KRABY_TEST_POSTGRES_URL (CI starts one; see .ci/postgres.sh).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import optuna
import pytest
import sqlalchemy as sa
from conftest import (
    FAST_HEARTBEAT,
    SERVER,
    TINY,
    children,
    fresh_database,
    has_study,
    kill_when,
    run_cli,
    spawn_cli,
    tiny_with_steps,
)
from optuna.trial import TrialState

from kraby_study.errors import DatabaseLost
from kraby_study.records.stored import counted, latest_by_key
from kraby_study.run.runner import Retrying

pytestmark = [pytest.mark.postgres,
              pytest.mark.skipif(not SERVER, reason="KRABY_TEST_POSTGRES_URL is not set")]

LONGER = tiny_with_steps(4096)
SPACE = """\
name: pgsearch
sampler: tpe
pruner: none
startup_trials: 2
checkpoints: 4
params:
  learning_rate: {path: ppo.learning_rate, type: float, low: 1.0e-4, high: 1.0e-2, log: true}
  gamma: {path: ppo.gamma, type: float, low: 0.5, high: 0.99}
"""


@pytest.fixture
def pg_url() -> Iterator[str]:
    with fresh_database() as url:
        yield url


def _trials(url: str, name: str) -> list[optuna.trial.FrozenTrial]:
    """The study's trials, once a command has created it (read without creating tables)."""
    if not has_study(url, name):
        return []
    storage = optuna.storages.RDBStorage(url, skip_table_creation=True)
    try:
        return optuna.load_study(study_name=name, storage=storage).get_trials(deepcopy=False)
    finally:
        storage.engine.dispose()


def superseded(trials: list[optuna.trial.FrozenTrial]) -> set[int]:
    """Numbers of the attempts that do not count: a later attempt replaced them."""
    return {t.number for t in trials} - {t.number for t in counted(trials)}


def _kill_tree(proc) -> None:  # type: ignore[no-untyped-def]
    for pid in [proc.pid, *children(proc.pid, workers_only=False)]:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    proc.wait()


def _three_commands_one_killed(args: list[str], cwd: Path, url: str, name: str) -> list[str]:
    procs = [spawn_cli(*args, cwd=cwd) for _ in range(3)]
    # Killed while the store shows a trial of each command running (one worker each).
    kill_when(lambda: sum(t.state == TrialState.RUNNING for t in _trials(url, name)) >= 3,
              procs[0])
    outputs = []
    for proc in procs[1:]:
        out, _ = proc.communicate(timeout=600)
        assert proc.returncode == 0, out
        outputs.append(out)
    return outputs


@pytest.mark.slow
def test_three_commands_share_one_sweep_and_a_killed_trial_runs_again(
        workdir: Path, pg_url: str) -> None:
    args = ["run", "study=clip_range", "workers=1", f"storage={pg_url}", *LONGER,
            *FAST_HEARTBEAT]
    _three_commands_one_killed(args, workdir, pg_url, "clip_range")
    trials = _trials(pg_url, "clip_range")
    complete = sorted(t.user_attrs["key"] for t in trials if t.state == TrialState.COMPLETE)
    assert complete == sorted(f"v{v}-s{s}" for v in range(4) for s in range(2))
    latest = latest_by_key(trials)
    assert all(t.state == TrialState.COMPLETE for t in latest.values())
    failed = [t for t in trials if t.state == TrialState.FAIL]
    assert len(failed) == 1, "exactly the killed command's trial failed"
    assert superseded(trials) == {failed[0].number}
    assert not [t for t in trials if t.state in (TrialState.RUNNING, TrialState.WAITING)]


@pytest.mark.slow
def test_three_commands_share_one_search_and_respect_its_total(
        workdir: Path, pg_url: str) -> None:
    (workdir / "conf" / "search").mkdir(parents=True)
    (workdir / "conf" / "search" / "pg.yaml").write_text(SPACE)
    args = ["optuna", "--trials", "6", "search=pg", "--workers", "1", f"--storage={pg_url}",
            *LONGER, "budget.seeds=1", *FAST_HEARTBEAT]
    _three_commands_one_killed(args, workdir, pg_url, "pgsearch")
    trials = _trials(pg_url, "pgsearch")
    replaced = superseded(trials)
    counted = [t for t in trials if t.number not in replaced]
    assert len(counted) == 6
    assert all(t.state == TrialState.COMPLETE for t in counted)
    failed = [t for t in trials if t.state == TrialState.FAIL]
    assert len(failed) == 1 and replaced == {failed[0].number}
    retry = next(t for t in trials if t.user_attrs.get("retry_of") == failed[0].number)
    assert retry.params == failed[0].params


def test_a_sweep_on_postgresql_runs_and_lists(workdir: Path, pg_url: str,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("run", "study=clip_range", "budget.seeds=1", "workers=2",
                   f"storage={pg_url}", *TINY) == 0
    trials = _trials(pg_url, "clip_range")
    assert len(trials) == 4 and all(t.state == TrialState.COMPLETE for t in trials)
    capsys.readouterr()
    assert run_cli("list", f"storage={pg_url}") == 0
    assert "4/4" in capsys.readouterr().out


OPEN_STUDY = """\
import sys
from kraby_study.records.attributes import StudyAttrs
from kraby_study.store.store import Store
store = Store(sys.argv[1])
store.define("shared", StudyAttrs(kind="sweep", definition={"values": [1, 2]},
                                  fingerprint="fingerprint-1"))
store.close()
"""


def test_commands_starting_at_once_on_an_empty_database_all_open_it() -> None:
    # Without a lock, concurrent table creation fails on PostgreSQL with a duplicate type.
    for _ in range(3):
        with fresh_database() as url:
            procs = [subprocess.Popen([sys.executable, "-c", OPEN_STUDY, url], text=True,
                                      stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
                     for _ in range(3)]
            outputs = [(p.communicate(timeout=120)[0], p.returncode) for p in procs]
            assert [code for _, code in outputs] == [0, 0, 0], outputs
            studies = optuna.storages.RDBStorage(url, skip_table_creation=True)
            assert [s.study_name for s in studies.get_all_studies()] == ["shared"]
            studies.engine.dispose()


TAKE_OPENING = """\
import sys
from kraby_study.records.attributes import StudyAttrs
from kraby_study.run.search_source import take_opening
from kraby_study.store.store import Store
store = Store(sys.argv[1])
print(take_opening(store.define("joined", StudyAttrs(kind="search"))))
store.close()
"""


def test_commands_joining_a_search_at_once_take_different_openings() -> None:
    # Each opening seeds its own sampler (run.sampling.sampler_seed): two commands that saw
    # the same trial count at once drew the same random trials before openings were counted.
    with fresh_database() as url:
        procs = [subprocess.Popen([sys.executable, "-c", TAKE_OPENING, url], text=True,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
                 for _ in range(4)]
        outputs = [p.communicate(timeout=120)[0] for p in procs]
        assert sorted(int(out.strip().splitlines()[-1]) for out in outputs) == [0, 1, 2, 3], \
            outputs


def test_an_unreachable_server_is_one_line_and_non_zero(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = "postgresql+psycopg://nobody@127.0.0.1:9/nothing"
    assert run_cli("run", "study=clip_range", f"storage={url}", *TINY) == 2
    err = capsys.readouterr().err
    assert err.startswith("kraby-study: error: cannot open the store") and err.count("\n") == 1


class _Flaky:
    def __init__(self, failures: int) -> None:
        self.failures = failures
        self.calls = 0

    def next_trial(self) -> str:
        self.calls += 1
        if self.calls <= self.failures:
            raise sa.exc.OperationalError("SELECT 1", {}, Exception("server closed the "
                                                                    "connection"))
        return "claimed"


def test_a_lost_database_is_retried_then_given_up(capsys: pytest.CaptureFixture[str]) -> None:
    flaky = _Flaky(failures=2)
    assert Retrying(flaky, patience=30, stream=os.sys.stdout).next_trial() == "claimed"
    assert flaky.calls == 3
    assert "retrying" in capsys.readouterr().out
    with pytest.raises(DatabaseLost, match="lost the database for 1 s"):
        Retrying(_Flaky(failures=10**6), patience=1, stream=os.sys.stdout).next_trial()


def test_a_trial_taken_but_never_beaten_is_requeued_after_the_grace() -> None:
    """A command killed between taking a trial and its first heartbeat leaves it running with
    no heartbeat, which Optuna's stale check skips: past the grace it is requeued too."""
    from datetime import datetime, timedelta

    from kraby_study.records.attributes import StudyAttrs, TrialAttrs
    from kraby_study.store.store import opened

    with fresh_database() as url, opened(url, heartbeat_interval=1, heartbeat_grace=4) as store:
        ledger = store.define("orphan", StudyAttrs(kind="sweep", definition={"x": 1},
                                                   fingerprint="f"))
        ledger.queue({}, TrialAttrs(key="v0-s0"))
        storage = ledger._storage
        waiting = ledger.trials(TrialState.WAITING)[0]
        trial_id = storage.get_trial_id_from_study_id_trial_number(ledger._study_id,
                                                                   waiting.number)
        # Taken (running) without a heartbeat, as the killed command left it.
        assert storage.set_trial_state_values(trial_id, TrialState.RUNNING)
        assert ledger.requeue_orphans() == 0  # within the grace: its owner may be alive
        from optuna.storages._rdb import models
        session = storage.scoped_session()
        row = session.query(models.TrialModel).filter_by(trial_id=trial_id).one()
        row.datetime_start = datetime.now() - timedelta(seconds=10)
        session.commit()
        session.close()
        assert ledger.requeue_orphans() == 1
        states = [t.state for t in ledger.trials()]
        assert states == [TrialState.FAIL, TrialState.WAITING]
        assert ledger.trials(TrialState.WAITING)[0].user_attrs["key"] == "v0-s0"
