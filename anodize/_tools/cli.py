"""The ``anodize`` command: check, project, fsm, graph, lint, run, verify, replay, router, ps, status, channels,
echo, hz.

The only module that prints or exits. Exit status: 0 success, 1 the input
has errors (printed as ``path:line:col: error: ...``), 2 usage errors.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import logging
import os
import shlex
import shutil
import signal
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, TextIO

import sessiontypes
from sessiontypes import ProtocolError, ProtocolModule
from sessiontypes.limits import SOURCE, read_limited
from sessiontypes.printer import PrintTooLongError, print_local

from ..errors import AnodizeError
from .codegen import GeneratedModule, generate_modules
from .introspect import add_commands as add_introspection_commands
from .introspect import open_introspection, system_name
from .loglines import LogLines, replayed_lines
from .version import version_line

if TYPE_CHECKING:
    from .._live.server import LiveView
    from .._recording.selection import RecordSelection
    from .._supervision.report import GroupStatus
    from ..taps import ChannelTap

EXIT_OK, EXIT_ERRORS, EXIT_USAGE, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143
EXIT_NOT_EVIDENCE = 3  # verify: the hash chain does not vouch for the recording (changed, or unsigned with --key)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C would be: a run stops its groups the same way, and the
    command exits 143 (128 + SIGTERM), as shells report a process ended by it."""


