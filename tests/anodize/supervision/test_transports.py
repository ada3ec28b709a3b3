"""Transports as values, runs assembled from parts, channel taps; and the deprecated keyword forms."""

from __future__ import annotations

import dataclasses
import json
import warnings
from pathlib import Path

import pytest
import tap_roles

import anodize
import sessiontypes
from anodize import ConfigurationError, Dds, Inproc, Processes, RosBridge
from anodize._supervision.legacy import legacy_run

STREAM = sessiontypes.loads("""
global Stream(P, C) = mu t. P -> C : { data(int). t, stop. end }
""", "stream.proto").globals["Stream"]


def producer(ep: anodize.Endpoint) -> None:
    for i in range(5):
        ep.send("C", "data", i)
    ep.send("C", "stop")


def consumer(ep: anodize.Endpoint) -> None:
    while ep.recv("P").label == "data":
        pass


def stream(transport: object = None, **keywords: object) -> anodize.System:
    system = (anodize.System(STREAM, **keywords) if transport is None  # type: ignore[arg-type]
              else anodize.System(STREAM, transport, **keywords))  # type: ignore[arg-type]
    system.group("producing").role("P", producer)
    system.group("consuming").role("C", consumer)
    return system


# ---- the values -----------------------------------------------------------------------------

def test_values_are_frozen_compared_by_their_fields_and_inproc_is_the_default() -> None:
    assert Processes(liveness=3) == Processes(liveness=3) != Processes()
    assert Dds(domain=4, run_id="x").kind == "dds"
    with pytest.raises(dataclasses.FrozenInstanceError):
        Processes().liveness = 1.0  # type: ignore[misc]
    assert anodize.System(STREAM).transport == Inproc()
    assert RosBridge(topics={"P->C": "/a"}, external=("C",)) == RosBridge(topics={"P->C": "/a"},
                                                                          external=frozenset({"C"}))


@pytest.mark.parametrize(("make", "message"), [
    (lambda: Processes(liveness=0), "Processes liveness: expected a number of seconds > 0, got 0"),
    (lambda: Processes(liveness="2"), "Processes liveness: expected a number of seconds > 0, got '2'"),
    (lambda: Dds(domain=300), "Dds domain: expected a DDS domain id 0..232, got 300"),
    (lambda: Dds(domain=True), "Dds domain: expected a DDS domain id 0..232, got True"),
    (lambda: Dds(run_id="a b"), "Dds run_id: expected up to 64 letters, digits, '_', '.' or '-', got 'a b'"),
    (lambda: Dds(host="a/b"), "Dds host: expected a name such as robot or base_1, got 'a/b'"),
    (lambda: Dds(wait=-1), "Dds wait: expected a number of seconds > 0, got -1"),
    (lambda: RosBridge(topics=["/a"]), "RosBridge topics: expected a mapping"),
    (lambda: RosBridge(external="Joy"), "RosBridge external: expected role names such as"),
    (lambda: RosBridge(domain=233), "RosBridge domain: expected a DDS domain id 0..232 or None, got 233"),
])
def test_a_value_refuses_a_bad_field_naming_what_it_expected(make: object, message: str) -> None:
    with pytest.raises(ConfigurationError) as info:
        make()  # type: ignore[operator]
    assert str(info.value).startswith(message)


def test_a_system_refuses_what_is_not_a_transport_and_external_roles_off_dds() -> None:
    with pytest.raises(ConfigurationError,
                       match=r"transport: expected Inproc\(\), Processes\(...\), Dds\(...\) or Zenoh"):
        anodize.System(STREAM, transport=object())  # type: ignore[arg-type]
    with pytest.raises(ConfigurationError, match=r"need transport Dds\(...\) or Zenoh\(...\), not Processes"):
        anodize.System(STREAM, transport=Processes(), ros=RosBridge(external={"C"}))
    with pytest.raises(ConfigurationError, match="are the fields of Dds"):
        anodize.System(STREAM, transport=Dds(), domain=3)
    with pytest.warns(DeprecationWarning, match="deprecated"), pytest.raises(ConfigurationError, match="alone"):
        anodize.System(STREAM, transport="dds", ros_topics={"P->C:data": "/d"}, ros=RosBridge())


def test_a_system_runs_inproc_by_default() -> None:
    report = stream().run(timeout=10)
    assert report.ok, report.summary()
    assert report.transport == "inproc"


@pytest.mark.slow
def test_a_system_runs_on_processes_with_its_settings() -> None:
    report = stream(Processes(liveness=5.0)).run(timeout=30)
    assert report.ok, report.summary()
    assert (report.transport, report.messages) == ("process", {"P->C": 6})


def test_dds_checks_its_hosts_against_the_groups_before_anything_starts() -> None:
    pytest.importorskip("cyclonedds")
    with pytest.raises(ConfigurationError, match="no group runs on host 'moon'"):
        stream(Dds(host="moon")).run(timeout=1)


# ---- taps -----------------------------------------------------------------------------------

@pytest.mark.parametrize("transport", [pytest.param(Inproc(), id="inproc"),
                                       pytest.param(Processes(), id="process", marks=pytest.mark.slow)])
