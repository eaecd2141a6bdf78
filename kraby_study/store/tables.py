"""The tables kraby-study keeps beside Optuna's, and the names it checks a store by."""

from __future__ import annotations

import sqlalchemy as sa

OPTUNA_TABLES = ("studies", "trials", "version_info")
"""Tables every Optuna store has: a SQLite file without them is not a study store."""

CURVE_COLUMNS = ["number", "step", "mean_reward", "wall_time", "episodes"]
"""Columns of the learning-curve frames the store gives out (``number`` is the trial's)."""

metadata = sa.MetaData()
curve_points = sa.Table(
    "kraby_curve_points", metadata,
    sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
    sa.Column("study_id", sa.Integer, nullable=False, index=True),
    sa.Column("trial_id", sa.Integer, nullable=False, index=True),
    sa.Column("step", sa.Integer, nullable=False),
    sa.Column("mean_reward", sa.Float, nullable=False),
    sa.Column("wall_time", sa.Float, nullable=False),
    sa.Column("episodes", sa.Integer, nullable=False),
)
"""One row per learning-curve bin per trial."""
