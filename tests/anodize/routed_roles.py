"""Role functions for the routed-choice runs (module level: group processes import them).

A hands each job to B or to C; whoever does not get it from A learns the round's
branch from the other one. B and C take whichever message comes first
(``recv_any``): their local types receive from A or from the other at one state.
"""

from __future__ import annotations

from anodize import Endpoint

PLAN = ["B", "C", "C", "B", "C"]  # who gets each job from A; then A stops


def chooser(ep: Endpoint) -> None:
    for number, worker in enumerate(PLAN):
        ep.send(worker, "job", number)
        if worker == "B":
            ok = ep.recv("C")
            if ok != ("ok", None):
                raise AssertionError(f"round {number}: got {ok!r}")
        else:
            result = ep.recv("B")
            if result != ("result", number * 10):
                raise AssertionError(f"round {number}: got {result!r}")
    ep.send("B", "stop")


def worker_b(ep: Endpoint) -> None:
    rounds: list[str] = []
    while True:
        peer, message = ep.recv_any()
        rounds.append(f"{peer}:{message.label}")
        if (peer, message.label) == ("A", "job"):
            ep.send("C", "idle")
        elif (peer, message.label) == ("C", "work"):
            ep.send("A", "result", message.payload * 10)
        else:
            ep.send("C", "stop")
            break
    if rounds != ["A:job", "C:work", "C:work", "A:job", "C:work", "A:stop"]:
        raise AssertionError(f"B saw {rounds}")


def worker_c(ep: Endpoint) -> None:
    while True:
        peer, message = ep.recv_any()
        if (peer, message.label) == ("B", "idle"):
            ep.send("A", "ok")
        elif (peer, message.label) == ("A", "job"):
            ep.send("B", "work", message.payload)
        else:
            return


def worker_c_by_peer(ep: Endpoint) -> None:
    """C knowing the plan: ``recv(peer)`` at the state that may receive from either."""
    for worker in PLAN:
        if worker == "B":
            if ep.recv("B").label != "idle":
                raise AssertionError("expected idle")
            ep.send("A", "ok")
        else:
            job = ep.recv("A")
            ep.send("B", "work", job.payload)
    ep.recv("B")


def lazy_c(ep: Endpoint) -> None:
    """C waits for A where it should have heard from B first: its own violation."""
    ep.recv_any()  # job 0 went to B: idle from B
    ep.send("A", "ok")
    ep.recv("A")  # job 1 from A
    ep.send("A", "work", 1)  # work goes to B, not A