def test_every_runner_opens_the_taps_in_every_group_the_same_way(tmp_path: Path, transport: object) -> None:
    tap = tap_roles.FileTap(tmp_path)
    report = stream(transport).run(timeout=30, taps=[tap])
    assert report.ok, report.summary()
    (run,) = tap.runs
    assert (run.global_type.name, dict(run.group_of), run.transport) == (
        "Stream", {"P": "producing", "C": "consuming"}, report.transport)
    assert run.functions == {"P": f"{__name__}:producer", "C": f"{__name__}:consumer"}
    seen = {p.stem: json.loads(p.read_text()) for p in tmp_path.glob("*.json")}
    assert seen == {"producing-0": {"roles": ["P"], "sent": {"P->C": 6}},
                    "consuming-0": {"roles": ["C"], "sent": {}}}
    assert "file tap: producing-0 sent {'P->C': 6}" in report.notes


@pytest.mark.slow
def test_a_group_closing_its_taps_slowly_keeps_beating_and_is_not_failed(tmp_path: Path) -> None:
    """A recording's tail on a busy machine or a slow disk can take longer to write than the
    liveness limit: the group is closing, not frozen."""
    tap = tap_roles.FileTap(tmp_path, close_seconds=2.5)
    report = stream(Processes(liveness=1.0)).run(timeout=30, taps=[tap])
    assert report.ok, report.summary()
    assert {str(g.status) for g in report.groups.values()} == {"done"}
    assert sorted(p.stem for p in tmp_path.glob("*.json")) == ["consuming-0", "producing-0"]


def test_taps_hear_the_statuses_as_the_run_goes(tmp_path: Path) -> None:
    def slow_consumer(ep: anodize.Endpoint) -> None:
        ep.sleep(1.2)
        consumer(ep)

    system = anodize.System(STREAM)
    system.group("producing").role("P", producer)
    system.group("consuming").role("C", slow_consumer)
    tap = tap_roles.FileTap(tmp_path)
    assert system.run(timeout=10, taps=[tap]).ok
    assert tap.statuses >= 1


# ---- the deprecated keyword forms -----------------------------------------------------------

@pytest.mark.parametrize(("kind", "value"), [("inproc", Inproc()), ("process", Processes()), ("dds", Dds())])
def test_a_transport_string_is_a_deprecated_shim_for_the_value(kind: str, value: object) -> None:
    with pytest.warns(DeprecationWarning, match=rf"transport={kind!r}.*deprecated.*write System\(\.\.\., "
                                                rf"transport={type(value).__name__}\(\)\)"):
        system = anodize.System(STREAM, transport=kind)
    assert (system.transport, system.ros) == (value, None)


def test_the_dds_and_ros_keywords_build_dds_and_a_ros_bridge() -> None:
    with pytest.warns(DeprecationWarning, match=r"write System\(\.\.\., transport=Dds\(domain=7, run_id='r'\), "
                                                r"ros=RosBridge\(topics=\{'P->C:data': '/data'\}, distro='humble'\)\)"):
        system = anodize.System(STREAM, transport="dds", domain=7, run_id="r", ros_topics={"P->C:data": "/data"},
                                ros_distro="humble")
    assert system.transport == Dds(domain=7, run_id="r")
    assert system.ros == RosBridge(topics={"P->C:data": "/data"}, distro="humble")


def test_the_shims_check_what_they_always_checked() -> None:
    with pytest.raises(ConfigurationError, match="transport 'tcp': expected one of inproc, process, dds"):
        anodize.System(STREAM, transport="tcp")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        with pytest.raises(ConfigurationError, match=r"Dds domain: .* got 300"):
            anodize.System(STREAM, transport="process", domain=300)
    with pytest.raises(ConfigurationError, match="liveness: expected a number of seconds > 0, got 0"):
        stream().run(liveness=0)


def test_the_run_keywords_become_the_transport_s_fields() -> None:
    with pytest.warns(DeprecationWarning, match=r"System.run\(liveness=...\) is deprecated.*Processes\(liveness=5\)"):
        assert legacy_run(Processes(), 5, None, None) == Processes(liveness=5)
    with pytest.warns(DeprecationWarning, match=r"System.run\(host=..., wait=...\)"):
        assert legacy_run(Dds(), None, "robot", 3.0) == Dds(host="robot", wait=3.0)
    with pytest.warns(DeprecationWarning, match="liveness=..., host=..., wait=..."):  # only Dds has hosts
        assert legacy_run(Inproc(), 1.0, "robot", 3.0) == Inproc()
    assert legacy_run(Processes(), None, None, None) == Processes()


def test_run_liveness_still_runs_with_a_warning_pointing_at_the_caller() -> None:
    with pytest.warns(DeprecationWarning, match=r"System.run\(liveness=...\)") as caught:
        report = stream().run(timeout=10, liveness=1.0)
    assert report.ok, report.summary()
    assert caught[0].filename == __file__


def test_run_record_is_a_shim_for_a_recording_tap(tmp_path: Path) -> None:
    pytest.importorskip("mcap")
    with pytest.warns(DeprecationWarning, match=r"write System.run\(taps=\[anodize.Recording\(path\)\]\)"):
        report = stream().run(timeout=10, record=tmp_path / "r.mcap")
    assert report.ok, report.summary()
    assert (tmp_path / "r.mcap").is_file()
    assert any(note.startswith("recorded 6 messages") for note in report.notes), report.notes