class UsageError(Exception):
    """A command line that names something that is not there (exit 2)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    try:
        if _is_named_run(argv):  # 'anodize run NAME ...': the named system parses the rest
            args = argparse.Namespace(command="run", run=lambda _: _run_named(argv[1], argv[2:]))
        else:
            args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse has printed the usage message
        return exit_.code if isinstance(exit_.code, int) else EXIT_USAGE
    try:
        return int(args.run(args))
    except BrokenPipeError:  # the reader went away (e.g. '| head'): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_ERRORS
    except UsageError as error:
        print(f"anodize {args.command}: error: {error}", file=sys.stderr)
        return EXIT_USAGE
    except ProtocolError as error:
        print(error, file=sys.stderr)
        return EXIT_ERRORS
    except OSError as error:
        print(f"error: {error.filename or ''}: {error.strerror or error}", file=sys.stderr)
        return EXIT_ERRORS
    except AnodizeError as error:  # e.g. a system file's ConfigError: 'path: key: ...'
        print(f"error: {error}", file=sys.stderr)
        return EXIT_USAGE if getattr(error, "on_command_line", False) else EXIT_ERRORS  # -p, -r: a usage error
    except KeyboardInterrupt as interrupt:  # SIGINT or SIGTERM while reading or checking: one line
        terminated = isinstance(interrupt, Terminated)
        print(f"anodize {args.command}: {'terminated (SIGTERM)' if terminated else 'interrupted'}",
              file=sys.stderr)
        return EXIT_TERMINATED if terminated else EXIT_INTERRUPTED
    except MemoryError:  # e.g. under 'ulimit -v' or 'prlimit --as': the input needs more than allowed
        print(f"anodize {args.command}: error: out of memory (the input needs more memory than this process "
              "may take)", file=sys.stderr)
        return EXIT_ERRORS
    except Exception as error:  # a bug: one line, not a traceback, unless debugging
        if os.environ.get("ANODIZE_DEBUG"):
            raise
        print(f"anodize: internal error: {type(error).__name__}: {error} "
              "(set ANODIZE_DEBUG=1 for a traceback, and please report it)", file=sys.stderr)
        return 70


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="anodize", description=(
        "Multiparty session types for mixed-criticality systems: check protocols, "
        "project them onto roles, and run them."))
    parser.add_argument("--version", action="version", version=version_line())
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    check = commands.add_parser("check", help="check .proto files for well-formedness")
    check.add_argument("files", nargs="+", metavar="FILE")
    check.set_defaults(run=_check)

    project = commands.add_parser(
        "project", help="print the local type of every role, or generate typed endpoint modules")
    project.add_argument("file", metavar="FILE")
    project.add_argument("--global", dest="global_name", metavar="G", help="only this global type")
    project.add_argument("--role", metavar="R", help="only this role")
    project.add_argument("-o", "--output", dest="output_dir", metavar="DIR",
                         help="write one typed module <global>_<role>.py per role into DIR")
    project.add_argument("--check", action="store_true",
                         help="with -o: write nothing; exit 1 if a module in DIR is stale or missing")
    project.set_defaults(run=_project)

    fsm = commands.add_parser("fsm", help="print a role's state machine (DOT or JSON)")
    fsm.add_argument("file", metavar="FILE")
    fsm.add_argument("--global", dest="global_name", metavar="G",
                     help="the global type (optional when the file has one)")
    fsm.add_argument("--role", metavar="R", help="the role to project onto")
    fsm.add_argument("--local", dest="local_name", metavar="L",
                     help="a 'local' declaration instead of a projection")
    fsm.add_argument("--format", choices=("dot", "json"), default="dot")
    fsm.set_defaults(run=_fsm)

    graph = commands.add_parser("graph", help="draw the communication graph of a global type")
    graph.add_argument("file", metavar="FILE")
    graph.add_argument("--global", dest="global_name", metavar="G")
    graph.add_argument("-o", "--output", required=True, metavar="OUT",
                       help="OUT.dot, OUT.png or OUT.svg")
    graph.set_defaults(run=_graph)

    lint = commands.add_parser(
        "lint", help="warn about state a system's groups share outside the protocol, and priority inversions",
        description="Read a system's role code for state its groups share outside the protocol, and its "
                    "protocol and groups for every place where a higher-priority role can wait on a "
                    "lower-priority one. Exit 1 when there is an isolation finding; inversions are "
                    "warnings (exit 0) unless --strict, which also fails on an unbounded one.",
        epilog=f"named systems: {', '.join(_named_systems()) or '(none installed)'}")
    lint.add_argument("file", metavar="SYSTEM.toml|NAME")
    lint.add_argument("--json", metavar="FILE", help="also write the findings and inversions as JSON to FILE")
    lint.add_argument("--strict", action="store_true",
                      help="exit 1 on an unbounded priority inversion too (while priority inheritance "
                           "is not applied, most are)")
    lint.set_defaults(run=_lint)

    run_system = commands.add_parser(
        "run", help="run a system file (or a named system) and print the run report",
        description="Run a system file, or a system an installed package registers by name "
                    "('anodize run NAME --help' lists its options).",
        epilog=f"named systems: {', '.join(_named_systems()) or '(none installed)'}")
    run_system.add_argument("file", metavar="SYSTEM.toml|NAME")
    run_system.add_argument("--timeout", type=float, metavar="S",
                            help="stop roles still running after S seconds (default: the file's timeout)")
    run_system.add_argument("--json", metavar="FILE", help="also write the run report as JSON to FILE")
    run_system.add_argument("--quiet", action="store_true",
                            help="no live status lines, and of the roles' logs only WARN and above")
    run_system.add_argument("--transport", choices=("inproc", "process", "dds", "zenoh"),
                            help="run on this transport instead of the file's (e.g. dds, to try a system across "
                                 "hosts on one)")
    run_system.add_argument("--host", metavar="NAME",
                            help='transport kind "dds" or "zenoh": run only the groups placed on host NAME '
                                 "(default: every group; the file's transport.host)")
    run_system.add_argument("--wait", type=float, metavar="S",
                            help='transport kind "dds" or "zenoh": how long the groups wait for their peers to appear '
                                 "(default: the file's transport.wait, else 30)")
    run_system.add_argument("--record", metavar="PATH",
                            help="record every message, inside groups too (the file's [record] may choose "
                                 "channels): PATH.mcap is an MCAP file, any other PATH a rosbag2 folder (see "
                                 "'anodize verify' and 'anodize replay')")
    run_system.add_argument("--record-exclude", action="append", default=[], metavar="A->B",
                            help="with --record: leave channel A->B out of the recording (repeatable; quote "
                                 "it, 'A->B': > is the shell's)")
    run_system.add_argument("--record-between", action="store_true",
                            help="with --record: record only the channels between groups (cheaper; a role that "
                                 "talks inside its group then cannot be replayed alone)")
    _add_composition_arguments(run_system)
    run_system.add_argument("--record-inside", action="store_true",
                            help="the default now (every channel is recorded): accepted, and does nothing more")
    _add_sign_key_argument(run_system)
    _add_foxglove_argument(run_system)
    run_system.set_defaults(run=_run)

    verify = commands.add_parser(
        "verify", help="check a recording (MCAP file or rosbag2 folder) against a protocol",
        description="Replay each channel of a recording through the monitors of both its ends and report the "
                    "first violation on each, with the role to blame; check the recording's hash chain. Exit 0 "
                    "when it conforms and the chain holds (or it has none), 1 when it does not conform, 3 when "
                    "the chain shows it was changed after it was written (not evidence).")
    _add_recording_arguments(verify)
    verify.add_argument("--key", metavar="KEYFILE",
                        help="the secret key the chain heads were signed with (run --sign-key): check the signature")
    verify.set_defaults(run=_verify)

    replay = commands.add_parser(
        "replay", help="run one role's code against a recording: its inputs from the recording, its outputs "
                       "compared with it",
        description="Run role R's function alone, fed the messages its peers sent in the recorded run; each "
                    "message it sends is compared with the recorded one, and its monitor checks the protocol. "
                    "Its clock (Endpoint.now(), Endpoint.wall()) gives back the readings it took in the run; "
                    "Endpoint.sleep returns at once. "
                    "Exit 0 when its outputs match the recording and follow the protocol, 1 otherwise "
                    "(a replay that compared nothing included).")
    _add_recording_arguments(replay)
    replay.add_argument("--role", required=True, metavar="R", help="the role to replay")
    replay.add_argument("--function", metavar="MODULE:FUNCTION",
                        help="the role's function, your own code (needed: what a recording names is never "
                             "imported; the error says which function the recording says ran)")
    replay.add_argument("--pythonpath", action="append", default=[], metavar="DIR",
                        help="import role functions from DIR too (repeatable; the current directory always)")
    replay.add_argument("--timeout", type=float, default=60.0, metavar="S",
                        help="stop the role if it has not ended after S seconds (default 60)")
    replay.set_defaults(run=_replay)

    router = commands.add_parser(
        "router", help="run a Zenoh router here until Ctrl-C or SIGTERM (hosts of transport zenoh connect to it)",
        description="Run a Zenoh router in this process, as ROS 2's rmw_zenohd does, until SIGINT or SIGTERM "
                    "(then exit 0). The hosts of a run on transport zenoh in client mode connect to it "
                    "([zenoh] connect); it prints where it listens and each client, peer or router that connects "
                    "or leaves.")
    router.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help="listen on ENDPOINT, e.g. tcp/10.0.0.1:7447 (repeatable; default tcp/[::]:7447)")
    router.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                        help="connect to the router at ENDPOINT too, retrying until it answers (repeatable)")
    router.add_argument("--tls-certificate", metavar="PEM",
                        help="TLS: the router's certificate, naming the address hosts reach it at; with any "
                             "--tls-* option every endpoint is tls/ (default listen tls/[::]:7447)")
    router.add_argument("--tls-private-key", metavar="PEM", help="TLS: the key of --tls-certificate")
    router.add_argument("--tls-root-ca", metavar="PEM",
                        help="TLS: the authority that signs the certificates of the routers it connects to (and, "
                             "with --tls-mutual, of whoever connects)")
    router.add_argument("--tls-mutual", action="store_true",
                        help="TLS: whoever connects must show a certificate --tls-root-ca signed (mutual TLS)")
    router.set_defaults(run=_router)
    add_introspection_commands(commands, run=_introspect)
    return parser


def _load(path: str) -> ProtocolModule:
    module = sessiontypes.load(path)
    for warning in module.warnings:
        print(warning, file=sys.stderr)
    return module


def _check(args: argparse.Namespace) -> int:
    status = EXIT_OK
    for path in args.files:
        try:
            module = _load(path)
        except ProtocolError as error:
            print(error, file=sys.stderr)
            status = EXIT_ERRORS
        except OSError as error:
            print(f"error: {path}: {error.strerror or error}", file=sys.stderr)
            status = EXIT_ERRORS
        else:
            print(f"{path}: ok ({_count(len(module.globals), 'global')}, "
                  f"{_count(len(module.locals), 'local')})")
    return status


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}{'' if number == 1 else 's'}"


def _pick_globals(module: ProtocolModule, name: str | None) -> list[sessiontypes.GlobalType]:
    if name is None:
        return list(module.globals.values())
    if name not in module.globals:
        raise UsageError(f"no global {name} in {module.path}; expected one of "
                         f"{', '.join(module.globals) or '(none)'}")
    return [module.globals[name]]


def _one_global(module: ProtocolModule, name: str | None) -> sessiontypes.GlobalType:
    if name is None:
        if not module.globals:
            raise UsageError(f"{module.path} declares no global type")
        if len(module.globals) > 1:
            raise UsageError(f"{module.path} has {_count(len(module.globals), 'global')}; "
                             f"choose one with --global ({', '.join(module.globals)})")
    (chosen,) = _pick_globals(module, name)
    return chosen


def _project(args: argparse.Namespace) -> int:
    if args.check and args.output_dir is None:
        raise UsageError("--check compares generated modules with DIR: give -o DIR")
    # sessiontypes.load, with the text kept: generated modules carry its digest.
    text = sessiontypes.read_source(args.file)
    module = sessiontypes.loads(text, args.file)
    for warning in module.warnings:
        print(warning, file=sys.stderr)
    chosen = _pick_globals(module, args.global_name)
    if args.role:
        if not any(args.role in gt.roles for gt in chosen):
            roles = dict.fromkeys(r for gt in chosen for r in gt.roles)
            raise UsageError(f"no role {args.role} in {_names(chosen)}; expected one of "
                             f"{', '.join(roles)}")
        chosen = [gt for gt in chosen if args.role in gt.roles]
    if args.output_dir is not None:
        targets = [(gt, role) for gt in chosen for role in gt.roles
                   if args.role is None or role == args.role]
        return _generate(args, generate_modules(module, text, targets))
    lines: list[str] = []
    for gt in chosen:
        if len(chosen) > 1:
            lines.append(f"# {gt.name}")
        lines.extend(f"{role} = {_printed(gt, role)}" for role in gt.roles if args.role is None or role == args.role)
    if lines:
        print("\n".join(lines))
    return EXIT_OK


# A projection prints every use of a declaration in full: a file of n declarations
# each using the next twice prints 2**n interactions. Refuse rather than run for ever.
PRINT_LIMIT = 64 * 2**20


def _printed(global_type: sessiontypes.GlobalType, role: str) -> str:
    try:
        return print_local(global_type.project(role).body, PRINT_LIMIT)
    except PrintTooLongError:
        raise AnodizeError(f"{global_type.name} projected onto {role} is longer than {PRINT_LIMIT} "
                           "characters written out (declarations used in many places print in full at "
                           "every use); 'anodize fsm' shows it as a state machine") from None


def _generate(args: argparse.Namespace, modules: list[GeneratedModule]) -> int:
    directory = Path(args.output_dir)
    if not args.check:
        directory.mkdir(parents=True, exist_ok=True)
        for generated in modules:
            path = directory / generated.filename
            path.write_bytes(generated.text.encode("utf-8"))  # '\n' on every platform
            print(f"wrote {path}")
        return EXIT_OK
    outdated = []
    for generated in modules:
        path = directory / generated.filename
        try:
            current = read_limited(path, SOURCE)  # a FIFO or a device there is refused, not read
        except FileNotFoundError:
            outdated.append(f"{path}: missing")
            continue
        if current != generated.text.encode("utf-8"):
            outdated.append(f"{path}: stale (differs from what {args.file} generates now)")
    if not outdated:
        print(f"{directory}: {_count(len(modules), 'generated module')} up to date")
        return EXIT_OK
    for line in outdated:
        print(line, file=sys.stderr)
    command = ["anodize", "project", args.file, "-o", args.output_dir]
    command += ["--global", args.global_name] if args.global_name else []
    command += ["--role", args.role] if args.role else []
    print(f"{_count(len(outdated), 'module')} out of date; regenerate with: "
          f"{shlex.join(command)}", file=sys.stderr)
    return EXIT_ERRORS


def _names(globals_: list[sessiontypes.GlobalType]) -> str:
    return ", ".join(f"global {g.name}" for g in globals_) or "the file (it has no global)"


def _fsm(args: argparse.Namespace) -> int:
    module = _load(args.file)
    if args.local_name:
        if args.local_name not in module.locals:
            raise UsageError(f"no local {args.local_name} in {args.file}; expected one of "
                             f"{', '.join(module.locals) or '(none)'}")
        machine = module.locals[args.local_name].fsm()
    else:
        gt = _one_global(module, args.global_name)
        if args.role is None:
            raise UsageError(f"choose a role with --role ({', '.join(gt.roles)})")
        if args.role not in gt.roles:
            raise UsageError(f"no role {args.role} in global {gt.name}; expected one of "
                             f"{', '.join(gt.roles)}")
        machine = gt.project(args.role).fsm()
    print(machine.to_json() if args.format == "json" else machine.to_dot())
    return EXIT_OK


def _graph(args: argparse.Namespace) -> int:
    from sessiontypes.graph import communication_graph, graph_to_dot

    module = _load(args.file)
    gt = _one_global(module, args.global_name)
    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in {".dot", ".png", ".svg"}:
        raise UsageError(f"cannot write {out}: expected a name ending in .dot, .png or .svg")
    graph = communication_graph(gt)
    if suffix == ".dot":
        out.write_text(graph_to_dot(graph) + "\n", encoding="utf-8")
    else:
        from .drawing import draw_communication_graph

        draw_communication_graph(graph, out)
    print(f"wrote {out}")
    return EXIT_OK


def _system_file(path: str, named: bool = False) -> Path:
    file = Path(path)
    if file.is_dir():
        raise UsageError(f"{path} is a directory; expected a system file (.toml)")
    if not file.exists():
        names = _named_systems() if named and file.suffix != ".toml" else []
        known = f" or named system (named systems: {', '.join(names)})" if names else ""
        raise UsageError(f"no such system file{known}: {path}")
    if file.suffix != ".toml":
        raise UsageError(f"{path}: expected a system file ending in .toml")
    return file


def _lint(args: argparse.Namespace) -> int:
    from .config import load_config
    from .inversion import inversion_report
    from .lint import lint_report

    config = load_config(_lint_target(args.file))
    report = lint_report(config)
    for finding in report.findings:
        print(finding)
    modules = _count(len(report.modules), "module")
    if report.findings:
        print(f"{_count(len(report.findings), 'finding')} in {modules}")
    else:
        print(f"no isolation problems found in {modules}")
    inversions = inversion_report(config)
    lines = inversions.lines()
    if inversions.inversions:
        print()
    for line in lines:
        print(line)
    if args.json:
        _write_json(Path(args.json), {"findings": [dataclasses.asdict(f) for f in report.findings],
                                      "modules": list(report.modules), **inversions.to_dict()})
    # Shared state fails the lint. Inversions are warnings: priority inheritance, which bounds
    # most of them, is not applied yet, so failing on them would fail every realistic system;
    # --strict fails on an unbounded one for those who want it as a gate.
    return EXIT_ERRORS if report.findings or (args.strict and inversions.unbounded) else EXIT_OK


def _lint_target(given: str) -> Path:
    """The system file to lint: a path, or the file a named system declares as ``system_file``."""
    if not Path(given).is_file() and given in _named_systems():  # as for run: a name beats a folder
        from .named import find_named

        named = find_named(given)
        system_file = getattr(named, "system_file", None)
        if not isinstance(system_file, Path):
            raise UsageError(f"named system {given} has no system file to lint (it declares no system_file)")
        return system_file
    return _system_file(given, named=True)


def _run(args: argparse.Namespace) -> int:
    from .._supervision.transports import Dds, Zenoh
    from .config import build_system, load_config
    from .keys import read_signing_key

    if args.timeout is not None and not args.timeout > 0:
        raise UsageError(f"--timeout {args.timeout}: expected a number of seconds > 0")
    if args.wait is not None and not args.wait > 0:
        raise UsageError(f"--wait {args.wait}: expected a number of seconds > 0")
    if args.sign_key is not None and args.record is None:
        raise UsageError("--sign-key needs --record PATH")
    config = load_config(_system_file(args.file, named=True)).with_overrides(args.param, args.remap, args.namespace)
    if args.transport is not None:
        config = config.on_transport(args.transport)
    if args.host is not None and not isinstance(config.transport, Dds | Zenoh):
        raise UsageError(f"--host needs transport kind \"dds\" or \"zenoh\"; {config.path} uses "
                         f"{config.transport.kind!r}")
    if isinstance(config.transport, Dds | Zenoh) and (args.host is not None or args.wait is not None):
        config = dataclasses.replace(config, transport=dataclasses.replace(
            config.transport, host=args.host if args.host is not None else config.transport.host,
            wait=args.wait if args.wait is not None else config.transport.wait))
    system = build_system(config)
    timeout = args.timeout if args.timeout is not None else config.timeout
    given = [flag for flag, on in (("--record-inside", args.record_inside), ("--record-between", args.record_between),
                                   ("--record-exclude", args.record_exclude)) if on]
    if given and args.record is None:
        raise UsageError(f"{given[0]} needs --record PATH")
    selection = config.record.for_run(args.record_between, args.record_exclude, system.global_type)
    sign_key = read_signing_key(args.sign_key, "--sign-key") if args.sign_key is not None else None
    status = None if args.quiet else LiveStatus(sys.stdout)
    logs = LogLines(sys.stdout, logging.WARNING if args.quiet else logging.DEBUG,
                    status.clear if status is not None else None)
    with _taps(args.record, args.foxglove, selection, sign_key) as taps, \
            _introspection(system_name(args.file), str(config.path)) as served:
        report = system.run(timeout=timeout, on_status=status, taps=[*taps, *served], on_log=logs)
    print(report.summary())
    if args.json:
        out = Path(args.json)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(report.to_json() + "\n", encoding="utf-8")
        print(f"wrote {out}")
    return _exit_status(report.ok, report.interrupted)


def _verify(args: argparse.Namespace) -> int:
    from .._recording.reader import open_recording
    from .._recording.verify import verify
    from .keys import read_signing_key
    from .recordings import protocol_of, topic_map

    key = read_signing_key(args.key, "--key") if args.key is not None else None
    with open_recording(args.recording) as recording:
        global_type = protocol_of(recording, args.protocol, args.global_name)
        topics = topic_map(args.topics, global_type) if args.topics else None
        # The recording's own protocol is untrusted: its payload classes are not imported.
        report = verify(recording, global_type, topics, import_classes=args.protocol is not None, signing_key=key)
    print(report.text())
    if args.json:
        _write_json(Path(args.json), report.to_dict())
    if not report.conforms:
        return EXIT_ERRORS
    return EXIT_NOT_EVIDENCE if report.evidence is not None and report.evidence.faults else EXIT_OK


def _add_recording_arguments(parser: argparse.ArgumentParser) -> None:
    """What verify and replay share: the recording, its protocol and topic map, JSON out."""
    parser.add_argument("recording", metavar="RECORDING")
    parser.add_argument("--protocol", metavar="FILE.proto",
                        help="the protocol (default: the one an anodize recording carries)")
    parser.add_argument("--global", dest="global_name", metavar="G",
                        help="the global type (default: the recording's, or the file's only one)")
    parser.add_argument("--topics", metavar="MAP",
                        help="a TOML file mapping \"Sender->Receiver:label\" to topics (a system file's "
                             "[ros.topics], or the same entries at its top level), for recordings made by "
                             "other tools")
    parser.add_argument("--json", metavar="FILE", help="also write the result as JSON to FILE")


def _add_composition_arguments(parser: argparse.ArgumentParser) -> None:
    from .composition_args import add_composition_arguments

    add_composition_arguments(parser)


def _add_sign_key_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sign-key", metavar="KEYFILE",
                        help="with --record: sign the recording's hash chain heads with the secret key in "
                             "KEYFILE (HMAC-SHA256; 'anodize verify --key KEYFILE' checks it)")


def _add_foxglove_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--foxglove", nargs="?", type=int, const=8765, default=None, metavar="PORT",
                        help="serve every channel and each group's status live to the Foxglove app on "
                             "ws://127.0.0.1:PORT (default 8765; 0: any free port); a client publishing on a "
                             "channel's topic (e.g. /joy) reaches the role that sends it")


@contextlib.contextmanager
def _taps(record: str | os.PathLike[str] | None, foxglove: int | None,
          selection: RecordSelection | None = None, sign_key: bytes | None = None) -> Iterator[list[ChannelTap]]:
    """The run's channel taps: ``--record`` (first: it wraps the channels first, as it always has;
    ``selection``: which channels, default every one), then ``--foxglove``."""
    taps: list[ChannelTap] = []
    if record is not None:
        from .._recording import Recording

        taps.append(Recording(record, selection=selection, sign_key=sign_key))
    with _live_view(foxglove) as live:
        if live is not None:
            taps.append(live)
        yield taps


@contextlib.contextmanager
def _live_view(port: int | None) -> Iterator[LiveView | None]:
    """The run's live view in Foxglove (``--foxglove``), announced before the run starts."""
    if port is None:
        yield None
        return
    if not 0 <= port <= 65535:
        raise UsageError(f"--foxglove {port}: expected a port number 0..65535")
    from .._live import open_live_view

    live = open_live_view(port)
    print(f"foxglove: serving the run live at {live.url} (Foxglove app: Open connection > Foxglove WebSocket)",
          flush=True)
    try:
        yield live
    finally:
        live.close()


