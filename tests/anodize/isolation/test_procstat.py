"""The kernel's view of a process, read from /proc: state, CPU time, run-queue waits."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import pytest

from anodize._isolation import procstat

pytestmark = pytest.mark.skipif(not os.path.exists("/proc/self/schedstat"),
                                reason="needs /proc with schedstat (Linux, CONFIG_SCHED_INFO)")


@pytest.fixture
def child() -> Iterator[subprocess.Popen[bytes]]:
    process = subprocess.Popen([sys.executable, "-c", "import time\nwhile True: time.sleep(0.05)"])
    yield process
    process.kill()
    process.wait()


def test_a_sample_of_this_process_names_this_thread() -> None:
    looked = procstat.sample(os.getpid())
    assert looked is not None
    assert looked.waited.keys() == looked.states.keys()
    assert threading.get_native_id() in looked.states
    assert looked.states[threading.get_native_id()] == "R"  # it is reading its own state
    assert looked.cpu > 0 and not looked.stopped
    assert looked.cpus and all(0 <= cpu < (os.cpu_count() or 1024) for cpu in looked.cpus)


def test_a_stopped_process_is_seen_stopped(child: subprocess.Popen[bytes]) -> None:
    os.kill(child.pid, signal.SIGSTOP)
    deadline = time.monotonic() + 5
    while not ((looked := procstat.sample(child.pid)) and looked.stopped):
        assert time.monotonic() < deadline, "SIGSTOP not seen in /proc within 5 s"
        time.sleep(0.01)
    os.kill(child.pid, signal.SIGCONT)


def test_a_process_that_is_gone_has_no_sample(child: subprocess.Popen[bytes]) -> None:
    child.kill()
    child.wait()
    assert procstat.sample(child.pid) is None


def test_the_run_queue_wait_of_this_thread_only_grows() -> None:
    first = procstat.own_run_delay()
    assert first is not None
    sum(range(200_000))
    second = procstat.own_run_delay()
    assert second is not None and second >= first


def test_the_machine_load_is_described() -> None:
    assert procstat.machine_load().startswith("the machine")


def test_rivals_names_runnable_tasks_on_the_cpus_asked_about() -> None:
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        deadline = time.monotonic() + 10
        while not any(f"pid {spinner.pid}," in text for text in procstat.rivals(frozenset(), exclude=os.getpid(),
                                                                                   most=1000)):
            assert time.monotonic() < deadline, "a spinning process was never seen runnable"
            time.sleep(0.05)
        others = procstat.rivals(frozenset(), exclude=spinner.pid, most=1000)
        assert all(f"pid {spinner.pid}," not in text for text in others)
    finally:
        spinner.kill()
        spinner.wait()


CPU_CGROUPS = "/sys/fs/cgroup/cpu"


@pytest.mark.skipif(not os.access(os.path.join(CPU_CGROUPS, "cgroup.procs"), os.W_OK),
                    reason="needs a writable cgroup v1 cpu controller at /sys/fs/cgroup/cpu (root)")
def test_a_cpu_quota_is_named(child: subprocess.Popen[bytes]) -> None:
    cgroup = os.path.join(CPU_CGROUPS, f"anodize-test-{os.getpid()}-quota")
    os.makedirs(cgroup, exist_ok=True)
    try:
        assert procstat.cpu_quota(child.pid) is None  # the parent of every test cgroup has none
        with open(os.path.join(cgroup, "cpu.cfs_quota_us"), "w") as f:
            f.write("50000")
        with open(os.path.join(cgroup, "cgroup.procs"), "w") as f:
            f.write(str(child.pid))
        assert procstat.cpu_quota(child.pid) == "its cgroup's CPU quota (50 ms per 100 ms)"
    finally:
        child.kill()
        child.wait()
        os.rmdir(cgroup)
