"""``list`` reads every study as light rows, without Optuna (kraby_study.store.rows): its counts
and selections must be the ones Optuna's trials give, trial state by trial state, on SQLite and
PostgreSQL; and the storage URL it reads without composing must be the composed one."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import optuna
import pytest
from conftest import run_cli, sqlite_url
from optuna.distributions import CategoricalDistribution, FloatDistribution
from optuna.trial import TrialState, create_trial
from synthetic import DIVERGED, Run, add_search, add_sweep, add_trials, define, sweep_runs

from kraby_study.answers.standing import StudyStanding, store_standings, study_standing
from kraby_study.api.answers import study_info
from kraby_study.cli import standings_table
from kraby_study.config.compose import compose_config
from kraby_study.config.schema import KrabyConfig
from kraby_study.config.storage import DEFAULT_STORAGE, plain_storage
from kraby_study.records.attributes import RAY_NODE, Placement, StudyAttrs, TrialAttrs, TrialResult
from kraby_study.records.stored import Failure, Outcome, counted, failure, outcome, search_key
from kraby_study.records.values import swept_value
from kraby_study.store.ledger import StudyLedger
from kraby_study.store.rows import has_store, reading
from kraby_study.store.store import Store, opened, study_exists

INTERRUPTED = failure(Failure.INTERRUPTED, "its command stopped")
ERRORED = failure(Failure.ERROR, "a package is missing")
EPYC = {"hostname": "vm", "cpu": "AMD EPYC", "torch": "2.13.0+cpu"}
XEON = {"hostname": "vm2", "cpu": "Intel Xeon", "torch": "2.13.0+cpu"}


def _claim(ledger: StudyLedger, key: str, values: list[Any], name: str) -> int:
    trial = ledger.claim([key], {name: values})
    assert trial is not None, key
    return trial.number


def _complete(ledger: StudyLedger, number: int, score: float, seconds: float = 30.0) -> None:
    ledger.record(number, TrialResult(outcome=Outcome.COMPLETE, final_score=score,
                                      wall_time=seconds, env_steps=1000))


def add_states_sweep(store: Store) -> None:
    """A sweep (3 values x 4 seeds) holding every state: complete, failed, pruned, waiting,
    running, requeued then rerun to the end, requeued and waiting again, failed without a
    reason (a lost owner), and an attempt superseded by a later one of its key."""
    values = [0.1, 0.2, 0.3]
    runs = [Run(value=v, seed=s, final_score=-0.1 * i - 0.01 * s, wall_time=10.0 + i + s)
            for i, v in enumerate(values) for s in range(4)]
    runs[3].outcome, runs[3].failure = Outcome.FAILED, ERRORED
    for index in (7, 10, 11):
        runs[index].outcome = Outcome.PENDING  # queued, not run
    ledger = add_sweep(store, "states", "ppo.gamma", values, runs)
    running = _claim(ledger, "v1-s3", values, "gamma")  # left running
    ledger.note_provenance(running, EPYC | {RAY_NODE: "node-a"})
    number = _claim(ledger, "v2-s2", values, "gamma")
    ledger.note_provenance(number, XEON | {RAY_NODE: "node-b"})  # on a node then lost:
    ledger.requeue(number, INTERRUPTED)  # a new attempt is queued ...
    rerun = _claim(ledger, "v2-s2", values, "gamma")
    ledger.note_provenance(rerun, EPYC | {RAY_NODE: "node-a"})
    _complete(ledger, rerun, -0.25)  # ... and completes on another node
    waits = _claim(ledger, "v2-s3", values, "gamma")
    ledger.note_provenance(waits, EPYC)  # a local worker of the host "vm"
    ledger.requeue(waits, INTERRUPTED)  # waits again
    gamma = {"gamma": CategoricalDistribution(values)}
    add_trials(store, "states", [
        create_trial(state=TrialState.PRUNED, params={"gamma": 0.1}, distributions=gamma,
                     user_attrs={"key": "v0-s4", "seed": 4}),
        # Failed with no reason: Optuna's heartbeat gave it back; pending, not failed.
        create_trial(state=TrialState.FAIL, params={"gamma": 0.2}, distributions=gamma,
                     user_attrs={"key": "v1-s4", "seed": 4}),
        # Two attempts of one key: only the later counts.
        create_trial(state=TrialState.COMPLETE, value=5.0, params={"gamma": 0.3},
                     distributions=gamma, user_attrs={"key": "v2-s4", "wall_time": 3.0}),
        create_trial(state=TrialState.FAIL, params={"gamma": 0.3}, distributions=gamma,
                     user_attrs={"key": "v2-s4", "failure": DIVERGED}),
    ])


def add_states_search(store: Store, rng: np.random.Generator) -> None:
    """A search: synthetic complete, pruned and failed trials (no keys), keyless attempts one
    replaces (retry_of), and keyed trials asked by the sampler: complete, running, requeued
    then complete, requeued and waiting."""
    add_search(store, "search", 30, rng, points=20)
    ledger = store.load("search")
    space = {"lr": FloatDistribution(1e-4, 1.0, log=True)}
    add_trials(store, "search", [
        create_trial(state=TrialState.COMPLETE, value=9.0, params={"lr": 0.1},
                     distributions=space, user_attrs={"failure": "none"}),
    ])
    replaced = len(ledger.trials()) - 1  # a great value, replaced by a later attempt
    add_trials(store, "search", [
        create_trial(state=TrialState.COMPLETE, value=-1.0, params={"lr": 0.1},
                     distributions=space, user_attrs={"retry_of": replaced}),
    ])
    for step in range(4):
        trial = ledger.ask(space)
        ledger.set_attrs(trial.number, TrialAttrs(key=search_key(trial.number), seed=0))
        if step == 0:
            _complete(ledger, trial.number, -0.05)
        elif step in (2, 3):
            ledger.requeue(trial.number, INTERRUPTED)
            if step == 2:
                _complete(ledger, ledger.ask(space).number, 0.5)
    # step 1 stays running; step 3's new attempt waits


def add_rule_sweeps(store: Store, rng: np.random.Generator) -> None:
    """Sweeps under the auc rule and the retired fastest_tied (answered by fastest_equivalent:
    curves and training times read), a confirm
    study (its values are labels, kept in their order), an integer and a string sweep."""
    for name, rule in (("auc", "auc"), ("fastest", "fastest_tied")):
        values = [0.9, 0.8, 0.95]
        ledger = add_sweep(store, name, "ppo.gamma", values,
                           sweep_runs(values, 3, 10, 1000, rng, failed=1), steps=1000,
                           curve_every=100)
        ledger.update(StudyAttrs(select=rule))
    values = [64, 8, 32]
    ledger = add_sweep(store, "confirm", "ppo.n_steps", values,
                       sweep_runs(values, 3, 5, 1000, rng))
    ledger.update(StudyAttrs(kind="confirm"))
    add_sweep(store, "n_steps", "ppo.n_steps", values, sweep_runs(values, 2, 5, 1000, rng))
    words = ["default", "with_tip"]
    add_sweep(store, "observation", "env.observation", words,
              sweep_runs(words, 2, 5, 1000, rng, failed=1))


def add_foreign(store: Store) -> None:
    """A study kraby-study did not make, minimising, and one defined with no trial yet."""
    optuna.create_study(study_name="foreign", storage=store.storage, direction="minimize")
    space = {"x": FloatDistribution(0, 1)}
    add_trials(store, "foreign", [create_trial(state=TrialState.COMPLETE, value=v,
                                               params={"x": v}, distributions=space)
                                  for v in (0.7, 0.2, 0.5)])
    define(store, "empty", "sweep", {"kind": "sweep", "parameter": "ppo.gamma",
                                     "values": [0.9, 0.99]}, 4)


def build(url: str) -> None:
    rng = np.random.default_rng(3)
    store = Store(url)
    try:
        add_states_sweep(store)
        add_states_search(store, rng)
        add_rule_sweeps(store, rng)
        add_foreign(store)
    finally:
        store.close()


def optuna_standings(url: str) -> list[StudyStanding]:
    """Every study's standing read through Optuna, as ``list`` did before it read rows."""
    with opened(url, create=False, writer=False) as store:
        return [study_standing(store.load(name)) for name in store.study_names()]


