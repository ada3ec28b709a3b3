"""Recursion in local types: unfolding, substitution, free variables, equivalence."""

from __future__ import annotations

from . import local_types as lt

__all__ = ["unfold", "substitute", "free_vars", "equivalent"]


def unfold(term: lt.LocalTerm) -> lt.LocalTerm:
    """``mu t. T`` becomes ``T[mu t. T / t]``; anything else is returned as is."""
    if not isinstance(term, lt.Rec):
        return term
    return substitute(term.body, term.var, term)


def substitute(term: lt.LocalTerm, name: str, replacement: lt.LocalTerm) -> lt.LocalTerm:
    """Replace the free occurrences of variable ``name`` in ``term`` (capture-avoiding)."""
    match term:
        case lt.Var(name=n):
            return replacement if n == name else term
        case lt.End():
            return term
        case lt.Send(peer=peer, message=message, continuation=cont, location=location):
            return lt.Send(peer, message, substitute(cont, name, replacement), location, term.timing)
        case lt.Recv(peer=peer, message=message, continuation=cont, location=location):
            return lt.Recv(peer, message, substitute(cont, name, replacement), location, term.timing)
        case lt.Select(peer=peer, branches=branches, location=location):
            return lt.Select(peer, _substitute_branches(branches, name, replacement), location, term.timing)
        case lt.Offer(peer=peer, branches=branches, location=location):
            return lt.Offer(peer, _substitute_branches(branches, name, replacement), location, term.timing)
        case lt.SelectAmong(branches=sends, location=location):
            return lt.SelectAmong(tuple([lt.Send(b.peer, b.message, substitute(b.continuation, name, replacement),
                                                 b.location, b.timing) for b in sends]), location)
        case lt.OfferAmong(branches=recvs, location=location):
            return lt.OfferAmong(tuple([lt.Recv(b.peer, b.message, substitute(b.continuation, name, replacement),
                                                b.location, b.timing) for b in recvs]), location)
        case lt.Parallel(branches=parts, location=location):
            return lt.Parallel(tuple([substitute(p, name, replacement) for p in parts]), location)
        case lt.Rec(var=var, body=body, location=location):
            if var == name:
                return term
            if var in free_vars(replacement):
                fresh = var + "'"
                while fresh in free_vars(replacement) or fresh in free_vars(body):
                    fresh += "'"
                body = substitute(body, var, lt.Var(fresh))
                var = fresh
            return lt.Rec(var, substitute(body, name, replacement), location)
    raise AssertionError(f"unexpected local term {term!r}")


def _substitute_branches(branches: tuple[lt.Branch, ...], name: str,
                         replacement: lt.LocalTerm) -> tuple[lt.Branch, ...]:
    return tuple([lt.Branch(b.message, substitute(b.continuation, name, replacement), b.location)
                 for b in branches])


def free_vars(term: lt.LocalTerm) -> frozenset[str]:
    """The recursion variables free in ``term``."""
    match term:
        case lt.Var(name=n):
            return frozenset((n,))
        case lt.Send(continuation=cont) | lt.Recv(continuation=cont):
            return free_vars(cont)
        case lt.Select(branches=branches) | lt.Offer(branches=branches):
            return frozenset().union(*([free_vars(b.continuation) for b in branches]))
        case lt.SelectAmong(branches=actions) | lt.OfferAmong(branches=actions):
            return frozenset().union(*([free_vars(b.continuation) for b in actions]))
        case lt.Parallel(branches=parts):
            return frozenset().union(*([free_vars(p) for p in parts]))
        case lt.Rec(var=var, body=body):
            return free_vars(body) - {var}
    return frozenset()


def equivalent(left: lt.LocalTerm, right: lt.LocalTerm) -> bool:
    """Whether two local types describe the same behaviour.

    Equal up to the names of bound variables and to unfolding ``mu`` (so up to
    how a loop is written); decided coinductively: a pair met again while
    being compared is assumed equivalent.
    """
    return _Equivalence().check(left, right)


class _Equivalence:
    def __init__(self) -> None:
        self.assumed: set[tuple[lt.LocalTerm, lt.LocalTerm]] = set()

    def check(self, left: lt.LocalTerm, right: lt.LocalTerm) -> bool:
        # Messages both start with are walked in a loop: comparing what is left as
        # whole terms at every message would make long sequences quadratic.
        while (left is not right and isinstance(left, (lt.Send, lt.Recv)) and type(left) is type(right)
               and left.peer == right.peer and left.message == right.message and left.timing == right.timing):
            left, right = left.continuation, right.continuation
        if left is right or left == right:
            return True
        if isinstance(left, lt.Rec) or isinstance(right, lt.Rec):
            key = (left, right)
            if key in self.assumed:
                return True
            self.assumed.add(key)
            return self.check(unfold(left), unfold(right))
        if ((isinstance(left, lt.Send) and isinstance(right, lt.Send))
                or (isinstance(left, lt.Recv) and isinstance(right, lt.Recv))):
            return (left.peer == right.peer and left.message == right.message and left.timing == right.timing
                    and self.check(left.continuation, right.continuation))
        if ((isinstance(left, lt.Select) and isinstance(right, lt.Select))
                or (isinstance(left, lt.Offer) and isinstance(right, lt.Offer))):
            if left.peer != right.peer or left.timing != right.timing:
                return False
            theirs = {b.message.label: b for b in right.branches}
            if len(left.branches) != len(theirs):
                return False
            # Loops, not all(<generator>): resuming a generator deep in a recursion
            # costs time proportional to the depth in CPython 3.11.
            for ours in left.branches:
                twin = theirs.get(ours.message.label)
                if (twin is None or ours.message != twin.message
                        or not self.check(ours.continuation, twin.continuation)):
                    return False
            return True
        if ((isinstance(left, lt.SelectAmong) and isinstance(right, lt.SelectAmong))
                or (isinstance(left, lt.OfferAmong) and isinstance(right, lt.OfferAmong))):
            pairs = {(b.peer, b.message.label): b for b in right.branches}
            if len(left.branches) != len(pairs):
                return False
            for action in left.branches:
                other = pairs.get((action.peer, action.message.label))
                if (other is None or action.message != other.message or action.timing != other.timing
                        or not self.check(action.continuation, other.continuation)):
                    return False
            return True
        if isinstance(left, lt.Parallel) and isinstance(right, lt.Parallel):
            return len(left.branches) == len(right.branches) and all(
                map(self.check, left.branches, right.branches))
        return False
