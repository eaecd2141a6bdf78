"""The command line as a user meets it: one spelling per setting, user configs first, and the
inputs that must end in one line instead of a traceback."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from conftest import TINY, file_digest, refused_before_work, run_cli, sqlite_url

from kraby_study.cli import build_parser
from kraby_study.config.compose import compose_config
from kraby_study.plan.space import PRUNERS


@pytest.fixture(scope="module")
def one_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store elsewhere than the default place, holding a finished one-seed sweep."""
    db = tmp_path_factory.mktemp("elsewhere") / "k.db"
    assert run_cli("run", "study=clip_range", "study.values=[0.1,0.2]", "budget.seeds=2",
                   "workers=1", f"--storage={sqlite_url(db)}", *TINY) == 0
    return db


def test_every_command_takes_the_storage_flag_and_its_key_alike(
        workdir: Path, one_study: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = sqlite_url(one_study)
    capsys.readouterr()
    for args in (["list", "--storage", url], ["list", f"storage={url}"]):
        assert run_cli(*args) == 0
        assert "clip_range" in capsys.readouterr().out
    for args in (["best", "--study-name", "clip_range", "--storage", url],
                 ["best", "study=clip_range", f"storage={url}"]):
        assert run_cli(*args) == 0
        assert capsys.readouterr().out.startswith("best: clip_range=")
    for args in (["report", "--study-name", "clip_range", "--storage", url, "--out", "a",
                  "--no-policy"],
                 ["report", "study=clip_range", f"storage={url}", "out=b", "--no-policy"]):
        assert run_cli(*args) == 0
    assert (workdir / "a" / "clip_range" / "summary.csv").read_text() == (
        workdir / "b" / "clip_range" / "summary.csv").read_text()
    # Nothing went to the default store.
    assert not (workdir / "studies").exists()


def test_help_lists_the_flags_of_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    expected = {"run": ["--storage", "--workers"], "train": ["--storage"],
                "list": ["--storage"], "best": ["--storage", "--study-name", "--name"],
                "report": ["--storage", "--study-name", "--out", "--format"],
                "optuna": ["--storage", "--workers", "--trials", "--study-name"]}
    for command, flags in expected.items():
        with pytest.raises(SystemExit):
            parser.parse_args([command, "--help"])
        text = capsys.readouterr().out
        assert all(flag in text for flag in flags), (command, text)
        assert "storage=URL" in text  # the flag names the key it sets


def test_a_user_config_wins_over_the_packaged_one_of_the_same_name(workdir: Path) -> None:
    packaged = compose_config(["ppo=tuned"]).ppo.gamma
    (workdir / "conf" / "ppo").mkdir(parents=True)
    (workdir / "conf" / "ppo" / "tuned.yaml").write_text(
        "# @package _global_\nppo:\n  gamma: 0.5\n")
    assert packaged != 0.5
    assert compose_config(["ppo=tuned"]).ppo.gamma == 0.5
    # The packaged groups are still there beside the user's file.
    assert compose_config(["ppo=start"]).ppo.gamma == 0.9


def test_best_writes_the_working_folder_and_its_file_is_the_one_loaded(
        workdir: Path, one_study: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("best", "--study-name", "clip_range", "--name", "tuned",
                   "--storage", sqlite_url(one_study)) == 0
    written = workdir / "conf" / "ppo" / "tuned.yaml"
    assert written.is_file() and "clip_range=" in capsys.readouterr().out
    # conf/ppo/tuned.yaml also exists in the package: the working folder's file is loaded.
    assert compose_config(["ppo=tuned"]).ppo.n_epochs == 2  # TINY's, not the packaged 30


def test_the_old_name_of_a_renamed_setting_still_works_on_the_command_line() -> None:
    assert compose_config(["physics_processes=3"]).shards == 3
    assert compose_config(["shards=2"]).shards == 2


def _one_line_error(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    assert run_cli(*args) == 2
    err = capsys.readouterr().err
    assert err.startswith("kraby-study: error: ") and err.count("\n") == 1
    return err


@pytest.mark.parametrize("command", [["list"], ["run", "study=clip_range", *TINY]])
def test_a_postgresql_url_without_its_driver_is_one_line(
        workdir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        command: list[str]) -> None:
    monkeypatch.setitem(sys.modules, "psycopg", None)  # as if it were not installed
    err = _one_line_error(capsys, *command, "--storage",
                          "postgresql+psycopg://kraby@127.0.0.1:9/kraby")
    assert "pip install 'kraby-study[postgres]'" in err
    assert not (workdir / "studies").exists()


def test_a_report_folder_that_cannot_be_written_is_one_line(
        workdir: Path, one_study: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = workdir / "a-file"
    blocker.write_text("not a folder\n")
    before = file_digest(one_study)
    err = _one_line_error(capsys, "report", "--storage", sqlite_url(one_study),
                          "--out", str(blocker / "reports"))
    assert "cannot create the report folder" in err
    assert blocker.read_text() == "not a folder\n" and file_digest(one_study) == before
    # A folder the process may not write to (a read-only mount here: /proc).
    err = _one_line_error(capsys, "report", "--storage", sqlite_url(one_study), "--out",
                          "/proc/kraby-reports")
    assert "report folder" in err


@pytest.mark.parametrize(("setting", "message"), [
    ("report.threshold=2", "report.threshold must be at most 0"),
    ("report.threshold=nan", "report.threshold"),
    ("report.bootstrap=10", "report.bootstrap must be at least 100"),
    ("report.min_seeds=1", "report.min_seeds must be at least 2"),
])
def test_a_report_setting_out_of_range_is_one_line(
        workdir: Path, one_study: Path, capsys: pytest.CaptureFixture[str], setting: str,
        message: str) -> None:
    before = file_digest(one_study)
    err = _one_line_error(capsys, "report", "--storage", sqlite_url(one_study), "--out",
                          str(workdir / "r"), setting)
    assert message in err
    assert file_digest(one_study) == before and not (workdir / "r").exists()


@pytest.mark.parametrize(("argv", "message"), [
    (["--racing", "--pruner", "median"], "--racing stops configurations by its race"),
    (["--racing", "--objective", "final_reward,training_time", "--pruner", "none"],
     "--racing races one objective"),
    (["--racing", "--recheck", "2"], "drop --recheck"),
    (["--racing", "--sampler", "nsga2"], "choose --sampler tpe, gp or random"),
    (["--racing", "budget.seeds=3"], "racing.min_seeds (4) must not exceed budget.seeds (3)"),
])
def test_optuna_racing_refuses_what_it_cannot_race_in_one_line(
        workdir: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str) -> None:
    err = refused_before_work(workdir, capsys, "optuna", "--trials", "3", "budget=smoke", *argv)
    assert message in err


def test_optuna_help_offers_the_wilcoxon_pruner(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(["optuna", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "{median,hyperband,wilcoxon,none}" in text
    assert "search.wilcoxon_p" in text and "budget.seeds=5 or more" in text
    # Every pruner the flag offers is one the search accepts.
    assert set(PRUNERS) == {"median", "hyperband", "wilcoxon", "none"}


@pytest.mark.parametrize(("argv", "named"), [
    (["confirm", "confirm.name=confirm-ppo=zoo-X", *TINY], "confirm.name: cannot read the value "
     "'confirm-ppo=zoo-X' (mismatched input '=' expecting <EOF>)"),
    (["run", "study=clip_range", "study.values=[0.1,", *TINY],
     "study.values: cannot read the value"),
    (["optuna", "search.name=x)", *TINY], "search.name: cannot read the value 'x)'"),
    (["run", "study=clip_range", "gamma", *TINY], "gamma: not KEY=VALUE"),
])
def test_an_override_hydra_cannot_parse_is_one_line_naming_its_key(
        workdir: Path, one_study: Path, capsys: pytest.CaptureFixture[str], argv: list[str],
        named: str) -> None:
    before = file_digest(one_study)
    err = _one_line_error(capsys, *argv, f"storage={sqlite_url(one_study)}")
    assert named in err and "None" not in err
    if "KEY=VALUE" not in named:  # what a value may be, and the key's value quoted
        assert "a quoted string" in err and err.rstrip().endswith("'")
    assert file_digest(one_study) == before and not (workdir / "studies").exists()


def test_a_quoted_value_with_an_equals_sign_is_read_whole() -> None:
    cfg = compose_config(["confirm.name='confirm-ppo=zoo-X'"])
    assert cfg.confirm.name == "confirm-ppo=zoo-X"
