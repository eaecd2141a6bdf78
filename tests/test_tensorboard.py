"""tensorboard_dir=DIR: every training run writes SB3's logs to its own named folder."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
from conftest import TINY, run_cli

from kraby_study.config.compose import compose_config
from kraby_study.plan.confirm import Arm, confirm_plan
from kraby_study.plan.settings import folder_name, resolved_settings
from kraby_study.plan.sweep import expand_study
from kraby_study.plan.train import train_plan
from kraby_study.run.trial import tensorboard_folder

needs_tensorboard = pytest.mark.skipif(importlib.util.find_spec("tensorboard") is None,
                                       reason="the [tensorboard] extra is not installed")

ROLLOUTS = [128, 256, 384]
"""The env steps at the end of each rollout a TINY run learns from (4 legs x 32 steps; the
rollout that reaches the budget, 512, stops the run and is not learnt from)."""

SPACE = """\
name: tiny
sampler: random
pruner: none
seed: 0
startup_trials: 1
trials: 2
params:
  gamma: {path: ppo.gamma, type: float, low: 0.5, high: 0.99}
"""


def scalars(run: Path) -> dict[str, list[int]]:
    """The steps of each scalar tag in a run's folder, read back from its event files."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run))
    events.Reload()
    return {tag: [e.step for e in events.Scalars(tag)] for tag in events.Tags()["scalars"]}


def runs(study: Path) -> dict[str, dict[str, list[int]]]:
    """Each run folder of a study's TensorBoard logs, by name, with its scalars."""
    return {run.name: scalars(run) for run in sorted(study.iterdir())}


def assert_one_run(name: str, tags: dict[str, list[int]], study: Path) -> None:
    """A folder holds exactly one run's events: one event file, and SB3's rollout reward,
    losses and fps logged once per rollout of that run, never twice at a step."""
    assert len(list((study / name).glob("events.out.tfevents.*"))) == 1, name
    assert tags["time/fps"] == ROLLOUTS, (name, tags["time/fps"])
    steps = tags["rollout/ep_rew_mean"]
    assert steps and steps == sorted(set(steps)) and set(steps) <= set(ROLLOUTS), (name, steps)
    for loss in ("train/loss", "train/value_loss", "train/policy_gradient_loss",
                 "train/entropy_loss", "train/approx_kl"):
        # A rollout's losses are written with the next rollout's numbers.
        assert tags[loss] == ROLLOUTS[1:], (name, loss, tags[loss])


@needs_tensorboard
def test_a_sweep_on_two_workers_writes_one_folder_per_run(workdir: Path) -> None:
    assert run_cli("run", "study=clip_range", "study.values=[0.1, 0.3]", "workers=2", *TINY,
                   "tensorboard_dir=tb") == 0
    study = workdir / "tb" / "clip_range"
    logged = runs(study)
    assert sorted(logged) == ["clip_range=0.1-seed0", "clip_range=0.1-seed1",
                              "clip_range=0.3-seed0", "clip_range=0.3-seed1"]
    for name, tags in logged.items():
        assert_one_run(name, tags, study)


@needs_tensorboard
def test_a_search_writes_one_folder_per_trial_and_seed(workdir: Path) -> None:
    (workdir / "conf" / "search").mkdir(parents=True)
    (workdir / "conf" / "search" / "tiny.yaml").write_text(SPACE)
    assert run_cli("optuna", "--trials", "2", "search=tiny", "--workers", "1", *TINY,
                   "budget.seeds=2", "tensorboard_dir=tb") == 0
    study = workdir / "tb" / "tiny"
    logged = runs(study)
    assert sorted(logged) == ["t0-seed0", "t0-seed1", "t1-seed0", "t1-seed1"]
    for name, tags in logged.items():
        assert_one_run(name, tags, study)


def test_without_tensorboard_the_key_is_refused_and_nothing_is_written(
        workdir: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "tensorboard" else real(name, *a))
    assert run_cli("run", "study=gamma", *TINY, "tensorboard_dir=tb") == 2
    err = capsys.readouterr().err.strip()
    assert err == ("kraby-study: error: tensorboard_dir needs TensorBoard, which is not "
                   "installed: pip install 'kraby-study[tensorboard]'")
    assert list(workdir.iterdir()) == []


@needs_tensorboard
def test_a_file_as_the_folder_is_refused(workdir: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    (workdir / "tb").write_text("")
    assert run_cli("train", *TINY, "tensorboard_dir=tb") == 2
    assert "tensorboard_dir tb is a file" in capsys.readouterr().err
    assert not (workdir / "studies").exists()


@needs_tensorboard
def test_every_plan_names_its_runs(workdir: Path) -> None:
    cfg = compose_config(["study=gamma", "study.values=[0.8]", "budget=smoke",
                          "tensorboard_dir=tb"])
    root = workdir / "tb"
    sweep = expand_study(cfg).specs
    assert [s.tensorboard_run for s in sweep] == [str(root / "gamma" / "gamma=0.8")] * 2
    train = train_plan(cfg).specs[0]
    assert train.tensorboard_run == str(root / train.study / "train")
    arms = [Arm("t0 = ppo=tuned", resolved_settings(cfg), "trial 0")]
    confirm = confirm_plan(cfg, None, arms).specs
    assert {s.tensorboard_run for s in confirm} == {str(root / "confirm-t0_=_ppo=tuned"
                                                        / "t0_=_ppo=tuned")}


def test_runs_are_not_logged_unless_asked() -> None:
    cfg = compose_config(["study=gamma", "budget=smoke"])
    assert {s.tensorboard_run for s in expand_study(cfg).specs} == {None}


def test_a_retried_run_writes_beside_the_earlier_attempt(tmp_path: Path) -> None:
    run = str(tmp_path / "gamma" / "gamma=0.8")
    first, second, third = (tensorboard_folder(run, 3) for _ in range(3))
    assert [first.name, second.name, third.name] == [
        "gamma=0.8-seed3", "gamma=0.8-seed3-attempt2", "gamma=0.8-seed3-attempt3"]
    assert all(folder.is_dir() for folder in (first, second, third))


@pytest.mark.parametrize("text,name", [
    ("gamma=0.8", "gamma=0.8"), ("t0 = ppo=tuned", "t0_=_ppo=tuned"),
    ("net_arch=[64, 64]", "net_arch=_64,_64"), ("observation=a/b", "observation=a_b"),
    ("..", "_"), ("", "_"),
])
def test_folder_names_are_safe(text: str, name: str) -> None:
    assert folder_name(text) == name
