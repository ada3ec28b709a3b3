"""MkDocs hook: the parts of the site that are generated from the repository at build time.

A page asks for a generated part with a marker on a line of its own; the hook replaces it
before the page is rendered, so what the site says cannot drift from its source:

- ``<!-- generated: layers -->``: the import-linter contracts of ``pyproject.toml``;
- ``<!-- generated: benchmarks -->``: every ``bench/results/*.json``, with the machine's load;
- ``<!-- generated: benchmark NAME -->``: ``bench/results/NAME.json`` alone (for a guide page);
- ``<!-- generated: api PACKAGE -->``: one mkdocstrings block per name in ``PACKAGE.__all__``;
- ``<!-- generated: decisions -->``: the list of ``docs/decisions/NNNN-*.md``.

The functions are plain (text in, markdown out) so that tests can call them too.
"""

from __future__ import annotations

import ast
import json
import re
import tomllib
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
MARKER = re.compile(r"^<!--\s*generated:\s*(.*?)\s*-->[ \t]*$", re.MULTILINE)

# The order of the performance page; result files not named here follow, by name.
BENCH_ORDER = ["monitor_overhead", "peers", "transport", "dds", "zenoh", "ros_images", "check_scaling", "recording",
               "tinman", "tinman_patrol", "render"]
BENCH_KEYS = ("title", "how", "table", "load")


class GenerationError(ValueError):
    """A generated part cannot be made from what the repository holds."""


def _code(text: str) -> str:
    return f"`{text}`"


def layers(pyproject: Path = REPO / "pyproject.toml") -> str:
    """The import-linter contracts of ``pyproject``, as markdown: each contract's layers, top first."""
    config = tomllib.loads(pyproject.read_text(encoding="utf-8")).get("tool", {}).get("importlinter", {})
    contracts = config.get("contracts", [])
    if not contracts:
        raise GenerationError(f"{pyproject}: expected [[tool.importlinter.contracts]], found none")
    out = [(f"Root packages: {', '.join(_code(p) for p in config.get('root_packages', []))}. "
           f"{len(contracts)} contracts, checked by `lint-imports` in CI."), ""]
    for contract in contracts:
        kind = contract.get("type", "?")
        out += [f"### {contract.get('name', '(unnamed)')}", ""]
        if kind == "layers":
            containers = contract.get("containers", [])
            where = f"inside {', '.join(_code(c) for c in containers)}" if containers else "between packages"
            out += [(f"Layers {where}; a module may import only from the layers below its own "
                    "(names on one line are independent of each other):"), ""]
            for number, layer in enumerate(contract.get("layers", []), 1):
                # Separators (`|` independent, `:` siblings that may import each other) kept as written.
                out.append(f"{number}. " + re.sub(r"[\w.]+", lambda m: _code(m.group()), " ".join(layer.split())))
        elif kind == "forbidden":
            out.append(f"{', '.join(_code(m) for m in contract.get('source_modules', []))} must not import "
                       f"{', '.join(_code(m) for m in contract.get('forbidden_modules', []))}.")
        elif kind == "independence":
            out.append(f"Independent of each other: {', '.join(_code(m) for m in contract.get('modules', []))}.")
        else:
            settings = {k: v for k, v in contract.items() if k not in {"name", "type"}}
            out.append(f"A `{kind}` contract: {_code(json.dumps(settings))}.")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


def _cell(value: object) -> str:
    return str(value).replace("|", "\\|").replace("\n", " ")


def _table(rows: list[list[Any]]) -> list[str]:
    header, *body = rows
    lines = ["| " + " | ".join(_cell(c) for c in header) + " |", "|" + "|".join(" --- " for _ in header) + "|"]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in body]
    return lines


def _load(load: dict[str, Any]) -> str:
    def three(values: list[float]) -> str:
        return " / ".join(f"{x:.2f}" for x in values)

    line = (f"Load average (1 / 5 / 15 min) {three(load['loadavg_start'])} at the start and "
            f"{three(load['loadavg_end'])} at the end, on {load['cpus']} CPUs; other processes used "
            f"{load['others_per_cpu']:.2f} of each CPU during the run.")
    if load.get("busy"):
        reasons = "; ".join(load.get("reasons", [])) or "no reason recorded"
        return (f"**Taken on a busy machine** ({reasons}): other work ran beside it, so compare the "
                f"ratios within this table, not its absolute numbers with another machine's. {line}")
    return f"Taken on a quiet machine. {line}"


