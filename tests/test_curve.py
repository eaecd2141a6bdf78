"""The stored metrics of a run (learning curve and final score), from hand-made episodes.

An episode is ``(env steps at its end, its reward, seconds since training started)``; every
expected value below is worked out by hand next to the episodes it comes from.
"""

from __future__ import annotations

from kraby_study.records.attributes import CurvePoint
from kraby_study.run.curve import bin_curve, final_score, mean_curve


def test_a_bin_holds_the_episodes_ending_after_its_start_and_up_to_its_end() -> None:
    # every=64: bin 1 is steps 1..64 (point at 64), bin 2 is 65..128 (point at 128).
    curve = bin_curve([(64, -1.0, 1.0), (65, 5.0, 2.0)], every=64)
    assert [(p.step, p.mean_reward, p.episodes) for p in curve] == [(64, -1.0, 1), (128, 5.0, 1)]


def test_a_bin_averages_its_rewards_keeps_its_latest_wall_time_and_counts_its_episodes() -> None:
    episodes = [
        (64, -3.0, 1.5),  # bin 64: ends exactly on the bin's end, so still in it
        (10, -1.0, 0.5),  # bin 64
        (65, 4.0, 2.0),  # bin 128: one step past 64
        # bin 192 (129..192): no episode, so no point
        (256, 2.0, 2.5),  # bin 256
        (200, 1.0, 3.0),  # bin 256: ended before the one above yet later in wall time
    ]
    assert bin_curve(episodes, every=64) == [
        # rewards -3 and -1: mean (-3 + -1) / 2 = -2; wall time max(1.5, 0.5) = 1.5
        CurvePoint(step=64, mean_reward=-2.0, wall_time=1.5, episodes=2),
        CurvePoint(step=128, mean_reward=4.0, wall_time=2.0, episodes=1),
        # rewards 2 and 1: mean (2 + 1) / 2 = 1.5; wall time max(2.5, 3.0) = 3.0
        CurvePoint(step=256, mean_reward=1.5, wall_time=3.0, episodes=2),
    ]


def test_a_curve_of_no_episodes_is_empty() -> None:
    assert bin_curve([], every=64) == []


def test_final_score_averages_the_episodes_ending_strictly_after_ninety_percent() -> None:
    # total 1000 steps: 90 % is step 900; the episode ending at 900 is not in the last 10 %.
    episodes = [(500, 50.0, 1.0), (900, 100.0, 2.0), (901, -1.0, 3.0), (1000, -2.0, 4.0)]
    # (-1 + -2) / 2 = -1.5
    assert final_score(episodes, total_steps=1000) == -1.5


def test_final_score_on_the_full_budget() -> None:
    # 250,000 steps: 90 % is 225,000 (excluded); 225,001 and 250,000 count: (3 + 6) / 2 = 4.5
    episodes = [(225_000, -100.0, 1.0), (225_001, 3.0, 2.0), (250_000, 6.0, 3.0)]
    assert final_score(episodes, total_steps=250_000) == 4.5


def test_final_score_is_none_when_no_episode_ended_in_the_last_ten_percent() -> None:
    assert final_score([(100, 1.0, 1.0), (900, 2.0, 2.0)], total_steps=1000) is None
    assert final_score([], total_steps=1000) is None


def test_the_mean_of_one_curve_is_that_curve() -> None:
    curve = [CurvePoint(64, -2.0, 1.0, 2), CurvePoint(128, 4.0, 2.0, 1)]
    assert mean_curve([curve]) == curve


def test_the_mean_of_two_curves_averages_them_bin_by_bin() -> None:
    a = [CurvePoint(64, -2.0, 1.0, 2), CurvePoint(128, 4.0, 2.0, 1)]
    b = [CurvePoint(64, 0.0, 3.0, 1), CurvePoint(128, 1.0, 5.0, 4)]
    assert mean_curve([a, b]) == [
        # reward (-2 + 0) / 2 = -1; wall (1 + 3) / 2 = 2; episodes 2 + 1 = 3
        CurvePoint(step=64, mean_reward=-1.0, wall_time=2.0, episodes=3),
        # reward (4 + 1) / 2 = 2.5; wall (2 + 5) / 2 = 3.5; episodes 1 + 4 = 5
        CurvePoint(step=128, mean_reward=2.5, wall_time=3.5, episodes=5),
    ]


def test_a_bin_only_one_curve_has_is_the_mean_of_the_curves_that_have_it() -> None:
    a = [CurvePoint(64, -2.0, 1.0, 2), CurvePoint(192, 6.0, 4.0, 1)]
    b = [CurvePoint(64, 0.0, 3.0, 1), CurvePoint(128, 1.0, 5.0, 4)]
    c = [CurvePoint(64, 5.0, 2.0, 3), CurvePoint(192, 2.0, 6.0, 2)]
    assert mean_curve([a, b, c]) == [
        # all three: reward (-2 + 0 + 5) / 3 = 1; wall (1 + 3 + 2) / 3 = 2; episodes 2 + 1 + 3
        CurvePoint(step=64, mean_reward=1.0, wall_time=2.0, episodes=6),
        # b only: its own point, not (1 + 0 + 0) / 3
        CurvePoint(step=128, mean_reward=1.0, wall_time=5.0, episodes=4),
        # a and c: reward (6 + 2) / 2 = 4; wall (4 + 6) / 2 = 5; episodes 1 + 2 = 3
        CurvePoint(step=192, mean_reward=4.0, wall_time=5.0, episodes=3),
    ]