@contextlib.contextmanager
def _introspection(name: str, source: str) -> Iterator[list[ChannelTap]]:
    """The run's introspection server ('anodize ps|status|channels|echo|hz'), if it can be opened."""
    served, why = open_introspection(name, source)
    if served is None:
        print(f"introspection: off ({why}); the run goes on", file=sys.stderr)
    try:
        yield [served] if served is not None else []
    finally:
        if served is not None:
            served.close()


def _introspect(args: argparse.Namespace) -> int:
    """ps, status, channels, echo, hz: print what the run answers."""
    for line in args.lines(args):
        print(line, flush=True)
    return EXIT_OK


def _replay(args: argparse.Namespace) -> int:
    from .._recording.reader import open_recording
    from .._recording.replay import replay
    from .._session.logs import LogCapture
    from .recordings import protocol_of, role_function, topic_map

    if not args.timeout > 0:
        raise UsageError(f"--timeout {args.timeout}: expected a number of seconds > 0")
    with open_recording(args.recording) as recording:
        global_type = protocol_of(recording, args.protocol, args.global_name)
        if args.role not in global_type.roles:
            raise UsageError(f"no role {args.role} in global {global_type.name}; expected one of "
                             f"{', '.join(global_type.roles)}")
        topics = topic_map(args.topics, global_type) if args.topics else None
        function = role_function(recording, args.role, args.function, [".", *args.pythonpath])
        logs = LogCapture({args.role: "replay"})  # the role's records (ep.logger), shown after the report
        logs.install()
        try:
            report = replay(recording, global_type, args.role, function, topics, timeout=args.timeout,
                            import_classes=args.protocol is not None)
        finally:
            logs.uninstall()
    print(report.text())
    for line in replayed_lines(*logs.drain()):  # after the verdict, which stays the first line
        print(line)
    if args.json:
        _write_json(Path(args.json), report.to_dict())
    return EXIT_OK if report.ok else EXIT_ERRORS


