"""The command-line options that compose a system file: ``-p``, ``-r`` and ``--namespace``.

Shared by ``anodize run FILE`` and the named systems that take them (``anodize run tinman``):
each gives what :meth:`SystemConfig.with_overrides` takes, as ``ros2 run ... --ros-args``
gives ``-p name:=value`` and ``-r from:=to``.
"""

from __future__ import annotations

import argparse

__all__ = ["add_composition_arguments"]


def add_composition_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``-p/--param``, ``-r/--remap`` and ``--namespace`` to ``parser`` (``args.param``,
    ``args.remap``: lists; ``args.namespace``: str or None)."""
    parser.add_argument("-p", "--param", action="append", default=[], metavar="ROLE.NAME=VALUE",
                        help="set a role's parameter (repeatable); VALUE is TOML: 0.3, true, '\"text\"', [1, 2] "
                             "(overrides the file's [params.ROLE])")
    parser.add_argument("-r", "--remap", action="append", default=[], metavar="FROM:=TO",
                        help="rename a ROS topic (repeatable), as ros2 --remap: /cmd_vel:=/r1/cmd_vel")
    parser.add_argument("--namespace", metavar="NS",
                        help="the system's ROS namespace (e.g. /robot1): its relative topic names go under it "
                             "(overrides the file's [ros] namespace)")