def shown(standing: StudyStanding) -> tuple[Any, ...]:
    counts = standing.tally
    return (standing.name, standing.kind, counts.counts(), counts.pending, counts.running,
            standing.selected, standing.placement)


def test_rows_give_the_standings_optunas_trials_give(store_url: str, workdir: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    build(store_url)
    expected = optuna_standings(store_url)
    got = store_standings(store_url)
    assert [shown(s) for s in got] == [shown(s) for s in expected]
    by_name = {s.name: s for s in got}
    # Every state is there, and each study selects what its rule picks.
    states = by_name["states"].tally
    # 8 complete + 1 rerun; an error + the later attempt of v2-s4, diverged (its complete one
    # is superseded); pending: running, requeued and waiting, given back by a heartbeat.
    assert (states.complete, states.failed, states.pruned, states.running) == (9, 2, 1, 1)
    assert states.diverged == 1
    assert states.pending == 3
    search = by_name["search"].tally
    assert search.running == 1 and search.pending == 2 and search.pruned > 0
    assert by_name["search"].selected.startswith("trial ")
    assert by_name["foreign"].selected.endswith("(0.2)")  # it minimises
    assert by_name["empty"].selected == "-" and by_name["empty"].tally.planned == 4
    assert "selected by auc" in by_name["auc"].selected
    assert "selected by fastest_equivalent" in by_name["fastest"].selected
    assert by_name["observation"].selected.startswith("observation=")
    # Where trials ran: two Ray nodes (one lost, its trial rerun on the other) and a host, of
    # two CPU models; every attempt counts. A study without records says nothing.
    assert by_name["states"].placement == Placement(nodes=3, cpus=("AMD EPYC", "Intel Xeon"))
    assert by_name["states"].placement.text() == "3 nodes, 2 CPU models"
    assert by_name["search"].placement.text() == "-"
    # The command prints the table of Optuna's standings, to the character.
    capsys.readouterr()
    assert run_cli("list", f"storage={store_url}") == 0
    out = capsys.readouterr().out
    retries = [line for line in (s.retry_line() for s in expected) if line]
    assert out == "".join(f"{line}\n" for line in [
        *standings_table([study_info(s) for s in expected]), *retries])
    # Only the error is offered again: a diverged run is a result of its settings.
    assert "states: 1 run(s) failed with an error; to run them again" in out
    assert "ran on" in out.splitlines()[0] and "3 nodes, 2 CPU models" in out


def test_each_counted_row_is_its_optuna_trial(store_url: str, workdir: Path) -> None:
    build(store_url)
    with opened(store_url, create=False, writer=False) as store, reading(store_url) as reader:
        for study in reader.studies():
            ledger = store.load(study.name)
            trials = counted(ledger.trials())
            rows = counted(study.trials)
            assert [t.number for t in rows] == [t.number for t in trials]
            planned = ledger.attrs.definition.get("values", [])
            name = str(ledger.attrs.definition.get("parameter", "")).split(".")[-1]
            for row, trial in zip(rows, trials, strict=True):
                assert row.state.name == trial.state.name
                assert outcome(row) == outcome(trial)
                assert row.value == trial.value
                assert {k: trial.user_attrs[k] for k in row.user_attrs} == row.user_attrs
                if name:
                    assert swept_value(row, name, planned) == swept_value(trial, name, planned)
                    assert type(swept_value(row, name, planned)) is type(
                        swept_value(trial, name, planned))


def test_a_study_of_several_objectives_selects_nothing(workdir: Path) -> None:
    """Optuna's trials have no single value there (reading it raises): no best trial."""
    url = sqlite_url(workdir / "k.db")
    study = optuna.create_study(study_name="two", storage=url,
                                directions=["maximize", "minimize"])
    study.optimize(lambda t: (t.suggest_float("x", 0, 1), 1.0), n_trials=2)
    [standing] = store_standings(url)
    assert standing.selected == "-" and standing.tally.complete == 2


def test_a_store_without_studies_and_a_missing_one(workdir: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    url = "sqlite:///studies/kraby.db"  # the default, in the working folder
    assert run_cli("list") == 2
    assert capsys.readouterr().err == "kraby-study: error: no study store at studies/kraby.db\n"
    Store(url).close()
    assert store_standings(url) == []
    assert run_cli("list") == 0
    assert capsys.readouterr().out == f"no studies in {url}\n"


KILLED_MID_WRITE = """
import os, signal, sqlite3, sys
connection = sqlite3.connect(sys.argv[1], isolation_level=None)
connection.execute("PRAGMA cache_size = 10")  # spill: the file itself is half-written
connection.execute("BEGIN IMMEDIATE")
connection.execute("DELETE FROM trial_values")
connection.execute("CREATE TABLE filler (x)")
for _ in range(20000):
    connection.execute("INSERT INTO filler VALUES (?)", ("x" * 200,))
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_store_whose_writer_was_killed_mid_write_reads_as_last_committed(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A command killed inside a write leaves a hot journal beside the SQLite file; the
    read-only readers (``list``, the resume's check) read the last committed state, where
    SQLite alone refuses them ("attempt to write a readonly database")."""
    path = workdir / "studies" / "kraby.db"
    url = sqlite_url(path)
    build(url)
    capsys.readouterr()
    assert run_cli("list", f"storage={url}") == 0
    before = capsys.readouterr().out
    killed = subprocess.run([sys.executable, "-c", KILLED_MID_WRITE, str(path)], check=False)
    assert killed.returncode == -9
    assert Path(f"{path}-journal").stat().st_size > 0  # the hot journal is there
    assert has_store(url) and study_exists(url, "states")
    assert run_cli("list", f"storage={url}") == 0
    assert capsys.readouterr().out == before
    assert [shown(s) for s in store_standings(url)] == [shown(s) for s in optuna_standings(url)]


def test_list_loads_neither_optuna_nor_hydra_nor_the_statistics_stack(workdir: Path) -> None:
    """What makes ``list`` answer in well under a second: no Optuna storage (alembic, its
    models), no Hydra composition, no pandas or scipy.stats for a final_score sweep."""
    store = Store(sqlite_url(workdir / "k.db"))
    try:
        add_states_sweep(store)
    finally:
        store.close()
    code = ("import sys; from kraby_study.cli import main; main(['list', 'storage=sqlite:///k.db']);"
            " print(','.join(m for m in ('optuna', 'alembic', 'hydra', 'pandas', 'scipy.stats')"
            " if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=workdir, capture_output=True,
                         text=True, check=True).stdout
    assert "states" in out and out.splitlines()[-1] == ""


@pytest.mark.parametrize("url", [
    "sqlite:///studies/kraby.db", "sqlite:////tmp/a/b-c_d.db", "sqlite:///x+y.db",
    "postgresql+psycopg://postgres@127.0.0.1:55432/kraby",
    "postgresql+psycopg://u:p%40ss@host:5/db", "sqlite:///true", "sqlite:///1e5"])
def test_a_plain_storage_url_is_the_composed_one(url: str, workdir: Path) -> None:
    assert plain_storage([f"storage={url}"]) == compose_config([f"storage={url}"]).storage


def test_the_default_storage_is_the_composed_and_the_schemas(workdir: Path) -> None:
    assert plain_storage([]) == DEFAULT_STORAGE == compose_config([]).storage
    assert KrabyConfig().storage == DEFAULT_STORAGE


@pytest.mark.parametrize("overrides", [
    ["budget=quick"], ["storage=sqlite:///a.db", "workers=2"], ["storage=sqlite:///a=b.db"],
    ["storage=sqlite:///a b.db"], ["storage=${oc.env:HOME}"], ["storage=sqlite:///$x.db"],
    ["storage=sqlite:///a.db", "storage=sqlite:///b.db"]])
def test_anything_but_a_plain_url_is_composed(overrides: list[str], workdir: Path) -> None:
    assert plain_storage(overrides) is None


def test_a_config_yaml_of_the_users_is_composed(workdir: Path) -> None:
    """The working folder's conf/config.yaml replaces the packaged one: it may set storage."""
    import kraby_conf

    packaged = (Path(kraby_conf.__file__).parent / "config.yaml").read_text()
    (workdir / "conf").mkdir()
    (workdir / "conf" / "config.yaml").write_text(
        packaged.replace(f"storage: {DEFAULT_STORAGE}", "storage: sqlite:///mine.db"))
    assert plain_storage([]) is None
    assert compose_config([]).storage == "sqlite:///mine.db"


def test_a_config_group_file_of_the_users_cannot_set_the_storage(workdir: Path) -> None:
    """The packaged config.yaml composes itself last (``_self_``): a group file that sets
    storage, even in the global package, is overridden, so list need not compose for it."""
    (workdir / "conf" / "ppo").mkdir(parents=True)
    (workdir / "conf" / "ppo" / "start.yaml").write_text(
        "# @package _global_\nstorage: sqlite:///mine.db\n")
    assert plain_storage([]) == compose_config([]).storage == DEFAULT_STORAGE
