"""``anodize run tinman``: TinMan as a named system of anodize.

Registered under the ``anodize.systems`` entry point (see tinman/pyproject.toml), so
anodize finds it by name without importing tinman. It runs ``tinman.toml``,
then writes ``report.json`` and ``trajectory.png`` into the output folder.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from anodize import (
    AnodizeError,
    Finished,
    GroupStatus,
    Prepared,
    RosBridge,
    RunReport,
    SystemConfig,
    build_system,
    load_config,
)

from .contract import contract_lines
from .mission_outcome import counted, mission_line
from .outcome import build_report, world_clock_line
from .settings import FAULTS, Settings, export
from .worlds import DEFAULT_LOOK, WORLDS

__all__ = ["TINMAN", "TinMan", "SYSTEM_FILE", "TinManError", "patrol_done", "PATROL_HINT", "PATROL_LIMIT"]

SYSTEM_FILE = Path(__file__).with_name("tinman.toml")
SHORT_RUN = 20.0       # seconds: the default run, a sample of the patrol
PATROL_LIMIT = 180.0   # seconds: a whole patrol's default time limit (an ideal drive takes 45 s)
PATROL_DONE = "the patrol is completed (the Planner is back at the dock)"
PATROL_HINT = ("the whole patrol (five waypoints, then back to the dock): "
               f"anodize run tinman --patrol  (ends when done, or after {PATROL_LIMIT:g} s)")
PAPER_GLOBAL = "TinMan"  # Fig. 16 as written


class TinManError(AnodizeError):
    """A TinMan option or input that cannot be used (the message says which and why)."""


class TinMan:
    """The named system ``tinman``."""

    system_file = SYSTEM_FILE  # what 'anodize lint tinman' reads
    summary = ("TinMan, the robot system of the Anodize paper: camera, visual odometry, planner, "
               "joystick control and a simulated robot in four groups of different criticality. "
               "Writes report.json and trajectory.png.")

    def __init__(self) -> None:
        self.settings = Settings()

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--duration", type=float, default=None, metavar="S",
                            help=f"seconds to run (default {SHORT_RUN:g}); with --patrol, the time limit "
                                 f"(default {PATROL_LIMIT:g})")
        parser.add_argument("--patrol", action="store_true",
                            help="the whole patrol: every waypoint, then back to the dock; the run ends when "
                                 "the robot is back (or at the time limit, --duration)")
        parser.add_argument("--out", default="out/tinman", metavar="DIR",
                            help="folder for report.json and trajectory.png (default out/tinman)")
        parser.add_argument("--paper", action="store_true",
                            help="run Fig. 16's single-loop global type TinMan instead of TinManParallel")
        parser.add_argument("--inject", action="append", default=[], metavar="FAULT=GROUP",
                            help=f"inject a fault into a group ({', '.join(FAULTS)}), e.g. memory-hog=planning")
        parser.add_argument("--teleop", action="store_true",
                            help="drive with the keyboard (w/s forward/back, a/d turn, q/e curve) "
                                 "instead of the scripted joystick; needs a terminal")
        parser.add_argument("--dataset", metavar="DIR",
                            help="play a recorded TUM RGB-D sequence back as the camera (default: the simulated "
                                 "camera renders the room live from the simulated robot)")
        parser.add_argument("--world", choices=WORLDS, default=None,
                            help="how the room looks to the simulated camera: realistic (photographs, plain "
                                 "walls, repeated patterns, flickering lamps, motion blur; the default) or easy "
                                 "(procedural textures made for ORB)")
        parser.add_argument("--planner", choices=("rrt", "astar"), default="rrt",
                            help="RRT-Connect with shortcut smoothing (default) or grid A*")
        parser.add_argument("--transport", choices=("process", "dds"), default=None,
                            help="process pipes and shared memory (tinman.toml's, the default) or DDS, "
                                 "where the mapped labels travel on ROS 2 topics ([ros.topics] in tinman.toml)")
        parser.add_argument("--external", action="append", default=[], metavar="ROLE",
                            help="with --transport dds: a ROS 2 node on the network plays ROLE (e.g. Joy: a "
                                 "joy_node on /joy; Gazebo: a simulator on /cmd_vel); TinMan does not run it")
        parser.add_argument("--record", nargs="?", const="", default=None, metavar="PATH",
                            help="record every message (camera images, poses, plans, commands; inside groups too, "
                                 "so that each role can be replayed alone with 'anodize replay') and every role's "
                                 "clock readings to PATH: an MCAP file if it ends in .mcap, else a rosbag2 folder "
                                 "(default: OUT/run.mcap); check it with 'anodize verify PATH'")
        parser.add_argument("--record-exclude", action="append", default=[], metavar="A->B",
                            help="with --record: leave channel A->B out of the recording (repeatable; quote "
                                 "it: > is the shell's), e.g. 'Gazebo->Camera', the camera's images as rendered")
        parser.add_argument("--record-between", action="store_true",
                            help="with --record: record only the channels between groups (cheaper; the roles "
                                 "that talk inside their group then cannot be replayed alone)")

    def prepare(self, args: argparse.Namespace, log: Callable[[str], None]) -> Prepared:
        patrol = bool(getattr(args, "patrol", False))
        if args.duration is None:
            args.duration = PATROL_LIMIT if patrol else SHORT_RUN
        if not args.duration > 0:
            raise TinManError(f"--duration {args.duration}: expected a number of seconds > 0")
        config = load_config(SYSTEM_FILE).with_overrides(getattr(args, "param", []), getattr(args, "remap", []),
                                                         getattr(args, "namespace", None))
        if args.paper:
            config = dataclasses.replace(config, global_name=PAPER_GLOBAL)
        if getattr(args, "transport", None) is not None:
            config = config.on_transport(args.transport)
        if args.external:
            config = _external(config, args.external)
        groups = {role: group.name for group in config.groups.values() for role in group.roles}
        inject = _faults(args.inject, sorted(config.groups))
        if args.teleop:
            _check_terminal()
        out = Path(args.out)
        chosen = getattr(args, "world", None)  # None: not given (so it cannot clash with --dataset)
        world = chosen or DEFAULT_LOOK
        if args.dataset is not None and chosen is not None:
            raise TinManError(f"--world {world} with --dataset: a recording is played back as it was filmed; "
                              "--world chooses what the simulated camera renders")
        dataset = _dataset(args.dataset) if args.dataset is not None else ""
        self.settings = Settings(out=str(out.resolve()), dataset=dataset, world=world,
                                 duration=float(args.duration), patrol=patrol, paper=args.paper, teleop=args.teleop,
                                 inject=inject, groups=groups, planner=args.planner)
        shutil.rmtree(self.settings.records, ignore_errors=True)  # no record of an older run may linger
        self.settings.records.mkdir(parents=True, exist_ok=True)
        export(self.settings)
        record = None if args.record is None else Path(args.record or out / "run.mcap")
        exclude, between = getattr(args, "record_exclude", []), bool(getattr(args, "record_between", False))
        if record is None and (exclude or between):
            raise TinManError(f"{'--record-exclude' if exclude else '--record-between'} needs --record")
        system = build_system(config)
        # tinman.toml's [record] (every channel by default), with the command line's choices.
        selection = config.record.for_run(between, exclude, system.global_type)
        return Prepared(system, timeout=float(args.duration), grace=3.0, record=record, record_selection=selection,
                        stop_when=patrol_done(self.settings.records) if patrol else None)

    def progress(self, statuses: dict[str, GroupStatus], elapsed: float) -> str:
        """The live line, as much of it as the terminal has room for (80 columns when unknown).

        In full where it fits (``TinMan 12.3/20 s | control running 152 msg/s | perception
        running 62 msg/s | ...``), else abbreviated: ``TinMan 12.3/20s con 152/s per 62/s pla 1/s
        sim 100/s``, a group that is not running showing its state instead of its rate (a
        failed one ``FAILED``). The abbreviated line of TinMan's four groups is under 70 columns.
        """
        shown = min(elapsed, self.settings.duration)
        width = shutil.get_terminal_size().columns - 1  # the last column is the cursor's
        full = [f"TinMan {shown:4.1f}/{self.settings.duration:g} s"]
        for status in statuses.values():
            rate = f" {status.rate_hz:.0f} msg/s" if status.rate_hz is not None and status.state == "running" else ""
            full.append(f"{status.name} {status.state}{rate}")
        if len(" | ".join(full)) <= width:
            return " | ".join(full)
        short = _abbreviations([status.name for status in statuses.values()])
        return " ".join([f"TinMan {shown:.1f}/{self.settings.duration:g}s",
                         *(f"{short[status.name]} {_brief(status)}" for status in statuses.values())])

    def finish(self, report: RunReport, args: argparse.Namespace) -> Finished:
        from .picture import draw_run  # matplotlib: only once there is something to draw

        settings = self.settings
        data = build_report(report, settings)
        ok, problems = _judge(data, settings)
        data["ok"], data["problems"] = ok, problems
        out = Path(settings.out)
        report_file = out / "report.json"
        report_file.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        title = "TinMan"
        fused = data["fused"]
        if fused["ate_rmse_m"] is not None:
            title += (f": fused ATE RMSE {fused['ate_rmse_m'] * 100:.1f} cm over {fused['trajectory_length_m']:.2f} m "
                      f"({fused['ate_percent']:.2f}%)")
        if data["ate_rmse_m"] is not None:
            title += (("," if fused["ate_rmse_m"] is not None else ":")
                      + f" VO ATE RMSE {data['ate_rmse_m'] * 100:.1f} cm ({data['ate_percent']:.2f}%)")
        picture = draw_run(out / "trajectory.png", settings, title=title)
        lines = [*_lines(data, problems), f"wrote {_shown(report_file)} and {_shown(picture)}"]
        if not settings.patrol:
            lines.append(PATROL_HINT)
        return Finished(ok, lines)


def patrol_done(records: Path) -> Callable[[], str | None]:
    """``stop_when`` of a whole patrol: the reason to stop once the Planner has written its
    ``Patrol`` record (back at the dock by its pose), else None."""
    def done() -> str | None:
        try:
            return PATROL_DONE if (records / "Patrol.json").is_file() else None
        except OSError:
            return None
    return done


_BRIEF_STATES = {"starting": "start", "restarting": "restart", "stopped": "stop", "failed": "FAILED"}


def _brief(status: GroupStatus) -> str:
    """A group in the abbreviated live line: its rate while running, else its state."""
    if status.state == "running":
        return f"{status.rate_hz:.0f}/s" if status.rate_hz is not None else "run"
    return _BRIEF_STATES.get(str(status.state), str(status.state))


def _abbreviations(names: list[str]) -> dict[str, str]:
    """Each name's shortest prefix of three or more letters that starts no other name
    (``control`` -> ``con``, ``planning`` -> ``pla``); a name that starts another stays whole."""
    short = {}
    for name in names:
        prefix = name
        for length in range(3, len(name)):
            if not any(other != name and other.startswith(name[:length]) for other in names):
                prefix = name[:length]
                break
        short[name] = prefix
    return short


def _faults(requests: list[str], groups: list[str]) -> dict[str, str]:
    faults: dict[str, str] = {}
    for request in requests:
        fault, _, group = request.partition("=")
        if fault not in FAULTS or not group:
            raise TinManError(f"--inject {request}: expected FAULT=GROUP with FAULT one of {', '.join(FAULTS)}")
        if group not in groups:
            raise TinManError(f"--inject {request}: no group {group!r}; expected one of {', '.join(groups)}")
        faults[group] = fault
    return faults


def _external(config: SystemConfig, roles: list[str]) -> SystemConfig:
    """The system with ``roles`` played by ROS 2 nodes: out of their groups (a group left with no
    role is dropped), and named external.

    Raises:
        TinManError: not on DDS, or not a role of TinMan.
    """
    if config.transport.kind != "dds":
        raise TinManError("--external needs --transport dds: a ROS 2 node plays the role on TinMan's ROS topics")
    every = [role for group in config.groups.values() for role in group.roles]
    unknown = [role for role in roles if role not in every]
    if unknown:
        raise TinManError(f"--external {unknown[0]}: TinMan has no role {unknown[0]}; its roles are {', '.join(every)}")
    groups = {name: dataclasses.replace(group, roles={r: f for r, f in group.roles.items() if r not in roles})
              for name, group in config.groups.items()}
    ros = dataclasses.replace(config.ros or RosBridge(), external=frozenset(roles))
    return dataclasses.replace(config, groups={name: g for name, g in groups.items() if g.roles}, ros=ros)


def _check_terminal() -> None:
    try:
        os.close(os.open("/dev/tty", os.O_RDONLY))
    except OSError as error:
        raise TinManError(f"--teleop needs a terminal to read keys from ({error.strerror})") from None


def _dataset(given: str) -> str:
    """A recorded sequence for the camera, checked now rather than in a group process."""
    from .dataset import DatasetError, TumSequence

    try:
        TumSequence.open(given)
    except DatasetError as error:
        raise TinManError(str(error)) from None
    return str(Path(given).resolve())


def _judge(data: dict[str, Any], settings: Settings) -> tuple[bool, list[str]]:
    """Whether the run did what TinMan is for; the problems if not."""
    problems = []
    if data["violations"]:
        problems.append(counted(data["violations"], "protocol violation"))
    for name, group in data["groups"].items():
        if group["status"] == "failed" and name not in settings.inject:
            errors = [group["error"]] + [role["error"] for role in data["roles"].values() if role["group"] == name]
            first = next((error for error in errors if error), {"type": "?", "message": "see the report"})
            problems.append(f"group {name} failed: {first['type']}: {first['message']}")
        if group["status"] != "failed" and settings.inject.get(name) == "memory-hog":
            problems.append(f"group {name} was injected with {settings.inject[name]} but did not fail")
    problems.extend(f"mission failed: {failure}" for failure in data["mission"]["failures"])
    if not data["frames_processed"] and "perception" not in settings.inject:
        problems.append("visual odometry tracked no frame")
    if data["control_period_ms"].get("p50") is None and "control" not in settings.inject:
        problems.append("the control loop sent no command")
    return not problems, problems


def _lines(data: dict[str, Any], problems: list[str]) -> list[str]:
    """The printed report under the run's summary: the mission's outcome first (the summary's first
    line is the system's), then what each part of the robot did."""
    lines = [mission_line(data["mission"])]
    if data["ate_rmse_m"] is not None:
        lines.append(f"visual odometry: ATE RMSE {data['ate_rmse_m']:.3f} m over {data['trajectory_length_m']:.2f} m "
                     f"({data['ate_percent']:.2f}%), {counted(data['frames_processed'] or 0, 'frame')} tracked, "
                     f"{data['frames_dropped']} dropped")
    fused = data.get("fused") or {}  # absent from a report written before the fused pose
    if fused.get("ate_rmse_m") is not None:
        fusion = data.get("fusion") or {}
        matched = fusion.get("scan_matches")
        on_the_map = f"; {counted(matched, 'scan')} matched on the map" if isinstance(matched, int) else ""
        lines.append(f"fused pose (wheels, VO and the map, what the robot steers by): ATE RMSE "
                     f"{fused['ate_rmse_m']:.3f} m over {fused['trajectory_length_m']:.2f} m "
                     f"({fused['ate_percent']:.2f}%){on_the_map}")
    period = data["control_period_ms"]
    if period.get("p50") is not None:
        lines.append(f"control loop: period p50 {period['p50']:.1f} ms, p99 {period['p99']:.1f} ms "
                     f"over {counted(data['control']['commands'] or 0, 'command')}")
    robot = data["robot"]
    steered = fused if fused.get("final_position_error_m") is not None else data
    if steered.get("final_position_error_m") is not None and robot.get("distance_m") is not None:
        drift = steered.get("drift_per_m")  # None when the robot did not travel (e.g. turned on the spot)
        which = "fused pose" if steered is fused else "odometry"
        lines.append(f"robot (steered by the {which}): drove {robot['distance_m']:.2f} m, "
                     f"{counted(robot['waypoints_reached'], 'waypoint')} reached, "
                     f"{counted(robot['bumps'] or 0, 'bump')}; "
                     f"{which}'s final position error {steered['final_position_error_m']:.3f} m"
                     + (f" ({drift * 100:.2f} cm per metre)" if drift is not None else ""))
    control = data["control"]
    if control.get("safety_stops") is not None:
        stops, slowed, blind = control["safety_stops"], control["safety_slowed"], control.get("safety_blind") or 0
        lines.append(f"safety layer (range scan): {counted(stops, 'safety stop')}, "
                     f"{counted(slowed, 'command')} slowed near an obstacle"
                     + (f", {counted(blind, 'command')} held for want of a fresh scan" if blind else ""))
    recovery = data.get("recovery") or {}
    if data.get("vo_lost_frames") or recovery.get("recoveries"):
        times = recovery.get("time_to_recover_s") or {}
        lines.append(f"visual odometry lost track on {counted(data['vo_lost_frames'] or 0, 'frame')}: "
                     f"{counted(recovery.get('recoveries') or 0, 'recovery', 'recoveries')}"
                     + (f", time to recover p50 {times['p50']:.2f} s, max {times['max']:.2f} s"
                        if times.get("p50") is not None else "")
                     + (", still lost at the end" if recovery.get("lost_at_the_end") else "")
                     + f"; {counted(control.get('recovering_commands') or 0, 'path command')} on the wheels alone")
    if control.get("stops_for_lost_tracking"):
        lines.append(f"no fresh estimate for a while (perception slow or gone): the robot stopped "
                     f"{counted(control['stops_for_lost_tracking'], 'time')}, then drove on "
                     f"({counted(control['path_commands_after_a_stop'] or 0, 'path command')} after)")
    lost = data["control"].get("planner_lost")
    if lost:
        lines.append(f"planner lost during the run; teleop commands after that: "
                     f"{data['control']['teleop_commands_after_planner_lost']}")
    world = world_clock_line(data.get("world_clock") or {})
    if world is not None:
        lines.append(world)
    lines.extend(contract_lines(data.get("contract") or []))  # absent from a report written before the contract
    lines.append(f"protocol violations: {data['violations']}")
    lines.extend(f"problem: {problem}" for problem in problems)
    return lines


def _shown(path: Path) -> str:
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


TINMAN = TinMan()
