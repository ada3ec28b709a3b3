"""Role functions for the logging tests (importable by module path, so group processes can run them)."""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path

from anodize import Endpoint

module_log = logging.getLogger(__name__)

FLOOD = 100_000  # records the flooding role logs in a tight loop


SEEN_WITHIN = 30.0  # seconds the held producer waits for the file LOGGING_TEST_SEEN names


def producer(ep: Endpoint) -> None:
    """Logs once at each severity through its endpoint's logger, then streams two numbers."""
    _log_each_severity(ep)
    _stream(ep)


def held_producer(ep: Endpoint) -> None:
    """Logs as :func:`producer` does, then waits (bounded) until the file that the environment's
    ``LOGGING_TEST_SEEN`` names exists (the test's client has seen the records), then streams."""
    _log_each_severity(ep)
    seen = Path(os.environ["LOGGING_TEST_SEEN"])
    deadline = time.monotonic() + SEEN_WITHIN
    while not seen.exists() and time.monotonic() < deadline:
        time.sleep(0.02)
    _stream(ep)


def _log_each_severity(ep: Endpoint) -> None:
    ep.logger.setLevel(logging.DEBUG)
    ep.logger.debug("debug from P")
    ep.logger.info("planning %d items", 2)
    ep.logger.warning("battery low")
    ep.logger.error("lidar lost")
    ep.logger.critical("safety stop")


def _stream(ep: Endpoint) -> None:
    for i in range(2):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def consumer(ep: Endpoint) -> None:
    """Logs through its module's logger (not the endpoint's): still the role's record."""
    while ep.recv("P").label == "data":
        pass
    module_log.info("consumer done")


def flooder(ep: Endpoint) -> None:
    """Logs :data:`FLOOD` records as fast as it can, then ends the stream."""
    for i in range(FLOOD):
        ep.logger.info("flood %d", i)
    ep.send("C", "stop")
