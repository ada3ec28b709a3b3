"""Optional dependencies: a missing extra fails where it is needed, naming the fix."""

from __future__ import annotations

import pytest

from anodize._extras import import_extra
from anodize.errors import AnodizeError, MissingExtraError


def test_a_missing_extra_names_the_pip_install_that_fixes_it() -> None:
    with pytest.raises(MissingExtraError) as info:
        import_extra("no_such_module_for_anodize", "dds", "the DDS transport")
    assert str(info.value) == ("the DDS transport needs the Python package of module 'no_such_module_for_anodize', "
                               "which is not installed; install it with: pip install 'anodize[dds]'")
    assert (info.value.feature, info.value.extra, info.value.module) == (
        "the DDS transport", "dds", "no_such_module_for_anodize")
    assert isinstance(info.value, ImportError) and isinstance(info.value, AnodizeError)


def test_an_installed_module_is_returned() -> None:
    assert import_extra("json", "dds", "the DDS transport").__name__ == "json"
