"""The words supervisors of one run on several hosts say to each other, whatever carries them.

A transport's host link (:mod:`.hostlink` on DDS, :mod:`.zenohlink` on Zenoh) moves the bytes
and says which host and supervisor of the run wrote them (it checks the writer's claim); this
module is what the bytes mean: a word encoded as a length-prefixed JSON object, parsed back
without trusting it (a malformed word is ``None``, never an exception), and the batches the
restarts heard so far name (which groups start as which incarnation).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable
from typing import Any

from .words import Decision, HelloWord, RestartWord, StopWord, Word

__all__ = ["encode", "parse", "Batches"]

_KINDS = {StopWord: "stop", RestartWord: "restart", HelloWord: "hello"}


def encode(word: Word) -> bytes:
    """``word`` as bytes: a 4-byte little-endian length, then JSON (who said it is the carrier's to say)."""
    fields = {key: value for key, value in dataclasses.asdict(word).items() if key not in ("host", "supervisor")}
    body = json.dumps({"kind": _KINDS[type(word)], **fields}).encode()
    return len(body).to_bytes(4, "little") + body


def parse(body: bytes, host: str, supervisor: str = "") -> Word | None:
    """The word in ``body``, said by ``host``'s supervisor ``supervisor`` (as the carrier
    established), or None when it is malformed."""
    try:
        length = int.from_bytes(body[:4], "little")
        fields = json.loads(body[4:4 + length])
        kind = fields["kind"]
        if kind == "stop":
            return StopWord(host=host, why=_text(fields["why"]), supervisor=supervisor)
        if kind == "restart":
            return RestartWord(host=host, groups=_names(fields["groups"]), incarnation=_int(fields["incarnation"]),
                               why=_text(fields["why"]), supervisor=supervisor)
        if kind == "hello":
            return HelloWord(
                host=host, supervisor=supervisor, pid=_int(fields["pid"]), groups=_incarnations(fields["groups"]),
                state=_text(fields["state"]), why=_text(fields["why"]),
                restarts=tuple(Decision(_int(d["incarnation"]), _names(d["groups"]), _text(d["why"]), _text(d["host"]))
                               for d in fields["restarts"]),
                gone={_text(h): _incarnations(groups) for h, groups in dict(fields["gone"]).items()},
                number=_int(fields["number"]))
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError):  # JSON nested past the stack
        return None
    return None


def _text(value: Any) -> str:
    if not isinstance(value, str):
        raise TypeError("expected a string")
    return value


def _int(value: Any) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise TypeError("expected an integer")
    return value


def _names(value: Any) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise TypeError("expected a list")
    return tuple(_text(v) for v in value)


def _incarnations(value: Any) -> dict[str, int]:
    if not isinstance(value, dict):
        raise TypeError("expected an object")
    return {_text(k): _int(v) for k, v in value.items()}


class Batches(dict[int, frozenset[str]]):
    """Incarnation -> the groups that start as it (every group starts as 0; given no groups, the
    runner knows them): a group's channels to groups outside its batch are gone to it."""

    def __init__(self, groups: Iterable[str]) -> None:
        first = frozenset(groups)
        super().__init__({0: first} if first else {})

    def hear(self, word: Word) -> None:
        """Note the batches a word names (a restart said here or heard from another host, or the
        restarts a supervisor's hello recalls)."""
        if isinstance(word, RestartWord):
            self[word.incarnation] = self.get(word.incarnation, frozenset()) | set(word.groups)
        elif isinstance(word, HelloWord):
            for decision in word.restarts:
                self[decision.incarnation] = self.get(decision.incarnation, frozenset()) | set(decision.groups)
