"""A role whose module takes $HOSTS_TEST_SLOW_IMPORT seconds to import (bounded), in a group's process."""

from __future__ import annotations

import os
import time

from anodize import Endpoint

if os.environ.get("HOSTS_TEST_SLOW_IMPORT"):
    time.sleep(min(float(os.environ["HOSTS_TEST_SLOW_IMPORT"]), 120.0))


def producer(ep: Endpoint) -> None:
    """Never reached in the test: the group's start is over before its module is imported."""
    ep.send("C", "stop")
