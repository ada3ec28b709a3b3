"""The import rules of ARCHITECTURE.md and STYLE.md, checked on the source."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import grimp
import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("sessiontypes", "anodize", "tinman")


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module.split(".")[0])
    return found


def test_layers_contract_holds() -> None:
    lint = Path(sys.executable).with_name("lint-imports")
    result = subprocess.run([str(lint)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contracts = pyproject["tool"]["importlinter"]["contracts"]
    assert len(contracts) >= 6  # between the packages, and inside anodize and its subpackages
    assert f"{len(contracts)} kept, 0 broken" in result.stdout


def test_only_parse_imports_lark() -> None:
    users = sorted(p.name for p in (ROOT / "sessiontypes").glob("*.py") if "lark" in _imports(p))
    assert users == ["parse.py"]


def test_sessiontypes_depends_only_on_stdlib_lark_networkx() -> None:
    allowed = {"lark", "networkx", "sessiontypes", "__future__"} | set(sys.stdlib_module_names)
    for path in (ROOT / "sessiontypes").glob("*.py"):
        assert _imports(path) <= allowed, (path.name, _imports(path) - allowed)


def import_cycles(*packages: str) -> list[list[str]]:
    """Each group of modules of ``packages`` that import one another, directly or not.

    Every import counts: at module level, inside functions (a circle "closed" by a
    function-level import is still a circle) and under ``TYPE_CHECKING``.
    """
    graph = grimp.build_graph(*packages, cache_dir=None)
    edges: nx.DiGraph[str] = nx.DiGraph()
    for module in graph.modules:
        edges.add_edges_from((module, imported) for imported in graph.find_modules_directly_imported_by(module))
    return sorted(sorted(group) for group in nx.strongly_connected_components(edges) if len(group) > 1)


def test_no_import_cycles() -> None:
    assert import_cycles(*PACKAGES) == []


def test_import_cycles_are_found_through_function_level_and_type_checking_imports(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    package = tmp_path / "circled"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "terms.py").write_text("def show() -> str:\n    from .printer import text\n    return text()\n")
    (package / "printer.py").write_text("from .terms import show\n\ndef text() -> str:\n    return ''\n")
    (package / "typed.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .user import U\n")
    (package / "user.py").write_text("from .typed import TYPE_CHECKING\n")
    (package / "leaf.py").write_text("from . import printer\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert import_cycles("circled") == [["circled.printer", "circled.terms"], ["circled.typed", "circled.user"]]


def test_sessiontypes_imports_itself_only_at_module_level() -> None:
    """No stage is imported inside a function (the way a circle used to be hidden)."""
    found = []
    for path in sorted((ROOT / "sessiontypes").rglob("*.py")):
        for function in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef):
                found += [f"{path.relative_to(ROOT)}:{node.lineno}" for node in ast.walk(function)
                          if isinstance(node, ast.ImportFrom)
                          and (node.level > 0 or (node.module or "").startswith("sessiontypes"))]
    assert found == []


PACKAGE_DIRS = (ROOT / "sessiontypes", ROOT / "anodize", ROOT / "tinman" / "src" / "tinman")


def _children(package: Path) -> set[str]:
    """The modules and subpackages directly inside ``package``, by their last name."""
    modules = {p.stem for p in package.glob("*.py") if p.stem != "__init__"}
    return modules | {p.parent.name for p in package.glob("*/__init__.py")}


def _layered(layer: str) -> set[str]:
    # `|` separates independent modules of a layer, `:` siblings that may import each other, and
    # parentheses mark an optional layer.
    return {name.strip().strip("()") for name in re.split(r"[|:]", layer)}


def uncontracted_packages(package_dirs: tuple[Path, ...], contracts: list[dict[str, Any]]) -> list[str]:
    """What is wrong with the layers contracts of every package of two or more modules.

    Each such package, found on disk under ``package_dirs`` (the root packages), needs a
    ``layers`` contract with that package as its one container, marked ``exhaustive`` and
    listing exactly the package's modules and subpackages. Returns one line per problem.
    """
    by_container = {tuple(c.get("containers", [])): c for c in contracts if c.get("type") == "layers"}
    problems = []
    for root in package_dirs:
        for init in sorted(root.rglob("__init__.py")):
            package = init.parent
            name = ".".join(package.relative_to(root.parent).parts)
            children = _children(package)
            if len(children) < 2:
                continue
            contract = by_container.get((name,))
            if contract is None:
                problems.append(f"{name}: expected a layers contract with containers = [{name!r}], found none")
                continue
            if contract.get("exhaustive") is not True:
                problems.append(f"{name}: expected its layers contract to be exhaustive, it is not")
            listed = set().union(*(_layered(layer) for layer in contract.get("layers", [])))
            if listed != children:
                problems.append(f"{name}: expected the layers to list {sorted(children)}, "
                                f"unlisted {sorted(children - listed)}, not modules {sorted(listed - children)}")
    return problems


def test_every_package_of_two_or_more_modules_has_an_exhaustive_layers_contract() -> None:
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert uncontracted_packages(PACKAGE_DIRS, pyproject["tool"]["importlinter"]["contracts"]) == []


def test_a_package_without_a_complete_contract_is_found(tmp_path: Path) -> None:
    top = tmp_path / "top"
    for folder in (top, top / "sub", top / "one", top / "part"):
        folder.mkdir()
        (folder / "__init__.py").write_text("")
    for module in ("top/a.py", "top/b.py", "top/sub/x.py", "top/sub/y.py", "top/one/only.py",
                   "top/part/p.py", "top/part/q.py"):
        (tmp_path / module).write_text("")
    contracts: list[dict[str, Any]] = [
        {"type": "layers", "containers": ["top"], "exhaustive": True, "layers": ["a : sub", "(b) | one | part"]},
        {"type": "layers", "containers": ["top.part"], "layers": ["p"]},
        {"type": "forbidden", "containers": ["top.sub"]},
    ]
    assert uncontracted_packages((top,), contracts) == [
        "top.part: expected its layers contract to be exhaustive, it is not",
        "top.part: expected the layers to list ['p', 'q'], unlisted ['q'], not modules []",
        "top.sub: expected a layers contract with containers = ['top.sub'], found none",
    ]
