"""One module, anodize/_transport/dds/binding.py, is the seam to the Cyclone DDS binding.

Only it may import ``cyclonedds`` (through ``import_extra``) or reach into the
binding's private API: its C layer ``cyclonedds._clayer``, a private attribute of a
binding object (``writer._ref``), or an explicit ``__del__()``. Every other module
under anodize/ uses the names the seam declares, so a binding release that moves its
privates breaks one module. anodize/_ros/idl.py may import the binding's public
``cyclonedds.idl`` (lazily): the ROS message layer sits below the transports and
cannot import the seam.
"""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

from cyclonedds import core, domain, pub, sub, topic  # the tests' environment has every extra

ANODIZE = Path(__file__).resolve().parents[3] / "anodize"
SEAM = ANODIZE / "_transport" / "dds" / "binding.py"
PUBLIC_IMPORTS = {ANODIZE / "_ros" / "idl.py": {"cyclonedds.idl"}}


def _binding_privates() -> frozenset[str]:
    """The private attribute names of the binding's entity classes: their own and those they set."""
    names: set[str] = set()
    for module in (core, domain, pub, sub, topic):
        names |= set(re.findall(r"\bself\.(_[A-Za-z]\w*)", inspect.getsource(module)))
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__.startswith("cyclonedds"):
                names |= {name for name in vars(cls) if name.startswith("_") and not name.startswith("__")}
    return frozenset(names)


def _anodize_own(paths: list[Path]) -> frozenset[str]:
    """Private names anodize defines itself (``self._lock = ...``, ``def _update``): not the binding's."""
    own: set[str] = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
                own.add(node.attr)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                own.add(node.name)
    return frozenset(own)


def violations(source: str, private: frozenset[str], public_imports: set[str] = frozenset()) -> list[str]:
    """What in ``source`` reaches into the binding, one line each."""
    found = []
    if "_clayer" in source:
        found.append("mentions cyclonedds._clayer")
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            modules = [node.module or ""] if node.level == 0 else []
        else:
            modules = []
        found.extend(f"line {node.lineno}: imports {module}" for module in modules
                     if module.split(".")[0] == "cyclonedds" and module not in public_imports)
        if isinstance(node, ast.Attribute) and node.attr in private:
            found.append(f"line {node.lineno}: .{node.attr}")
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "__del__":
            found.append(f"line {node.lineno}: calls __del__()")
    return found


def test_no_module_but_the_seam_touches_the_bindings_private_api() -> None:
    paths = sorted(ANODIZE.rglob("*.py"))
    private = _binding_privates() - _anodize_own(paths)
    assert "_ref" in private  # the one the transport needs, found by the introspection
    offenders = {str(path.relative_to(ANODIZE)): found for path in paths if path != SEAM
                 if (found := violations(path.read_text(), private, PUBLIC_IMPORTS.get(path, set())))}
    assert offenders == {}


def test_the_seam_is_where_the_private_api_is_used() -> None:
    # The check above is not vacuous: the seam itself has what it would refuse elsewhere.
    found = violations(SEAM.read_text(), _binding_privates())
    assert any("_clayer" in line for line in found) and any("._ref" in line for line in found)
    assert any("__del__" in line for line in found)


def test_the_checker_sees_each_kind_of_reach() -> None:
    private = frozenset({"_ref"})
    source = ("from cyclonedds._clayer import ddspy_write\nimport cyclonedds.pub\n"
              "ddspy_write(writer._ref, b'')\nreader.__del__()\n")
    assert sorted(violations(source, private)) == [
        "line 1: imports cyclonedds._clayer", "line 2: imports cyclonedds.pub", "line 3: ._ref",
        "line 4: calls __del__()", "mentions cyclonedds._clayer"]
    assert violations("from cyclonedds.idl import types\n", private, {"cyclonedds.idl"}) == []
