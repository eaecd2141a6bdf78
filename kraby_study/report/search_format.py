"""How a search's parameters are written in its tables and drawn on its axes."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from optuna.distributions import (
    BaseDistribution,
    CategoricalDistribution,
    FloatDistribution,
    IntDistribution,
)


def format_param(value: Any, distribution: BaseDistribution | None) -> str:
    """A parameter value for a table cell."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(distribution, CategoricalDistribution) or isinstance(value, str):
        return str(value)
    if isinstance(distribution, IntDistribution):
        return str(int(value))
    if isinstance(distribution, FloatDistribution) and distribution.log:
        return f"{float(value):.3g}"
    return f"{float(value):.4g}" if isinstance(value, float) else str(value)


def is_log(distribution: BaseDistribution | None) -> bool:
    """Whether a parameter is searched on a log scale."""
    return isinstance(distribution, FloatDistribution | IntDistribution) and distribution.log


def numeric_array(values: pd.Series) -> np.ndarray:
    """A column as floats (NaN for missing)."""
    return pd.to_numeric(values, errors="coerce").to_numpy(dtype=float)

