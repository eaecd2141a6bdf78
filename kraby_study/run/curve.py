"""The stored metrics of a run: its learning curve and its final score, from its episodes.

An episode is ``(env steps at its end, its reward, seconds since training started)``.
"""

from __future__ import annotations

import numpy as np

from kraby_study.records.attributes import CurvePoint
from kraby_study.records.definition import FINAL_FRACTION

Episode = tuple[int, float, float]


def bin_curve(episodes: list[Episode], every: int) -> list[CurvePoint]:
    """Average episodes into bins of ``every`` env steps; a bin holds the episodes that ended
    after its start and at or before its end (its ``step``). Empty bins are left out."""
    bins: dict[int, list[Episode]] = {}
    for episode in episodes:
        bins.setdefault((episode[0] - 1) // every, []).append(episode)
    return [
        CurvePoint(step=(index + 1) * every,
                   mean_reward=float(np.mean([e[1] for e in members])),
                   wall_time=max(e[2] for e in members), episodes=len(members))
        for index, members in sorted(bins.items())
    ]


def final_score(episodes: list[Episode], total_steps: int) -> float | None:
    """Mean reward of the episodes that ended in the last 10 % of ``total_steps`` (strictly
    after 90 %); None if none did."""
    start = total_steps * (1.0 - FINAL_FRACTION)
    late = [e[1] for e in episodes if e[0] > start]
    return float(np.mean(late)) if late else None


def mean_curve(curves: list[list[CurvePoint]]) -> list[CurvePoint]:
    """Average several runs' curves bin by bin (a trial of several seeds stores one curve):
    the mean reward and mean wall time of the runs that have the bin, their episodes summed."""
    if len(curves) == 1:
        return curves[0]
    by_step: dict[int, list[CurvePoint]] = {}
    for curve in curves:
        for point in curve:
            by_step.setdefault(point.step, []).append(point)
    return [CurvePoint(step=step, mean_reward=float(np.mean([p.mean_reward for p in pts])),
                       wall_time=float(np.mean([p.wall_time for p in pts])),
                       episodes=sum(p.episodes for p in pts))
            for step, pts in sorted(by_step.items())]
