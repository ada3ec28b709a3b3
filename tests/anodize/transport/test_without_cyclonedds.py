"""Without the ``anodize[dds]`` extra: anodize imports and the inproc and process transports
work; asking for DDS fails with a MissingExtraError that names the extra.

Each check runs in a fresh interpreter whose import system hides ``cyclonedds`` (as if
it were not installed), so nothing imported earlier by the test process can mask an
eager import.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

_HIDE_CYCLONEDDS = """
import importlib.abc
import sys


class HideCycloneDds(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "cyclonedds" or name.startswith("cyclonedds."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, HideCycloneDds())
"""


def _run(body: str) -> str:
    script = _HIDE_CYCLONEDDS + textwrap.dedent(body)
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_anodize_imports_and_the_inproc_transport_runs_without_cyclonedds() -> None:
    out = _run("""
        import anodize, sessiontypes
        import anodize._transport.dds  # its settings need no binding
        assert not any(m == "cyclonedds" or m.startswith("cyclonedds.") for m in sys.modules)

        ping = sessiontypes.loads("global P(A, B) = A -> B : go(nat). end", "p.proto").globals["P"]
        system = anodize.System(ping)
        group = system.group("all")
        got = []
        group.role("A", lambda ep: ep.send("B", "go", 7))
        group.role("B", lambda ep: got.append(ep.recv("A").payload))
        report = system.run(timeout=20)
        assert report.ok, report.summary()
        print(got)
    """)
    assert out.strip() == "[7]"


def test_the_process_transports_pipes_carry_messages_without_cyclonedds() -> None:
    out = _run("""
        import os
        from anodize._transport.codec import Codec
        from anodize._transport.network import GroupNetwork
        from anodize._transport.process import PipeLinks

        read, write = os.pipe()
        sending = GroupNetwork(["A"], [("A", "B")], PipeLinks({("A", "B"): write}), {}, lambda pair: Codec())
        receiving = GroupNetwork(["B"], [("A", "B")], PipeLinks({("A", "B"): read}), {}, lambda pair: Codec())
        sending.queues[("A", "B")].put(("go", [1, "two"]))
        print(receiving.queues[("A", "B")].get(timeout=10))
        assert "cyclonedds" not in sys.modules
    """)
    assert out.strip() == "('go', [1, 'two'])"


def test_asking_for_dds_without_cyclonedds_names_the_extra() -> None:
    out = _run("""
        import anodize, sessiontypes
        from anodize.errors import MissingExtraError

        ping = sessiontypes.loads("global P(A, B) = A -> B : go(nat). end", "p.proto").globals["P"]
        system = anodize.System(ping, transport=anodize.Dds(run_id="no-cyclone"))
        import json  # any importable function: the run fails before a role starts
        system.group("a").role("A", json.dumps)
        system.group("b").role("B", json.dumps)
        try:
            system.run(timeout=5)
        except MissingExtraError as error:
            print(error.extra, "|", error)
        import anodize._transport.dds  # its settings need no binding; the rest needs the extra
        for name in ("DdsLinks", "Frame"):
            try:
                getattr(anodize._transport.dds, name)
            except MissingExtraError as error:
                print(name, error.extra)
    """)
    first, *rest = out.strip().splitlines()
    assert first.startswith("dds | the DDS transport needs the Python package of module 'cyclonedds")
    assert first.endswith("install it with: pip install 'anodize[dds]'")
    assert rest == ["DdsLinks dds", "Frame dds"]
