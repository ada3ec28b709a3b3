"""The life of one group's process, from spawn to exit.

The supervisor (:mod:`anodize._supervision.processes`) spawns a fresh interpreter per group
and hands it a :class:`GroupSpec` and its pipes. The process then:

1. applies the group's CPU set and priority to itself (its threads inherit them);
2. imports its role functions by ``module:function`` and builds its endpoints;
3. starts one thread per role, held at a gate, measures its memory baseline,
   sets the memory bound, reports "ready" and waits for "go";
4. runs, sending a heartbeat (memory in use, messages sent) four times a second
   and a report per role as each ends; a failed role's receivers are told;
5. exits when every role has ended. A role (or a thread it started) meeting ``MemoryError``
   stops the whole group at once (``os._exit``: every thread, and the memory goes back to
   the OS) after reporting the bound and the peak.

Everything sent to the supervisor is a typed control message (:mod:`.control`), plain
data encoded by :mod:`anodize._transport.codec` (never pickled), so a misbehaving group cannot
run code in the supervisor.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import functools
import gc
import importlib
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from queue import Empty, SimpleQueue
from typing import TYPE_CHECKING, Any

from sessiontypes import Sort, StateMachine

from .._isolation.inherit import BoostTable, RoleSeat
from .._isolation.memory import data_size, limit_data
from .._isolation.sched import apply_thread_scheduling
from .._isolation.tree import become_subreaper, kill_tree
from .._ros import RosType, ros_type
from .._session.clock import adopt_clocks
from .._session.endpoint import Endpoint
from .._session.logs import LogCapture
from .._session.payloads import resolve_class, with_field_classes
from .._transport.codec import MAX_FRAME, Codec, DecodeError, make_codec
from .._transport.network import GroupNetwork
from .._transport.process import LinkEnd, PipeLinks
from .._transport.shm import ArrayRing, RingReader
from .._transport.spin import SpinPolicy
from ..errors import MemoryBoundError, error_to_data
from ..taps import GroupTap, GroupTapPlan, TapGroup
from .control import (
    Beat,
    Crash,
    FrameReader,
    Go,
    GroupMessage,
    MemoryExceeded,
    Notice,
    PeerFailed,
    Ready,
    RoleEnded,
    Stop,
    SupervisorMessage,
    decode_control,
    send_control,
)
from .group import resolve_function
from .logcarry import to_messages
from .report import RoleReport, RoleStatus, constraint_counts
from .roles import describe_error, run_role

if TYPE_CHECKING:
    from .._transport.links import NetworkSettings

__all__ = ["GroupSpec", "group_main", "EXIT_MEMORY", "HEARTBEAT"]

EXIT_MEMORY = 87  # the exit status of a group stopped for exceeding its memory bound
HEARTBEAT = 0.25  # seconds
# How long a thread of a real-time group may keep the GIL while another waits for it (Python's
# default is 5 ms): the group's roles are all at its priority, and a role due to send waits for
# whichever holds the GIL, up to one interval per holder. At 1 ms the tail of TinMan's joystick
# slips shrank in 20 s runs, quiet and beside CPU hogs (decision 0067).
REAL_TIME_SWITCH_INTERVAL = 0.001  # seconds
TAPS_CLOSE_WITHIN = 10.0  # seconds the group waits for its taps to close (each bounds its own close)
_PR_SET_PDEATHSIG = 1  # prctl option (linux/prctl.h)
_RESERVE = 4 * 2**20  # freed on MemoryError so that reporting it can allocate


@dataclass(frozen=True)
class GroupSpec:
    """What a group's process needs (pickled by multiprocessing at spawn, by the supervisor)."""

    run_id: str
    name: str
    incarnation: int
    protocol: str
    roles: dict[str, str]                  # role -> "module:function"
    machines: dict[str, StateMachine]      # the local roles' state machines
    channels: tuple[tuple[str, str], ...]  # every pair the global type connects
    dead: dict[str, str]                   # remote roles not reachable, and why
    monitors: bool = True
    priority: int | None = None
    nice: int | None = None
    cpus: frozenset[int] | None = None
    memory: int | None = None
    sys_path: tuple[str, ...] = ()
    capacities: dict[tuple[str, str], int] = field(default_factory=dict)  # channels that hold at most so many
    taps: tuple[GroupTapPlan, ...] = ()    # what the group opens to tap its channels (recording, live view)
    network: NetworkSettings | None = None  # Dds, Zenoh: how the group joins the run's network (else pipes)
    inheritance: tuple[tuple[RoleSeat, ...], str | None] | None = None  # the inheritance table's seats and file
    params: dict[str, dict[str, object]] = field(default_factory=dict)  # role -> its parameters, checked
    spin: int = 0                          # nanoseconds its receivers may poll before sleeping (0: never)
    spin_note: str = ""                    # the spin asked, or why it was refused, for the report


