"""PyBullet, imported once with its build-time banner kept off the terminal."""

from __future__ import annotations

import os
import sys
from types import ModuleType


def _import_quietly() -> ModuleType:
    # pybullet's C code writes "pybullet build time: ..." to file descriptor 2 when imported,
    # into every command's and every worker's output. Import errors still raise as usual.
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
            import pybullet
    finally:
        os.dup2(saved, 2)
        os.close(saved)
    return pybullet


p = _import_quietly()
