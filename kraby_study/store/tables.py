"""The tables kraby-study keeps beside Optuna's, the names it checks a store by, and its curves
read back."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import TYPE_CHECKING

import sqlalchemy as sa

if TYPE_CHECKING:
    import pandas as pd

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

_trials = sa.table("trials", sa.column("trial_id"), sa.column("study_id"))
"""Optuna's trials, as far as an orphan curve point is told by them."""


def drop_orphan_curves(connection: sa.Connection) -> int:
    """Delete the learning-curve points whose trial is no longer stored, and count them.

    A study deleted with Optuna's own tools (``optuna delete-study``), which know nothing of
    this table, leaves its points behind, and a later trial can be given a deleted trial's id
    (SQLite reuses the highest ids): the points would then read as that trial's curve. A
    command that writes calls this when it opens the store, before it creates any trial.
    """
    orphan = ~sa.exists().where(_trials.c.trial_id == curve_points.c.trial_id,
                                _trials.c.study_id == curve_points.c.study_id)
    return connection.execute(curve_points.delete().where(orphan)).rowcount


def read_curves(connection: sa.Connection, study_id: int, numbers_of: Mapping[int, int],
                numbers: Collection[int] | None = None) -> pd.DataFrame:
    """Learning-curve points (columns ``CURVE_COLUMNS``) of one study's trials, or of the given
    trial numbers, in one query, sorted by trial and step; empty for a plain Optuna store.

    Args:
        connection: An open connection to the store.
        study_id: Optuna's id of the study.
        numbers_of: Trial number of each of the study's trial ids.
        numbers: The trials wanted (None: all).
    """
    # pandas is loaded here, by the commands that read curves (the report, the auc rule):
    # list and most commands never need it, and it costs a quarter of a second.
    import pandas as pd

    query = (sa.select(curve_points.c.trial_id, curve_points.c.step,
                       curve_points.c.mean_reward, curve_points.c.wall_time,
                       curve_points.c.episodes)
             .where(curve_points.c.study_id == study_id))
    if not sa.inspect(connection).has_table(curve_points.name):
        return pd.DataFrame(columns=CURVE_COLUMNS)
    frame = pd.read_sql(query, connection)
    frame.insert(0, "number", frame.pop("trial_id").map(numbers_of))
    if numbers is not None:
        frame = frame[frame["number"].isin(list(numbers))]
    frame = frame.astype({"number": int})
    return frame.sort_values(["number", "step"], kind="stable").reset_index(drop=True)
