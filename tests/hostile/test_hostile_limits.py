"""The bounds themselves: an address-space limit (item 7), SIGINT and SIGTERM while a command
reads and checks (item 8), and the limits' own rules (sessiontypes.limits)."""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

import pytest
from hostile_inputs import (
    ANODIZE,
    ROOT,
    assert_clean,
    nested_choice_proto,
    run_bounded,
    sequence_proto,
    wait_for,
    wide_choice_proto,
)

from sessiontypes.limits import PROTOCOL, InputLimit, InputLimitError, check_file, check_text, read_limited


def test_check_runs_under_a_2_gib_address_space_limit(tmp_path: Path) -> None:
    # Item 7: the deep-recursion thread reserved a 2 GiB stack, so under 'prlimit --as=2GiB'
    # every check was "internal error: can't start new thread".
    (tmp_path / "p.proto").write_text(sequence_proto(400), encoding="utf-8")
    done = subprocess.run(["prlimit", f"--as={2 * 2**30}", "--", *ANODIZE, "check", "p.proto"], cwd=tmp_path,
                          env=_env(), capture_output=True, text=True, timeout=120, check=False)
    assert (done.returncode, done.stderr, done.stdout) == (0, "", "p.proto: ok (1 global, 0 locals)\n")


@pytest.mark.parametrize("megabytes", [400, 600])
def test_deep_checks_fit_a_smaller_address_space(tmp_path: Path, megabytes: int) -> None:
    (tmp_path / "p.proto").write_text(nested_choice_proto(150), encoding="utf-8")
    done = subprocess.run(["prlimit", f"--as={megabytes * 2**20}", "--", *ANODIZE, "check", "p.proto"],
                          cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=120, check=False)
    assert (done.returncode, done.stderr) == (0, "")


@pytest.mark.parametrize(("signum", "status", "line"), [
    (signal.SIGINT, 130, "anodize check: interrupted\n"),
    (signal.SIGTERM, 143, "anodize check: terminated (SIGTERM)\n"),
])
def test_a_signal_while_checking_ends_the_command_with_one_line(tmp_path: Path, signum: int, status: int,
                                                                line: str) -> None:
    # Item 8: a long check must honour SIGINT and SIGTERM (130/143, one line, no traceback).
    # The file is one that takes seconds to check; the signal is sent once the process has
    # started its checking thread (sessiontypes.deep: /proc counts its threads), so mid-check.
    path = tmp_path / "p.proto"
    path.write_text(wide_choice_proto(400_000), encoding="utf-8")
    assert path.stat().st_size < PROTOCOL.default
    process = subprocess.Popen([*ANODIZE, "check", str(path)], env=_env(), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        assert wait_for(lambda: _threads(process.pid) >= 2 or process.poll() is not None)
        assert process.poll() is None, "the check ended before the signal was sent"
        process.send_signal(signum)
        out, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(timeout=60)
    assert (process.returncode, err, out) == (status, line, "")


def test_a_file_that_grows_past_the_limit_while_read_is_refused(tmp_path: Path) -> None:
    limit = InputLimit("test file", 10, "ANODIZE_TEST_NO_SUCH_VARIABLE")
    path = tmp_path / "f"
    path.write_bytes(b"x" * 10)
    assert read_limited(path, limit) == b"x" * 10
    path.write_bytes(b"x" * 11)
    with pytest.raises(InputLimitError, match=r"^.*/f: larger than the 10 bytes limit for a test file "
                                              r"\(set ANODIZE_TEST_NO_SUCH_VARIABLE to raise it\)$"):
        read_limited(path, limit)
    with pytest.raises(InputLimitError) as refused:
        check_file(path, limit)
    assert (refused.value.limit, refused.value.filename) == (10, str(path))


def test_limits_read_their_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    limit = InputLimit("test file", 10, "ANODIZE_TEST_LIMIT")
    for given, expected in [("", 10), ("2KiB", 2048), ("3 MB", 3_000_000), ("7", 7), ("lots", 10)]:
        monkeypatch.setenv("ANODIZE_TEST_LIMIT", given)
        assert limit.bytes() == expected


def test_devices_and_fifos_are_refused_without_blocking(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "fifo")  # no writer: a blocking open would wait for ever
    for path, kind in [("/dev/zero", "a character device"), (tmp_path / "fifo", "a FIFO"), (tmp_path, "a directory")]:
        with pytest.raises(InputLimitError, match=rf": not a regular file \({kind}\); expected a protocol file$"):
            read_limited(path, PROTOCOL)


def test_text_inside_another_file_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(PROTOCOL.variable, "8")
    assert check_text("12345678", PROTOCOL, "r.mcap: p.proto") == "12345678"
    with pytest.raises(InputLimitError, match=r"^r.mcap: p.proto: larger than the 8 bytes limit"):
        check_text("1234567\u00e9", PROTOCOL, "r.mcap: p.proto")


def test_the_harness_sees_a_crash() -> None:
    # assert_clean could pass by never looking: a traceback and a signal must fail it.
    crashed = run_bounded([*ANODIZE[:1], "-c", "raise SystemExit(1) from ValueError()"], ROOT)
    assert_clean(crashed)
    with pytest.raises(AssertionError):
        assert_clean(run_bounded([*ANODIZE[:1], "-c", "import os; os.abort()"], ROOT))
    with pytest.raises(AssertionError):
        assert_clean(run_bounded([*ANODIZE[:1], "-c", "raise ValueError('x')"], ROOT))


def _threads(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("Threads:"))
    except (OSError, StopIteration, ValueError):
        return 0


def _env() -> dict[str, str]:
    environment = {key: value for key, value in os.environ.items() if key != "ANODIZE_DEBUG"}
    environment["PYTHONPATH"] = f"{ROOT}{os.pathsep}{ROOT / 'tinman' / 'src'}"
    return environment
