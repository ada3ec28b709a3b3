"""Roles that reach a package's submodule two ways; the anodize runtime itself is not read."""

import plant.state
from plant import state

from anodize import Endpoint


def producer(ep: Endpoint) -> None:
    plant.state.events.append("started")
    ep.send("C", "stop")


def consumer(ep: Endpoint) -> None:
    ep.recv("P")
    state.events.clear()