def _router(args: argparse.Namespace) -> int:
    from .._transport.zenoh.settings import ZenohTls
    from ..errors import ConfigurationError
    from .router import check_endpoint, open_router

    for option, endpoints in (("--listen", args.listen or ()), ("--connect", args.connect)):
        for endpoint in endpoints:
            problem = check_endpoint(endpoint)
            if problem is not None:
                raise UsageError(f"{option} {endpoint}: {problem}")
    tls = None
    if args.tls_certificate or args.tls_private_key or args.tls_root_ca or args.tls_mutual:
        try:
            tls = ZenohTls(root_ca=args.tls_root_ca or "", certificate=args.tls_certificate or "",
                           private_key=args.tls_private_key or "", mutual=args.tls_mutual)
        except ConfigurationError as error:
            raise UsageError(f"the --tls-* options: {error}") from None
    try:
        router = open_router(args.listen, args.connect, tls)
    except ConfigurationError as error:  # the options do not go together, or a file is not there
        raise UsageError(str(error)) from None
    try:
        print(f"router {router.zid}: listening on {', '.join(router.locators)}", flush=True)
        if args.connect:
            print(f"router {router.zid}: connecting to {', '.join(args.connect)}", flush=True)
        while True:
            line = router.next_event(timeout=1.0)
            if line is not None:  # the line and its end in one write: a signal comes between two
                print(f"router: {line}\n", end="", flush=True)
    except KeyboardInterrupt as interrupt:  # Ctrl-C or SIGTERM: the way a router is stopped
        print(f"router: stopped ({'SIGTERM' if isinstance(interrupt, Terminated) else 'SIGINT'})", flush=True)
        return EXIT_OK
    finally:
        router.close()