def group_main(spec: GroupSpec, control: Connection, pipes: dict[tuple[str, str], LinkEnd]) -> None:
    """The entry point of a group's process (the target multiprocessing runs)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the supervisor's to handle
    _bind_to_supervisor()
    for fd in (control.fileno(), *(end.fileno() for end in pipes.values())):  # received over a socket:
        os.set_inheritable(fd, False)  # inheritable, unless told
    for path in reversed(spec.sys_path):
        if path not in sys.path:
            sys.path.insert(0, path)
    try:
        _GroupProcess(spec, control, pipes).run()
    except BaseException as error:  # a failure of the group itself: say so, then go
        with contextlib.suppress(OSError):
            send_control(control, Crash(error=error_to_data(error)))
        kill_tree(os.getpid(), include_root=False)
        os._exit(1)
    kill_tree(os.getpid(), include_root=False)  # a process a role left running ends with the group
    os._exit(0)


def _bind_to_supervisor() -> None:
    """Adopt what our roles start (so the supervisor can kill the whole tree) and die with the
    supervisor (a killed supervisor must not leave groups running on)."""
    supervisor = os.getppid()
    become_subreaper()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass  # not Linux: the control connection's end-of-file still ends us (see _read_control)
    if os.getppid() != supervisor:  # it died before the signal was armed
        os._exit(1)


class _GroupProcess:
    def __init__(self, spec: GroupSpec, control: Connection, pipes: dict[tuple[str, str], LinkEnd]) -> None:
        self.spec = spec
        self.control = control
        self.pipes = pipes  # kept: closing a Connection would close its descriptor
        self.results: SimpleQueue[RoleReport] = SimpleQueue()
        self.gate = threading.Event()
        self.reserve: bytearray | None = bytearray(_RESERVE)
        self.baseline = 0
        self.peak = 0
        self.inheritance: BoostTable | None = None
        self.send_lock = threading.Lock()  # the control reader and the main thread both send
        self.logs = LogCapture(dict.fromkeys(spec.roles, spec.name))
        self.spin = SpinPolicy(spec.spin / 1e9) if spec.spin else None  # its receivers' spin then park

    def run(self) -> None:
        spec = self.spec
        scheduling = apply_thread_scheduling(spec.priority, spec.cpus, spec.nice)  # inherited by our threads
        if scheduling.startswith("SCHED_FIFO"):
            sys.setswitchinterval(REAL_TIME_SWITCH_INTERVAL)
        if spec.spin_note:
            scheduling += f"; {spec.spin_note}"
        functions = {role: resolve_function(ref) for role, ref in spec.roles.items()}
        threading.excepthook = self._thread_failed
        self.logs.install(root_level=logging.INFO)  # our own process: a role's module logger logs INFO too
        network = self.network = self._network()
        self.inheritance = None if spec.inheritance is None or spec.inheritance[1] is None else (
            BoostTable.open(spec.inheritance[0], spec.inheritance[1]))
        network.inheritance = self.inheritance  # before the endpoints: they hook their waits on it
        self.taps = _open_taps(spec, network.queues)  # before the endpoints take their channels
        for tap in self.taps:
            adopt_clocks(network, tap)  # a recording records its roles' clock readings
        endpoints = {role: Endpoint(role, spec.protocol, spec.machines[role], network, spec.monitors)
                     for role in spec.roles}
        threads = [threading.Thread(target=self._role_thread, name=f"anodize:{spec.name}/{role}",
                                    args=(role, functions[role], endpoints[role]), daemon=True)
                   for role in spec.roles]
        # What the start made (modules, classes, endpoints) lives as long as the process: no
        # collection need look at it again. Unfrozen, a full collection, which runs in whichever
        # role's thread allocates at that moment and holds the GIL throughout, took 11-18 ms with
        # TinMan's role modules imported: longer than its joystick's period may slip (decision 0066).
        gc.freeze()
        for thread in threads:
            thread.start()
        network.start()
        self.endpoints = endpoints
        threading.Thread(target=self._read_control, name="anodize-control", daemon=True).start()
        memory_note = self._bound_memory()  # every thread of ours exists by now
        # Counts before "ready": the supervisor shows the group running only once it is ready, and
        # by then it has every channel's count (none sent yet) and high-water mark to show with it.
        self._heartbeat()
        self._send(Ready(pid=os.getpid(), scheduling=scheduling, baseline=self.baseline,
                         memory_note=memory_note))
        self._supervise(len(threads))

    def _network(self) -> GroupNetwork:
        spec = self.spec
        classes = _payload_classes(spec.machines.values())
        ros_types = _payload_ros_types(spec.machines.values())
        local = set(spec.roles)
        doorbell_roles = [r for r, m in spec.machines.items() if m.forks or m.waits_on_several()]
        if spec.network is not None:  # every channel between groups is a DDS topic or Zenoh key; arrays in the frames
            module, _, name = spec.network.LINKS.partition(":")
            links = getattr(importlib.import_module(module), name)(
                spec.network, spec.name, spec.incarnation, report=lambda line: self._send(Notice(text=line)))
            network = GroupNetwork(spec.roles, spec.channels, links, spec.dead,
                                   lambda pair: make_codec(classes, None, None, ros_types), doorbell_roles,
                                   spec.capacities)
            links.wait_for_peers()  # the start barrier: "ready" means every peer has appeared
            return network

        def codec_for(pair: tuple[str, str]) -> Codec:
            sender, receiver = pair
            # A channel's rings are named after it: a receiver maps no other ring.
            prefix = f"anodize-{spec.run_id}-{sender.encode().hex()}-{receiver.encode().hex()}-"
            inbox = f"{prefix}{spec.incarnation}"  # where the sender hands the rings' memory over
            if sender not in local:
                reader = RingReader(inbox)  # bound now: before any group is told to go
                return make_codec(classes, None, functools.partial(reader.read, prefix=prefix), ros_types)
            # With every slot held, an array up to a frame's size (less room for the rest) goes inline.
            ring = ArrayRing(f"{prefix}{spec.incarnation}", peer_gone=lambda: self._gone(receiver), inbox=inbox,
                             channel=f"{sender}->{receiver}", inline_max=MAX_FRAME - 2**20)
            return make_codec(classes, ring, None, ros_types)

        return GroupNetwork(spec.roles, spec.channels, PipeLinks.from_ends(self.pipes, self.spin), spec.dead, codec_for,
                            doorbell_roles, spec.capacities)

    def _gone(self, receiver: str) -> str | None:
        network = self.network
        if receiver in network.failed:
            return network.failed[receiver]
        return "the run is stopping" if network.stopping else None

    def _bound_memory(self) -> str:
        """Measure the baseline (threads started, roles not yet running); set the bound."""
        # A thread that ends makes glibc drop the stacks it caches for reuse (a deep
        # protocol parse at import may have left a huge one): they are not the roles'.
        flush = threading.Thread(target=lambda: None)
        flush.start()
        flush.join()
        self.baseline = data_size() or 0
        if self.spec.memory is None:
            return ""
        if not self.baseline:
            return "not enforced: /proc/self/status is not readable here"
        how = limit_data(self.baseline + self.spec.memory)
        return f"{how} at baseline {self.baseline / 2**20:.1f} MiB + bound"

    def _thread_failed(self, args: threading.ExceptHookArgs) -> None:
        """A thread a role started died: past the memory bound, the whole group stops."""
        if self._out_of_memory(args.exc_value):
            self._memory_exceeded(args.thread.name if args.thread is not None else "a thread")
        threading.__excepthook__(args)

    def _out_of_memory(self, error: BaseException | None) -> bool:
        """MemoryError, or (under a bound) a mapping the kernel refused: ``mmap`` raises OSError
        ENOMEM where ``RLIMIT_DATA`` stops it."""
        return isinstance(error, MemoryError) or (
            self.spec.memory is not None and isinstance(error, OSError) and error.errno == errno.ENOMEM)

    def _role_thread(self, role: str, function: Any, endpoint: Endpoint) -> None:
        self.gate.wait()
        run_role(self.spec.name, None, None, role, function, endpoint, self.results.put, schedule=False,
                 inheritance=self.inheritance, params=self.spec.params.get(role))

    def _supervise(self, count: int) -> None:
        reported = 0
        next_beat = time.monotonic()
        while reported < count:
            try:
                report = self.results.get(timeout=max(0.0, next_beat - time.monotonic()))
            except Empty:
                self._heartbeat()
                next_beat = time.monotonic() + HEARTBEAT
                continue
            reported += 1
            if self._out_of_memory(report.error):
                self._memory_exceeded(report.name)
            # The supervisor hears of a failure before the peers do: the root cause, not
            # the peers' PeerFailedErrors, is then what its policy acts on.
            self._heartbeat()
            self._send(RoleEnded(role=report.name, status=str(report.status),
                                 error=error_to_data(report.error) if report.error else None,
                                 where=report.where, traceback=report.traceback, detail=report.detail))
            if report.status is RoleStatus.FAILED:
                self.network.fail(report.name, describe_error(report.error))
        self._close_taps()  # every role has ended: nothing more will be sent
        if self.spin is not None:  # what spinning cost and saved, for the group's line of the report
            self._send(Notice(text=self.spin.summary()))
        notes = getattr(getattr(self.network, "links", None), "notes", None)
        for line in notes() if notes is not None else ():  # what a network transport saw (Zenoh: resends)
            self._send(Notice(text=line))
        self._heartbeat(final=True)
        close = getattr(self.network, "close", None)
        if close is not None:  # a DDS or Zenoh network: what was written reaches its readers before we exit
            close()

    def _close_taps(self) -> None:
        """Close every tap (a recording writes its tail), beating meanwhile: on a busy machine
        that can take longer than the supervisor's liveness limit, and the group is not frozen.
        Each tap bounds its own close; this waits at most :data:`TAPS_CLOSE_WITHIN` in all."""
        if not self.taps:
            return

        def close_all() -> None:
            for tap in self.taps:
                tap.close()

        closing = threading.Thread(target=close_all, name="anodize-close-taps",
                                   daemon=True)  # inherits the group's scheduling: its own work now
        closing.start()
        deadline = time.monotonic() + TAPS_CLOSE_WITHIN
        while closing.is_alive() and time.monotonic() < deadline:
            closing.join(HEARTBEAT)
            self._heartbeat()

    def _heartbeat(self, final: bool = False) -> None:
        for message in to_messages(*self.logs.drain()):  # before the beat: the final one comes last
            self._send(message)
        used = max(0, (data_size() or self.baseline) - self.baseline)
        self.peak = max(self.peak, used)
        statistics = {role: ep.statistics() for role, ep in self.endpoints.items()}
        sent = {f"{role}->{peer}": n for role, st in statistics.items() for peer, n in st.sent.items()}
        received = {f"{peer}->{role}": n for role, st in statistics.items() for peer, n in st.received.items()}
        waiting = {f"{role}->{peer}": n for role, st in statistics.items() for peer, n in st.high_water.items()}
        checked, closest, timeouts = constraint_counts(statistics)
        self._send(Beat(at=time.monotonic(), memory=used, peak=self.peak, sent=sent, received=received,
                        waiting=waiting, final=final, checked=checked, closest=closest, timeouts=timeouts))

    def _memory_exceeded(self, role: str) -> None:
        self.reserve = None  # room to report in
        self._heartbeat()
        error = MemoryBoundError(self.spec.name, self.spec.memory or 0, self.peak)
        self._send(MemoryExceeded(role=role, error=error_to_data(error)))
        os._exit(EXIT_MEMORY)  # every thread stops; the OS takes the memory back

    def _read_control(self) -> None:
        reader = FrameReader(self.control.fileno())
        while True:
            try:
                frames = reader.read()
                messages = [decode_control(frame) for frame in frames]
                if reader.eof:
                    raise EOFError
            except (EOFError, OSError, DecodeError):
                self.network.stop()  # the supervisor is gone: do not linger
                time.sleep(2.0)
                os._exit(1)
            for message in messages:
                self._obey(message)

    def _obey(self, message: GroupMessage | SupervisorMessage) -> None:
        match message:
            case Go():
                self.gate.set()
            case PeerFailed():
                self.network.fail(message.role, message.cause)
            case Stop():
                self.gate.set()  # a group stopped before "go" must still end
                self.network.stop()
            case _:
                pass  # a group's message sent to a group: not ours to act on

    def _send(self, message: GroupMessage) -> None:
        # OSError: the supervisor is gone; the control reader ends the process.
        with self.send_lock, contextlib.suppress(OSError):
            send_control(self.control, message)


def _payload_classes(machines: Iterable[StateMachine]) -> list[type]:
    """The classes named as sorts by the local types (the only ones that may be decoded)."""
    targets = {sort.target for sort in _payload_sorts(machines)
               if sort.target and not sort.target.startswith("ros:")}
    return with_field_classes(resolve_class(t) for t in sorted(targets))


def _payload_ros_types(machines: Iterable[StateMachine]) -> list[RosType]:
    """The ROS 2 message types named as sorts by the local types (they travel as CDR)."""
    targets = {sort.target for sort in _payload_sorts(machines) if sort.target and sort.target.startswith("ros:")}
    return [ros_type(t) for t in sorted(targets)]


def _payload_sorts(machines: Iterable[StateMachine]) -> list[Sort]:
    """The sorts payloads are made of: each label's sort, or the sorts of its named payloads."""
    return [sort for machine in machines for t in machine.all_transitions() if t.sort is not None
            for sort in t.sort.components()]


def _open_taps(spec: GroupSpec, queues: dict[tuple[str, str], Any]) -> list[GroupTap]:
    """The group's taps (a recording, the live view), each wrapping the channels it watches."""
    group = TapGroup(spec.name, spec.incarnation, spec.protocol, spec.machines, spec.memory)
    opened = []
    for plan in spec.taps:
        tap = plan.open(group)
        tap.attach(queues)
        opened.append(tap)
    return opened
