"""Monitored endpoints: how a role talks to its peers.

``send`` checks the action against the role's local type *before* the
message leaves, so a rejected send delivers nothing; ``recv`` checks what
arrives. A role whose local type is a parallel composition has one monitor
per branch: after the fork, ``send``/``recv`` are routed to the branch that
owns the channel, ``recv_any`` waits on whichever incoming channel has a
message first, and ``fork()`` hands out one endpoint per branch for
thread-per-branch code. A failed peer fails only the branches it takes
part in.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
import warnings
from collections.abc import Callable, Collection, Iterable
from itertools import repeat
from operator import itemgetter
from typing import TYPE_CHECKING, Any, NamedTuple, NoReturn

from sessiontypes import StateMachine

from ..errors import Action, AnodizeError, PeerFailedError, ProtocolViolationError, RoleStopped
from . import compiled
from .channel import STOP, Channel, Corrupt, Network, PeerFailure
from .clock import LIVE, clock_of
from .inheriting import Lender, get_lending, inheriting, lend_to_any
from .logs import role_logger
from .monitor import TIMEOUT, Monitor
from .statistics import EndpointStatistics
from .timed import Rule, to_nanos

__all__ = ["Message", "Endpoint", "EndpointStatistics", "RoleStopped", "TIMEOUT", "peers_of", "put_each"]


_LABEL, _PAYLOAD = itemgetter(0), itemgetter(1)
_new_tuple = tuple.__new__  # builds a Message without NamedTuple's Python-level __new__
_DRAIN_AT = 4096  # doorbell rings left by recv() before they are cleared


class Message(NamedTuple):
    """What ``recv`` returns: the label and the payload (None when there is none)."""

    label: str
    payload: Any = None


def _deprecated(old: str, field: str) -> None:
    warnings.warn(f"Endpoint.{old} is deprecated; use Endpoint.statistics().{field}", DeprecationWarning,
                  stacklevel=3)


def _compiled_core() -> type | None:
    """The compiled core (``_endpoint_core.c``), unless it was not built or ANODIZE_PURE_PYTHON is set."""
    if not compiled.allowed():
        return None
    try:
        from ._endpoint_core import EndpointCore, configure
    except ImportError:  # built without a C compiler: the Python core does the work
        return None
    configure(Message, Monitor, Rule)  # the classes whose constrained steps it checks itself
    return EndpointCore


COMPILED_CORE = _compiled_core()
if TYPE_CHECKING:
    _Core = object
else:
    _Core = COMPILED_CORE or object


class Endpoint(_Core):
    """One role's (or one parallel branch's) view of the session.

    ``send`` and ``recv`` are written here in Python, the reference. Where the compiled core
    was built (:data:`COMPILED_CORE`) the class inherits it and uses its ``send`` and ``recv``
    instead: they take the commonest path (no parallel branches, an allowed message of an
    exact type, no failure, no timeout) in C and hand everything else to these
    (``_send_python``, ``_recv_python``), so both behave the same.
    """

    def __init__(self, role: str, protocol: str, machine: StateMachine, network: Network,
                 monitored: bool = True, peers: tuple[set[str], set[str]] | None = None, branch: str = "") -> None:
        self.role = role
        self.protocol = protocol
        self._machine = machine
        self._network = network
        self._clock = clock = clock_of(network, role)
        self._branch = branch  # which endpoint of the role reads the clock: "" the role's, "1", "2", ... a branch's
        # The monitor reads the role's clock (in ns) where a constraint needs it, and only there.
        # The machine's clock is read as time.monotonic_ns (the same clock, exact and cheaper).
        read: Callable[[], int] = time.monotonic_ns if clock is LIVE else lambda: to_nanos(clock.now(branch))
        self._monitor: Monitor | None = Monitor(machine, protocol, role, read) if monitored else None
        sends_to, receives_from = peers if peers is not None else peers_of(machine)
        queues = network.queues
        # Per peer: the channel and the receiver's doorbell (None for most roles).
        self._out = {p: (queues[(role, p)], network.doorbells.get(p))
                     for p in sends_to if (role, p) in queues}
        self._in = {p: queues[(p, role)] for p in receives_from if (p, role) in queues}
        # Priority inheritance (where the network carries a table): only blocking waits lend.
        self._lender: Lender | None = getattr(network, "inheritance", None)
        self._lending = inheriting(self._lender, role, self._in,
                                   {p: channel for p, (channel, _) in self._out.items()})
        self.sent: dict[str, int] = dict.fromkeys(self._out, 0)
        # Channels that can say how many messages wait in them (queues between threads, DDS with
        # credits; not pipes): the most seen just after a send is the channel's high-water mark.
        self._waiting = {p: channel.qsize for p, (channel, _) in self._out.items() if hasattr(channel, "qsize")}
        self.high_water: dict[str, int] = dict.fromkeys(self._waiting, 0)
        self.received: dict[str, int] = dict.fromkeys(self._in, 0)
        self._stop_event = network.stop_event_for(role)
        self._plain = not machine.forks  # no parallel composition: skip the routing checks
        self._fork_lock = threading.Lock()
        self._doorbell = network.doorbells.get(role)
        self._branches: tuple[Endpoint, ...] | None = None
        self._send_route: dict[str, Endpoint] = {}
        self._recv_route: dict[str, Endpoint] = {}
        self.failed_peer: str | None = None  # set when a peer failure ended this endpoint
        self._skipped: set[str] = set()  # rung by peers whose messages were not expected yet
        # A parallel branch's endpoint under priority inheritance: its thread is registered (to be
        # boosted with the role) at its first action, which takes the Python path until then.
        self._join_pending = False

    # ---- the protocol's actions ------------------------------------------------------
    def send(self, to: str, label: str, payload: object = None) -> None:
        """Send ``label`` (with ``payload``) to role ``to``.

        Raises:
            ProtocolViolationError: the local type does not allow it now, or a refinement of
                the message is false of ``payload`` (nothing is sent).
            DeadlineMissedError: later than the message's ``within`` after this role's previous
                action, or outside its period ``every T +- J`` (nothing is sent).
            PeerFailedError: ``to`` has failed.
        """
        try:  # what this send uses, read once: whatever a payload's code does to them counts from the next call
            plain = self._plain  # one statement each: a tuple assignment builds and unpacks a tuple
            monitor = self._monitor
            network = self._network
            outbox = self._out
            sent = self.sent
            waiting = self._waiting
            high_water = self.high_water
            role = self.role
        except AttributeError as error:
            raise self._missing(error) from None
        if not plain and self._forked_now():
            self._branch_for(self._send_route, to, "send", label).send(to, label, payload)
            return
        if monitor is not None:  # first: a forbidden send is a violation, whatever the peer
            # The monitor's step inlined for an allowed send of an exact type (one look-up);
            # anything else goes through Monitor.send, which checks in full or raises.
            step = monitor.sends[monitor.state].get((to, label))
            if step is not None and ((kind := type(payload)) is step[1] or id(kind) in step[5]):
                monitor.state = step[0]
            else:
                monitor.send(to, label, payload)
        if network.alarm:
            self._refuse_if_down(to, label)
        out = outbox.get(to)
        if out is None:
            self._no_channel(to)
        channel, doorbell = out
        # A plain tuple: the garbage collector stops tracking those, not tuple subclasses,
        # and a backlog of tracked objects slows every collection.
        channel.put((label, payload))
        sent[to] += 1
        size_of = waiting.get(to)
        if size_of is not None and (size := size_of()) > high_water[to]:
            high_water[to] = size
        if doorbell is not None:
            doorbell.put(role)

    def send_many(self, to: str, label: str, payloads: Iterable[object]) -> int:
        """Send ``label`` once per payload, in order, to role ``to``: ``send`` in a loop, but
        a transport that can hands the whole batch on at once (between processes: one write
        for all the frames), which streams small messages several times faster.

        Every message is checked as ``send`` checks it, and nothing is sent before the checks:
        if the local type refuses the k-th, the k before it are sent (they were allowed),
        then the violation is raised. A batch that reaches a parallel composition goes on in
        the branch that owns the channel. Returns how many were sent.

        Raises:
            ProtocolViolationError, PeerFailedError: as :meth:`send`.
        """
        if not self._plain and self._forked_now():
            return self._branch_for(self._send_route, to, "send", label).send_many(to, label, payloads)
        pending = list(payloads)
        monitor = self._monitor
        # A stream loops on one message: while the state sends it and stays, only each payload's
        # type is to check, all at once (the loop below checks one by one, from where this stops).
        looping = 0 if monitor is None else _looping_sends(monitor, to, label, pending)
        items: list[tuple[str, object]] = [(label, payload) for payload in pending[:looping]]
        refused: BaseException | None = None
        state: int | None = None  # the state whose step for (to, label) is in `step`
        step = None
        for payload in pending[looping:]:
            if monitor is not None:
                if monitor.state != state:  # looked up again only when the state changes
                    state = monitor.state
                    if state in monitor.fork_states:  # the rest is a parallel branch's: send these, go on there
                        break
                    step = monitor.sends[state].get((to, label))
                if step is not None and ((kind := type(payload)) is step[1] or id(kind) in step[5]):
                    monitor.state = step[0]
                else:
                    try:
                        monitor.send(to, label, payload)
                    except ProtocolViolationError as error:
                        refused = error
                        break
            items.append((label, payload))
        if items:
            self._put_all(to, label, items)
        if refused is not None:
            raise refused
        if len(items) < len(pending):  # at a fork
            return len(items) + self.send_many(to, label, pending[len(items):])
        return len(items)

    def _put_all(self, to: str, label: str, items: list[tuple[str, object]]) -> None:
        """Hand checked messages to the channel: at once where it can take a batch."""
        if self._network.alarm:
            self._refuse_if_down(to, label)
        out = self._out.get(to)
        if out is None:
            self._no_channel(to)
        channel, doorbell = out
        put_many = getattr(channel, "put_many", None)
        try:
            if put_many is not None:
                put_many(items)
            else:
                put_each(channel, items)
        except BaseException as error:  # what did go out still counts
            self.sent[to] += getattr(error, "sent_in_batch", 0)
            raise
        self.sent[to] += len(items)
        waiting = self._waiting.get(to)
        if waiting is not None and (size := waiting()) > self.high_water[to]:
            self.high_water[to] = size
        if doorbell is not None:
            for _ in items:  # one ring per message, as send() rings
                doorbell.put(self.role)

    def _no_channel(self, to: str) -> NoReturn:
        """Raise for a send to a role this one has no channel to (only reachable without a monitor)."""
        raise AnodizeError(f"role {_role_of(self)} has no channel to {to}")

    def _refuse_if_down(self, to: str, label: str) -> None:
        """Raise if ``to`` has failed or this role must stop (checked only once an alarm is up)."""
        try:
            network, stop, role = self._network, self._stop_event, self.role
        except AttributeError as error:
            raise self._missing(error) from None
        failed = network.failed.get(to)
        if failed is not None:
            raise PeerFailedError(role, to, failed)
        if stop.is_set():
            raise RoleStopped(f"interrupted sending {label} to {to}, in state {self._state_number()}")

    def _route(self, out: tuple[Channel, Any]) -> tuple[Channel, Any]:
        """``channel, doorbell = out``, as send unpacks it (the compiled core calls this for
        anything but a pair, so that both raise the same)."""
        channel, doorbell = out
        return channel, doorbell

    def _missing(self, error: AttributeError) -> AnodizeError:
        """The error for a send or receive that finds one of the endpoint's own attributes gone
        (code that ran inside an earlier call deleted it: a payload's methods, say)."""
        name = error.name if error.obj is self and isinstance(error.name, str) else None
        if name is None:
            name = next((field for field in _FIELDS if not hasattr(self, field)), "?")
        return AnodizeError(f"role {_role_of(self)}: the endpoint's attribute {name} is missing (deleted by code "
                            "that ran during one of its sends or receives, such as a payload's own methods); "
                            "this endpoint cannot send or receive any more")

    def buffer(self, to: str, shape: tuple[int, ...], dtype: object = "uint8", strict: bool = False) -> Any:
        """A numpy array to fill and then send to ``to``, with no copy on the way.

        Between groups of the process transport the array lives in a slot of the
        channel's shared-memory ring: sending it (alone or inside a payload) passes
        only the slot's address, and the array becomes read-only here (the slot is
        the receiver's), with every numpy view of it; a view made before the send and
        still alive makes the slot's pages read-only too. ``strict``: always make them
        so (a write through any pointer then faults; use it where C code or ctypes
        holds the array's address). Sending it again after its slot was reused raises
        ``StaleBufferError``. Elsewhere it is an ordinary ``numpy.empty`` array.
        """
        if not self._plain and self._forked_now():
            return self._branch_for(self._send_route, to, "send", "").buffer(to, shape, dtype, strict)
        out = self._out.get(to)
        make = getattr(out[0], "buffer", None) if out is not None else None
        if make is not None:
            return make(tuple(shape), dtype, strict)
        import numpy as np

        return np.empty(shape, dtype)

    def recv(self, frm: str, timeout: float | None = None) -> Message:
        """Receive the next message from role ``frm``.

        Where the protocol gives the message a deadline (``within``), the wait ends there: a
        message already there is taken; else ``DeadlineMissedError`` blames ``frm`` the moment
        the deadline passes, or, with ``else timeout``, ``Message(TIMEOUT, None)`` is returned
        and the role waits for the same message again.

        Raises:
            ProtocolViolationError: this role may not receive from ``frm`` now (blame: this
                role), or the message is not allowed (blame: ``frm``; a refinement that is
                false of it, too).
            DeadlineMissedError: the message's deadline passed with nothing from ``frm``.
            PeerFailedError: ``frm`` failed before sending.
            TimeoutError: nothing arrived within ``timeout`` seconds.
        """
        try:  # what this receive uses, read once: whatever code runs meanwhile does to them counts from the next call
            plain = self._plain
            monitor = self._monitor
            inbox = self._in
            lending = self._lending
            doorbell = self._doorbell
            received = self.received
            role = self.role
        except AttributeError as error:
            raise self._missing(error) from None
        if not plain and self._forked_now():
            return self._branch_for(self._recv_route, frm, "recv", "").recv(frm, timeout)
        if monitor is not None and frm not in monitor.receives_from[monitor.state]:
            raise monitor.violation(Action("recv", frm, "*"), blame=role)
        channel = inbox.get(frm)
        if channel is None:
            raise AnodizeError(f"role {role} has no channel from {frm}")
        lend = lending.get(frm) if lending else None
        if monitor is not None and monitor.deadlines[monitor.state] and (due := monitor.deadline(frm)) is not None:
            return self._recv_due(frm, timeout, channel, lend, monitor, due[0])
        try:
            item = channel.get(timeout=timeout) if lend is None else get_lending(channel, timeout, lend)
        except queue.Empty:
            raise TimeoutError(f"role {role}: no message from {frm} within {timeout} s") from None
        if doorbell is not None and doorbell.qsize() > _DRAIN_AT:
            self._drain_doorbell()
        if type(item) is tuple:  # a message, not a signal: the fast path
            if monitor is not None:  # Monitor.recv inlined for an allowed message of an exact type
                step = monitor.recvs[monitor.state].get((frm, item[0]))
                if step is not None and ((kind := type(item[1])) is step[1] or id(kind) in step[5]):
                    monitor.state = step[0]
                else:
                    monitor.recv(frm, item[0], item[1])
            received[frm] += 1
            return _new_tuple(Message, item)
        return self._accept(frm, item, channel)

    def _recv_due(self, frm: str, timeout: float | None, channel: Channel, lend: Any, monitor: Monitor,
                  due: int) -> Message:
        """Receive from ``frm`` in a state whose message from it is due at ``due`` (ns, the role's
        clock): a message already there is taken (a late reader is not the sender's fault); else
        the wait ends at the deadline, where the monitor blames the sender or, with ``else
        timeout``, ``Message(TIMEOUT, None)`` is returned and the state stays.

        The wait is the deadline less the clock's reading. Live, that is the time left; in a
        replay the readings are the recording's, so the wait is what was left in the recorded
        run, and a message the recording holds is there at once. So that a replay is given back
        the readings in the order they were taken, the clock is read here once whether or not
        the message is there (and once more by the monitor, for the time of the receive)."""
        left = (due - monitor.clock()) / 1e9
        if self._expired_in_the_run():  # a replay: the recorded run's wait expired here
            monitor.expire(frm)
            return Message(TIMEOUT, None)
        try:
            item = channel.get_nowait()
        except queue.Empty:
            wait = left if timeout is None else min(timeout, left)
            try:
                if wait <= 0:
                    raise queue.Empty from None
                item = channel.get(timeout=wait) if lend is None else get_lending(channel, wait, lend)
            except queue.Empty:
                if timeout is not None and timeout < left:
                    raise TimeoutError(f"role {self.role}: no message from {frm} within {timeout} s") from None
                try:  # a message that is there is always taken before the deadline is judged
                    item = channel.get_nowait()
                except queue.Empty:
                    self._note_expiry()
                    monitor.expire(frm)  # raises DeadlineMissedError, unless `else timeout` was written
                    return Message(TIMEOUT, None)
        if type(item) is tuple:  # a message (a signal goes the common way)
            monitor.recv(frm, item[0], item[1])
            self.received[frm] += 1
            return _new_tuple(Message, item)
        return self._accept(frm, item, channel)

    def _note_expiry(self) -> None:
        """Tell the clock a deadline passed as this endpoint waited (a recording records it)."""
        note = getattr(self._clock, "expiry", None)
        if note is not None:
            note(self._branch)

    def _expired_in_the_run(self) -> bool:
        """Whether the clock is a replay's whose recorded run expired this wait (see ReplayClock)."""
        expired = getattr(self._clock, "expired", None)
        return expired is not None and bool(expired(self._branch))

    def recv_many(self, frm: str, limit: int = 1024, timeout: float | None = None) -> list[Message]:
        """Receive the next message from ``frm`` as :meth:`recv` does, then up to ``limit - 1``
        more from ``frm`` that have already arrived, without waiting for any.

        Each is checked as ``recv`` checks it. A message the fast check cannot pass at once (a
        payload needing the full check, one the local type refuses, a failure or stop) is left
        in the channel: the next receive takes it, and raises there if it must. Between
        processes the batch comes from what one read brought in, so a stream is taken several
        times faster; elsewhere the list holds the one message.

        Raises:
            ProtocolViolationError, PeerFailedError, TimeoutError: as :meth:`recv`, for the first.
        """
        if limit < 1:
            raise ValueError(f"recv_many: limit {limit} must be at least 1")
        if not self._plain and self._forked_now():
            return self._branch_for(self._recv_route, frm, "recv", "").recv_many(frm, limit, timeout)
        messages = [self.recv(frm, timeout)]
        take = getattr(self._in.get(frm), "take_ready", None)
        if take is None or limit == 1:
            return messages
        batch: list[tuple[str, object]] = take(limit - 1)
        monitor = self._monitor
        if monitor is None or _loops_on_all(monitor, frm, batch):  # nothing to check, or types only: done
            messages += map(_new_tuple, repeat(Message), batch)  # map: no Python frame per message
        else:
            state = monitor.state
            table = monitor.recvs[state]
            label: str | None = None  # the label whose step from this state is in `step`
            step = None
            for index, item in enumerate(batch):
                if item[0] != label:  # a stream repeats its label: looked up again when it changes
                    label = item[0]
                    step = table.get((frm, label))
                if step is None or id(type(item[1])) not in step[5]:  # the next recv checks it in full
                    self._in[frm].give_back(batch[index:])  # type: ignore[attr-defined]
                    break
                if step[0] != state:
                    state = step[0]
                    table = monitor.recvs[state]
                    label = None
                messages.append(_new_tuple(Message, item))
            monitor.state = state
        self.received[frm] += len(messages) - 1
        return messages

    def _drain_doorbell(self) -> None:
        """Clear rings for messages taken by recv(); ring again for channels still holding some."""
        doorbell = self._doorbell
        assert doorbell is not None
        try:
            while True:
                doorbell.get_nowait()
        except queue.Empty:
            pass
        for peer, channel in self._all_in().items():
            if not channel.empty():
                doorbell.put(peer)

    def recv_any(self, timeout: float | None = None, peers: Collection[str] | None = None,
                 ) -> tuple[str, Message]:
        """Receive from whichever incoming channel, allowed now, has a message first.

        Messages from a peer the local type does not expect yet stay queued. This is
        how a role takes a choice it learns from several peers (``&{?A(m).T, ?C(n).U}``).
        ``peers``, when given, narrows the wait to those peers (what an unmonitored
        endpoint, which does not know its state, needs).
        A deadline of a message it waits for ends the wait as in :meth:`recv` (the earliest,
        if several have one): ``(peer, Message(TIMEOUT, None))`` with ``else timeout``.

        Returns:
            ``(peer, message)``.

        Raises:
            ProtocolViolationError: no receive is allowed now (blame: this role), or the
                message is not allowed (blame: the sender).
            PeerFailedError, TimeoutError: as :meth:`recv`.
        """
        def wanted(peer: str) -> bool:
            return (peers is None or peer in peers) and self._expects(peer)

        if self._join_pending:
            self._forked_now()

        if not any(wanted(peer) for peer in self._all_in()):
            if self._monitor is None:
                raise AnodizeError(f"role {self.role} has no channel from {', '.join(sorted(peers or ())) or 'anyone'}")
            raise self._monitor.violation(Action("recv", None, "*"), blame=self.role)
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            for peer in [p for p in self._skipped if wanted(p)]:
                channel = self._all_in()[peer]
                if channel.empty():
                    self._skipped.discard(peer)
                    continue
                message = self._take(peer, channel)
                if channel.empty():  # else more of its messages wait without a ring
                    self._skipped.discard(peer)
                return peer, message
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            due = self._earliest_due(wanted)
            if due is not None:  # the protocol's deadline may end the wait first
                owner, monitor = due[1], due[1]._monitor
                assert monitor is not None  # only monitored endpoints have deadlines
                left = max(0.0, (due[0] - monitor.clock()) / 1e9)
                if owner._expired_in_the_run():  # a replay: the recorded run's wait expired here
                    monitor.expire(due[2])
                    return due[2], Message(TIMEOUT, None)
                if remaining is None or left < remaining:
                    try:
                        peer = self._wait_any(left, wanted)
                    except TimeoutError:
                        return self._expire_any(owner, due[2], wanted)
                    if not wanted(peer):
                        self._skipped.add(peer)
                        continue
                    channel = self._all_in()[peer]
                    if channel.empty():
                        continue
                    return peer, self._take(peer, channel)
            peer = self._wait_any(remaining, wanted)
            if not wanted(peer):
                self._skipped.add(peer)
                continue
            channel = self._all_in()[peer]
            if channel.empty():  # a stale ring: that message was taken by recv()
                continue
            return peer, self._take(peer, channel)

    def _earliest_due(self, wanted: Callable[[str], bool]) -> tuple[int, Endpoint, str] | None:
        """The earliest deadline among the messages ``recv_any`` waits for: when (ns), whose
        endpoint (this one or a branch's: its monitor holds the deadline), from which peer; None
        if none has one."""
        found: tuple[int, Endpoint, str] | None = None
        for owner in self._leaf_endpoints():
            monitor = owner._monitor
            if monitor is None or not monitor.deadlines[monitor.state] or monitor.previous is None:
                continue
            for peer, (within, _, _) in monitor.deadlines[monitor.state].items():
                if peer is not None and wanted(peer) and (found is None or monitor.previous + within < found[0]):
                    found = (monitor.previous + within, owner, peer)
        return found

    def _leaf_endpoints(self) -> list[Endpoint]:
        if self._branches is not None:
            return [e for branch in self._branches for e in branch._leaf_endpoints()]
        return [self]

    def _expire_any(self, owner: Endpoint, peer: str, wanted: Callable[[str], bool]) -> tuple[str, Message]:
        """``recv_any``'s deadline passed: a wanted message that is there is taken first; else the
        monitor of ``owner`` (this endpoint or a branch's) blames ``peer`` or takes the timeout
        (``else timeout``)."""
        for other, channel in self._all_in().items():
            if wanted(other) and not channel.empty():
                return other, self._take(other, channel)
        monitor = owner._monitor
        assert monitor is not None
        owner._note_expiry()
        monitor.expire(peer)
        return peer, Message(TIMEOUT, None)

    def _take(self, peer: str, channel: Channel) -> Message:
        item = channel.get_nowait()  # only this role's thread(s) read its channels
        owner = self._recv_route.get(peer, self) if self._forked() else self
        return owner._accept(peer, item, channel)

    def _expects(self, peer: str) -> bool:
        if self._forked():
            branch = self._recv_route.get(peer)
            return branch is not None and branch._expects(peer)
        return self._monitor is None or self._monitor.expects_from(peer)

    def fork(self) -> tuple[Endpoint, ...]:
        """At a parallel composition: one endpoint per branch, in order.

        Raises:
            ProtocolViolationError: the local type is not at a parallel composition.
        """
        if self._branches is None:
            monitor = self._monitor
            if monitor is None:
                forks = list(self._machine.forks)
                if len(forks) != 1:
                    raise AnodizeError(f"role {self.role}: without monitors, fork() needs exactly one "
                                       f"parallel composition in the local type (it has {len(forks)})")
                self._start_branches(forks[0])
            elif not monitor.at_fork:
                raise monitor.violation(Action("fork", None, "||"), blame=self.role)
            else:
                self._start_branches(monitor.state)
        assert self._branches is not None
        return self._branches

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` (a role's pacing; ``math.inf``: until the run stops).

        A role that paces itself with ``time.sleep`` notices a stop only at its next
        send or receive; this wait ends the moment the supervisor stops the run. Waking,
        it reads the role's clock (:meth:`now`): a recording then holds when each sleep
        ended, and a replay keeps the role's threads in that order.

        Raises:
            RoleStopped: the run is stopping.
        """
        if self._stop_event.wait(None if seconds == float("inf") else max(0.0, seconds)):
            raise RoleStopped(f"sleeping in state {self._state_number()} (Endpoint.sleep)")
        self._clock.now(self._branch)

    def now(self) -> float:
        """The role's monotonic clock, in seconds (only differences between readings mean anything).

        Live, ``time.monotonic()``. Read time here, not from ``time``, and a recorded run can
        be replayed: a recording records each reading, and ``anodize replay`` gives the role
        the readings it took in the run, in order (then, beyond them, the recorded time of the
        message it received last, advanced by its ``sleep`` calls). Each parallel branch's
        endpoint (``fork()``) has its own sequence of readings: a thread reads its own.
        """
        return self._clock.now(self._branch)

    def wall(self) -> float:
        """The wall clock, in seconds since the epoch: what a role stamps messages with.

        Live, ``time.time()``; recorded and replayed as :meth:`now` is.
        """
        return self._clock.wall(self._branch)

    @property
    def logger(self) -> logging.Logger:
        """The role's logger: a standard :class:`logging.Logger` named after the role, at INFO
        unless its level was set (``ep.logger.info("new plan")``, as ROS's ``node.get_logger()``).

        In a run its records reach the terminal, the run's report, a recording (``/rosout``),
        the live view and, on DDS, ROS's ``/rosout`` (docs/guide/logging.md). Logging never
        waits: past a bound, records are dropped and counted.
        """
        return role_logger(self.role)

    # ---- completion ------------------------------------------------------------------
    def unfinished(self) -> list[Endpoint]:
        """Endpoints (this one or its branches) whose local type has not reached ``end``.

        A branch ended by a failed peer is excused.
        """
        if self.failed_peer is not None or self._monitor is None:
            return []
        if self._branches is not None:
            return [e for b in self._branches for e in b.unfinished()]
        return [] if self._monitor.finished else [self]

    def end_violation(self) -> Exception:
        """The violation for returning before ``end`` (on an unfinished endpoint)."""
        assert self._monitor is not None
        return self._monitor.violation(Action("end", None, ""), blame=self.role)

    def statistics(self) -> EndpointStatistics:
        """Per peer, the messages sent and received and the most that waited, with the branches'."""
        monitor = self._monitor
        constraints = monitor.constraint_statistics() if monitor is not None and monitor.rules else {}
        own = EndpointStatistics(self.sent, self.received, self.high_water, constraints)
        if not self._branches:
            return own
        return EndpointStatistics.combined(own, (branch.statistics() for branch in self._branches))

    # Deprecated: the three dicts before statistics(); kept one release for callers outside anodize.
    def sent_counts(self) -> dict[str, int]:
        """Deprecated: ``statistics().sent``."""
        _deprecated("sent_counts()", "sent")
        return dict(self.statistics().sent)

    def high_water_marks(self) -> dict[str, int]:
        """Deprecated: ``statistics().high_water``."""
        _deprecated("high_water_marks()", "high_water")
        return dict(self.statistics().high_water)

    def received_counts(self) -> dict[str, int]:
        """Deprecated: ``statistics().received``."""
        _deprecated("received_counts()", "received")
        return dict(self.statistics().received)

    @property
    def state(self) -> str:
        """The current state and the local type that remains (for messages and debugging)."""
        if self._monitor is None:
            return "unmonitored"
        if self._branches is not None:
            return " || ".join(b.state for b in self._branches)
        return f"{self._monitor.state} ({self._machine.describe(self._monitor.state)})"

    # ---- internals ---------------------------------------------------------------------
    def _accept(self, frm: str, item: object, channel: Channel) -> Message:
        try:
            return self._accept_as_is(frm, item, channel)
        except AttributeError as error:
            if error.obj is not self:
                raise
            raise self._missing(error) from None

    def _accept_as_is(self, frm: str, item: object, channel: Channel) -> Message:
        if type(item) is tuple:
            if self._monitor is not None:
                self._monitor.recv(frm, item[0], item[1])
            self.received[frm] += 1
            return _new_tuple(Message, item)
        if isinstance(item, PeerFailure):
            channel.put(item)  # later receives fail too
            self.failed_peer = item.peer
            raise PeerFailedError(self.role, item.peer, item.cause)
        if item is STOP:
            channel.put(item)
            raise RoleStopped(self._blocked_on(frm))
        if isinstance(item, Corrupt):  # a frame from another process that did not decode
            monitor = self._monitor or Monitor(self._machine, self.protocol, self.role)
            raise monitor.violation(Action("recv", frm, "?"), blame=frm,
                                    reason=f"the message could not be decoded ({item.reason})")
        raise AnodizeError(f"role {self.role}: the channel from {frm} delivered {item!r}, "
                           "which is neither a message nor a signal")

    def _state_number(self) -> str:
        return "unmonitored" if self._monitor is None else str(self._monitor.state)

    def _blocked_on(self, frm: str | None) -> str:
        """What a stopped receive was waiting for: ``blocked in state 3 waiting for ?Cam(Frame)``,
        or at the first state of a recursive local type (where a loop waits for its next round,
        not a deadlock) ``waiting at the head of its loop (state 0) for ?Cam(Frame)``."""
        monitor = self._monitor
        if monitor is None:
            return f"blocked waiting for a message from {frm or 'any peer'}"
        waits = [str(Action("recv", t.peer, t.label, t.sort.spelling if t.sort else None))
                 for t in self._machine.expected(monitor.state)
                 if t.action == "recv" and (frm is None or t.peer == frm)]
        what = " or ".join(waits) or f"a message from {frm}"
        if _loop_head(self._machine, monitor.state):
            return f"waiting at the head of its loop (state {monitor.state}) for {what}"
        return f"blocked in state {monitor.state} waiting for {what}"

    def _forked_now(self) -> bool:
        """``_forked()``, having first registered a branch's thread for priority inheritance."""
        if self._join_pending:
            self._join_pending = False
            self._plain = not self._machine.forks
            if self._lender is not None:
                self._lender.join(self.role)
        return self._forked()

    def _forked(self) -> bool:
        if self._branches is not None:
            return True
        monitor = self._monitor
        if monitor is not None and monitor.at_fork:
            self._start_branches(monitor.state)
            return True
        return False

    def _start_branches(self, fork_state: int) -> None:
        # Branch threads may reach the fork together: build the branches once.
        with self._fork_lock:
            if self._branches is not None:
                return
            branches = []
            for number, machine in enumerate(self._machine.forks[fork_state], start=1):
                sends_to, receives_from = peers_of(machine)
                # Each branch has its own clock sequence and its own previous action (from the fork).
                name = f"{self._branch}.{number}" if self._branch else str(number)
                branch = type(self)(self.role, self.protocol, machine, self._network,
                                    self._monitor is not None, (sends_to, receives_from), name)
                branch._doorbell = self._doorbell
                if self._lender is not None:
                    branch._join_pending = True
                    branch._plain = False  # the Python path at first: see _join_pending
                branches.append(branch)
                self._send_route.update(dict.fromkeys(sends_to, branch))
                self._recv_route.update(dict.fromkeys(receives_from, branch))
            self._branches = tuple(branches)

    def _branch_for(self, routes: dict[str, Endpoint], peer: str, kind: str, label: str) -> Endpoint:
        branch = routes.get(peer)
        if branch is None:
            assert self._monitor is not None
            raise self._monitor.violation(Action(kind, peer, label or "*"), blame=self.role)
        return branch

    def _wait_any(self, timeout: float | None, wanted: Callable[[str], bool]) -> str:
        doorbell = self._doorbell
        if doorbell is not None:
            try:
                if self._lender is None:
                    return doorbell.get(timeout=timeout)
                try:
                    return doorbell.get_nowait()  # a ring waits already: no scheduling call
                except queue.Empty:
                    if timeout is not None and timeout <= 0:
                        raise
                lend = lend_to_any(self._lender, self.role, filter(wanted, self._all_in()))
                if lend is None:
                    return doorbell.get(timeout=timeout)
                with lend():  # blocked on whichever wanted peer sends first: each is lent our priority
                    return doorbell.get(timeout=timeout)
            except queue.Empty:
                raise TimeoutError(f"role {self.role}: no message within {timeout} s") from None
        # No doorbell (a role without parallel branches): poll its few channels.
        deadline = None if timeout is None else time.monotonic() + timeout
        looked = self._lender is None
        with contextlib.ExitStack() as lending:
            while True:
                for peer, channel in self._all_in().items():
                    if wanted(peer) and not channel.empty():
                        return peer
                if deadline is not None and time.monotonic() >= deadline:
                    raise TimeoutError(f"role {self.role}: no message within {timeout} s")
                if not looked:  # nothing found: it waits from now on, lending to the peers it waits for
                    looked = True
                    lend = lend_to_any(self._lender, self.role, filter(wanted, self._all_in()))
                    if lend is not None:
                        lending.enter_context(lend())
                time.sleep(0.0005)

    def _all_in(self) -> dict[str, Channel]:
        if self._branches is None:
            return self._in
        found: dict[str, Channel] = {}
        for branch in self._branches:
            found.update(branch._all_in())
        return found

    # The Python core's send and recv, by these names too: the compiled core hands them what
    # it does not take itself.
    _send_python = send
    _recv_python = recv


if COMPILED_CORE is not None:  # the compiled core's send and recv (same calls, same errors) take over
    del Endpoint.send, Endpoint.recv


# What the endpoint's own code reads from it (the error for one gone names the first missing).
_FIELDS = ("role", "_plain", "_monitor", "_network", "_out", "_in", "sent", "received", "_waiting", "high_water",
           "_doorbell", "_lending")


def _role_of(endpoint: Endpoint) -> str:
    """The endpoint's role for an error's text (it may be the attribute that is gone)."""
    role = getattr(endpoint, "role", None)
    return role if type(role) is str else "?"


def _looping_sends(monitor: Monitor, to: str, label: str, payloads: list[object]) -> int:
    """How many of ``payloads`` the monitor allows at once, sent as ``label`` to ``to``: all of them
    when the current state sends that message and stays (a loop) and every payload's type is one
    the step takes exactly; else none (the caller checks them one by one)."""
    state = monitor.state
    if state in monitor.fork_states:
        return 0
    step = monitor.sends[state].get((to, label))
    if step is None or step[0] != state or not set(map(id, map(type, payloads))) <= step[5]:
        return 0
    return len(payloads)


def _loops_on_all(monitor: Monitor, frm: str, batch: list[tuple[str, object]]) -> bool:
    """Whether the monitor allows every message of ``batch`` from ``frm`` at once, as
    :func:`_looping_sends` does for sends: one label, received in a loop, payloads of exact types."""
    if not batch:
        return True
    state = monitor.state
    label = batch[0][0]
    step = monitor.recvs[state].get((frm, label))
    # map and itemgetter loop in C: a third cheaper per message than two set comprehensions.
    return (step is not None and step[0] == state and set(map(_LABEL, batch)) == {label}
            and {id(kind) for kind in set(map(type, map(_PAYLOAD, batch)))} <= step[5])


def peers_of(machine: StateMachine) -> tuple[set[str], set[str]]:
    """The roles a machine (with its forks) sends to and receives from."""
    sends: set[str] = set()
    recvs: set[str] = set()
    for t in machine.all_transitions():
        if t.peer is not None:
            (sends if t.action == "send" else recvs).add(t.peer)
    return sends, recvs


def put_each(channel: Channel, items: list[tuple[str, object]]) -> None:
    """Put messages one by one; on a failure the exception's ``sent_in_batch`` says how many went."""
    for sent, item in enumerate(items):
        try:
            channel.put(item)
        except BaseException as error:
            error.sent_in_batch = sent  # type: ignore[attr-defined]
            raise


def _loop_head(machine: StateMachine, state: int) -> bool:
    """``state`` is the first state of a recursive local type: its start, which some action leads back to."""
    return state == machine.initial and any(t.target == state for row in machine.table for t in row.values())