def _write_json(out: Path, data: object) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {out}")


def _exit_status(ok: bool, interrupted: bool) -> int:
    """0 for a run that went to the end, 130 after Ctrl-C (as shells do), else 1."""
    if interrupted:
        return EXIT_INTERRUPTED
    return EXIT_OK if ok else EXIT_ERRORS


def _named_systems() -> list[str]:
    from .named import named_systems

    return named_systems()


def _is_named_run(argv: list[str]) -> bool:
    return (len(argv) >= 2 and argv[0] == "run" and not argv[1].startswith("-")
            and not Path(argv[1]).is_file() and argv[1] in _named_systems())


def _run_named(name: str, rest: list[str]) -> int:
    from .keys import read_signing_key
    from .named import find_named

    named = find_named(name)
    assert named is not None  # _is_named_run saw it registered
    parser = argparse.ArgumentParser(prog=f"anodize run {name}", description=named.summary)
    parser.add_argument("--quiet", action="store_true", help="no live progress line")
    _add_foxglove_argument(parser)
    _add_sign_key_argument(parser)
    _add_composition_arguments(parser)  # prepare() applies them: SystemConfig.with_overrides
    named.add_arguments(parser)
    try:
        args = parser.parse_args(rest)
    except SystemExit as exit_:
        return exit_.code if isinstance(exit_.code, int) else EXIT_USAGE
    sign_key = read_signing_key(args.sign_key, "--sign-key") if args.sign_key is not None else None
    prepared = named.prepare(args, lambda line: print(line, flush=True))
    if sign_key is not None and prepared.record is None:
        raise UsageError("--sign-key needs --record")
    progress = None if args.quiet else ProgressLine(sys.stdout, named.progress)
    logs = LogLines(sys.stdout, logging.WARNING if args.quiet else logging.DEBUG,
                    progress.clear if progress is not None else None)
    try:
        with _taps(prepared.record, args.foxglove, prepared.selection(), sign_key) as taps, \
                _introspection(name, name) as served:
            report = prepared.system.run(timeout=prepared.timeout, grace=prepared.grace, on_status=progress,
                                         taps=[*taps, *served], stop_when=prepared.stop_when, on_log=logs)
    finally:
        if progress is not None:
            progress.close()
    print(report.summary())
    finished = named.finish(report, args)
    for line in finished.lines:
        print(line)
    return _exit_status(finished.ok, report.interrupted)


