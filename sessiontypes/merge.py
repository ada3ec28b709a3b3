"""Full merge of local types (LANGUAGE.md section 5).

Merge accepts identical types; joins external choices (receives) branch-wise
by (peer, label): a pair in both merges its continuations, a pair in one is
kept, so receives from different peers join into ``&{?A(m).T, ?C(n).U}``
(the role learns the branch from whichever message comes; whether that is
safe is checked by :mod:`sessiontypes.races`); merges internal choices
(sends) with exactly the same (peer, label) pairs pair by pair, merging the
continuations; and unfolds ``mu``
when the two sides differ, remembering the pairs it is already merging so
that two spellings of one recursive behaviour merge instead of looping.
"Identical" is taken up to the spelling of recursion (see
:func:`sessiontypes.recursion.equivalent`): ``mu t.!B(x).t`` and
``mu u.!B(x).!B(x).u`` are the same behaviour. A label carries the same sort
(and refinement) and the same time clause on both sides or the two do not merge.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from . import local_types as lt
from .recursion import equivalent, free_vars, unfold
from .sorts import Interaction
from .work import METER

__all__ = ["merge", "merge_all", "MergeError"]


class MergeError(Exception):
    """Internal: two local types do not merge. ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason
        self.index = -1  # merge_all: the term that did not merge with those before it


def merge(left: lt.LocalTerm, right: lt.LocalTerm) -> lt.LocalTerm:
    """Merge two local types (full merge).

    Raises:
        MergeError: they do not merge; ``reason`` says why.
    """
    merger = _Merger()
    try:
        return merger.merge(left, right)
    finally:
        METER.add("merge", merger.steps)


def merge_all(terms: list[lt.LocalTerm]) -> lt.LocalTerm:
    """Merge ``terms`` left to right: ``merge(merge(terms[0], terms[1]), terms[2])`` and so on.

    Receives are merged all at once, branch by branch: folded pairwise, a
    choice of n branches each received rebuilt the growing choice n times
    (quadratic in a wide choice).

    Raises:
        MergeError: some term does not merge with those before it; ``index`` says which.
    """
    first = terms[0]
    if all(term is first for term in terms):
        return first
    if len(terms) > 2 and all(isinstance(term, _OFFERS) for term in terms):
        return _merge_receives(terms)  # type: ignore[arg-type]
    merged = first
    for index in range(1, len(terms)):
        try:
            merged = merge(merged, terms[index])
        except MergeError as error:
            error.index = index
            raise
    return merged


def _merge_receives(terms: list[_Offers]) -> lt.LocalTerm:
    """:func:`merge_all` of external choices: the pairwise fold's result, each branch merged once."""
    merged: dict[tuple[str | None, str], lt.Recv] = {}
    steps = 0
    try:
        for index, term in enumerate(terms):
            receives = lt.receives_of(term)
            steps += len(receives)
            try:
                for branch in receives:
                    key = (branch.peer, branch.message.label)
                    twin = merged.get(key)
                    if twin is None or index == 0:
                        merged[key] = branch
                        continue
                    _same_sort(twin.message, branch.message)
                    _same_timing(twin, branch)
                    merged[key] = lt.Recv(twin.peer, twin.message, merge(twin.continuation, branch.continuation),
                                          twin.location, twin.timing)
                _one_timing(tuple(merged.values()))
            except MergeError as error:
                error.index = index
                raise
    finally:
        METER.add("merge", steps)
    return lt.offer_among(tuple(merged.values()), terms[0].location)


