"""Whether anodize's compiled extensions may be used (``_endpoint_core.c``, ``_frames.c``).

Not when the environment sets ``ANODIZE_PURE_PYTHON`` to anything but empty or ``0``: then
every part runs its pure-Python reference, as where nothing was compiled.
"""

from __future__ import annotations

import os

__all__ = ["allowed"]


def allowed() -> bool:
    """False when ``ANODIZE_PURE_PYTHON`` asks for the pure-Python code."""
    return os.environ.get("ANODIZE_PURE_PYTHON", "") in ("", "0")
