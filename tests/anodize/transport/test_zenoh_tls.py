"""Zenoh over TLS (``anodize.ZenohTls``, ``[zenoh.tls]``, ``anodize router --tls-*``): a run through
a TLS router delivers everything in order; a host that does not trust the router's certificate,
or that has none where the router asks for one (mutual TLS), never joins and says why; and no
setting lets a part of a TLS run travel in the clear. Certificates are made per test
(tls_certs.py); routers listen on loopback."""

from __future__ import annotations

import re
import socket
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import dds_roles
import pytest
import tls_certs

import anodize
import sessiontypes
from anodize._tools.config import ConfigError, load_config
from anodize._tools.router import DEFAULT_LISTEN, TLS_LISTEN, Router, open_router, tls_endpoints
from anodize._transport.zenoh.settings import ZenohSettings, session_config, supervisor_settings

pytest.importorskip("zenoh", reason="the zenoh extra is not installed")

STREAM = sessiontypes.loads(dds_roles.STREAM, "stream.proto").globals["Stream"]


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The run's authority and the router's and a host's certificates it signed; and a stranger's
    authority, with a host it signed."""
    directory = tmp_path_factory.mktemp("certs")
    ours, theirs = tls_certs.authority(directory, "site-ca"), tls_certs.authority(directory, "other-ca")
    router, robot = tls_certs.host(directory, "router", ours), tls_certs.host(directory, "robot", ours)
    stranger = tls_certs.host(directory, "stranger", theirs)
    return {"ca": ours.certificate, "other_ca": theirs.certificate, "router": router.certificate,
            "router_key": router.key, "robot": robot.certificate, "robot_key": robot.key,
            "stranger": stranger.certificate, "stranger_key": stranger.key}


def tls_endpoint() -> str:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tls/127.0.0.1:{probe.getsockname()[1]}"


def tls_router(certs: dict[str, Path], mutual: bool = False) -> tuple[Router, str]:
    endpoint = tls_endpoint()
    tls = anodize.ZenohTls(root_ca=str(certs["ca"]) if mutual else "", certificate=str(certs["router"]),
                           private_key=str(certs["router_key"]), mutual=mutual)
    return open_router([endpoint], tls=tls), endpoint


def stream_over(endpoint: str, tls: anodize.ZenohTls, wait: float = 20.0) -> anodize.System:
    transport = anodize.Zenoh(mode="client", connect=(endpoint,), scouting=False, run_id="t" + uuid.uuid4().hex[:12],
                              wait=wait, tls=tls)
    system = anodize.System(STREAM, transport=transport)
    system.group("producing").role("P", dds_roles.producer)
    system.group("consuming").role("C", dds_roles.consumer)
    return system


def through_a_router(certs: dict[str, Path], tls: anodize.ZenohTls,
                     wait: float = 20.0) -> tuple[anodize.RunReport, str]:
    """The stream run through a TLS router of the site; its report, and the router's endpoint."""
    router, endpoint = tls_router(certs)
    try:
        return stream_over(endpoint, tls, wait).run(timeout=60), endpoint
    finally:
        router.close()


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_a_run_through_a_tls_router_delivers_everything_in_order(
        certs: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "2000")
    report, _ = through_a_router(certs, anodize.ZenohTls(root_ca=str(certs["ca"])))
    assert report.ok, report.summary()
    assert report.groups["consuming"].received == 2001  # the consumer checks 0..1999 in order, then done
    assert any(note.startswith("Zenoh TLS on every link: ") for note in report.notes), report.notes


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_a_host_that_does_not_trust_the_routers_certificate_never_joins(
        certs: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "10")
    report, endpoint = through_a_router(certs, anodize.ZenohTls(root_ca=str(certs["other_ca"])), wait=2.0)
    assert not report.ok
    error = str(report.groups["producing"].error)
    assert f"cannot open a Zenoh session in client mode (connect {endpoint}; listen none)" in error, error
    assert (f"over TLS, does the certificate of what it connects to name the address connected to, signed by "
            f"{certs['other_ca']}?" in error), error


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_with_mutual_tls_only_a_host_with_a_certificate_of_the_site_joins(
        certs: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DDS_TEST_COUNT", "200")
    router, endpoint = tls_router(certs, mutual=True)
    ca = str(certs["ca"])
    try:
        without = stream_over(endpoint, anodize.ZenohTls(root_ca=ca), wait=2.0).run(timeout=60)
        foreign = stream_over(endpoint, anodize.ZenohTls(root_ca=ca, certificate=str(certs["stranger"]),
                                                         private_key=str(certs["stranger_key"]), mutual=True),
                              wait=2.0).run(timeout=60)
        site = anodize.ZenohTls(root_ca=ca, certificate=str(certs["robot"]), private_key=str(certs["robot_key"]),
                                mutual=True)
        robot = stream_over(endpoint, site).run(timeout=60)
    finally:
        router.close()
    for turned_away in (without, foreign):
        assert not turned_away.ok
        assert "cannot open a Zenoh session" in str(turned_away.groups["producing"].error), turned_away.summary()
    assert robot.ok, robot.summary()
    assert robot.groups["consuming"].received == 201


@pytest.mark.slow  # Zenoh groups in processes for seconds
def test_peers_over_tls_meet_with_the_endpoints_of_each_host(
        certs: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    # Every group runs here (no --host), each with its own host's endpoints: A listens, B connects.
    monkeypatch.setenv("DDS_TEST_COUNT", "500")
    listening = tls_endpoint()
    tls = anodize.ZenohTls(root_ca=str(certs["ca"]), certificate=str(certs["robot"]),
                           private_key=str(certs["robot_key"]))
    transport = anodize.Zenoh(mode="peer", scouting=False, run_id="t" + uuid.uuid4().hex[:12], wait=20, tls=tls,
                              listen=(listening,), hosts=(("A", "peer", (), (listening,)),
                                                          ("B", "peer", (listening,), (tls_endpoint(),))))
    system = anodize.System(STREAM, transport=transport)
    system.group("producing", host="A").role("P", dds_roles.producer)
    system.group("consuming", host="B").role("C", dds_roles.consumer)
    report = system.run(timeout=60)
    assert report.ok, report.summary()
    assert report.groups["consuming"].received == 501


def test_the_session_configuration_carries_the_files_to_zenoh(certs: dict[str, Path]) -> None:
    tls = anodize.ZenohTls(root_ca=str(certs["ca"]), certificate=str(certs["robot"]),
                           private_key=str(certs["robot_key"]), mutual=True)
    settings = ZenohSettings(mode="peer", run_id="r", host="a", group_of={}, host_of={}, listen=("tls/0.0.0.0:7448",),
                             tls=tls)
    assert session_config(settings)["transport"]["link"]["tls"] == {
        "enable_mtls": True, "root_ca_certificate": str(certs["ca"]),
        "listen_certificate": str(certs["robot"]), "listen_private_key": str(certs["robot_key"]),
        "connect_certificate": str(certs["robot"]), "connect_private_key": str(certs["robot_key"])}
    plain = ZenohSettings(mode="peer", run_id="r", host="a", group_of={}, host_of={})
    assert "tls" not in session_config(plain)["transport"]["link"]
    # A supervisor's peer session listens nowhere, rather than on Zenoh's default (plain TCP).
    supervisor = supervisor_settings(settings)
    assert session_config(supervisor)["listen"] == {"endpoints": []}
    assert session_config(supervisor)["connect"]["endpoints"] == ["tls/127.0.0.1:7448"]


CONNECTING = anodize.ZenohTls(root_ca="ca.pem")
LISTENING = anodize.ZenohTls(certificate="host.pem", private_key="host.key")


@pytest.mark.parametrize(("tls", "fields", "expected"), [
    (CONNECTING, {"mode": "client", "connect": ("tcp/10.0.0.1:7447",)},
     ("with tls, every endpoint must be tls/ADDRESS:PORT (or quic/), got 'tcp/10.0.0.1:7447' (it would not be "
      "encrypted)")),
    (CONNECTING, {"mode": "client", "connect": ("tls/10.0.0.1:7447",),
                  "hosts": (("base", "peer", (), ("tcp/0.0.0.0:7448",)),)},
     "Zenoh hosts base: with tls, every endpoint must be tls/ADDRESS:PORT (or quic/), got 'tcp/0.0.0.0:7448'"),
    (CONNECTING, {"mode": "peer", "listen": ("tls/0.0.0.0:7448",)},
     "Zenoh tls: it listens (tls/0.0.0.0:7448), so it needs certificate and private_key"),
    (LISTENING, {"mode": "peer", "listen": ("tls/0.0.0.0:7448",)},
     "Zenoh tls: a peer connects to the peers it hears of, so it needs root_ca"),
])
def test_no_setting_lets_a_part_of_a_tls_run_travel_in_the_clear(
        tls: anodize.ZenohTls, fields: dict[str, object], expected: str) -> None:
    with pytest.raises(anodize.ConfigurationError) as raised:
        anodize.Zenoh(tls=tls, scouting=False, **fields)  # type: ignore[arg-type]
    assert expected in str(raised.value)


def test_quic_is_tls_too_and_a_peer_need_not_listen() -> None:
    anodize.Zenoh(mode="client", connect=("quic/10.0.0.1:7447",), tls=CONNECTING, scouting=False)
    # A peer that only connects out listens nowhere (its session's listen endpoints are an empty list).
    anodize.Zenoh(mode="peer", connect=("tls/10.0.0.1:7448",), tls=CONNECTING, scouting=False)


@pytest.mark.parametrize(("listen", "connect", "tls", "expected"), [
    (None, (), LISTENING, [TLS_LISTEN]),  # with TLS, the default is encrypted
    (("tls/10.0.0.1:7447",), (), LISTENING, ["tls/10.0.0.1:7447"]),
    (None, (), None, list(DEFAULT_LISTEN)),
    (DEFAULT_LISTEN, (), LISTENING, "every endpoint of the router is tls/"),  # asked for in the clear: refused
    (("tls/10.0.0.1:7447", "tcp/10.0.0.1:7448"), (), LISTENING, "every endpoint of the router is tls/"),
    (("tls/10.0.0.1:7447",), ("tcp/10.0.0.2:7447",), LISTENING, "every endpoint of the router is tls/"),
    (("tls/10.0.0.1:7447",), (), None, "a tls/ endpoint needs the router's TLS files"),
    (("tls/10.0.0.1:7447",), (), CONNECTING, "to listen on a tls/ endpoint, the router needs --tls-certificate"),
    ((), ("tls/10.0.0.2:7447",), LISTENING, "to connect to a tls/ endpoint, the router needs --tls-root-ca"),
])
def test_a_router_with_tls_listens_and_connects_only_over_tls(
        listen: tuple[str, ...] | None, connect: tuple[str, ...], tls: anodize.ZenohTls | None,
        expected: list[str] | str) -> None:
    if isinstance(expected, list):
        assert tls_endpoints(listen, connect, tls) == expected
    else:
        with pytest.raises(anodize.ConfigurationError, match=re.escape(expected)):
            tls_endpoints(listen, connect, tls)


@pytest.mark.parametrize(("fields", "expected"), [
    ({"certificate": "host.pem"}, "certificate is given but not private_key"),
    ({"root_ca": "ca.pem", "mutual": True}, "mutual: expected root_ca, certificate and private_key"),
    ({}, "expected root_ca (to connect), or certificate and private_key (to listen), or all three"),
    ({"root_ca": 7}, "tls root_ca: expected the path of a PEM file, got 7"),
])
def test_a_tls_setting_that_cannot_work_is_refused_saying_why(fields: dict[str, object], expected: str) -> None:
    with pytest.raises(anodize.ConfigurationError) as raised:
        anodize.ZenohTls(**fields)  # type: ignore[arg-type]
    assert expected in str(raised.value)


def test_a_missing_file_is_named_when_the_run_starts(tmp_path: Path) -> None:
    transport = anodize.Zenoh(mode="client", connect=("tls/127.0.0.1:9",), scouting=False,
                              tls=anodize.ZenohTls(root_ca=str(tmp_path / "nowhere.pem")))
    system = anodize.System(STREAM, transport=transport)
    system.group("producing").role("P", dds_roles.producer)
    system.group("consuming").role("C", dds_roles.consumer)
    with pytest.raises(anodize.ConfigurationError, match=r"Zenoh tls root_ca: cannot read .*nowhere\.pem"):
        system.run(timeout=10)


SYSTEM = """\
protocol = "stream.proto"
global = "Stream"

[transport]
kind = "zenoh"

[groups.producing]
roles = {{ P = "dds_roles:producer" }}

[groups.consuming]
roles = {{ C = "dds_roles:consumer" }}

[zenoh]
mode = "client"
connect = ["tls/router.site:7447"]
{tls}
"""


def test_the_system_file_reads_zenoh_tls_with_paths_beside_it(tmp_path: Path) -> None:
    (tmp_path / "stream.proto").write_text(dds_roles.STREAM)
    system = tmp_path / "system.toml"
    system.write_text(SYSTEM.format(tls=textwrap.dedent("""\
        [zenoh.tls]
        root_ca = "certs/ca.pem"
        certificate = "certs/robot.pem"
        private_key = "certs/robot.key"
        mutual = true""")))
    transport = load_config(system).transport
    assert isinstance(transport, anodize.Zenoh)
    assert transport.tls == anodize.ZenohTls(root_ca=str(tmp_path / "certs/ca.pem"),
                                             certificate=str(tmp_path / "certs/robot.pem"),
                                             private_key=str(tmp_path / "certs/robot.key"), mutual=True)


@pytest.mark.parametrize(("tls", "key", "expected"), [
    ('[zenoh.tls]\nroot_ca = "ca.pem"\nverify = false', "zenoh.tls.verify", "unknown key"),
    ('[zenoh.tls]\ncertificate = "robot.pem"', "zenoh.tls", "certificate is given but not private_key"),
    ('[zenoh.tls]\nroot_ca = ""', "zenoh.tls.root_ca", "expected the path of a PEM file"),
])
def test_a_wrong_zenoh_tls_table_is_an_error_at_its_line(tmp_path: Path, tls: str, key: str, expected: str) -> None:
    (tmp_path / "stream.proto").write_text(dds_roles.STREAM)
    system = tmp_path / "system.toml"
    system.write_text(SYSTEM.format(tls=tls))
    with pytest.raises(ConfigError) as raised:
        load_config(system)
    assert raised.value.key == key and expected in str(raised.value), str(raised.value)
    assert "system.toml:" in str(raised.value)  # file:line:col, with the line


def test_the_router_command_refuses_a_tls_endpoint_without_its_files() -> None:
    done = subprocess.run([sys.executable, "-m", "anodize._tools.cli", "router", "--listen", tls_endpoint()],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr  # a usage error
    assert "a tls/ endpoint needs the router's TLS files (--tls-certificate and --tls-private-key" in done.stderr