class ProgressLine:
    """``on_status`` for a named system: its one-line account of the run so far.

    On a terminal the line is redrawn in place, no wider than the terminal: the named
    system is expected to make it fit (``shutil.get_terminal_size``), and a longer line is
    cut, naming the groups that failed at its end. In a log, one line every 5 s, whole.
    """

    LOG_EVERY = 5.0  # seconds

    def __init__(self, stream: TextIO, describe: Callable[[dict[str, GroupStatus], float], str]) -> None:
        self.stream = stream
        self.describe = describe
        self.tty = stream.isatty()
        self.started = time.monotonic()
        self.logged = 0.0  # elapsed time of the last line written to a log

    def __call__(self, statuses: dict[str, GroupStatus]) -> None:
        elapsed = time.monotonic() - self.started
        line = self.describe(statuses, elapsed)
        if self.tty:
            failed = [status.name for status in statuses.values() if status.state == "failed"]
            line = self.fit(line, self.width(), self.stream, failed)
            self.stream.write(f"\r\x1b[2K{line}")
        elif elapsed - self.logged >= self.LOG_EVERY:
            self.logged = elapsed
            self.stream.write(line + "\n")
        self.stream.flush()

    def clear(self) -> None:
        """Clear the line drawn in place (a log record is written there); the next call redraws it."""
        if self.tty:
            self.stream.write("\r\x1b[2K")

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()

    @staticmethod
    def width() -> int:
        """Columns a live line may take: the terminal's (80 when unknown) but the last, which
        the cursor takes (a character there makes some terminals wrap)."""
        return max(1, shutil.get_terminal_size().columns - 1)

    @staticmethod
    def fit(line: str, width: int, stream: TextIO, failed: Sequence[str] = ()) -> str:
        """``line`` in at most ``width`` characters: cut, the cut marked by an ellipsis (``...``
        where ``stream`` cannot write one), and then the groups in ``failed`` named, so that a
        failure never goes out of sight."""
        if len(line) <= width:
            return line
        encoding = (getattr(stream, "encoding", None) or "utf-8").lower().replace("-", "")
        ellipsis = "\u2026" if encoding == "utf8" else "..."
        tail = f" FAILED {','.join(failed)}" if failed else ""
        keep = max(0, width - len(ellipsis) - len(tail))
        return (line[:keep] + ellipsis + tail)[:width]


