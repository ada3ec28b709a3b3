"""Roles for the priority inheritance tests (module level: group processes import them).

Each target role writes its thread id where the asking role can find it (``ANODIZE_TEST_DIR``),
answers each ``ask`` with the priority its own thread has *while the asker waits* (it sleeps
first, so the asker is surely blocked), and the asker reads the target's priority by thread id
after the wait ended, to see the boost removed. Every wait is bounded; nothing spins.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

from anodize import Endpoint

PAUSE = 0.2  # how long a target sleeps before answering: the asker blocks meanwhile


def _dir() -> Path:
    return Path(os.environ["ANODIZE_TEST_DIR"])


def own_priority(tid: int = 0) -> int:
    """The SCHED_FIFO priority of thread ``tid`` (0: this one), 0 when not under SCHED_FIFO."""
    return os.sched_getparam(tid).sched_priority if os.sched_getscheduler(tid) == os.SCHED_FIFO else 0


def _tell_tid(role: str) -> None:
    (_dir() / f"{role}.tid").write_text(str(threading.get_native_id()))


def _tid_of(role: str) -> int:
    path = _dir() / f"{role}.tid"
    deadline = time.monotonic() + 10
    while not path.exists() or not path.read_text():
        if time.monotonic() > deadline:
            raise AssertionError(f"{role} never wrote its thread id")
        time.sleep(0.01)
    return int(path.read_text())


def _log(line: str) -> None:
    with (_dir() / "log").open("a") as log:
        log.write(line + "\n")


def asker(ep: Endpoint) -> None:
    """H: ask twice (logs what the target ran at during each wait, and just after), then stop."""
    tid = _tid_of("L")
    for _ in range(2):
        ep.send("L", "ask")
        during = ep.recv("L", timeout=10).payload
        _log(f"during {during} after {own_priority(tid)}")
    ep.send("L", "stop")


def impatient_asker(ep: Endpoint) -> None:
    """H: asks, gives up waiting before the answer comes, looks at the target, then takes it."""
    tid = _tid_of("L")
    ep.send("L", "ask")
    try:
        ep.recv("L", timeout=PAUSE / 4)
    except TimeoutError:
        _log(f"timeout after {own_priority(tid)}")
    ep.recv("L", timeout=10)
    ep.send("L", "stop")


def _answer_asks_of(ep: Endpoint, asker: str) -> None:
    """L: answers each ask of ``asker``, after a pause, with its own priority at that moment."""
    _tell_tid("L")
    while ep.recv(asker, timeout=30).label == "ask":
        time.sleep(PAUSE)
        ep.send(asker, "answer", own_priority())


def answerer(ep: Endpoint) -> None:
    """L: answers H."""
    _answer_asks_of(ep, "H")


def middle(ep: Endpoint) -> None:
    """M in a chain H -> M -> L: each ask from H becomes an ask to L; L's answer goes back."""
    _tell_tid("M")
    while ep.recv("H", timeout=30).label == "ask":
        ep.send("L", "ask")
        ep.send("H", "answer", ep.recv("L", timeout=10).payload)
    ep.send("L", "stop")


def chain_answerer(ep: Endpoint) -> None:
    """L at the end of the chain: answers M."""
    _answer_asks_of(ep, "M")


def chain_asker(ep: Endpoint) -> None:
    """H at the head of the chain: asks M once, logs what L ran at, and after."""
    tid = _tid_of("L")
    ep.send("M", "ask")
    during = ep.recv("M", timeout=10).payload
    _log(f"during {during} after {own_priority(tid)}")
    ep.send("M", "stop")


def dying_asker(ep: Endpoint) -> None:
    """H: asks, then its process dies (SIGKILL) while it waits."""
    _tid_of("L")
    ep.send("L", "ask")
    threading.Timer(PAUSE / 4, os.kill, (os.getpid(), 9)).start()
    ep.recv("L", timeout=10)


