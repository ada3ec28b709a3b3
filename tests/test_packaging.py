"""Packaging: the wheels work outside the checkout, the core installs alone, typed endpoints type-check anywhere.

The repository holds two distributions: ``anodize`` (packages ``sessiontypes`` and ``anodize``;
pyproject.toml) and TinMan, ``anodize-tinman`` (package ``tinman``; tinman/pyproject.toml).

``test_wheel_installs_and_runs_outside_the_checkout`` builds both wheels from a clean copy
of the source tree, installs them with ``--no-deps`` into a fresh venv outside the checkout
and runs the installed commands there. The venv gets its dependencies without a download:
a ``.pth`` file adds a folder of links to exactly the distributions the two declare (TinMan's,
and anodize's with the extras TinMan asks for), followed transitively through the metadata of
the environment running the tests. anodize's own packages and the test tools (pytest, mypy,
...) are not among them, so a module a wheel misses, or an import of an undeclared
dependency, fails here as it would for a user.

``test_the_core_installs_and_runs_without_the_extras`` installs the anodize wheel the way a
user does (``pip install``, which fetches lark, networkx and numpy from the package index)
into a clean venv, and runs ``anodize check`` and ``anodize run`` of a two-role protocol
there, on the inproc and processes transports; asking for DDS fails naming ``anodize[dds]``.

``test_typed_endpoints_type_check_outside_the_checkout`` generates endpoint modules with
the development install's ``anodize project`` in a folder outside the checkout and runs
``mypy --strict`` there (no MYPYPATH), against the development install and against the
wheel's venv: a program that follows the protocol passes, one that calls out of order
fails on that call, and ``anodize`` is always found (an editable install mypy cannot
follow makes it ``import-not-found`` and the states ``Any``; docs/decisions/0005-packaging-and-editable-installs.md).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from packaging.requirements import Requirement

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("sessiontypes", "anodize", "tinman")  # every import package of the two distributions
ANODIZE_PACKAGES = ("sessiontypes", "anodize")      # the anodize wheel's; TinMan's wheel holds tinman
TINMAN = REPO / "tinman"                             # TinMan's distribution (pyproject.toml, src/tinman)
# What a clean checkout would not have: never copied into the wheel's source tree.
NOT_SOURCE = shutil.ignore_patterns(".git", ".venv", "venv", "build", "dist", "*.egg-info", "__pycache__",
                                    "*.pyc", ".mypy_cache", ".pytest_cache", ".ruff_cache", ".hypothesis",
                                    ".import_linter_cache", "out", "results")
BIN = Path(sys.executable).parent  # the development install's commands (anodize, mypy)

PING_PROTO = """\
global Ping(A, B) =
  mu t. A -> B : {
    ping(int). B -> A : pong(int). t,
    stop
  }
"""

PING_ROLES = '''\
"""The roles of ping.proto; each notes which anodize it ran on."""

from pathlib import Path

import anodize


def pinger(ep: anodize.Endpoint) -> None:
    Path("ran_A.txt").write_text(anodize.__file__, encoding="utf-8")
    for number in range(3):
        ep.send("B", "ping", number)
        assert ep.recv("B").payload == number + 1
    ep.send("B", "stop")


def ponger(ep: anodize.Endpoint) -> None:
    Path("ran_B.txt").write_text(anodize.__file__, encoding="utf-8")
    while (message := ep.recv("A")).label == "ping":
        ep.send("A", "pong", message.payload + 1)
'''

PING_SYSTEM = """\
protocol = "ping.proto"
global = "Ping"
transport = "{transport}"
timeout = 30.0

[groups.left]
priority = 20
roles = {{ A = "pingroles:pinger" }}