@dataclass
class _Merger:
    # pairs being merged -> the variable that stands for their merge, and whether it was used
    in_progress: dict[tuple[lt.LocalTerm, lt.LocalTerm], list[object]] = field(default_factory=dict)
    steps: int = 0  # messages and choices walked, for the work meter

    def merge(self, left: lt.LocalTerm, right: lt.LocalTerm) -> lt.LocalTerm:
        # The messages both sides start with are walked in a loop, not compared as
        # whole terms at every step: sequences nest deeply, and comparing what is
        # left at each message would make merging them quadratic.
        start = left
        prefix: list[lt.Send | lt.Recv] = []
        while (left is not right and isinstance(left, (lt.Send, lt.Recv)) and type(left) is type(right)
               and left.peer == right.peer and left.message == right.message and left.timing == right.timing):
            prefix.append(left)
            left, right = left.continuation, right.continuation
        self.steps += len(prefix) + 1
        merged = self._merge_node(left, right)
        if merged is left:  # nothing new: keep the original term (and its sharing)
            return start
        for step in reversed(prefix):
            merged = type(step)(step.peer, step.message, merged, step.location, step.timing)
        return merged

    def _merge_node(self, left: lt.LocalTerm, right: lt.LocalTerm) -> lt.LocalTerm:
        if left is right or left == right:
            return left
        if isinstance(left, lt.Rec) or isinstance(right, lt.Rec):
            return self._merge_recursive(left, right)
        if isinstance(left, _OFFERS) and isinstance(right, _OFFERS):
            return self._merge_offers(left, right)
        if isinstance(left, _SELECTIONS) and isinstance(right, _SELECTIONS):
            return self._merge_selections(left, right)
        if equivalent(left, right):
            return left
        raise MergeError(_difference(left, right))

    def _merge_offers(self, left: _Offers, right: _Offers) -> lt.LocalTerm:
        """Choices a peer makes: joined branch-wise by (peer, label), peers may differ."""
        merged: list[lt.Recv] = []
        left_receives = lt.receives_of(left)
        right_branches = {(b.peer, b.message.label): b for b in lt.receives_of(right)}
        self.steps += len(left_receives) + len(right_branches)
        for branch in left_receives:
            twin = right_branches.pop((branch.peer, branch.message.label), None)
            if twin is None:
                merged.append(branch)
                continue
            _same_sort(branch.message, twin.message)
            _same_timing(branch, twin)
            merged.append(lt.Recv(branch.peer, branch.message,
                                  self.merge(branch.continuation, twin.continuation), branch.location,
                                  branch.timing))
        merged.extend(right_branches.values())
        _one_timing(tuple(merged))
        return lt.offer_among(tuple(merged), left.location)

    def _merge_selections(self, left: _Selections, right: _Selections) -> lt.LocalTerm:
        """Choices the role makes: the same (peer, label) pairs; continuations merged pair by pair."""
        left_branches, right_branches = lt.sends_of(left), lt.sends_of(right)
        self.steps += len(left_branches) + len(right_branches)
        left_peers = list(dict.fromkeys(b.peer for b in left_branches))
        right_peers = list(dict.fromkeys(b.peer for b in right_branches))
        if set(left_peers) != set(right_peers):
            raise MergeError(f"one sends to {_peers(left_peers)}, the other to {_peers(right_peers)}")
        theirs = {(b.peer, b.message.label): b for b in right_branches}
        if ({(b.peer, b.message.label) for b in left_branches} != theirs.keys()
                or len(left_branches) != len(right_branches)):
            raise MergeError(f"it sends {_labels(left_branches)} in one and "
                             f"{_labels(right_branches)} in the other")
        merged: list[lt.Send] = []
        for branch in left_branches:  # in the first one's order
            twin = theirs[branch.peer, branch.message.label]
            _same_sort(branch.message, twin.message)
            _same_timing(branch, twin)
            merged.append(lt.Send(branch.peer, branch.message,
                                  self.merge(branch.continuation, twin.continuation), branch.location,
                                  branch.timing))
        return lt.select_among(tuple(merged), left.location)

    def _merge_recursive(self, left: lt.LocalTerm, right: lt.LocalTerm) -> lt.LocalTerm:
        if equivalent(left, right):  # keeps the first spelling rather than an unfolding
            return left
        key = (left, right)
        entry = self.in_progress.get(key)
        if entry is not None:
            entry[1] = True
            return lt.Var(str(entry[0]))
        binder = left if isinstance(left, lt.Rec) else right
        assert isinstance(binder, lt.Rec)
        name = binder.var
        taken = free_vars(left) | free_vars(right)
        while name in taken:
            name += "'"
        entry = [name, False]
        self.in_progress[key] = entry
        try:
            result = self.merge(unfold(left), unfold(right))
        finally:
            del self.in_progress[key]
        return lt.Rec(name, result, binder.location) if entry[1] else result


_Offers = lt.Recv | lt.Offer | lt.OfferAmong
_Selections = lt.Send | lt.Select | lt.SelectAmong
_OFFERS = (lt.Recv, lt.Offer, lt.OfferAmong)
_SELECTIONS = (lt.Send, lt.Select, lt.SelectAmong)


def _peers(peers: list[str | None]) -> str:
    return " and ".join(str(p) for p in peers)


def _same_sort(ours: Interaction, theirs: Interaction) -> None:
    if ours != theirs:
        raise MergeError(f"label '{ours.label}' carries {_sort_name(ours)} in one and "
                         f"{_sort_name(theirs)} in the other")


def _same_timing(ours: lt.Send | lt.Recv, theirs: lt.Send | lt.Recv) -> None:
    if ours.timing != theirs.timing:
        raise MergeError(f"label '{ours.message.label}' has {_timing_name(ours)} in one and "
                         f"{_timing_name(theirs)} in the other")


def _one_timing(receives: tuple[lt.Recv, ...]) -> None:
    """Receives from one peer join into one choice, which has one time clause."""
    if not lt.one_timing(receives):
        peer = next(r.peer for r in receives if any(o.peer == r.peer and o.timing != r.timing for o in receives))
        raise MergeError(f"the receives from {peer} have different time clauses")


def _timing_name(action: lt.Send | lt.Recv) -> str:
    return f"'{action.timing}'" if action.timing is not None else "no time clause"


def _labels(branches: tuple[lt.Send | lt.Recv, ...]) -> str:
    several = len({b.peer for b in branches}) > 1
    names = ", ".join(f"'{b.message.label}' to {b.peer}" if several else f"'{b.message.label}'"
                      for b in branches)
    return names if len(branches) == 1 else f"one of {names}"


def _sort_name(message: Interaction) -> str:
    return str(message.sort) if message.sort else "nothing"


def _difference(left: lt.LocalTerm, right: lt.LocalTerm) -> str:
    kinds = {lt.Send: "a send", lt.Select: "a choice it makes", lt.SelectAmong: "a choice it makes",
             lt.Recv: "a receive", lt.Offer: "a choice it receives",
             lt.OfferAmong: "a choice it receives", lt.End: "end", lt.Var: "a loop back",
             lt.Parallel: "a parallel composition"}
    if isinstance(left, lt.Var) and isinstance(right, lt.Var):
        return f"one loops back to {left.name}, the other to {right.name}"
    a, b = kinds.get(type(left), "?"), kinds.get(type(right), "?")
    if a == b:  # parallel compositions: only identical ones merge
        return f"{a} merges only with an identical one"
    return f"{a} cannot merge with {b}"
