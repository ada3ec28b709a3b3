"""scripts/bootstrap says what it installs, and why, before it installs anything (--dry-run: only that).

Run with a stand-in ``dpkg-query`` that reports every Debian package missing and a stand-in
``id`` that makes the script root or not; --dry-run touches nothing, so no apt-get or pip runs.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "bootstrap"
PACKAGES = ["gcc", "python3-dev", "g++", "libfastrtps-dev", "libfastcdr-dev", "nftables"]


def _copy(tmp_path: Path) -> Path:
    """The script in an empty checkout: should an option ever be ignored and the script install,
    nothing of the repository is touched (the script works in the folder above its own)."""
    script = tmp_path / "checkout" / "scripts" / "bootstrap"
    script.parent.mkdir(parents=True)
    script.write_bytes(SCRIPT.read_bytes())
    script.chmod(0o755)
    return script


def _dry_run(tmp_path: Path, uid: int) -> subprocess.CompletedProcess[str]:
    script = _copy(tmp_path)
    tools = tmp_path / "bin"
    tools.mkdir()
    for name, body in {"dpkg-query": "exit 1", "id": f"echo {uid}", "apt-get": "exit 0", "nft": "exit 127"}.items():
        tool = tools / name
        tool.write_text(f"#!/bin/sh\n{body}\n", encoding="utf-8")
        tool.chmod(0o755)
    (tools / "nft").unlink()  # nftables absent: no nft on PATH
    path = f"{tools}:/usr/bin:/bin"
    return subprocess.run([str(script), "--dry-run"], capture_output=True, text=True, timeout=60, check=False,
                          env={**os.environ, "PATH": path, "PYTHON": os.environ.get("PYTHON", "python3")})


def test_the_script_is_valid_bash() -> None:
    subprocess.run(["bash", "-n", str(SCRIPT)], check=True, timeout=30)


@pytest.mark.parametrize("uid", [0, 1000], ids=["root", "user"])
def test_the_plan_names_each_package_and_why_before_anything(tmp_path: Path, uid: int) -> None:
    if not (Path("/usr/bin/python3").exists() or Path("/bin/python3").exists()):
        pytest.skip("needs a python3 in /usr/bin (the script's default interpreter)")
    done = _dry_run(tmp_path, uid)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line.split()[0] for line in lines if line.lstrip().startswith("[")] == ["[1/4]", "[2/4]", "[3/4]", "[4/4]"]
    for package in PACKAGES:
        assert any(line.split()[:1] == [package] and len(line.split()) > 1 for line in lines), \
            f"{package} is not named with its reason:\n{done.stdout}"
    # python3-venv too when python3 is Debian's own (it ships venv apart)
    told = any(line.strip().removeprefix("apt-get install ").removeprefix("python3-venv ") == " ".join(PACKAGES)
               for line in lines)
    assert told == (uid != 0), done.stdout  # as another user it says what to install as root, instead of doing it
    assert lines[-1] == "bootstrap: --dry-run: nothing installed"
    assert not (tmp_path / "checkout" / ".venv").exists()


def test_an_unknown_option_is_a_usage_error(tmp_path: Path) -> None:
    done = subprocess.run([str(_copy(tmp_path)), "--frobnicate"], capture_output=True, text=True, timeout=30,
                          check=False)
    assert done.returncode == 2
    assert "expected --dry-run or --help" in done.stderr
