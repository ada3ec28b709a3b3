"""The import rules of ARCHITECTURE.md and STYLE.md, checked on the source."""

from __future__ import annotations

import ast
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


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
