"""Payload classes that codegen_fixtures/features.proto binds its types to."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Point:
    x: float
    y: float


class Outer:
    @dataclass(frozen=True)
    class Inner:
        name: str


@dataclass(frozen=True)
class State0:
    """Named like a generated state class, so the generated module must alias it."""

    value: int
