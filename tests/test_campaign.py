"""Campaigns: stages run in order with the earlier stages' selected values, `${winner:...}` in
a study file, the report's campaign table, `best --campaign`, and bad input."""

from __future__ import annotations

import csv
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path

import optuna
import pytest
import yaml
from conftest import (
    FAST_HEARTBEAT,
    SERVER,
    TINY,
    file_digest,
    fresh_database,
    has_study,
    kill_when,
    load,
    run_cli,
    spawn_cli,
    sqlite_url,
    tiny_with_steps,
)
from omegaconf import DictConfig
from optuna.distributions import CategoricalDistribution
from optuna.trial import TrialState, create_trial
from synthetic import add_trials

from kraby_study.answers.raced import race_record
from kraby_study.answers.selected import sweep_selection
from kraby_study.config.compose import compose_config
from kraby_study.decision.race import race
from kraby_study.plan.campaign import campaign_of
from kraby_study.plan.spec import StudyPlan
from kraby_study.plan.sweep import expand_study
from kraby_study.records.attributes import StudyAttrs, TrialAttrs
from kraby_study.records.stored import (
    Tally,
    counted,
    ended_runs,
    latest_by_key,
    parse_sweep_key,
    tally,
)
from kraby_study.records.values import param_name
from kraby_study.report import write_report
from kraby_study.run.campaign_run import run_campaign
from kraby_study.run.plan_source import PlanSource
from kraby_study.run.runner import CommandRun
from kraby_study.store.store import opened

SEEDS = "budget.seeds=2"
STUDIES = {
    # name: (parameter, values, extra settings of the study file)
    "s_gamma": ("ppo.gamma", [0.5, 0.99], {}),
    "s_clip": ("ppo.clip_range", [0.1, 0.3], {}),
    # Eight runs: a kill on its first complete run lands mid-stage even on a loaded machine.
    "s_clip4": ("ppo.clip_range", [0.1, 0.2, 0.3, 0.4], {}),
    "s_ent": ("ppo.ent_coef", [0.0, 0.05], {}),
    # Bad ones: a winner of a later stage, and of itself.
    "s_fwd": ("ppo.gae_lambda", [0.9, 0.95], {"ppo": {"clip_range": "${winner:s_clip}"}}),
    "s_self": ("ppo.gae_lambda", [0.9, 0.95], {"ppo": {"vf_coef": "${winner:s_self}"}}),
    # A standalone study taking the campaign's first winner.
    "s_after": ("ppo.ent_coef", [0.0, 0.05], {"ppo": {"gamma": "${winner:tri-s_gamma}"}}),
    "s_absent": ("ppo.ent_coef", [0.0, 0.05], {"ppo": {"gamma": "${winner:nope}"}}),
    "s_me": ("ppo.ent_coef", [0.0, 0.05], {"ppo": {"gamma": "${winner:s_me}"}}),
}
CAMPAIGNS = {
    "tri": {"name": "tri", "description": "Three smoke stages.", "start": {"ppo.gamma": 0.9},
            "stages": [{"study": "s_gamma", "documented": 0.99},
                       {"study": "s_clip", "documented": 0.3},
                       {"study": "s_ent", "select": "fastest_equivalent", "documented": 0.0}]},
    "long": {"name": "long", "start": {"ppo.gamma": 0.9},
             "stages": [{"study": "s_gamma"}, {"study": "s_clip4"}, {"study": "s_ent"}]},
    "fwd": {"name": "fwd", "stages": [{"study": "s_fwd"}, {"study": "s_clip"}]},
    "selfref": {"name": "selfref", "stages": [{"study": "s_gamma"}, {"study": "s_self"}]},
    "unknown": {"name": "unknown", "stages": [{"study": "s_gamma"}, {"study": "nope"}]},
    "twice": {"name": "twice", "stages": [{"study": "s_gamma"}, {"study": "s_gamma"}]},
}


