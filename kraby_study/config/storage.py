"""The store a command names, read from its overrides without composing the config.

Composing (Hydra and the schema) costs about a third of a second, and ``list`` needs nothing of
the config but the storage URL. When the overrides set nothing but ``storage``, as a plain URL,
and the working folder's ./conf/ holds no config.yaml of its own (which would replace the
packaged one), that URL, or the packaged default, is what composing would give; otherwise the
command composes as every other does. A file of a config group cannot set ``storage``: the
packaged config.yaml composes itself last (``_self_``), over its groups.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

from kraby_study.config.conf_dirs import user_conf_dir

DEFAULT_STORAGE = "sqlite:///studies/kraby.db"
"""The packaged default of ``storage`` (conf/config.yaml and the schema; a test holds the three
alike)."""
PLAIN_URL = re.compile(r"^[A-Za-z][A-Za-z0-9_+]*://[A-Za-z0-9_./:@%+?-]*$")
"""A URL Hydra's override grammar reads as it is written: no quotes, escapes, interpolations,
spaces, commas, brackets or equal signs."""


def plain_storage(overrides: Sequence[str], cwd: Path | None = None) -> str | None:
    """The storage URL the overrides name, known without composing; None when only composing
    can tell (another override, a URL Hydra would parse, a ./conf/config.yaml of the user's)."""
    urls = [o.split("=", 1)[1] for o in overrides if o.startswith("storage=")]
    if len(urls) != len(overrides) or len(urls) > 1:
        return None
    if urls and not PLAIN_URL.match(urls[0]):
        return None
    user = user_conf_dir(cwd)
    if user is not None and (user / "config.yaml").exists():
        return None
    return urls[0] if urls else DEFAULT_STORAGE
