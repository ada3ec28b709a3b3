"""Full merge of local types (LANGUAGE.md section 5).

Merge accepts identical types, joins external choices from the same peer
branch-wise, and unfolds ``mu`` when the two sides differ, remembering the
pairs it is already merging so that two spellings of one recursive behaviour
merge instead of looping. "Identical" is taken up to the spelling of
recursion (see :func:`sessiontypes.recursion.equivalent`): ``mu t.!B(x).t``
and ``mu u.!B(x).!B(x).u`` are the same behaviour.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from . import local_types as lt
from .recursion import equivalent, free_vars, unfold
from .sorts import Message

__all__ = ["merge", "MergeError"]


class MergeError(Exception):
    """Internal: two local types do not merge. ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def merge(left: lt.LocalTerm, right: lt.LocalTerm) -> lt.LocalTerm:
    """Merge two local types (full merge).

    Raises:
        MergeError: they do not merge; ``reason`` says why.
    """
    return _Merger().merge(left, right)


@dataclass
class _Merger:
    # pairs being merged -> the variable that stands for their merge, and whether it was used
    in_progress: dict[tuple[lt.LocalTerm, lt.LocalTerm], list[object]] = field(default_factory=dict)

    def merge(self, left: lt.LocalTerm, right: lt.LocalTerm) -> lt.LocalTerm:
        if left is right or left == right:
            return left
        if isinstance(left, lt.Rec) or isinstance(right, lt.Rec):
            return self._merge_recursive(left, right)
        if isinstance(left, (lt.Recv, lt.Offer)) and isinstance(right, (lt.Recv, lt.Offer)):
            return self._merge_offers(left, right)
        if equivalent(left, right):
            return left
        raise MergeError(_difference(left, right))

    def _merge_offers(self, left: lt.Recv | lt.Offer, right: lt.Recv | lt.Offer) -> lt.LocalTerm:
        if left.peer != right.peer:
            raise MergeError(f"one receives from {left.peer}, the other from {right.peer}")
        merged: list[lt.Branch] = []
        right_branches = {b.message.label: b for b in _offer_branches(right)}
        for branch in _offer_branches(left):
            twin = right_branches.pop(branch.message.label, None)
            if twin is None:
                merged.append(branch)
                continue
            if branch.message != twin.message:
                raise MergeError(f"label '{branch.message.label}' carries "
                                 f"{_sort_name(branch.message)} in one and "
                                 f"{_sort_name(twin.message)} in the other")
            merged.append(lt.Branch(branch.message, self.merge(branch.continuation, twin.continuation),
                                    branch.location))
        merged.extend(right_branches.values())
        return lt.offer(left.peer, tuple(merged), left.location)

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


def _offer_branches(term: lt.Recv | lt.Offer) -> tuple[lt.Branch, ...]:
    if isinstance(term, lt.Recv):
        return (lt.Branch(term.message, term.continuation, term.location),)
    return term.branches


def _sort_name(message: Message) -> str:
    return str(message.sort) if message.sort else "nothing"


def _difference(left: lt.LocalTerm, right: lt.LocalTerm) -> str:
    kinds = {lt.Send: "a send", lt.Select: "a choice it makes", lt.Recv: "a receive",
             lt.Offer: "a choice it receives", lt.End: "end", lt.Var: "a loop back",
             lt.Parallel: "a parallel composition"}
    a, b = kinds.get(type(left), "?"), kinds.get(type(right), "?")
    if a == b:
        return "only identical behaviours merge unless both receive"
    return f"{a} cannot merge with {b}"
