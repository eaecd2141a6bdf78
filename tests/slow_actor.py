"""A trial actor whose start imports a module that takes ``KRABY_TEST_SLOW_IMPORT`` seconds
to load, as torch does from a slow disk or on a loaded node (a fixture of the Ray tests)."""

from __future__ import annotations

import importlib
import sys
import time

from kraby_study.run.ray_pool import TrialActor


class SlowTrialActor(TrialActor):
    """:class:`TrialActor` after a slow import in its start; says how long the import took."""

    def __init__(self, shards: int) -> None:
        began = time.monotonic()
        sys.modules.pop("slow_import", None)
        importlib.import_module("slow_import")
        self.imported = time.monotonic() - began
        super().__init__(shards)

    def import_seconds(self) -> float:
        """How long the slow import took in this actor's start."""
        return self.imported

