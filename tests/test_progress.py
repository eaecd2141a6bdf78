"""Progress lines and the live bar, driven with a fake clock (no training)."""

from __future__ import annotations

import io
import re

import pytest

from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import Outcome
from kraby_study.run.progress import REASON_CHARS, Progress

A, B, C = "clip_range=0.2 seed 1", "clip_range=0.4 seed 0", "lr=0.0031 gamma=0.91 (t7)"
FIGURES = re.compile(r" \| ([\d,?]+) steps/s, ETA (\S+)$")


class Clock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def complete(steps: int = 1000, score: float = -0.0123, wall: float = 12.0) -> TrialResult:
    return TrialResult(outcome=Outcome.COMPLETE, final_score=score, wall_time=wall,
                       env_steps=steps)


def make(total: int = 8, done: int = 2, live: bool = False) -> tuple[Progress, io.StringIO, Clock]:
    stream, clock = io.StringIO(), Clock()
    return Progress("clip_range", total, done, stream, live, clock=clock), stream, clock


def lines(stream: io.StringIO) -> list[str]:
    return stream.getvalue().splitlines()


def figures(line: str) -> tuple[str, str]:
    match = FIGURES.search(line)
    assert match, line
    return match.group(1), match.group(2)


def test_lines_count_done_out_of_total_from_the_trials_done_before() -> None:
    progress, stream, clock = make(total=8, done=2)
    progress.start(A, 1000)
    progress.start(B, 1000)
    clock.now += 10
    progress.finish(A, complete())
    progress.finish(B, TrialResult(outcome=Outcome.PRUNED, pruned_at=20480, env_steps=20480))
    out = lines(stream)
    assert out[0].startswith(f"started  {A} | ")
    assert out[1].startswith(f"started  {B} | ")
    assert out[2].startswith(f"[3/8] {A}: complete, score -0.0123 (12 s) | ")
    assert out[3].startswith(f"[4/8] {B}: pruned at 20,480 env steps | ")
    assert (progress.done, progress.failed) == (4, 0)


def test_steps_per_second_and_eta_are_exact_with_a_controlled_clock() -> None:
    progress, stream, clock = make(total=4, done=0)
    progress.start(A, 2000)
    progress.start(B, 2000)
    assert figures(lines(stream)[-1]) == ("?", "?")  # nothing measured yet
    clock.now += 2
    progress.step(A, 1000)
    progress.step(B, 1000)
    assert progress.rate() == 1000.0  # 2,000 steps in 2 s, running trials included
    clock.now += 2
    progress.finish(A, complete(steps=2000))
    # 2,000 + 1,000 steps in 4 s: 750 steps/s. Left: 1,000 of B, and 2 waiting trials of
    # 2,000 steps (the mean of the ended ones): 5,000 steps / 750 = 6.7 s.
    assert figures(lines(stream)[-1]) == ("750", "0m06s")
    progress.step(B, 1500)
    assert progress.figures() == "875 steps/s, ETA 0m05s"  # 4,500 steps / 875 = 5.1 s
    clock.now += 1
    progress.finish(B, complete(steps=2000))
    # 4,000 steps in 5 s = 800 steps/s; 2 trials of 2,000 steps wait: 5 s.
    assert figures(lines(stream)[-1]) == ("800", "0m05s")


def test_eta_uses_the_started_budgets_until_a_trial_ended() -> None:
    progress, stream, clock = make(total=3, done=0)
    progress.start(A, 3000)
    clock.now += 10
    progress.step(A, 1000)  # 100 steps/s; left: 2,000 + 2 waiting x 3,000 = 8,000 steps
    assert progress.remaining_steps() == 8000
    assert progress.eta() == "1m20s"
    progress.finish(A, TrialResult(outcome=Outcome.PRUNED, pruned_at=1000, env_steps=1000))
    assert progress.remaining_steps() == 2000  # a pruned trial pulls the mean down
    progress.finish(B, complete())
    progress.finish(C, complete())
    assert progress.eta() == "0m00s"


def test_nothing_left_is_an_eta_of_zero_even_unmeasured() -> None:
    progress, stream, _ = make(total=1, done=0)
    assert progress.eta() == "?"
    progress.finish(A, TrialResult(outcome=Outcome.FAILED))  # no step trained, no time passed
    assert figures(lines(stream)[-1]) == ("?", "0m00s")
    assert make(total=3, done=3)[0].eta() == "0m00s"


def test_a_failure_reason_is_one_line_cut_with_an_ellipsis() -> None:
    progress, stream, _ = make()
    progress.start(B, 1000)
    reason = ("diverged: ValueError: Expected parameter loc (Tensor of shape (64, 3)) of\n"
              "   distribution Normal(loc: torch.Size([64, 3]))  to satisfy the constraint "
              "Real(), but found invalid values:\ntensor([[nan, nan, nan]])")
    progress.finish(B, TrialResult(outcome=Outcome.FAILED, failure=reason))
    out = lines(stream)
    assert len(out) == 2
    head = f"[3/8] {B}: failed ("
    assert out[1].startswith(head)
    shown = out[1][len(head):out[1].index(") | ")]
    assert len(shown) == REASON_CHARS and shown.endswith("...")
    assert shown.startswith("diverged: ValueError: Expected parameter loc (Tensor of shape "
                            "(64, 3)) of distribution Normal(")
    assert "  " not in shown