[groups.right]
priority = 10
roles = {{ B = "pingroles:ponger" }}
"""

# A user's program on generated two-buyer states (protocols/two_buyer.proto), run when executed.
TYPED_PROGRAM = '''\
from __future__ import annotations

import sys
from pathlib import Path
from typing import assert_never

import sessiontypes

import anodize
from gen import twobuyer_b1, twobuyer_b2, twobuyer_s


def buyer1(start: twobuyer_b1.Initial) -> twobuyer_b1.End:
    quote, sharing = start.send_title("Ulysses").recv_quote()
    return sharing.send_share(quote // 2)


def buyer2(start: twobuyer_b2.Initial) -> twobuyer_b2.End:
    quote, waiting = start.recv_quote()
    share, deciding = waiting.recv_share()
    if quote - share > 50:
        return deciding.select_quit()
    date, end = deciding.select_ok("1 Wonderland Road").recv_date()
    return end


def seller(start: twobuyer_s.Initial) -> twobuyer_s.End:
    title, quoting = start.recv_title()
    outcome = quoting.send_quote(60).send_quote(60).offer()
    match outcome:
        case twobuyer_s.State3Ok(address, dating):
            return dating.send_date("tomorrow")
        case twobuyer_s.State3Quit(end):
            return end
        case _:
            assert_never(outcome)


def main() -> int:
    protocol = sessiontypes.load(Path(__file__).with_name("two_buyer.proto")).globals["TwoBuyer"]
    system = anodize.System(protocol, transport=anodize.Inproc())
    system.group("buyers").role("B1", buyer1).role("B2", buyer2)
    system.group("seller").role("S", seller)
    report = system.run(timeout=20)
    print(report.summary())
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
'''
IN_ORDER = 'start.send_title("Ulysses").recv_quote()'
OUT_OF_ORDER = 'start.send_title("Ulysses").send_share(30)'  # B1 must receive the quote first


@dataclass(frozen=True)
class Installed:
    """The two wheels installed in a venv outside the checkout."""

    wheel: Path         # anodize's
    tinman_wheel: Path  # TinMan's
    venv: Path
    python: Path
    site_packages: Path
    work: Path  # an empty folder outside the checkout to run commands in

    def command(self, name: str) -> Path:
        return self.venv / "bin" / name


def _clean_environment() -> dict[str, str]:
    """The environment minus what would point Python or mypy at the checkout."""
    drop = {"PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "PYTHONSAFEPATH", "MYPYPATH", "VIRTUAL_ENV"}
    return {key: value for key, value in os.environ.items() if key not in drop}


def _run(command: list[str | Path], cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(part) for part in command], cwd=cwd, env=_clean_environment(),
                          capture_output=True, text=True, timeout=timeout, check=False)


def _ok(command: list[str | Path], cwd: Path, timeout: float = 120) -> str:
    done = _run(command, cwd, timeout)
    assert done.returncode == 0, f"{command} exited {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done.stdout


def _outside_the_checkout(path: Path) -> Path:
    assert not path.resolve().is_relative_to(REPO), f"{path} is inside the checkout {REPO}"
    return path


def _project(folder: Path) -> dict[str, Any]:
    """The [project] table of the pyproject.toml in ``folder``."""
    with (folder / "pyproject.toml").open("rb") as file:
        project: dict[str, Any] = tomllib.load(file)["project"]
    return project


def _declared(folder: Path, extras: set[str] | frozenset[str] = frozenset()) -> list[Requirement]:
    """The requirements a distribution of this repository declares, with the extras asked for."""
    project = _project(folder)
    optional = project.get("optional-dependencies", {})
    return [Requirement(text) for text in [*project["dependencies"], *(r for x in sorted(extras) for r in optional[x])]]


def _runtime_distributions() -> list[importlib.metadata.Distribution]:
    """The distributions TinMan's and anodize's declared requirements pull in, transitively.

    The first level is read from the two pyproject.toml files (the checkout's, not an installed
    copy's metadata); anodize's requirement on itself (TinMan's ``anodize[dds,...]``) adds
    anodize's own with those extras. Third-party requirements are followed through the
    metadata of the environment running the tests (their own extras are not followed).
    """
    found: dict[str, importlib.metadata.Distribution] = {}
    wanted = _declared(TINMAN)
    while wanted:
        requirement = wanted.pop()
        if requirement.marker is not None and not requirement.marker.evaluate({"extra": ""}):
            continue
        if requirement.name == "anodize":
            wanted.extend(_declared(REPO, requirement.extras))
            continue
        distribution = importlib.metadata.distribution(requirement.name)
        name = re.sub(r"[-_.]+", "-", distribution.metadata["Name"]).lower()
        if name in found:
            continue
        found[name] = distribution
        wanted.extend(Requirement(text) for text in distribution.requires or [])
    return list(found.values())


def _link_dependencies(folder: Path) -> list[str]:
    """Link the top-level entries (packages, modules, .libs, dist-info) of the runtime dependencies
    of TinMan and anodize into ``folder``; returns the distributions' names."""
    folder.mkdir()
    names = []
    for distribution in _runtime_distributions():
        names.append(distribution.metadata["Name"])
        files = distribution.files
        assert files is not None, f"{distribution.metadata['Name']} has no RECORD: cannot tell its files"
        for top in {file.parts[0] for file in files if file.parts[0] != ".."}:
            assert top.split(".")[0] not in PACKAGES, f"a dependency provides {top}"
            target = Path(str(distribution.locate_file(top)))
            if target.exists() and not (folder / top).exists():
                (folder / top).symlink_to(target)
    return names


@dataclass(frozen=True)
class Wheels:
    """The two wheels, built from a clean copy of the checkout."""

    anodize: Path
    tinman: Path


@pytest.fixture(scope="module")
def wheels(tmp_path_factory: pytest.TempPathFactory) -> Wheels:
    if importlib.util.find_spec("venv") is None:
        pytest.skip("this Python has no venv module (Debian: apt-get install python3-venv)")
    root = _outside_the_checkout(tmp_path_factory.mktemp("wheels"))
    # From a copy of the source tree: nothing stale in a build/ folder gets in, and nothing is
    # written into the checkout. The build requirements are those of the environment running
    # the tests (scripts/bootstrap installs them): no download.
    source = root / "source"
    shutil.copytree(REPO, source, symlinks=True, ignore=NOT_SOURCE)
    dist = root / "dist"
    for project in (source, source / "tinman"):
        _ok([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
             "--check-build-dependencies", "--disable-pip-version-check", "-q", "-w", dist, project], root, 300)
    (anodize,) = dist.glob("anodize-[0-9]*.whl")
    (tinman,) = dist.glob("anodize_tinman-*.whl")
    return Wheels(anodize, tinman)


@pytest.fixture(scope="module")
def installed(wheels: Wheels, tmp_path_factory: pytest.TempPathFactory) -> Installed:
    root = _outside_the_checkout(tmp_path_factory.mktemp("packaging"))
    venv = root / "venv"
    _ok([sys.executable, "-m", "venv", "--without-pip", venv], root)
    python = venv / "bin" / "python"
    _ok([sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "--no-index",
         "--disable-pip-version-check", "-q", wheels.anodize, wheels.tinman], root, 300)
    site_packages = Path(_ok([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                             root).strip())
    dependencies = root / "dependencies"
    names = _link_dependencies(dependencies)
    assert {"lark", "numpy"} <= {name.lower() for name in names}, names
    (site_packages / "anodize_test_dependencies.pth").write_text(
        f"import site; site.addsitedir({str(dependencies)!r})\n", encoding="utf-8")
    work = root / "work"
    work.mkdir()
    return Installed(wheels.anodize, wheels.tinman, venv, python, site_packages, work)


def _files(folder: Path, packages: tuple[str, ...]) -> set[str]:
    """The files of ``packages`` (folders in ``folder``), as paths relative to ``folder``."""
    return {path.relative_to(folder).as_posix() for package in packages for path in (folder / package).rglob("*")
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc"}


def _in_wheel(wheel: Path) -> set[str]:
    with zipfile.ZipFile(wheel) as archive:
        return {name for name in archive.namelist() if ".dist-info/" not in name}


def test_tinman_requires_the_anodize_of_its_release() -> None:
    anodize, tinman = _project(REPO), _project(TINMAN)
    assert tinman["version"] == anodize["version"]
    (requirement,) = (r for r in _declared(TINMAN) if r.name == "anodize")
    assert str(requirement.specifier) == f"=={anodize['version']}"
    assert requirement.extras <= set(anodize["optional-dependencies"])
    # TinMan's command and named system belong to TinMan's distribution, not anodize's.
    assert set(anodize["scripts"]) == {"anodize"} and "entry-points" not in anodize
    assert tinman["scripts"] == {"tinman": "tinman.cli:run"}
    assert tinman["entry-points"] == {"anodize.systems": {"tinman": "tinman.app:TINMAN"}}


@pytest.mark.slow
def test_wheel_installs_and_runs_outside_the_checkout(installed: Installed) -> None:
    # Every file of the packages is in its distribution's wheel, with their data files; nothing else is.
    in_wheel = _in_wheel(installed.wheel)
    assert sorted(in_wheel ^ _files(REPO, ANODIZE_PACKAGES)) == []
    in_tinman_wheel = _in_wheel(installed.tinman_wheel)
    assert sorted(in_tinman_wheel ^ _files(TINMAN / "src", ("tinman",))) == []
    assert {"sessiontypes/grammar.lark", *(f"{package}/py.typed" for package in ANODIZE_PACKAGES)} <= in_wheel
    assert {"tinman/tinman.toml", "tinman/tinman.proto", "tinman/py.typed"} <= in_tinman_wheel

    # The installed packages are imported, not the checkout; the test tools are not there.
    work, python = installed.work, installed.python
    located = json.loads(_ok([python, "-c", (
        "import json, importlib.util, anodize, sessiontypes, tinman; "
        "print(json.dumps({m.__name__: m.__file__ for m in (anodize, sessiontypes, tinman)}"
        " | {'pytest': importlib.util.find_spec('pytest') is not None}))")], work))
    assert located.pop("pytest") is False
    # The compiled hot path was built into the wheel wherever the checkout's could be built.
    compiled = _ok([python, "-c", "from anodize._transport import frames; print(frames.COMPILED)"], work)
    assert compiled.strip() == str(importlib.util.find_spec("anodize._transport._frames") is not None)
    assert located == {package: str(installed.site_packages / package / "__init__.py") for package in PACKAGES}

    anodize = installed.command("anodize")
    _check_and_run_ping(anodize, work, located["anodize"])

    # TinMan: its commands, its named system, its system file and the protocol beside it.
    assert _ok([installed.command("tinman"), "--help"], work).startswith("usage: tinman")
    assert "named systems: tinman" in _ok([anodize, "run", "--help"], work)
    assert _ok([anodize, "run", "tinman", "--help"], work).startswith("usage: anodize run tinman")
    tinman = installed.site_packages / "tinman"
    assert _ok([anodize, "check", tinman / "tinman.proto"], work).endswith(": ok (2 globals, 0 locals)\n")
    assert _ok([anodize, "lint", tinman / "tinman.toml"], work).startswith("no isolation problems found")
    assert _ok([python, "-c", (
        "import tomllib, sessiontypes\n"
        "from importlib.metadata import entry_points\n"
        "from tinman.app import SYSTEM_FILE\n"
        "(point,) = entry_points(group='anodize.systems', name='tinman')\n"
        "assert point.load() is not None\n"
        "config = tomllib.loads(SYSTEM_FILE.read_text(encoding='utf-8'))\n"
        "protocol = SYSTEM_FILE.parent / config['protocol']\n"
        "print(protocol, sorted(sessiontypes.load(protocol).globals))")], work) == (
        f"{tinman / 'tinman.proto'} ['TinMan', 'TinManParallel']\n")


def _check_and_run_ping(anodize: Path, work: Path, anodize_file: str) -> None:
    """``anodize check`` a two-role protocol and ``anodize run`` it on the inproc and process
    transports, in ``work``; each role must run on the anodize at ``anodize_file``."""
    # The grammar loads (sessiontypes/grammar.lark), from a protocol outside the checkout.
    (work / "ping.proto").write_text(PING_PROTO, encoding="utf-8")
    assert _ok([anodize, "check", "ping.proto"], work) == "ping.proto: ok (1 global, 0 locals)\n"
    # A tiny system with its roles in a module beside it, on both transports.
    (work / "pingroles.py").write_text(PING_ROLES, encoding="utf-8")
    for transport in ("inproc", "process"):
        system = work / f"ping_{transport}.toml"
        system.write_text(PING_SYSTEM.format(transport=transport), encoding="utf-8")
        for ran in work.glob("ran_*.txt"):
            ran.unlink()
        report_file = work / f"report_{transport}.json"
        _ok([anodize, "run", system.name, "--quiet", "--json", report_file.name], work)
        report = json.loads(report_file.read_text(encoding="utf-8"))
        assert (report["ok"], report["transport"]) == (True, transport), report
        for role in "AB":  # each role (a child process with "process") ran on the installed anodize
            assert (work / f"ran_{role}.txt").read_text(encoding="utf-8") == anodize_file


@pytest.mark.slow
def test_the_core_installs_and_runs_without_the_extras(wheels: Wheels,
                                                       tmp_path_factory: pytest.TempPathFactory) -> None:
    root = _outside_the_checkout(tmp_path_factory.mktemp("core"))
    venv = root / "venv"
    _ok([sys.executable, "-m", "venv", "--without-pip", venv], root)
    python = venv / "bin" / "python"
    # As a user installs it: pip reads the wheel's requirements and fetches them from the
    # package index (lark, networkx and numpy: three wheels, no build).
    _ok([sys.executable, "-m", "pip", "--python", python, "install", "--disable-pip-version-check", "-q",
         "--only-binary", ":all:", wheels.anodize], root, 600)
    distributions = _ok([python, "-c", (
        "import importlib.metadata as m, re\n"
        "print(' '.join(sorted(re.sub(r'[-_.]+', '-', d.metadata['Name']).lower() for d in m.distributions())))")],
        root)
    assert distributions.split() == ["anodize", "lark", "networkx", "numpy"]
    work = root / "work"
    work.mkdir()
    located = _ok([python, "-c", "import anodize; print(anodize.__file__)"], work).strip()
    assert Path(located).is_relative_to(venv), located
    anodize = venv / "bin" / "anodize"
    _check_and_run_ping(anodize, work, located)

    # What needs an extra says which one, where it is asked for.
    system = work / "ping_dds.toml"
    system.write_text(PING_SYSTEM.format(transport="dds"), encoding="utf-8")
    done = _run([anodize, "run", system.name, "--quiet"], work)
    assert done.returncode != 0, done.stdout
    assert ("the DDS transport needs the Python package of module 'cyclonedds', which is not installed; "
            "install it with: pip install 'anodize[dds]'") in done.stderr, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    # The demo is not part of the core.
    assert _run([python, "-c", "import tinman"], work).returncode == 1
    assert not (venv / "bin" / "tinman").exists()


def _mypy(work: Path, programs: list[str], cache: str, *options: str | Path) -> tuple[int, str]:
    """``mypy --strict`` of the development install on ``programs``, from ``work``."""
    done = _run([BIN / "mypy", "--strict", "--no-color-output", "--no-error-summary", "--cache-dir", cache,
                 *options, *programs], work, 300)
    assert done.stderr == "", done.stderr
    return done.returncode, done.stdout


@pytest.mark.slow
def test_typed_endpoints_type_check_outside_the_checkout(installed: Installed,
                                                         tmp_path_factory: pytest.TempPathFactory) -> None:
    work = _outside_the_checkout(tmp_path_factory.mktemp("typed"))
    shutil.copy(REPO / "protocols" / "two_buyer.proto", work / "two_buyer.proto")
    _ok([BIN / "anodize", "project", "two_buyer.proto", "-o", "gen"], work)
    assert sorted(p.name for p in (work / "gen").iterdir()) == ["twobuyer_b1.py", "twobuyer_b2.py",
                                                                "twobuyer_s.py"]
    assert TYPED_PROGRAM.count(IN_ORDER) == 1
    (work / "conforming.py").write_text(TYPED_PROGRAM, encoding="utf-8")
    (work / "out_of_order.py").write_text(TYPED_PROGRAM.replace(IN_ORDER, OUT_OF_ORDER), encoding="utf-8")
    line = TYPED_PROGRAM.splitlines().index(f"    quote, sharing = {IN_ORDER}") + 1

    # Against the development install, then the wheel's venv: both programs in one mypy run
    # each (a run costs seconds). Every finding is out_of_order.py's: conforming.py, the
    # generated modules and anodize have none (a finding in any of them would be a line of its own).
    for cache, options in [(".mypy_cache", ()), (".mypy_cache_wheel", ("--python-executable", installed.python))]:
        status, out = _mypy(work, ["conforming.py", "out_of_order.py"], cache, *options)
        assert status == 1, (options, out)
        assert all(finding.startswith("out_of_order.py:") for finding in out.splitlines()), (options, out)
        assert re.search(rf'^out_of_order\.py:{line}: error: "\w+" has no attribute "send_share"  \[attr-defined\]$',
                         out, re.MULTILINE), (options, out)
        assert "import-not-found" not in out and "import-untyped" not in out, (options, out)

    # The conforming program also runs, on the wheel's anodize (it exits 1 unless the run is ok).
    _ok([installed.python, "conforming.py"], work)