class LiveStatus:
    """``on_status`` for ``anodize run``: one line per group.

    On a terminal the lines are redrawn in place, each cut to the terminal's width
    (a line the terminal wrapped would throw the redrawing off; the group's name and
    state come first, so they stay); otherwise (a log, a pipe) a group's line is
    printed whole, and only when its state changed, so logs stay short.
    """

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.drawn = 0                       # lines drawn last time (terminal)
        self.states: dict[str, str] = {}     # state last printed per group (log)

    def clear(self) -> None:
        """Clear the lines drawn in place (a log record is written there); the next call redraws them."""
        if self.tty and self.drawn:
            self.stream.write(f"\x1b[{self.drawn}F\x1b[J")
            self.drawn = 0

    def __call__(self, statuses: dict[str, GroupStatus]) -> None:
        if self.tty:
            up = f"\x1b[{self.drawn}F" if self.drawn else ""
            width = ProgressLine.width()
            lines = "".join(f"\x1b[2K{ProgressLine.fit(status.line(), width, self.stream)}\n"
                            for status in statuses.values())
            self.stream.write(f"{up}{lines}\x1b[J")  # [J: clear what a longer frame left below
            self.drawn = len(statuses)
        else:
            for name, status in statuses.items():
                if self.states.get(name) != status.state:
                    self.states[name] = status.state
                    self.stream.write(status.line() + "\n")
        self.stream.flush()


def run() -> NoReturn:
    """Console-script entry point."""
    # SIGTERM (a service manager, a container stop) ends a run as Ctrl-C does: the groups
    # are stopped, cgroups and rings removed, and the report still printed and written.
    signal.signal(signal.SIGTERM, _terminated)
    # Python installs its Ctrl-C handler only where SIGINT was not ignored at start (a job started
    # with '&' by a script ignores it): install it anyway, so that SIGINT always ends a long read.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.exit(main())


def _terminated(signum: int, frame: object) -> None:
    raise Terminated


if __name__ == "__main__":
    run()
