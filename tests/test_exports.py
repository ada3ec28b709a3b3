"""anodize's public API, declared and checked (in the spirit of trio's ``_tests/test_exports.py``).

The rule: the public modules are ``anodize`` and ``anodize.errors`` (:data:`PUBLIC_MODULES`);
every other module under ``anodize`` is private, whatever its name. The subpackages are to
be renamed with a leading underscore (``anodize/_session``, ``anodize/_transport``, ...), and
until then they count as private here too. What a user needs is re-exported from ``anodize``.

Checked here:

- TinMan (the reference application, its own distribution), ``examples/`` and the generated
  endpoint modules in ``examples/generated`` import nothing from a private module, and name no
  private attribute of ``anodize`` (an AST scan; bench/ and tests/ may use private modules);
- every name in ``anodize.__all__`` resolves and is listed once, and has a docstring;
- every public exception defined anywhere under ``anodize/`` (a subclass of ``AnodizeError``)
  is reachable from ``anodize`` as the same class, and has a docstring;
- ``import anodize`` and ``from anodize import *`` need none of the extras.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

import anodize
from anodize.errors import AnodizeError

ROOT = Path(__file__).resolve().parents[1]

# The public modules, each with the reason it is public.
PUBLIC_MODULES = {
    "anodize": "the API: everything a program, a system file's roles or a named system needs",
    "anodize.errors": "the error family, for programs that catch by module",
}
# Where programs that users write (or generate) live: they may use the public API only.
USER_CODE = {
    "tinman": ROOT / "tinman" / "src" / "tinman",
    "examples": ROOT / "examples",  # with examples/generated, the output of `anodize project`
}
# The extras' top-level modules (pyproject.toml, [project.optional-dependencies]).
EXTRA_MODULES = ("cyclonedds", "zenoh", "rosbags", "mcap", "foxglove", "matplotlib")


def _python_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts)


def _private_uses(source: str, label: str) -> list[str]:
    """Where the program ``source`` reaches past anodize's public API: imports of a private
    module, or a name (or attribute) of ``anodize`` that it does not export."""
    public_names = {*anodize.__all__, *(m.rpartition(".")[2] for m in PUBLIC_MODULES if m != "anodize")}
    tree = ast.parse(source, label)
    found: list[str] = []
    for node in ast.walk(tree):
        where = f"{label}:{getattr(node, 'lineno', 0)}"
        if isinstance(node, ast.Import):
            found.extend(f"{where}: import {alias.name}" for alias in node.names
                         if alias.name.split(".")[0] == "anodize" and alias.name not in PUBLIC_MODULES)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] != "anodize":
                continue
            if node.module not in PUBLIC_MODULES:
                found.append(f"{where}: from {node.module} import ...")
            elif node.module == "anodize":
                found.extend(f"{where}: from anodize import {alias.name}" for alias in node.names
                             if alias.name not in public_names)
        elif (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "anodize"
              and node.attr not in public_names and not node.attr.startswith("__")):
            found.append(f"{where}: anodize.{node.attr}")
    return found


@pytest.mark.parametrize("name", sorted(USER_CODE))
def test_user_code_uses_only_the_public_api(name: str) -> None:
    files = _python_files(USER_CODE[name])
    assert files, f"no Python files under {USER_CODE[name]}"
    assert [use for path in files
            for use in _private_uses(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))] == []


def test_the_scan_finds_private_uses() -> None:
    # The check above could pass by finding nothing: it must see each kind of private use.
    source = ("import anodize._session\nfrom anodize._tools.config import load_config\nfrom anodize import tools\n"
              "import anodize\nanodize._supervision.System\nfrom anodize import System, errors\n"
              "from anodize.errors import AnodizeError\nanodize.System\n")
    uses = _private_uses(source, "program.py")
    assert [use.split(": ", 1)[1] for use in uses] == [
        "import anodize._session", "from anodize._tools.config import ...", "from anodize import tools",
        "anodize._supervision"]


def test_every_exported_name_resolves_is_listed_once_and_is_documented() -> None:
    assert [name for name, n in Counter(anodize.__all__).items() if n > 1] == []
    missing = [name for name in anodize.__all__ if not hasattr(anodize, name)]
    assert missing == []
    undocumented = [name for name in anodize.__all__
                    if (inspect.isclass(getattr(anodize, name)) or inspect.isfunction(getattr(anodize, name)))
                    and not inspect.getdoc(getattr(anodize, name))]
    assert undocumented == []
    star: dict[str, object] = {}
    exec("from anodize import *", star)
    assert set(star) - {"__builtins__"} == set(anodize.__all__)


def _anodize_modules() -> list[str]:
    names = []
    for path in _python_files(ROOT / "anodize"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__main__":
            continue
        names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


def _public_exceptions() -> dict[str, type[BaseException]]:
    """Every exception class with a public name defined under anodize/ that derives from AnodizeError."""
    found: dict[str, type[BaseException]] = {}
    for module_name in _anodize_modules():
        module = importlib.import_module(module_name)
        for name, value in vars(module).items():
            if (inspect.isclass(value) and issubclass(value, AnodizeError) and value.__module__ == module_name
                    and not name.startswith("_")):
                assert name not in found or found[name] is value, f"two public exceptions named {name}"
                found[name] = value
    return found


def test_every_public_exception_is_reachable_from_anodize_and_documented() -> None:
    exceptions = _public_exceptions()
    # The scan found the family, including errors defined deep in the subpackages.
    assert {"AnodizeError", "ConfigurationError", "EncodeError", "DecodeError", "RecordingError",
            "ConfigError", "StartBarrierError"} <= set(exceptions)
    unreachable = sorted(f"{cls.__module__}.{name}" for name, cls in exceptions.items()
                         if getattr(anodize, name, None) is not cls)
    assert unreachable == []
    undocumented = sorted(name for name, cls in exceptions.items() if not (cls.__doc__ or "").strip())
    assert undocumented == []
    # RoleStopped (a BaseException, so `except Exception` in a role does not swallow a stop) too.
    assert anodize.RoleStopped.__doc__


def test_anodize_imports_without_any_extra() -> None:
    # A fresh interpreter in which the extras' modules cannot be imported, as after a bare
    # `pip install anodize`: the public API imports, and a name whose module needs an extra
    # says which extra to install.
    program = f"""
import importlib.abc, sys
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in {EXTRA_MODULES!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
sys.meta_path.insert(0, Block())
import anodize, anodize.errors
from anodize import *
print(anodize.StartBarrierError.__name__, anodize.SplitBrainError.__name__)  # DDS's and Zenoh's, no extra
try:
    anodize.Zenoh().runner(None)
except anodize.MissingExtraError as error:
    print(error)
print(sorted(m for m in sys.modules if m.split(".")[0] in {EXTRA_MODULES!r}))
"""
    done = subprocess.run([sys.executable, "-c", program], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "StartBarrierError SplitBrainError",
        ("the Zenoh transport needs the Python package of module 'zenoh', which is not installed; "
         "install it with: pip install 'anodize[zenoh]'"),
        "[]",
    ]
