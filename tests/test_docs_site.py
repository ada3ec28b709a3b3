"""The site's generated parts (docs/hooks/generate.py) say what their sources say.

The architecture page lists every import-linter contract of pyproject.toml, the
performance page every result file in bench/results/ with the load it was taken under
(a result without one is refused), the API reference every public name and nothing
private, the decisions' index every decision file.
"""

from __future__ import annotations

import importlib.util
import json
import re
import tomllib
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]


def _load(name: str, path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


generate = _load("docs_generate", REPO / "docs" / "hooks" / "generate.py")


def test_every_contract_and_layer_is_on_the_architecture_page() -> None:
    config = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["importlinter"]
    page = generate.layers()
    for contract in config["contracts"]:
        assert f"### {contract['name']}" in page
        for layer in contract.get("layers", []):
            for name in re.findall(r"[\w.]+", layer):
                assert f"`{name}`" in page


def test_a_new_contract_appears_without_editing_the_page(tmp_path: Path) -> None:
    pyproject = tmp_path / "pyproject.toml"
    pyproject.write_text('[tool.importlinter]\nroot_packages = ["p"]\n[[tool.importlinter.contracts]]\n'
                         'name = "p: a -> b"\ntype = "layers"\ncontainers = ["p"]\nlayers = ["a", "b | c"]\n'
                         '[[tool.importlinter.contracts]]\nname = "no c"\ntype = "forbidden"\n'
                         'source_modules = ["p.a"]\nforbidden_modules = ["p.c"]\n', encoding="utf-8")
    page = generate.layers(pyproject)
    assert "1. `a`\n2. `b` | `c`" in page
    assert "`p.a` must not import `p.c`." in page


def test_every_result_file_is_on_the_performance_page_with_its_load() -> None:
    page = generate.benchmarks()
    files = sorted((REPO / "bench" / "results").glob("*.json"))
    assert files, "bench/results/ holds the benchmarks' results"
    for path in files:
        document = json.loads(path.read_text(encoding="utf-8"))
        assert f"## {document['title']}" in page
        assert f"`{document.get('script') or f'bench/{path.stem}.py'}`" in page  # a mode of a script names it
        load = document["load"]
        assert {"cpus", "loadavg_start", "loadavg_end", "others_per_cpu", "busy"} <= set(load), path.name
    assert page.count("Load average (1 / 5 / 15 min)") == len(files)


def test_one_benchmark_alone_for_a_guide_page() -> None:
    page = generate.expand("<!-- generated: benchmark inversion -->\n")
    assert "`bench/inversion.py`" in page and "## Priority inversion and inheritance" in page
    assert "`bench/peers.py`" not in page
    with pytest.raises(generate.GenerationError, match="no such benchmark result"):
        generate.generate("benchmark nonsense")


def test_a_result_without_its_load_is_refused() -> None:
    document = {"title": "t", "how": "h", "table": [["a"], ["1"]]}
    with pytest.raises(generate.GenerationError, match="missing load"):
        generate.benchmark("x", document)
    busy = {**document, "load": {"cpus": 2, "loadavg_start": [3.0, 2.0, 1.0], "loadavg_end": [3.0, 2.0, 1.0],
                                 "others_per_cpu": 0.9, "busy": True, "reasons": ["1-minute load 3.00"]}}
    assert "**Taken on a busy machine** (1-minute load 3.00)" in generate.benchmark("x", busy)


def test_the_api_reference_is_the_public_names_through_the_package() -> None:
    import anodize
    import sessiontypes

    for package in (anodize, sessiontypes):
        blocks = generate.api(package.__name__).split()
        names = [b for b in blocks if b != ":::"]
        assert names == [f"{package.__name__}.{name}" for name in package.__all__]
        assert not any("._" in name for name in names)


def test_every_decision_is_in_the_index() -> None:
    listed = generate.decisions()
    files = [p for p in (REPO / "docs" / "decisions").glob("*.md") if p.name != "index.md"]
    assert len(files) >= 17
    for path in files:
        assert f"]({path.name})" in listed
    assert not (REPO / "docs" / "decisions.md").exists(), "decisions are one file each now"


def test_an_unknown_marker_fails_the_build() -> None:
    with pytest.raises(generate.GenerationError, match="unknown generated part"):
        generate.expand("<!-- generated: nonsense -->\n")