def benchmark(name: str, document: dict[str, Any]) -> str:
    """One result file as a section of the performance page."""
    missing = [key for key in BENCH_KEYS if key not in document]
    if missing:
        raise GenerationError(f"bench/results/{name}.json: expected the keys {', '.join(BENCH_KEYS)} "
                              f"(written by bench/runs.py's write_results), missing {', '.join(missing)}")
    table = document["table"]
    if not (isinstance(table, list) and len(table) >= 2 and all(isinstance(r, list) for r in table)):
        raise GenerationError(f"bench/results/{name}.json: expected a table of a header and rows, got {table!r}")
    source = document.get("source", {})
    commit = f", commit `{source['commit'][:10]}`" if isinstance(source, dict) and source.get("commit") else ""
    options = document.get("options", {})
    quick = (" A `--quick` smoke run: fewer repetitions and smaller workloads than the defaults."
             if isinstance(options, dict) and options.get("quick") else "")
    script = document.get("script") or f"bench/{name}.py"  # a mode of another script names it so
    return "\n".join([
        f"## {document['title']}", "",
        f"`{script}`, {document.get('date', 'undated')}{commit}: {document['how']}.{quick}", "",
        _load(document["load"]), "",
        *_table(table), "",
    ])


def benchmarks(results: Path = REPO / "bench" / "results") -> str:
    """Every result file under ``results``, in :data:`BENCH_ORDER`, as markdown sections."""
    files = {path.stem: path for path in results.glob("*.json")}
    if not files:
        raise GenerationError(f"{results}: no benchmark results (run a bench/*.py script)")
    order = [n for n in BENCH_ORDER if n in files] + sorted(n for n in files if n not in BENCH_ORDER)
    return "\n".join(benchmark(n, json.loads(files[n].read_text(encoding="utf-8"))) for n in order)


def public_names(package: str) -> list[str]:
    """``package.__all__``, read from its ``__init__.py`` without importing it."""
    init = REPO / package / "__init__.py"
    for node in ast.parse(init.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets) and node.value is not None:
                names = ast.literal_eval(node.value)
                if isinstance(names, list | tuple) and all(isinstance(n, str) for n in names):
                    return list(names)
    raise GenerationError(f"{init}: expected a literal __all__ list of names")


def api(package: str) -> str:
    """One mkdocstrings block per public name, referenced through the package itself."""
    return "\n".join(f"::: {package}.{name}\n" for name in public_names(package))


def decisions(folder: Path = REPO / "docs" / "decisions") -> str:
    """A list item per decision file, numbered ones in order, with the title of each."""
    items = []
    for path in sorted(folder.glob("*.md")):
        if path.name == "index.md":
            continue
        first = path.read_text(encoding="utf-8").splitlines()[:1]
        if not first or not first[0].startswith("# "):
            raise GenerationError(f"{path}: expected a '# Title' first line")
        number = path.name.split("-", 1)[0]
        items.append(f"- [{number}: {first[0][2:].strip()}]({path.name})")
    return "\n".join(items) + "\n"


def generate(what: str) -> str:
    """The markdown for one marker's request (``layers``, ``api anodize``, ...)."""
    verb, *rest = what.split()
    if verb == "layers" and not rest:
        return layers()
    if verb == "benchmarks" and not rest:
        return benchmarks()
    if verb == "benchmark" and len(rest) == 1:
        path = REPO / "bench" / "results" / f"{rest[0]}.json"
        if not path.exists():
            raise GenerationError(f"{path}: no such benchmark result (run bench/{rest[0]}.py)")
        return benchmark(rest[0], json.loads(path.read_text(encoding="utf-8")))
    if verb == "api" and len(rest) == 1 and rest[0] in {"anodize", "sessiontypes"}:
        return api(rest[0])
    if verb == "decisions" and not rest:
        return decisions()
    raise GenerationError(f"unknown generated part {what!r}; expected layers, benchmarks, benchmark NAME, "
                          "decisions, api anodize or api sessiontypes")


def expand(markdown: str) -> str:
    """``markdown`` with every marker replaced by what it asks for."""
    return MARKER.sub(lambda m: generate(m.group(1)), markdown)


def on_page_markdown(markdown: str, **_: Any) -> str:
    """MkDocs' hook: expand the page's markers before it is rendered."""
    return expand(markdown)
