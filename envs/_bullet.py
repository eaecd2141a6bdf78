"""PyBullet, imported once with its build-time banner kept off standard output."""

from __future__ import annotations

import os
import sys


def _import_quietly():  # noqa: ANN202 - returns the pybullet module
    # pybullet's C code prints "pybullet build time: ..." to file descriptor 1 on import,
    # which would garble the CLI's output and any machine-read stdout.
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            import pybullet
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    return pybullet


p = _import_quietly()
