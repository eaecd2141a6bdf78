"""Progress of a running study: a tqdm bar on a terminal, plain lines in a log.

Every per-trial line carries the same figures as the bar: trials done out of total, env steps
per second and an ETA, e.g.::

    [3/8] clip_range=0.2 seed 1: complete, score -0.0123 (12 s) | 1,820 steps/s, ETA 1m05s

On a terminal the lines are written with `tqdm.tqdm.write` above one live bar line; in a log or a
pipe there is no bar and no escape code, only the lines, flushed one by one.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

from tqdm import tqdm

from kraby_study.records.attributes import TrialResult
from kraby_study.records.stored import Outcome

REDRAW_SECONDS = 0.5
"""The live bar is redrawn at most this often on steps (starts and ends redraw it at once)."""

REASON_CHARS = 120
"""A failure reason is cut to this many characters (the ellipsis included)."""

_BAR_FORMAT = "{desc}: {n_fmt}/{total_fmt} |{bar}| {elapsed}{postfix}"


def duration(seconds: float) -> str:
    """``1m05s``, or ``2h03m`` from an hour on."""
    seconds = int(max(0, seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}h{minutes:02d}m" if hours else f"{minutes}m{secs:02d}s"


def one_line(text: str, limit: int = REASON_CHARS) -> str:
    """Text on one line (whitespace runs and newlines collapsed), cut to ``limit`` characters."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3].rstrip() + "..."


def describe(result: TrialResult, cost: bool = False, why: str | None = None) -> str:
    """How a trial ended, in a few words: ``complete, score -0.0123 (12 s)`` and the like;
    with ``cost`` (a two-objective search) its cost too: ``complete, score -0.0123, cost
    8.41 CPU s/seed (12 s)``; ``why``: why its source stopped a pruned trial, when not its
    pruner (``pruned at 4,096 env steps: <why>``)."""
    if result.outcome == Outcome.COMPLETE:
        score = "" if result.final_score is None else f", score {result.final_score:.4g}"
        seconds = result.training_time()
        if cost and seconds is not None:
            score += f", cost {seconds:.3g} CPU s/seed"
        return f"complete{score} ({result.wall_time or 0:.0f} s)"
    if result.outcome == Outcome.PRUNED:
        where = "" if result.pruned_at is None else f" at {result.pruned_at:,} env steps"
        return f"pruned{where}" + (f": {why}" if why else "")
    if result.outcome == Outcome.FAILED:
        return f"failed ({one_line(result.failure)})" if result.failure else "failed"
    return str(result.outcome)


def interrupted(reason: str) -> str:
    """``worker exit code -9, rerun`` -> ``interrupted (worker exit code -9), rerun``;
    ``queued for the next run`` -> ``interrupted, queued for the next run``."""
    reason = one_line(reason)
    if not reason:
        return "interrupted"
    cause, sep, then = reason.rpartition(", ")
    return f"interrupted ({cause}), {then}" if sep else f"interrupted, {reason}"


