"""Every trial says what made it: machine, versions, code, command; reproducibility.md reads it."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import optuna
import pytest
import sqlalchemy as sa
from conftest import SERVER, TINY, fresh_database, load, run_cli, sqlite_url

from kraby_study.records.attributes import PROVENANCE_PREFIX
from kraby_study.run.provenance import PACKAGES, git_state, hide_passwords
from kraby_study.store.store import opened

SWEEP = ["run", "study=gamma", *TINY, "study.values=[0.8,0.99]", "workers=2"]


def records(study: optuna.Study) -> dict[str, dict[str, str]]:
    return {k[len(PROVENANCE_PREFIX):]: v for k, v in study.user_attrs.items()
            if k.startswith(PROVENANCE_PREFIX)}


def provenance_of(study: optuna.Study) -> list[dict[str, str]]:
    """Each trial's provenance record, in trial order."""
    stored = records(study)
    return [stored[t.user_attrs["provenance"]] for t in study.trials]


def git(folder: Path, *args: str) -> None:
    subprocess.run(["git", "-C", str(folder), "-c", "user.email=t@t", "-c", "user.name=t",
                    *args], check=True, capture_output=True)


@pytest.fixture
def checkout(workdir: Path) -> Path:
    """The working folder as a git checkout with one commit of a tracked file."""
    git(workdir, "init", "-q")
    (workdir / "notes.txt").write_text("one\n")
    git(workdir, "add", "notes.txt")
    git(workdir, "commit", "-qm", "first")
    return workdir


@pytest.mark.parametrize("text,shown", [
    ("--storage=postgresql+psycopg://kraby:s3cret@db:5432/k",
     "--storage=postgresql+psycopg://kraby:***@db:5432/k"),
    ("storage=postgresql://u:p@h/d workers=2", "storage=postgresql://u:***@h/d workers=2"),
    ("ray.address=ray://admin:pw@head:10001", "ray.address=ray://admin:***@head:10001"),
    ("storage=postgresql://u@h/d", "storage=postgresql://u@h/d"),
    ("study=gamma", "study=gamma"),
])
def test_passwords_in_urls_are_hidden(text: str, shown: str) -> None:
    assert hide_passwords(text) == shown


def test_a_sweeps_trials_store_the_machine_the_code_and_the_command(checkout: Path) -> None:
    assert run_cli(*SWEEP) == 0
    study = load(checkout / "studies" / "kraby.db", "gamma")
    made = provenance_of(study)
    assert len(made) == 4 and len(records(study)) == 1  # one record, referenced four times
    record = made[0]
    assert record["hostname"] == socket.gethostname()
    for package in PACKAGES:
        assert record[package] == metadata.version(package)
    head = subprocess.run(["git", "-C", str(checkout), "rev-parse", "HEAD"],
                          capture_output=True, text=True, check=True).stdout.strip()
    assert record["git_commit"] == head and record["git_dirty"] == "no"
    assert record["command"].startswith("kraby-study run study=gamma")
    assert run_cli("report", "--no-policy") == 0
    page = (checkout / "reports" / "gamma" / "reproducibility.md").read_text()
    assert "Tuning seeds (the seeds this study's runs trained): 0-1 (2 seeds)" in page
    assert "Warning" not in page and f"| torch | {metadata.version('torch')} |" in page
    assert "Runs that trained: 4; env steps trained in all: 2,048." in page
    assert "CPU seconds in all" in page
    assert "[reproducibility.md](gamma/reproducibility.md)" in (
        checkout / "reports" / "index.md").read_text()


def test_a_dirty_checkout_is_flagged(checkout: Path) -> None:
    (checkout / "notes.txt").write_text("changed\n")
    assert git_state(checkout)["git_dirty"] == "yes"
    assert run_cli(*SWEEP) == 0
    assert {r["git_dirty"] for r in provenance_of(load(checkout / "studies" / "kraby.db",
                                                         "gamma"))} == {"yes"}
    assert run_cli("report", "--no-policy") == 0
    page = (checkout / "reports" / "gamma" / "reproducibility.md").read_text()
    assert "Warning: 4 trials ran from a git checkout with uncommitted changes" in page


def test_outside_a_checkout_the_code_version_says_so(tmp_path: Path) -> None:
    assert git_state(tmp_path) == {"git_commit": "not a git checkout", "git_dirty": "unknown"}


