"""LivenessWatch: where the rule's samples come from, and the notes a starvation episode leaves."""

from __future__ import annotations

import pytest

from anodize._isolation import procstat
from anodize._isolation.procstat import ProcSample
from anodize._supervision.liveness import Alive, HoldingGil, Starved
from anodize._supervision.watching import SAMPLE_EVERY, LivenessWatch


class Kernel:
    """What /proc says about one process (pid 7), one look at a time."""

    def __init__(self) -> None:
        self.at = 0.0
        self.cpu = 0.0
        self.waited = 0.0
        self.state = "S"

    def sample(self, pid: int) -> ProcSample:
        assert pid == 7
        return ProcSample(at=self.at, cpu=self.cpu, waited={7: self.waited}, ran={7: self.cpu}, slices={7: 1},
                          states={7: self.state}, cpus=frozenset({1}))


@pytest.fixture
def kernel(monkeypatch: pytest.MonkeyPatch) -> Kernel:
    kernel = Kernel()
    monkeypatch.setattr(procstat, "sample", kernel.sample)
    monkeypatch.setattr(procstat, "rivals", lambda cpus, exclude, most=3: [f"hog (pid 9, cpus {sorted(cpus)})"])
    monkeypatch.setattr(procstat, "machine_load", lambda: "the machine: load 4.0 on 2 CPUs")
    monkeypatch.setattr(procstat, "cpu_quota", lambda pid: None)
    return kernel


def test_a_starvation_episode_is_reported_once_when_it_ends(kernel: Kernel) -> None:
    watch = LivenessWatch(limit=1.0)
    watch.sample({"g": (7, 0.0)}, 0.0)  # the look at its last heartbeat (sent at 0)
    kernel.at, kernel.waited, kernel.state = 3.0, 2.9, "R"
    verdict, notes = watch.check("g", 7, 0.0, 3.0)
    assert isinstance(verdict, Starved) and notes == []
    kernel.at, kernel.waited = 4.0, 3.9
    assert isinstance(watch.check("g", 7, 0.0, 4.0)[0], Starved)
    verdict, notes = watch.check("g", 7, 4.1, 4.2)  # a heartbeat again
    assert verdict == Alive()
    assert notes == [("starved, not failed: no heartbeat for 4.0 s (the limit is 1 s) while runnable, 3.9 s of it "
                      "waiting for a CPU; by the machine: load 4.0 on 2 CPUs; runnable there: hog (pid 9, cpus [1])")]
    assert watch.check("g", 7, 4.2, 4.3) == (Alive(), [])


def test_an_open_episode_is_reported_when_the_group_is_forgotten(kernel: Kernel) -> None:
    watch = LivenessWatch(limit=1.0)
    watch.sample({"g": (7, 0.0)}, 0.0)
    kernel.at, kernel.waited, kernel.state = 2.0, 2.0, "R"
    assert isinstance(watch.check("g", 7, 0.0, 2.0)[0], Starved)
    assert watch.forget("g")[0].startswith("starved, not failed: no heartbeat for 2.0 s")
    assert watch.forget("g") == []


def test_the_supervisors_stall_excuses_the_silence_and_is_reported(kernel: Kernel) -> None:
    watch = LivenessWatch(limit=1.0)
    watch.sample({"g": (7, 0.0)}, 0.0)
    watch.turn(started=0.1, expected=0.2, woke=2.6)  # asked to wake at 0.2, ran again at 2.6
    kernel.at, kernel.cpu = 2.7, 0.0
    assert watch.check("g", 7, 0.0, 2.7) == (Alive(), [])
    assert "held up 1 times (longest 2.40 s)" in watch.notes()[0]


def test_a_silent_group_that_runs_holds_the_gil(kernel: Kernel) -> None:
    watch = LivenessWatch(limit=1.0)
    watch.sample({"g": (7, 0.0)}, 0.0)
    for step in range(1, 5):  # looked at every SAMPLE_EVERY, on the CPU all along
        kernel.at = kernel.cpu = step * SAMPLE_EVERY
        kernel.state = "R"
        watch.sample({"g": (7, 0.0)}, kernel.at)
    kernel.at = kernel.cpu = 1.1
    verdict, _ = watch.check("g", 7, 0.0, 1.1)
    assert isinstance(verdict, HoldingGil) and verdict.cpu == pytest.approx(1.1)