def test_a_short_failure_reason_is_kept_whole() -> None:
    progress, stream, _ = make()
    progress.finish(B, TrialResult(outcome=Outcome.FAILED, failure="error: no finite score"))
    assert lines(stream)[0].startswith(f"[3/8] {B}: failed (error: no finite score) | ")


def test_failed_count_comes_from_the_outcome() -> None:
    progress, stream, _ = make(live=True)
    progress.finish(A, TrialResult(outcome=Outcome.FAILED))
    progress.finish(B, TrialResult(outcome=Outcome.COMPLETE, failure="failed: not a failure"))
    progress.finish(C, TrialResult(outcome=Outcome.FAILED, failure="diverged: NaN loss"))
    progress.finish("d", TrialResult(outcome=Outcome.PRUNED, pruned_at=100))
    assert progress.failed == 2
    assert "0 running, 2 failed" in stream.getvalue()
    assert "3 failed" not in stream.getvalue()
    progress.close()


@pytest.mark.parametrize(("reason", "expected"), [
    ("worker exit code -9, rerun", "interrupted (worker exit code -9), rerun"),
    ("queued for the next run", "interrupted, queued for the next run"),
])
def test_an_interrupted_trial_is_not_done(reason: str, expected: str) -> None:
    progress, stream, clock = make(total=8, done=2)
    progress.start(A, 1000)
    clock.now += 1
    progress.step(A, 400)
    progress.interrupt(A, reason)
    assert lines(stream)[-1].startswith(f"{A}: {expected} | 400 steps/s, ETA ")
    assert (progress.done, progress.running) == (2, {})
    progress.start(A, 1000)
    clock.now += 1
    progress.finish(A, complete(steps=1000))
    # Not done twice; the lost attempt's steps were trained and count in steps/s.
    assert lines(stream)[-1].startswith(f"[3/8] {A}: complete")
    assert figures(lines(stream)[-1])[0] == "700"


def test_a_log_gets_plain_lines_and_no_bar() -> None:
    progress, stream, clock = make(live=None)  # a StringIO is no terminal
    progress.start(A, 1000)
    clock.now += 1
    progress.step(A, 500)
    progress.finish(A, complete())
    progress.close()
    text = stream.getvalue()
    assert progress.live is False and progress.bar is None
    assert "\r" not in text and "\x1b" not in text and "|#" not in text
    assert len(lines(stream)) == 2  # steps print nothing in a log
    assert all(FIGURES.search(line) for line in lines(stream))


def test_the_live_bar_shows_the_figures_and_close_removes_it() -> None:
    progress, stream, clock = make(total=8, done=2, live=True)
    assert progress.bar is not None
    progress.start(A, 1000)
    clock.now += 2
    progress.step(A, 1000)
    progress.finish(A, complete())
    text = stream.getvalue()
    assert "\rclip_range: 2/8 |" in text and "\rclip_range: 3/8 |" in text
    assert "1 running, 0 failed, ETA" in text and "500 steps/s, 0 running" in text
    assert f"\n[3/8] {A}: complete, score -0.0123 (12 s) | 500 steps/s, ETA 0m10s\n" \
        in text.replace("\r", "\n")
    bar = progress.bar
    progress.close()
    assert progress.bar is None and bar.disable  # closed, not merely dropped
    text = stream.getvalue()
    bar = text.rsplit("\rclip_range: ", 1)[1].split("\r", 1)[0]  # the last bar drawn
    # ... then the last thing written blanks its whole line and returns to its start.
    assert re.search(rf"\r {{{len(bar) + len('clip_range: ')},}}\r$", text)
    progress.close()  # twice is harmless


def test_the_live_bar_is_redrawn_at_most_twice_a_second_on_steps() -> None:
    progress, stream, clock = make(live=True)
    progress.start(A, 10_000)

    def draws() -> int:
        return stream.getvalue().count("\rclip_range: 2/8")

    before = draws()
    for _ in range(3):
        clock.now += 0.125
        progress.step(A, 100)
    assert draws() == before
    clock.now += 0.125
    progress.step(A, 200)
    assert draws() == before + 1  # 0.5 s since the last draw
    clock.now += 0.375
    progress.step(A, 300)
    assert draws() == before + 1
    clock.now += 0.125
    progress.step(A, 400)
    assert draws() == before + 2
    progress.close()


def test_steps_of_an_unknown_trial_are_ignored() -> None:
    progress, stream, clock = make()
    clock.now += 1
    progress.step("nobody", 5000)
    assert progress.trained() == 0 and progress.rate() is None
    assert stream.getvalue() == ""
