"""Role functions for the logging tests (importable by module path, so group processes can run them)."""

from __future__ import annotations

import logging

from anodize import Endpoint

module_log = logging.getLogger(__name__)

FLOOD = 100_000  # records the flooding role logs in a tight loop


def producer(ep: Endpoint) -> None:
    """Logs once at each severity through its endpoint's logger, then streams two numbers."""
    ep.logger.setLevel(logging.DEBUG)
    ep.logger.debug("debug from P")
    ep.logger.info("planning %d items", 2)
    ep.logger.warning("battery low")
    ep.logger.error("lidar lost")
    ep.logger.critical("safety stop")
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