class Progress:
    """Trials done out of total, env steps per second and an ETA, for one command.

    The figures count this command's trials only:

    - **steps/s**: env steps trained by the trials this command ran (the ended ones, the
      running ones so far, and the attempts lost to a dead worker, which were trained too)
      divided by the wall time since the command started.
    - **ETA**: env steps still to train divided by steps/s. The steps still to train are the
      running trials' budgets minus their steps so far, plus, for each trial neither ended nor
      running, the mean env steps of a trial: of the trials this command ended (so pruned and
      failed trials pull it down), else of the budgets of the trials it started. ``?`` until
      a step was measured. Trials that other commands run (several machines on one store)
      are counted as waiting here, so the ETA is then an upper bound.

    Interrupted attempts are not ended trials: they do not count as done.

    A search under a CPU budget ends when the budget is used, whatever its trial total, so its
    ``budget`` (a callable giving e.g. ``845 of 1,200 CPU s used``) takes the ETA's place.
    """

    def __init__(self, title: str, total: int, done: int, stream: TextIO | None = None,
                 live: bool | None = None, *, clock: Callable[[], float] = time.monotonic,
                 budget: Callable[[], str] | None = None) -> None:
        self.title = title
        self.budget = budget
        self.total = total
        self.done = done
        self.failed = 0
        self.stream = stream if stream is not None else sys.stdout
        self.live = self.stream.isatty() if live is None else live
        self.clock = clock
        self.started = clock()
        self.running: dict[str, tuple[int, int]] = {}
        """label -> (env steps so far, env steps it will train)."""
        self.ended_steps = 0
        """Env steps of the trials this command ended."""
        self.ended = 0
        """Trials this command ended."""
        self.lost_steps = 0
        """Env steps of interrupted attempts (trained, then thrown away)."""
        self.budgets: list[int] = []
        """Env steps of each trial this command started."""
        self._last_draw = self.started
        self.bar: tqdm | None = None
        if self.live:
            self.bar = tqdm(total=total, initial=done, desc=title, file=self.stream,
                            unit="trial", bar_format=_BAR_FORMAT, dynamic_ncols=True,
                            mininterval=REDRAW_SECONDS, leave=False, postfix=self._status())

    # -- events -------------------------------------------------------------------------------

    def start(self, label: str, steps: int) -> None:
        """A trial started on a worker; ``steps``: env steps it will train (all seeds)."""
        if label in self.running:  # started again without an interrupt: its steps are lost
            self.lost_steps += self.running[label][0]
        self.running[label] = (0, steps)
        self.budgets.append(steps)
        self._print_line(f"started  {label}")

    def step(self, label: str, steps_done: int) -> None:
        """A running trial reported its env steps so far."""
        if label not in self.running:
            return
        self.running[label] = (steps_done, self.running[label][1])
        if self.bar is not None and self.clock() - self._last_draw >= REDRAW_SECONDS:
            self._draw()

    def finish(self, label: str, result: TrialResult, cost: bool = False,
               why: str | None = None) -> None:
        """A trial ended: complete, failed or pruned; ``cost``: show its cost (a
        two-objective search's trial); ``why``: why its source stopped it
        ([`describe`][kraby_study.run.progress.describe])."""
        so_far, _ = self.running.pop(label, (0, 0))
        trained = max(result.env_steps or 0, so_far)
        self.ended_steps += trained
        self.ended += 1
        self.done += 1
        if self.done > self.total:  # a search's rechecks may outnumber the ones foreseen
            self.total = self.done
            if self.bar is not None:
                self.bar.total = self.total
        if result.outcome == Outcome.FAILED:
            self.failed += 1
        if self.bar is not None:
            self.bar.update(1)
        self._print_line(f"[{self.done}/{self.total}] {label}: {describe(result, cost, why)}")

    def interrupt(self, label: str, reason: str) -> None:
        """A trial stopped without ending (its worker died, or Ctrl-C): not done."""
        so_far, _ = self.running.pop(label, (0, 0))
        self.lost_steps += so_far
        self._print_line(f"{label}: {interrupted(reason)}")

    def note(self, text: str) -> None:
        """A line of the command's own between the trials' (a racing search's moves)."""
        self._print_line(text)

    def close(self) -> None:
        """Leave the terminal clean: the bar is removed (the lines stay)."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        self.stream.flush()

    # -- figures ------------------------------------------------------------------------------

    def trained(self) -> int:
        """Env steps trained by this command's trials so far."""
        return self.ended_steps + self.lost_steps + sum(s for s, _ in self.running.values())

    def rate(self) -> float | None:
        """Env steps per second of wall time (None until a step was trained)."""
        elapsed = self.clock() - self.started
        steps = self.trained()
        return steps / elapsed if steps > 0 and elapsed > 0 else None

    def remaining_steps(self) -> float | None:
        """Env steps still to train (None when a waiting trial's size is not known yet)."""
        left = sum(max(0, budget - so_far) for so_far, budget in self.running.values())
        waiting = max(0, self.total - self.done - len(self.running))
        if not waiting:
            return float(left)
        if self.ended:
            mean = self.ended_steps / self.ended
        elif self.budgets:
            mean = sum(self.budgets) / len(self.budgets)
        else:
            return None
        return left + waiting * mean

    def eta(self) -> str:
        """Time left (see the class docstring), ``?`` when not measured yet."""
        rate, left = self.rate(), self.remaining_steps()
        if left == 0:
            return duration(0)
        if rate is None or left is None:
            return "?"
        return duration(left / rate)

    def speed(self) -> str:
        """``1,820``: env steps per second, ``?`` until measured."""
        rate = self.rate()
        return "?" if rate is None else f"{rate:,.0f}"

    def figures(self) -> str:
        """``1,820 steps/s, ETA 1m05s``: what every line ends with."""
        return f"{self.speed()} steps/s, {self._left()}"

    # -- output -------------------------------------------------------------------------------

    def _print_line(self, text: str) -> None:
        line = f"{text} | {self.figures()}"
        if self.bar is None:
            print(line, file=self.stream, flush=True)
            return
        self._postfix()
        tqdm.write(line, file=self.stream)  # clears the bar, writes, draws the bar again
        self.stream.flush()
        self._last_draw = self.clock()

    def _status(self) -> str:
        """What the bar shows after its count: ``1,820 steps/s, 2 running, 0 failed, ETA ...``."""
        return (f"{self.speed()} steps/s, {len(self.running)} running, {self.failed} failed, "
                f"{self._left()}")

    def _left(self) -> str:
        """``ETA 1m05s``, or under a CPU budget what of it is used."""
        return self.budget() if self.budget is not None else f"ETA {self.eta()}"

    def _postfix(self) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(self._status(), refresh=False)

    def _draw(self) -> None:
        """Redraw the bar now."""
        if self.bar is None:
            return
        self._postfix()
        self.bar.refresh()
        self._last_draw = self.clock()
