"""The scheduling loop of run_trials, without training: a fake source and a fake worker pool.

The fake pool "runs" each submitted trial by saying one scripted event per running trial on each
events() call, as workers would: progress, a checkpoint (answered through reply), a result, or
the worker's death.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import Any

import pytest

from kraby_study.plan.spec import TrialSpec
from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import Failure, Outcome, failure_kind
from kraby_study.run.pool import Event
from kraby_study.run.progress import Progress
from kraby_study.run.runner import MAX_WORKER_DEATHS, CommandRun, run_trials

STEPS = 1000

# A scripted attempt: what the worker says, one step per events() call.
#   ("progress", (steps, CPU s so far)) | ("checkpoint", (step, value))
#   | ("result", TrialResult) | ("died", code)
Attempt = list[tuple[str, Any]]


def spec(number: int) -> TrialSpec:
    return TrialSpec(study="s", key=f"v{number}-s0", seed=0, steps=STEPS, curve_every=100,
                     settings={}, label=f"trial {number}")


def result(outcome: Outcome = Outcome.COMPLETE, score: float | None = 1.0) -> TrialResult:
    return TrialResult(outcome=outcome, final_score=score if outcome == Outcome.COMPLETE else None,
                       env_steps=STEPS,
                       failure="diverged: NaN" if outcome == Outcome.FAILED else None)


def runs(*attempt: tuple[str, Any]) -> list[Attempt]:
    """A trial's script of one attempt."""
    return [list(attempt)]