def test_a_study_trained_with_two_torch_versions_is_warned(workdir: Path) -> None:
    assert run_cli(*SWEEP) == 0
    url = sqlite_url(workdir / "studies" / "kraby.db")
    storage = optuna.storages.RDBStorage(url, skip_table_creation=True)
    study = optuna.load_study(study_name="gamma", storage=storage)
    [(key, record)] = records(study).items()
    other = dict(record, torch="2.12.0", hostname="node-b", cpu="Intel Xeon (AVX-512)",
                 cpu_capability="DEFAULT")
    study.set_user_attr(PROVENANCE_PREFIX + "elsewhere", other)
    # As if a second machine had trained one of the trials (finished trials are read-only to
    # Optuna, so its attribute is rewritten in its table).
    with storage.engine.begin() as conn:
        conn.execute(sa.text("UPDATE trial_user_attributes SET value_json = :v WHERE "
                             "key = 'provenance' AND trial_id = :t"),
                     {"v": json.dumps("elsewhere"), "t": study.trials[0]._trial_id})
    storage.engine.dispose()
    assert run_cli("report", "--no-policy") == 0
    page = (workdir / "reports" / "gamma" / "reproducibility.md").read_text()
    here = metadata.version("torch")
    assert f"Warning: trials differ in torch: {here} (3 trials), 2.12.0 (1 trial)." in page
    assert f"| hostname | {socket.gethostname()} (3 trials), node-b (1 trial) |" in page
    assert "differ in hostname" not in page  # machines may differ; their software may not
    # Two CPU models: the page says what that does to the seeds' numbers.
    here_cpu = record["cpu"]
    assert (f"Warning: trials differ in cpu: {here_cpu} (3 trials), Intel Xeon (AVX-512) (1 "
            "trial); the same settings and seed give the same numbers bit for bit only on one "
            "CPU model with the same software") in page
    assert "its trials (every attempt, a lost node's too; a Ray node by its node id, else a " \
        "host by its name): 2. CPU models: 2 (" in page
    assert "ray_node" not in page  # no trial ran on Ray
    assert (f"Warning: trials differ in cpu_capability: {record['cpu_capability']} (3 trials), "
            "DEFAULT (1 trial); torch's kernels then sum in another order") in page


SPACE = """\
name: small
sampler: random
pruner: none
seed: 0
params:
  gamma: {path: ppo.gamma, type: float, low: 0.5, high: 0.99}
"""


def test_a_search_stores_provenance_and_its_space(workdir: Path) -> None:
    (workdir / "conf" / "search").mkdir(parents=True)
    (workdir / "conf" / "search" / "small.yaml").write_text(SPACE)
    assert run_cli("optuna", "--trials", "2", "--workers", "2", "search=small", *TINY) == 0
    study = load(workdir / "studies" / "kraby.db", "small")
    assert all(r["hostname"] == socket.gethostname() for r in provenance_of(study))
    assert run_cli("report", "--no-policy") == 0
    page = (workdir / "reports" / "small" / "reproducibility.md").read_text()
    assert "Search space:" in page and "| gamma | path=ppo.gamma type=float low=0.5" in page
    assert "Tuning seeds (the seeds this study's runs trained): 0-1 (2 seeds)" in page


@pytest.mark.postgres
@pytest.mark.skipif(not SERVER, reason="KRABY_TEST_POSTGRES_URL is not set")
def test_a_password_on_the_command_line_is_nowhere_in_the_store_or_the_report(
        workdir: Path) -> None:
    secret = "pw-4e1f9b"
    with fresh_database() as url:
        # The test server trusts loopback, so any password is accepted and never checked.
        scheme, rest = url.split("://", 1)
        user, host = rest.split("@", 1)
        with_password = f"{scheme}://{user}:{secret}@{host}"
        assert run_cli(*SWEEP, f"storage={with_password}") == 0
        study = load(url, "gamma")
        stored = repr(study.user_attrs) + repr([t.user_attrs for t in study.trials])
        assert "***" in stored and secret not in stored
        assert run_cli("report", "--no-policy", f"storage={with_password}") == 0
    for path in (workdir / "reports").rglob("*"):
        if path.is_file():
            assert secret.encode() not in path.read_bytes(), path


def trained(workdir: Path, name: str, **env: str) -> tuple[float, list[float], dict[str, str]]:
    """A TINY ``train`` run in a fresh process with ``env`` added to its environment: its
    score, its curve and its provenance record."""
    url = sqlite_url(workdir / f"{name}.db")
    done = subprocess.run([sys.executable, "-m", "kraby_study.cli", "train", *TINY,
                           "budget.steps=2048", f"storage={url}"], cwd=workdir,
                          env={**os.environ, **env}, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    with opened(url, create=False, writer=False) as store:
        (study,) = store.study_names()
        ledger = store.load(study)
        (trial,) = ledger.trials()
        curve = ledger.curves([trial.number]).mean_reward.tolist()
        record = ledger.provenances()[trial.user_attrs["provenance"]]
    return float(trial.value), curve, record


def test_a_seed_is_bit_for_bit_on_one_instruction_set_and_not_across_two(workdir: Path) -> None:
    """What "reproducible" means (docs/reference/reproducibility.md): the same settings and seed
    give the same numbers to the bit on one CPU and software, and other numbers when torch's kernels
    run another instruction set (ATEN_CPU_CAPABILITY=default: no SIMD, as on an older CPU),
    since they then add in another order. The record says which set a trial ran."""
    import torch

    here = str(torch.backends.cpu.get_cpu_capability())
    if here == "DEFAULT":
        pytest.skip("this CPU has no SIMD set for torch to give up")
    first, again, other = (trained(workdir, "first"), trained(workdir, "again"),
                           trained(workdir, "other", ATEN_CPU_CAPABILITY="default"))
    assert again[:2] == first[:2]  # score and every curve point, to the bit
    assert other[0] != first[0] and other[1] != first[1]
    assert abs(other[0] - first[0]) < 0.1 * abs(first[0])  # another run, not another result
    assert (first[2]["cpu_capability"], other[2]["cpu_capability"]) == (here, "DEFAULT")
