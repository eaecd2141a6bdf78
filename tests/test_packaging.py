"""A built wheel, installed away from the source tree, finds its configs and robot description."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CHECK = """
import pathlib, sys
import kraby_conf, kraby_envs, kraby_study
from kraby_study.config.compose import compose_config
from kraby_study.plan.sweep import expand_study
target = pathlib.Path(sys.argv[1]).resolve()
for module in (kraby_conf, kraby_envs, kraby_study):
    assert target in pathlib.Path(module.__file__).resolve().parents, module.__file__
plan = expand_study(compose_config(["study=batch_size", "budget=smoke"]))
assert len(plan.specs) == 16, len(plan.specs)
from kraby_envs.robot import URDF_PATH
assert URDF_PATH.is_file() and target in URDF_PATH.resolve().parents
import kraby_study.report
from kraby_study.env import adapter_for
assert target in pathlib.Path(sys.modules["kraby_study.env"].__file__).resolve().parents
assert adapter_for({"id": "Pendulum-v1"}).kind == "gym"
env = kraby_envs.make_batched(n_envs=2, seed=0)
assert env.reset().shape[0] == 2
print("wheel ok")
"""


@pytest.mark.slow
def test_wheel_installed_elsewhere_works(tmp_path: Path) -> None:
    wheels, target, cwd = tmp_path / "wheels", tmp_path / "site", tmp_path / "elsewhere"
    cwd.mkdir()
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(wheels),
                    str(ROOT)], check=True)
    wheel = next(wheels.glob("kraby_study-*.whl"))
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target",
                    str(target), str(wheel)], check=True)
    env = dict(os.environ, PYTHONPATH=str(target))
    out = subprocess.run([sys.executable, "-c", CHECK, str(target)], cwd=cwd, env=env,
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "wheel ok" in out.stdout
    cli = subprocess.run([sys.executable, "-m", "kraby_study.cli", "--help"], cwd=cwd, env=env,
                         capture_output=True, text=True)
    assert cli.returncode == 0 and "optuna" in cli.stdout