def completes(score: float = 1.0) -> list[Attempt]:
    return runs(("progress", (STEPS // 2, 0.0)), ("result", result(score=score)))


class FakeSource:
    """Hands out trials 0, 1, ... and notes every call in ``log``, in order."""

    def __init__(self, count: int, answers: dict[int, bool] | None = None,
                 elsewhere: Sequence[bool] = (), comes_back: Sequence[int] = ()) -> None:
        self.queue = [(n, spec(n)) for n in range(count)]
        self.comes_back = [(n, spec(n)) for n in comes_back]
        """Trials another command runs: claimable once the queue was found empty."""
        self.answers = answers or {}
        self.elsewhere = list(elsewhere)
        self.log: list[tuple[str, Any]] = []
        self.recorded: list[tuple[int, TrialSpec, TrialResult]] = []
        self.requeued: list[tuple[int, TrialSpec, str]] = []
        self.checkpoints: list[tuple[int, int, float]] = []
        self.heartbeats: list[list[int]] = []
        self.cpu: dict[int, float] = {}

    def next_trial(self) -> tuple[int, TrialSpec] | None:
        if not self.queue:
            self.queue, self.comes_back = self.comes_back, []
            return None
        claimed = self.queue.pop(0)
        self.log.append(("claim", claimed[0]))
        return claimed

    def checkpoint(self, number: int, step: int, value: float) -> bool:
        self.checkpoints.append((number, step, value))
        return self.answers.get(number, True)

    def stopped_why(self, number: int) -> str | None:
        return None

    def using(self, number: int, steps: int, cpu: float) -> None:
        self.cpu[number] = cpu

    def record(self, number: int, spec: TrialSpec, result: TrialResult) -> None:
        self.log.append(("record", number))
        self.recorded.append((number, spec, result))

    def requeue(self, number: int, spec: TrialSpec, reason: str) -> None:
        self.log.append(("requeue", number))
        self.requeued.append((number, spec, reason))

    def heartbeat(self, numbers: list[int]) -> None:
        self.log.append(("heartbeat", sorted(numbers)))
        self.heartbeats.append(list(numbers))

    def running_elsewhere(self) -> bool:
        return self.elsewhere.pop(0) if self.elsewhere else False

    def results(self) -> dict[int, TrialResult]:
        return {number: res for number, _, res in self.recorded}


class FakePool:
    """WorkerPool's methods; each submitted attempt plays the next script of its trial."""

    def __init__(self, size: int, shards: int, scripts: dict[int, list[Attempt]],
                 interrupt_at: int | None) -> None:
        self.size = size
        self.shards = shards
        self.scripts = {n: [list(a) for a in attempts] for n, attempts in scripts.items()}
        self.interrupt_at = interrupt_at
        self.playing: dict[int, tuple[TrialSpec, Attempt]] = {}
        self.submitted: list[tuple[int, TrialSpec]] = []
        self.replies: list[tuple[int, bool]] = []
        self.closed: list[bool] = []
        self.calls = 0
        self.most_at_once = 0

    def idle(self) -> int:
        return self.size - len(self.playing)

    def submit(self, number: int, spec: TrialSpec) -> None:
        assert len(self.playing) < self.size, "submitted to a full pool"
        assert number not in self.playing, "submitted a trial that is running"
        attempts = self.scripts.get(number) or completes()
        self.playing[number] = (spec, attempts.pop(0))
        self.submitted.append((number, spec))
        self.most_at_once = max(self.most_at_once, len(self.playing))

    def running(self) -> dict[int, TrialSpec]:
        return {number: spec for number, (spec, _) in self.playing.items()}

    def events(self, timeout: float) -> list[Event]:
        self.calls += 1
        if self.calls == self.interrupt_at:
            raise KeyboardInterrupt  # Ctrl-C while waiting for the workers
        assert self.calls < 1000, "the runner does not end"
        out = []
        for number, (spec, attempt) in list(self.playing.items()):
            if not attempt:
                continue  # its script is played: it runs on, silent
            kind, payload = attempt.pop(0)
            if kind in ("result", "died"):
                del self.playing[number]
            if kind == "died":
                payload = (spec, f"exit code {payload}")
            out.append(Event(kind, number, payload))
        return out

    def reply(self, event: Event, keep_going: bool) -> None:
        assert event.kind == "checkpoint"
        self.replies.append((event.number, keep_going))

    def close(self, terminate: bool = False) -> None:
        self.closed.append(terminate)
        self.playing.clear()


class Pools:
    """Stands in for an executor: its pool is a FakePool with the scripts the test set."""

    def __init__(self) -> None:
        self.made: list[FakePool] = []
        self.scripts: dict[int, list[Attempt]] = {}
        self.interrupt_at: int | None = None

    def script(self, scripts: dict[int, list[Attempt]], interrupt_at: int | None = None) -> None:
        """What the workers will do, by trial number (a trial not named completes); Ctrl-C on
        the ``interrupt_at``-th events() call."""
        self.scripts, self.interrupt_at = scripts, interrupt_at

    def pool(self, size: int) -> FakePool:
        """The executor's pool: a FakePool playing the scripts."""
        pool = FakePool(size, 1, self.scripts, self.interrupt_at)
        self.made.append(pool)
        return pool

    @property
    def only(self) -> FakePool:
        """The one pool run_trials built."""
        assert len(self.made) == 1
        return self.made[0]


@pytest.fixture
def pools() -> Pools:
    return Pools()


def run(pools: Pools, source: FakeSource, workers: int) -> tuple[CommandRun, str]:
    """run_trials on the fake pool, a heartbeat on every turn of its loop; the summary and
    what the progress printed."""
    stream = io.StringIO()
    total = len(source.queue) + len(source.comes_back)
    progress = Progress("test", total, 0, stream=stream, live=False)
    summary = run_trials(source, workers, progress, pools, heartbeat_seconds=0.0,
                         poll_seconds=0.01)
    return summary, stream.getvalue()


def test_a_running_trials_cpu_seconds_reach_the_source_with_its_progress(pools: Pools) -> None:
    pools.script({0: runs(("progress", (100, 1.5)), ("progress", (900, 4.0)),
                          ("result", result()))})
    source = FakeSource(1)
    run(pools, source, workers=1)
    assert source.cpu == {0: 4.0}  # the latest report


def test_every_claimed_trial_is_recorded_once_with_its_result(pools: Pools) -> None:
    scores = {0: 0.5, 1: -1.0, 2: 2.0, 3: 0.0, 4: 7.0}
    expected = {n: result(score=s) for n, s in scores.items()}
    pools.script({n: runs(("progress", (100, 0.0)), ("progress", (900, 0.0)),
                          ("result", expected[n]))
                   for n in scores})
    source = FakeSource(5)
    summary, _ = run(pools, source, workers=2)
    assert sorted(n for n, _, _ in source.recorded) == [0, 1, 2, 3, 4]  # each once
    assert source.results() == expected
    assert all(s == spec(n) for n, s, _ in source.recorded)
    assert [n for kind, n in source.log if kind == "claim"] == [0, 1, 2, 3, 4]
    assert summary == CommandRun(complete=5)
    assert source.requeued == []
    assert pools.only.closed  # the workers are stopped at the end


def test_the_summary_counts_complete_failed_and_pruned(pools: Pools) -> None:
    outcomes = [Outcome.COMPLETE, Outcome.FAILED, Outcome.PRUNED, Outcome.COMPLETE,
                Outcome.FAILED, Outcome.COMPLETE]
    pools.script({n: runs(("result", result(o))) for n, o in enumerate(outcomes)})
    source = FakeSource(len(outcomes))
    summary, out = run(pools, source, workers=3)
    assert summary == CommandRun(complete=3, failed=2, pruned=1, interrupted=False)
    assert {n: r.outcome for n, r in source.results().items()} == dict(enumerate(outcomes))
    assert "[6/6]" in out


def test_at_most_workers_trials_run_at_once(pools: Pools) -> None:
    # Trials of different lengths, so that workers free up at different times.
    pools.script({n: runs(*[("progress", (10, 0.0))] * (n % 3), ("result", result()))
                   for n in range(7)})
    source = FakeSource(7)
    run(pools, source, workers=3)
    assert pools.only.size == 3
    assert pools.only.most_at_once == 3
    # Seen from the store: never more than 3 claimed trials without their record.
    open_trials: set[int] = set()
    for kind, number in source.log:
        if kind == "claim":
            open_trials.add(number)
            assert len(open_trials) <= 3
        elif kind == "record":
            open_trials.remove(number)
    assert len(source.recorded) == 7


def test_heartbeats_name_the_running_trials(pools: Pools) -> None:
    pools.script({0: runs(("progress", (1, 0.0)), ("progress", (2, 0.0)), ("result", result())),
                   1: runs(("result", result()))})
    source = FakeSource(2)
    run(pools, source, workers=2)
    assert source.heartbeats, "no heartbeat"
    running: set[int] = set()
    for kind, item in source.log:
        if kind == "claim":
            running.add(item)
        elif kind == "record":
            running.discard(item)
        else:
            assert kind == "heartbeat" and set(item) == running
    assert [0] in [sorted(h) for h in source.heartbeats]  # after trial 1 ended


def test_a_trial_whose_worker_died_runs_again_under_its_number(pools: Pools) -> None:
    pools.script({1: [[("progress", (300, 0.0)), ("died", -9)],
                       [("progress", (500, 0.0)), ("result", result(score=4.0))]]})
    source = FakeSource(3)
    summary, out = run(pools, source, workers=2)
    assert [n for n, _ in pools.only.submitted].count(1) == 2
    assert [s for n, s in pools.only.submitted if n == 1] == [spec(1), spec(1)]
    assert [n for kind, n in source.log if kind == "claim"] == [0, 1, 2]  # not claimed again
    assert sorted(n for n, _, _ in source.recorded) == [0, 1, 2]
    assert source.results()[1] == result(score=4.0)
    assert summary == CommandRun(complete=3)
    assert "trial 1: interrupted (worker exit code -9), rerun" in out


def test_a_trial_whose_worker_dies_every_time_is_recorded_as_failed(
        pools: Pools) -> None:
    codes = [-9, 137, -11, 1, 2][:MAX_WORKER_DEATHS]
    pools.script({0: [[("progress", (10, 0.0)), ("died", code)] for code in codes]})
    source = FakeSource(2)
    summary, _ = run(pools, source, workers=2)
    assert [n for n, _ in pools.only.submitted].count(0) == MAX_WORKER_DEATHS  # not once more
    assert [n for n, _, _ in source.recorded].count(0) == 1
    failed = source.results()[0]
    assert failed.outcome == Outcome.FAILED
    assert failure_kind(failed.failure) == Failure.ERROR
    assert f"exit code {codes[-1]}" in str(failed.failure)
    assert summary == CommandRun(complete=1, failed=1, errors=1)


def test_a_checkpoint_is_answered_with_what_the_source_said(pools: Pools) -> None:
    pools.script({
        0: runs(("checkpoint", (500, 1.5)), ("result", result())),
        1: runs(("progress", (200, 0.0)), ("checkpoint", (500, -3.0)),
                ("result", TrialResult(outcome=Outcome.PRUNED, pruned_at=500))),
    })
    source = FakeSource(2, answers={0: True, 1: False})
    summary, _ = run(pools, source, workers=2)
    assert sorted(source.checkpoints) == [(0, 500, 1.5), (1, 500, -3.0)]
    assert sorted(pools.only.replies) == [(0, True), (1, False)]
    assert summary == CommandRun(complete=1, pruned=1)


def test_ctrl_c_gives_the_running_trials_back_and_keeps_what_ended(
        pools: Pools) -> None:
    long = runs(*[("progress", (10 * i, 0.0)) for i in range(20)], ("result", result()))
    # Trial 0 ends on the 2nd events() call and trial 2 takes its worker; trial 1 runs on.
    pools.script({0: runs(("progress", (10, 0.0)), ("result", result())), 1: long, 2: long},
           interrupt_at=4)
    source = FakeSource(4)
    summary, out = run(pools, source, workers=2)
    assert summary.interrupted is True
    assert (summary.complete, summary.failed, summary.pruned) == (1, 0, 0)
    assert [n for n, _, _ in source.recorded] == [0]
    assert sorted(n for n, _, _ in source.requeued) == [1, 2]
    assert all(s == spec(n) for n, s, _ in source.requeued)
    assert all(failure_kind(reason) == Failure.INTERRUPTED for _, _, reason in source.requeued)
    assert ("claim", 3) not in source.log  # nothing new is started after Ctrl-C
    assert pools.only.closed[0] is True  # the workers are stopped at once, not politely
    assert "queued for the next run" in out


def test_it_waits_for_trials_that_other_commands_may_give_back(pools: Pools) -> None:
    # Trial 5 is another command's: it can be claimed only after the queue was found empty,
    # while the source says trials run elsewhere.
    source = FakeSource(1, elsewhere=[True], comes_back=[5])
    summary, _ = run(pools, source, workers=1)
    assert [n for kind, n in source.log if kind == "claim"] == [0, 5]
    assert sorted(n for n, _, _ in source.recorded) == [0, 5]
    assert summary == CommandRun(complete=2)


def test_it_ends_when_nothing_is_left_here_or_elsewhere(pools: Pools) -> None:
    source = FakeSource(1, comes_back=[5])  # never claimed: nothing runs elsewhere
    summary, _ = run(pools, source, workers=1)
    assert [n for n, _, _ in source.recorded] == [0]
    assert summary == CommandRun(complete=1)
