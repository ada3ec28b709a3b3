"""bench/zenoh_transport.py: its raw Zenoh peers deliver everything, in order, peer to peer and
through a router, and its table judges issue 32's targets from the medians.

The peers run in two threads of this process (a ``threading.Barrier`` in place of the spawned
processes' one): the same code the benchmark's processes run, without their start-up time.
"""

from __future__ import annotations

import importlib
import json
import os
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"
JOIN = 30.0  # seconds a test waits for a peer's thread: far above a run of these sizes, far below a hang


@pytest.fixture(scope="module")
def bench() -> Iterator[ModuleType]:
    """bench/zenoh_transport.py, imported with bench/ on the path; the path and environment restored after."""
    path, env = list(sys.path), os.environ.get("PYTHONPATH")
    # bench/ and the tests' own folders share module names (dds_roles is both tests/anodize/dds_roles.py
    # and bench/dds_roles.py): the tests' modules are set aside while bench's are imported, then put back.
    names = {p.stem for p in BENCH.glob("*.py")}
    aside = {name: sys.modules.pop(name) for name in names & set(sys.modules)}
    sys.path.insert(0, str(BENCH))
    try:
        yield importlib.import_module("zenoh_transport")
    finally:
        sys.path[:] = path
        if env is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = env
        for name in names:
            sys.modules.pop(name, None)
        sys.modules.update(aside)


@pytest.fixture
def out(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("ANODIZE_BENCH", json.dumps({"out": str(tmp_path)}))
    return tmp_path


def _run(*targets: tuple[Callable[..., None], tuple[Any, ...]]) -> list[BaseException]:
    """Run each function in a thread; the errors they raised, and one for each still running after JOIN."""
    errors: list[BaseException] = []

    def guarded(function: Callable[..., None], args: tuple[Any, ...]) -> None:
        try:
            function(*args)
        except BaseException as error:  # collected for the test to look at
            errors.append(error)

    threads = [threading.Thread(target=guarded, args=target, daemon=True) for target in targets]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(JOIN)
    return errors + [TimeoutError(f"{t.name} still running after {JOIN:g} s") for t in threads if t.is_alive()]


def _result(out: Path, name: str) -> dict[str, Any]:
    return json.loads((out / f"{name}.json").read_text(encoding="utf-8"))  # type: ignore[no-any-return]


@pytest.mark.parametrize("callback", [False, True], ids=["fifo", "callback"])
def test_raw_peers_stream_every_int_in_order_peer_to_peer(bench: ModuleType, out: Path, callback: bool) -> None:
    raw, barrier = bench.raw, threading.Barrier(2)
    with bench.raw_sides(via_router=False, callback=callback) as (listener, connector):
        assert (listener["listen"], connector["connect"]) == (connector["connect"], listener["listen"])
        errors = _run((raw.int_producer, (listener, "test/stream", barrier, 500)),
                      (raw.int_consumer, (connector, "test/stream", barrier, 500)))
    assert errors == []
    assert (_result(out, "end")["count"], _result(out, "end")["bad"]) == (500, 0)
    assert _result(out, "start")["start"] <= _result(out, "end")["end"]


def test_raw_peers_send_frames_through_a_router(bench: ModuleType, out: Path) -> None:
    raw, barrier = bench.raw, threading.Barrier(2)
    with bench.raw_sides(via_router=True) as (first, second):
        assert first["mode"] == second["mode"] == "client" and first["connect"] == bench._router
        errors = _run((raw.frame_producer, (first, "test/frames", barrier, 5)),
                      (raw.frame_consumer, (second, "test/frames", barrier, 5)))
    assert errors == [] and bench._router == []
    assert (_result(out, "end")["count"], _result(out, "end")["bad"]) == (5, 0)


def test_raw_ping_pong_times_each_round(bench: ModuleType, out: Path) -> None:
    raw, barrier = bench.raw, threading.Barrier(2)
    with bench.raw_sides(via_router=False) as (listener, connector):
        errors = _run((raw.ping_server, (listener, "test/pingpong", barrier)),
                      (raw.ping_client, (connector, "test/pingpong", barrier, 20, 5)))
    assert errors == []
    found = _result(out, "pingpong")
    assert found["rounds"] == 20 and 0 < found["p50_us"] <= found["p99_us"] <= found["max_us"]


def _stats(median: float) -> dict[str, float]:
    return {"median": median, "min": median, "max": median, "runs": 1}


def test_the_targets_are_judged_from_the_medians(bench: ModuleType) -> None:
    results = {
        "messages": {"stats": {"per_second": {"zenoh": _stats(80.0), "raw_zenoh": _stats(100.0),
                                              "dds": _stats(50.0)}}},
        "frames": {"stats": {"per_second": {"zenoh": _stats(70.0), "raw_zenoh": _stats(100.0),
                                            "zenoh_router": _stats(29.0), "raw_zenoh_router": None}}},
        "round_trip": {"stats": {"p50_us": {"zenoh": _stats(125.0), "raw_zenoh": _stats(100.0)},
                                 "p99_us": {"zenoh": _stats(126.0), "raw_zenoh": _stats(100.0)}}},
    }
    rows, targets = bench.summarise(results, 1)
    met = {t["name"]: t["met"] for t in targets}
    assert list(met.values()) == [True, False, None, True, False, False]
    assert rows[0] == ["measure", "way", "median (min-max)", "target"]
    assert ["target", "frames through a router: anodize zenoh, frames/s", "29.0", ">= 30 frames/s: NOT met"] in rows
    assert any(row[1] == "raw Zenoh, client-router-client" and row[2] == "failed (1 of 1)" for row in rows)


@pytest.mark.parametrize("side", ["producer", "consumer"])
def test_a_lone_raw_peer_fails_within_its_bound(bench: ModuleType, out: Path, monkeypatch: pytest.MonkeyPatch,
                                                side: str) -> None:
    raw = bench.raw
    monkeypatch.setattr(raw, "TIMEOUT", 0.5)
    with bench.raw_sides(via_router=False) as (listener, connector):
        function, where = (raw.int_producer, listener) if side == "producer" else (raw.int_consumer, connector)
        errors = _run((function, (where, "test/lone", threading.Barrier(2), 10)))
    expected = "raw Zenoh: no subscriber matched within 0.5 s" if side == "producer" else ""
    assert [(type(e), str(e)) for e in errors] == [
        (TimeoutError if side == "producer" else threading.BrokenBarrierError, expected)]
