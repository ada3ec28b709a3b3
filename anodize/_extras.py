"""Optional dependencies, imported only where a feature needs them.

The core of anodize installs with lark, networkx and numpy. Networked and ROS pieces
live in extras (``anodize[dds]``, ``anodize[ros]``, ...); each is imported through
:func:`import_extra` at the place that needs it, so a missing one fails there with a
:class:`~anodize.errors.MissingExtraError` that names the ``pip install`` that fixes it.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import MissingExtraError

__all__ = ["import_extra"]


def import_extra(module: str, extra: str, feature: str) -> ModuleType:
    """Import ``module``, which the extra ``extra`` installs, for ``feature``.

    Raises:
        MissingExtraError: the module (or a module it imports) is not installed.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as error:
        raise MissingExtraError(feature, extra, error.name or module) from error
