"""The two config trees: the packaged one (``kraby_conf``) and the working folder's ./conf/,
which comes first in Hydra's search path (no Hydra here: ``list`` reads this without
composing)."""

from __future__ import annotations

from pathlib import Path

CONFIG_MODULE = "kraby_conf"
USER_CONF_DIR = "conf"
"""A folder of that name in the working directory extends the packaged tree (same groups)."""


def user_conf_dir(cwd: Path | None = None) -> Path | None:
    """The working folder's ./conf/, unless it is missing or is the packaged tree itself (a
    command run from an editable checkout)."""
    user_dir = ((cwd or Path.cwd()) / USER_CONF_DIR).resolve()
    if not user_dir.is_dir():
        return None
    packaged = Path(__import__(CONFIG_MODULE).__file__).resolve().parent
    return None if user_dir == packaged else user_dir
