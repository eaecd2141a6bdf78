"""Progress of a running study: a live block on a terminal, plain lines otherwise."""

from __future__ import annotations

import sys
import time
from typing import TextIO


def _duration(seconds: float) -> str:
    seconds = int(max(0, seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}h{minutes:02d}m" if hours else f"{minutes}m{secs:02d}s"


class Progress:
    """Trials done out of total, the running ones with their steps, and an ETA."""

    def __init__(self, title: str, total: int, done: int, stream: TextIO | None = None,
                 live: bool | None = None) -> None:
        self.title = title
        self.total = total
        self.done_before = done
        self.done = done
        self.failed = 0
        self.stream = stream or sys.stdout
        self.live = self.stream.isatty() if live is None else live
        self.started = time.monotonic()
        self.running: dict[str, tuple[int, int]] = {}
        self._drawn = 0
        self._last_draw = 0.0

    def start(self, label: str, steps: int) -> None:
        """A trial started on a worker."""
        self.running[label] = (0, steps)
        self._line(f"started  {label}")
        self.draw(force=True)

    def step(self, label: str, steps_done: int) -> None:
        """A running trial reported its steps."""
        if label in self.running:
            self.running[label] = (steps_done, self.running[label][1])
            self.draw()

    def finish(self, label: str, outcome: str) -> None:
        """A trial ended (complete, failed, pruned) or was interrupted."""
        self.running.pop(label, None)
        if not outcome.startswith("interrupted"):
            self.done += 1
            if outcome.startswith("failed"):
                self.failed += 1
        self._line(f"[{self.done}/{self.total}] {label}: {outcome}")
        self.draw(force=True)

    def eta(self) -> str:
        """Time left, from the pace of the trials finished in this command."""
        finished = self.done - self.done_before
        if finished <= 0:
            return "?"
        pace = (time.monotonic() - self.started) / finished
        return _duration(pace * (self.total - self.done))

    def _line(self, text: str) -> None:
        self._clear()
        print(text, file=self.stream, flush=True)

    def _clear(self) -> None:
        if self.live and self._drawn:
            self.stream.write(f"\x1b[{self._drawn}F\x1b[J")
            self._drawn = 0

    def draw(self, force: bool = False) -> None:
        """Redraw the live block (terminals only), at most twice a second."""
        if not self.live or (not force and time.monotonic() - self._last_draw < 0.5):
            return
        self._last_draw = time.monotonic()
        self._clear()
        lines = [f"{self.title}: {self.done}/{self.total} done, {self.failed} failed, "
                 f"{len(self.running)} running, elapsed "
                 f"{_duration(time.monotonic() - self.started)}, ETA {self.eta()}"]
        for label, (steps, total) in sorted(self.running.items()):
            lines.append(f"  {label}: {steps:,}/{total:,} steps")
        self.stream.write("\n".join(lines) + "\n")
        self.stream.flush()
        self._drawn = len(lines)

    def close(self) -> None:
        """Leave the terminal clean."""
        self._clear()