def write_conf(folder: Path) -> None:
    """The test's own studies and campaigns, in ./conf/ as a user writes them."""
    for name, (parameter, values, extra) in STUDIES.items():
        body = {"study": {"name": name, "parameter": parameter, "values": values}, **extra}
        path = folder / "conf" / "study" / f"{name}.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("# @package _global_\n" + yaml.safe_dump(body, sort_keys=False))
    for name, body in CAMPAIGNS.items():
        path = folder / "conf" / "campaign" / f"{name}.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("# @package campaign\n" + yaml.safe_dump(body, sort_keys=False))


@pytest.fixture(scope="module")
def ran(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A folder where the three-stage campaign `tri` ran to the end (once for the module)."""
    folder = tmp_path_factory.mktemp("campaign")
    write_conf(folder)
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(folder)
        assert run_cli("run", "campaign=tri", *TINY, SEEDS) == 0
    yield folder


@pytest.fixture
def inside(ran: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(ran)
    return ran


def db(folder: Path) -> Path:
    return folder / "studies" / "kraby.db"


def selected(folder: Path, name: str) -> object:
    with opened(sqlite_url(db(folder)), create=False, writer=False) as store:
        chosen = sweep_selection(store.load(name))
    assert chosen is not None and chosen.finished
    return chosen.value


def settings_of(folder: Path, name: str) -> list[dict]:
    return [TrialAttrs.of(t).settings for t in counted(load(db(folder), name).trials)]


def test_each_stage_runs_with_the_values_the_earlier_stages_selected(inside: Path) -> None:
    gamma, clip = selected(inside, "tri-s_gamma"), selected(inside, "tri-s_clip")
    for settings in settings_of(inside, "tri-s_gamma"):
        assert settings["ppo"]["clip_range"] == 0.2  # the packaged default until stage 2
    for settings in settings_of(inside, "tri-s_clip"):
        assert settings["ppo"]["gamma"] == gamma
    for settings in settings_of(inside, "tri-s_ent"):
        assert (settings["ppo"]["gamma"], settings["ppo"]["clip_range"]) == (gamma, clip)
    for name, planned in (("tri-s_gamma", 4), ("tri-s_clip", 4), ("tri-s_ent", 4)):
        trials = counted(load(db(inside), name).trials)
        assert len(trials) == planned and all(t.value is not None for t in trials)
    attrs = StudyAttrs.of(load(db(inside), "tri-s_ent").user_attrs)
    assert attrs.inputs == [
        {"setting": "ppo.gamma", "value": gamma, "study": "tri-s_gamma", "rule": "final_score"},
        {"setting": "ppo.clip_range", "value": clip, "study": "tri-s_clip",
         "rule": "final_score"}]
    assert attrs.select == "fastest_equivalent"
    assert attrs.campaign is not None and attrs.campaign["stage"] == 3


def test_the_stage_definition_holds_the_resolved_value(inside: Path) -> None:
    gamma = selected(inside, "tri-s_gamma")
    attrs = StudyAttrs.of(load(db(inside), "tri-s_clip").user_attrs)
    assert attrs.definition["settings"]["ppo"]["gamma"] == gamma


def test_rerunning_a_finished_campaign_runs_nothing(inside: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    before = {name: len(load(db(inside), name).trials)
              for name in ("tri-s_gamma", "tri-s_clip", "tri-s_ent")}
    assert run_cli("run", "campaign=tri", *TINY, SEEDS) == 0
    after = {name: len(load(db(inside), name).trials) for name in before}
    assert after == before
    out = capsys.readouterr().out
    assert "3/3 stages finished" in out and out.count("0 to run") == 3


def _as_chosen_by_the_retired_rule(folder: Path) -> Path:
    """A copy of the campaign's store in ``folder`` in which the clip stage was selected by
    fastest_tied, the retired rule: its own stored rule and the later stage's record of the
    value it took from it say so (as a store of that rule holds them)."""
    copy = folder / "studies" / "kraby.db"
    copy.parent.mkdir(parents=True)
    shutil.copy(db(Path.cwd()), copy)
    url = sqlite_url(copy)
    optuna.load_study(study_name="tri-s_clip", storage=url).set_user_attr(
        "kraby_select", "fastest_tied")
    later = optuna.load_study(study_name="tri-s_ent", storage=url)
    inputs = [dict(taken, rule="fastest_tied") if taken["study"] == "tri-s_clip" else taken
              for taken in later.user_attrs["kraby_inputs"]]
    later.set_user_attr("kraby_inputs", inputs)
    return copy


def test_later_stages_keep_the_value_they_ran_on_and_the_report_names_its_rule(
        inside: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    clip = selected(inside, "tri-s_clip")
    copy = _as_chosen_by_the_retired_rule(tmp_path / "store")
    storage = f"storage={sqlite_url(copy)}"
    def clip_row(seeds: str) -> dict[str, str]:
        report = tmp_path / f"report{seeds}"
        assert run_cli("report", "--no-policy", "--out", str(report), storage,
                       f"report.min_seeds={seeds}") == 0
        with open(report / "tri" / "campaign.csv", newline="") as handle:
            return {r["study"]: r for r in csv.DictReader(handle)}["tri-s_clip"]

    # The stage stored with the retired rule is answered by today's, which agrees here.
    row = clip_row("2")
    assert (row["rule"], row["selected"]) == ("fastest_tied", f"{clip:g}")
    assert row["notes"].startswith(f"later stages ran on {clip:g}, selected by fastest_tied; "
                                   f"today's rule fastest_equivalent selects {clip:g}, the same")
    # At 3 seeds a value, today's rule selects nothing from these 2-seed stages; the stages
    # that ran on their values keep them, so the finished campaign still runs nothing.
    assert run_cli("run", "campaign=tri", *TINY, SEEDS, storage, "report.min_seeds=3") == 0
    out = capsys.readouterr().out
    assert "3/3 stages finished" in out and out.count("0 to run") == 3
    row = clip_row("3")
    assert (row["rule"], row["selected"]) == ("fastest_tied", f"{clip:g}")
    assert row["notes"].startswith(f"later stages ran on {clip:g}, selected by fastest_tied; "
                                   "today's rule selects nothing yet")
    text = (tmp_path / "report2" / "index.md").read_text()
    assert "fastest_tied: a retired rule, kept where later stages ran on its choice" in text
    # The rerun kept the later stage's record of what it ran on, rule and all.
    later = optuna.load_study(study_name="tri-s_ent", storage=sqlite_url(copy))
    assert {"setting": "ppo.clip_range", "value": clip, "study": "tri-s_clip",
            "rule": "fastest_tied"} in later.user_attrs["kraby_inputs"]


def test_a_config_naming_the_retired_rule_is_refused_in_one_line(
        inside: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli("run", "study=s_gamma", "study.select=fastest_tied", *TINY, SEEDS) == 2
    err = capsys.readouterr().err
    assert "study.select: fastest_tied is retired; use fastest_equivalent" in err
    assert err.count("\n") == 1


def test_the_report_writes_the_campaign_table_and_one_selected_row_per_study(
        inside: Path, tmp_path: Path) -> None:
    out = tmp_path / "report"
    assert run_cli("report", "--no-policy", "--out", str(out)) == 0
    with open(out / "tri" / "campaign.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["study"] for r in rows] == ["tri-s_gamma", "tri-s_clip", "tri-s_ent"]
    assert [r["rule"] for r in rows] == ["final_score", "final_score", "fastest_equivalent"]
    assert [r["documented"] for r in rows] == ["0.99", "0.3", "0"]
    for row in rows:
        value = selected(inside, row["study"])
        assert row["selected"] == f"{value:g}"
        assert row["agree"] == str(float(row["selected"]) == float(row["documented"]))
        with open(out / row["study"] / "summary.csv", newline="") as handle:
            summary = list(csv.DictReader(handle))
        marked = [r["value"] for r in summary if r["selected"] == "True"]
        assert marked == [row["selected"]]
    index = (out / "index.md").read_text()
    assert "## Campaign tri" in index and "Settings the campaign ends with (after stage 3/3)" \
        in index
    gamma = selected(inside, "tri-s_gamma")
    assert f"ppo.gamma = {gamma:g}, selected in tri-s_gamma (final_score)" in index


def test_best_campaign_writes_the_settings_the_campaign_ends_with(inside: Path) -> None:
    assert run_cli("best", "--campaign", "tri") == 0
    written = yaml.safe_load((inside / "conf" / "ppo" / "campaign_tri.yaml").read_text())
    assert written["ppo"]["gamma"] == selected(inside, "tri-s_gamma")
    assert written["ppo"]["clip_range"] == selected(inside, "tri-s_clip")
    assert written["ppo"]["ent_coef"] == selected(inside, "tri-s_ent")
    assert run_cli("best", "--campaign", "nope") == 2


def test_campaign_name_runs_the_chain_again_as_its_own_studies(
        ran: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """campaign.name=NAME stores a second run of the same chain in the same store as
    NAME-STUDY (here on other seeds), each stage taking NAME's earlier winners, and best
    --campaign NAME reads it; the first run's studies are left as they were."""
    shutil.copytree(ran, tmp_path / "copy")
    folder = tmp_path / "copy"
    monkeypatch.chdir(folder)
    before = {n: len(load(db(folder), n).trials) for n in ("tri-s_gamma", "tri-s_clip",
                                                            "tri-s_ent")}
    assert run_cli("run", "campaign=tri", "campaign.name=tri_b", "seed=100", *TINY,
                   SEEDS) == 0
    assert {n: len(load(db(folder), n).trials) for n in before} == before
    gamma, clip = selected(folder, "tri_b-s_gamma"), selected(folder, "tri_b-s_clip")
    assert all(s["ppo"]["gamma"] == gamma for s in settings_of(folder, "tri_b-s_clip"))
    assert all(s["ppo"]["clip_range"] == clip for s in settings_of(folder, "tri_b-s_ent"))
    assert {t.user_attrs["seed"] for t in load(db(folder), "tri_b-s_gamma").trials} == {100,
                                                                                        101}
    assert run_cli("best", "--campaign", "tri_b") == 0
    written = yaml.safe_load((folder / "conf" / "ppo" / "campaign_tri_b.yaml").read_text())
    assert (written["ppo"]["gamma"], written["ppo"]["clip_range"]) == (gamma, clip)
    assert written["ppo"]["ent_coef"] == selected(folder, "tri_b-s_ent")


def test_a_standalone_study_takes_a_stored_winner(inside: Path) -> None:
    assert run_cli("run", "study=s_after", *TINY, "budget.seeds=1") == 0
    gamma = selected(inside, "tri-s_gamma")
    assert all(s["ppo"]["gamma"] == gamma for s in settings_of(inside, "s_after"))
    attrs = StudyAttrs.of(load(db(inside), "s_after").user_attrs)
    assert attrs.inputs == [{"setting": "ppo.gamma", "value": gamma, "study": "tri-s_gamma",
                             "rule": "final_score"}]


@pytest.mark.parametrize("args,message", [
    (["campaign=nope"], "Could not find 'campaign/nope'"),
    (["campaign=unknown"], "campaign unknown, stage 2 (nope): "),
    (["campaign=twice"], "campaign twice lists study s_gamma twice"),
    (["campaign=fwd"], "campaign fwd, stage 1 (s_fwd): ppo.clip_range: ${winner:s_clip} refers "
                       "to a later stage (2)"),
    (["campaign=selfref"], "campaign selfref, stage 2 (s_self): ppo.vf_coef: ${winner:s_self} "
                           "refers to the stage itself"),
    (["campaign=tri", "ppo.gamma=0.5"], "ppo.gamma is selected by stage s_gamma of campaign tri"),
    (["campaign=tri", "study=s_gamma"], "campaign tri runs its own studies"),
    (["campaign=tri", "campaign.stages.0.select=best"], "select must be one of"),
    (["study=s_absent"], "ppo.gamma: ${winner:nope}: no study 'nope' in the store yet"),
    (["study=s_me"], "ppo.gamma: ${winner:s_me} refers to the study itself"),
])
def test_bad_campaign_input_is_one_line_and_writes_nothing(
        workdir: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str) -> None:
    write_conf(workdir)
    assert run_cli("run", *args, *TINY) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (workdir / "studies").exists()


def test_a_changed_stored_stage_is_refused_before_any_work(
        ran: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    shutil.copytree(ran, tmp_path / "copy")
    monkeypatch.chdir(tmp_path / "copy")
    digest = file_digest(db(tmp_path / "copy"))
    assert run_cli("run", "campaign=tri", *TINY, SEEDS, "budget.steps=1024") == 2
    err = capsys.readouterr().err
    assert "campaign tri, stage 1 (s_gamma): study 'tri-s_gamma'" in err
    assert "steps: 512 -> 1024" in err
    assert file_digest(db(tmp_path / "copy")) == digest


def test_a_winner_of_an_unfinished_study_says_how_far_it_is(
        inside: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    url = sqlite_url(tmp_path / "half.db")
    cfg = compose_config(["study=s_gamma", *TINY, SEEDS, f"storage={url}"])
    plan = expand_study(cfg)
    with opened(url) as store:  # queued, never run: 0 of 4 complete
        ledger = store.define(plan.name, StudyAttrs(kind="sweep", definition=plan.definition,
                                                    fingerprint=plan.fingerprint))
        PlanSource(ledger, plan).queue_missing()
    assert run_cli("run", "study=s_clip", *TINY, f"storage={url}",
                   "ppo.gamma=${winner:s_gamma}") == 2
    err = capsys.readouterr().err
    assert "study 's_gamma' is incomplete (0/4 complete)" in err


SLOWER = tiny_with_steps(2048)
STAGES = ("tri-s_gamma", "tri-s_clip", "tri-s_ent")


def complete_keys(url: str, name: str) -> list[str]:
    """The keys of a study's complete trials, one entry per complete trial (so a key run twice
    shows twice)."""
    if not has_study(url, name):
        return []
    return sorted(str(t.user_attrs["key"]) for t in load(url, name).get_trials()
                  if t.state == TrialState.COMPLETE)


@pytest.mark.slow
def test_a_killed_campaign_resumes_where_it_stopped(workdir: Path, store_url: str) -> None:
    write_conf(workdir)
    args = ["run", "campaign=long", "workers=2", f"storage={store_url}", SEEDS, *SLOWER,
            *FAST_HEARTBEAT]
    proc = spawn_cli(*args, cwd=workdir)
    # Killed once the second stage has a complete run, as the store shows it at the kill.
    kill_when(lambda: len(complete_keys(store_url, "long-s_clip4")) >= 1, proc)
    first = [t.number for t in load(store_url, "long-s_gamma").get_trials()]
    assert len(complete_keys(store_url, "long-s_gamma")) == 4
    assert 1 <= len(complete_keys(store_url, "long-s_clip4")) < 8
    assert not has_study(store_url, "long-s_ent")
    # On a server the rerun takes the killed command's trials over once their heartbeat is
    # stale (heartbeat_grace): it waits for that itself.
    proc = spawn_cli(*args, cwd=workdir)
    out, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, out
    assert "3/3 stages finished" in out
    assert [t.number for t in load(store_url, "long-s_gamma").get_trials()] == first
    for name, runs in (("long-s_gamma", 4), ("long-s_clip4", 8), ("long-s_ent", 4)):
        keys = complete_keys(store_url, name)
        assert len(keys) == runs and len(set(keys)) == runs, (name, keys)


@pytest.mark.slow
@pytest.mark.postgres
@pytest.mark.skipif(not SERVER, reason="KRABY_TEST_POSTGRES_URL is not set")
def test_two_commands_on_postgresql_share_one_campaign(workdir: Path) -> None:
    write_conf(workdir)
    with fresh_database() as url:
        args = ["run", "campaign=tri", "workers=1", f"storage={url}", SEEDS, *SLOWER,
                *FAST_HEARTBEAT]
        procs = [spawn_cli(*args, cwd=workdir) for _ in range(2)]
        outs = [p.communicate(timeout=600)[0] for p in procs]
        for proc, out in zip(procs, outs, strict=True):
            assert proc.returncode == 0, out
            assert "3/3 stages finished" in out
        for name in STAGES:
            keys = complete_keys(url, name)
            assert len(keys) == 4 and len(set(keys)) == 4, (name, keys)
        # Both commands took part: each ran trials of the campaign.
        ran = [sum(out.count(f"] {p}") for p in ("gamma=", "clip_range=", "ent_coef="))
               for out in outs]
        assert all(count >= 1 for count in ran), ran


RACED_SCORES = {0: [0.0, 0.001, 0.002, 0.0015], 1: [1.0, 1.001, 1.002, 1.0015]}
"""A raced stage's runs, by value index and seed index: value 1 far ahead after round 4 (the
first look an answer allows), so the look after it drops value 0 and the race is over with one
value left (8 of 10 runs)."""


def raced_stage(cfg: DictConfig, plan: StudyPlan) -> tuple[CommandRun, Tally]:
    """Stand-in for a raced stage's run: store the runs of :data:`RACED_SCORES` under the
    stage's plan, and the race they make, as the race source leaves them."""
    assert plan.racing is not None
    seeds = list(plan.racing.round_seeds)
    short = param_name(plan.parameter)
    with opened(str(cfg.storage)) as store:
        ledger = store.define(plan.name, StudyAttrs(kind="sweep", definition=plan.definition,
                                                    fingerprint=plan.fingerprint))
        ledger.update(plan.notes())
        for spec in plan.specs:
            vi, seed = parse_sweep_key(spec.key) or (0, 0)
            scores = RACED_SCORES[vi]
            if seeds.index(seed) >= len(scores):
                continue
            score = scores[seeds.index(seed)]
            attrs = TrialAttrs(key=spec.key, seed=seed, settings=spec.settings,
                               steps=spec.steps, env_steps=spec.steps, wall_time=1.0,
                               final_score=score)
            add_trials(store, plan.name, [create_trial(
                state=TrialState.COMPLETE, value=score, params={short: spec.value},
                distributions={short: CategoricalDistribution(plan.values)},
                user_attrs=attrs.stored())])
        latest = latest_by_key(ledger.trials())
        runs = ended_runs(latest, seeds)
        state = race(list(range(len(plan.values))), runs, plan.racing)
        assert state.over and list(state.dropped) == [0]
        ledger.update(StudyAttrs(planned=len(latest),
                                 race=race_record(plan.values, state, runs)))
        return CommandRun(), tally(counted(ledger.trials()), len(latest))


def test_a_raced_campaign_goes_on_and_selects_among_each_stages_survivors(
        workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_conf(workdir)
    url = sqlite_url(workdir / "raced.db")
    overrides = ["campaign=tri", *TINY, "budget.seeds=5", "racing.enabled=true",
                 f"storage={url}"]
    campaign = campaign_of(compose_config(overrides), overrides)
    # A raced stage ends with fewer runs than values x seeds: it is finished, not "left".
    assert run_campaign(campaign, raced_stage, sys.stdout) == 0
    out = capsys.readouterr().out
    assert "3/3 stages finished" in out and "run(s) left" not in out
    assert "stage 1/3 tri-s_gamma: 8/8 complete, 0 failed; selected gamma=0.99" in out
    # Each stage selects its survivor (the second value), and the next stage trains with it.
    with opened(url, create=False, writer=False) as store:
        for name, value in (("tri-s_gamma", 0.99), ("tri-s_clip", 0.3), ("tri-s_ent", 0.05)):
            chosen = sweep_selection(store.load(name))
            assert chosen is not None and chosen.finished and chosen.value == value, name
    # The report's campaign table says each stage raced and selected among its survivors.
    index = write_report(url, workdir / "report", policy=False)
    with open(index.out / "tri" / "campaign.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["selected"] for r in rows] == ["0.99", "0.3", "0.05"]
    # The race began at the default compare.margin, 0.2, and says so in score units.
    rule = ("racing from round 4 of 5: the answers' step-down on the IQM at each look, alpha "
            "0.05 spent equally over 2 looks (0.025 each); a value leaves once shown worse by "
            "more than the margin (0.2 x the look's best |IQM|) or shown equivalent to the best "
            "within it")
    for row, dropped in zip(rows, ("0.5", "0.1", "0"), strict=True):
        assert (f"; raced ({rule}), selected among the values it did not drop; dropped: "
                f"{dropped} after round 4; raced: 8 of 10 runs (80 %)") in row["notes"], \
            row["notes"]
        assert "margin " in row["notes"] and "in score units" in row["notes"]
