"""A module that takes ``KRABY_TEST_SLOW_IMPORT`` seconds to import (see slow_actor.py)."""

import os
import time

time.sleep(float(os.environ.get("KRABY_TEST_SLOW_IMPORT", "0")))