def watching_answerer(ep: Endpoint) -> None:
    """L for dying_asker: logs its priority once its asker is long dead, then ends."""
    _tell_tid("L")
    ep.recv("H", timeout=30)
    time.sleep(PAUSE * 3)  # the asker died meanwhile, and the supervisor noticed
    _log(f"orphan {own_priority()}")


BIG = b"x" * 300_000  # between processes, a few of these fill the pipe (1 MiB)


def flooder(ep: Endpoint) -> None:
    """H: sends more than the channel holds (it blocks on a full channel), then looks at L."""
    tid = _tid_of("L")
    for _ in range(8):
        ep.send("L", "data", BIG)
    _log(f"after {own_priority(tid)}")
    ep.send("L", "stop")


def slow_sink(ep: Endpoint) -> None:
    """L: lets its channel fill (H blocks sending), logs its priority then, and drains it."""
    _tell_tid("L")
    time.sleep(PAUSE * 2)
    _log(f"during {own_priority()}")
    while ep.recv("H", timeout=30).label == "data":
        pass


def branch_answerer(ep: Endpoint) -> None:
    """L with two parallel branches, each on its own thread: the one H waits on answers H after
    a pause with its thread's priority; the other takes K's message."""
    _tell_tid("L")
    to_h, from_k = ep.fork()

    def answer_h() -> None:
        to_h.recv("H", timeout=30)
        time.sleep(PAUSE)
        to_h.send("H", "answer", own_priority())

    helper = threading.Thread(target=answer_h)
    helper.start()
    from_k.recv("K", timeout=30)
    helper.join(30)


def kicker(ep: Endpoint) -> None:
    """K: one message to L."""
    ep.send("L", "go")


def single_asker(ep: Endpoint) -> None:
    """H: asks once, logs what L's answering thread ran at."""
    ep.send("L", "ask")
    _log(f"during {ep.recv('L', timeout=10).payload}")


def any_asker(ep: Endpoint) -> None:
    """H: asks L and M, then takes whichever answers first (recv_any), twice."""
    ep.send("L", "ask")
    ep.send("M", "ask")
    for _ in range(2):
        peer, message = ep.recv_any(timeout=10)
        _log(f"{peer} during {message.payload}")


def any_answerer(ep: Endpoint) -> None:
    """L or M for any_asker: answers after a pause (M pauses longer: L answers first)."""
    ep.recv("H", timeout=30)
    time.sleep(PAUSE if ep.role == "L" else PAUSE * 2)
    ep.send("H", "answer", own_priority())


TICK = "tick_" + "x" * 250  # a long label: few of these small frames fill the pipe (1 MiB)


def ticker(ep: Endpoint) -> None:
    """H: small messages (the compiled writer's) until the pipe is full and well past it (it
    blocks rather than spins: each frame is about 270 bytes, so 8000 are twice the pipe)."""
    tid = _tid_of("L")
    for _ in range(8000):
        ep.send("L", TICK)
    _log(f"after {own_priority(tid)}")
    ep.send("L", "stop")


def tick_sink(ep: Endpoint) -> None:
    """L: lets the pipe fill (H blocks writing), logs its priority then, and drains it."""
    _tell_tid("L")
    time.sleep(PAUSE * 2)
    _log(f"during {own_priority()}")
    while True:
        if any(message.label == "stop" for message in ep.recv_many("H", timeout=30)):
            return


def late_asker(ep: Endpoint) -> None:
    """H: asks, lets the answer arrive in the pipe before it receives (the no-wait path), twice."""
    for _ in range(2):
        ep.send("L", "ask")
        time.sleep(PAUSE)
        ep.recv("L")  # no timeout (the compiled core's path); the run's timeout bounds it
    _log("answered")
    ep.send("L", "stop")


def prompt_answerer(ep: Endpoint) -> None:
    """L: answers each ask at once."""
    while ep.recv("H", timeout=30).label == "ask":
        ep.send("H", "answer", 0)
