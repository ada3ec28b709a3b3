"""Example counts for property tests that follow the active hypothesis profile."""

from __future__ import annotations

from hypothesis import settings

_BASE = 100  # hypothesis's default max_examples, which the dev and ci profiles keep


def examples(count: int) -> int:
    """``count`` scaled by the profile: ``count`` under dev and ci, 10x under thorough."""
    return max(1, round(count * settings.default.max_examples / _BASE))
