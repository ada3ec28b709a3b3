"""What the supervisors of one run, one per host, say to each other (the values; :mod:`.hostwords`
encodes them, a transport's host link carries them).

Who said a word is the carrier's to establish (it checks the writer's claim): ``host`` and
``supervisor`` (a random id each supervisor draws at its start) come from there, never from
the word's own bytes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["StopWord", "RestartWord", "HelloWord", "Word", "Decision"]


@dataclass(frozen=True)
class StopWord:
    """Every group of the run stops."""

    host: str
    why: str
    supervisor: str = ""


@dataclass(frozen=True)
class RestartWord:
    """The groups of ``groups``, wherever they run, start again as incarnation ``incarnation``."""

    host: str
    groups: tuple[str, ...]
    incarnation: int
    why: str
    supervisor: str = ""


@dataclass(frozen=True)
class Decision:
    """A restart some supervisor decided: ``groups`` start again as ``incarnation``."""

    incarnation: int
    groups: tuple[str, ...]
    why: str
    host: str  # where it was decided


@dataclass(frozen=True)
class HelloWord:
    """A supervisor says, every half second, who it is and what it knows, so that the others
    can tell two claimants of one group apart (split brain), notice when it is lost and when it
    is back, and learn what they missed meanwhile.

    Attributes:
        pid: its process.
        groups: the groups it runs (claims), with the incarnation each runs as now.
        state: ``"running"``, ``"stopping"`` (every group of the run stops: ``why``) or
            ``"ended"`` (its groups have ended; it leaves the run).
        restarts: every restart it decided or heard of.
        gone: the hosts it lost sight of, with the incarnations their groups had then (it moved
            on without them: their sessions with it are over).
        number: its hellos are numbered from 0 in the order it says them. Both carriers deliver
            a writer's words reliably and in order while its session lasts, so a gap in the
            numbers heard means the session was lost and the words meanwhile with it: a cut
            (a supervisor that was only slow to speak or to listen leaves no gap).
    """

    host: str
    pid: int
    groups: dict[str, int]
    state: str = "running"
    why: str = ""
    restarts: tuple[Decision, ...] = ()
    gone: dict[str, dict[str, int]] = field(default_factory=dict)
    number: int = 0
    supervisor: str = ""


Word = StopWord | RestartWord | HelloWord
