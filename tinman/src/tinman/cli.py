"""The ``tinman`` command: evaluate visual odometry, compare trajectories, make sequences.

    tinman vo-eval DATASET [--max-frames N] [--save FILE] [--features N] [--quiet]
    tinman ate GROUNDTRUTH ESTIMATE [--offset S] [--max-difference S] [--scale F]
    tinman generate DIR [--duration S] [--world easy|realistic] [--quiet]

vo-eval and generate take a minute or more over a whole sequence: they show a
progress bar on stderr when it is a terminal (a line every 10 s in a log; none
with --quiet).

The only tinman module that prints or exits. Exit status: 0 success, 1 an error
(one line on stderr, no traceback), 2 a usage error, 70 a bug (set
``TINMAN_DEBUG=1`` for its traceback).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

import numpy as np

from . import tum
from .ate import AteResult, evaluate_ate
from .version import version_line

__all__ = ["main", "run"]

EXIT_OK, EXIT_ERRORS, EXIT_USAGE, EXIT_BUG = 0, 1, 2, 70


class CommandError(Exception):
    """Something the user asked for cannot be done (exit 1); the message is the whole story."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status."""
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse has printed the usage message
        return exit_.code if isinstance(exit_.code, int) else EXIT_USAGE
    try:
        return int(args.run(args))
    except BrokenPipeError:  # the reader went away (e.g. '| head'): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_ERRORS
    except CommandError as error:
        print(f"tinman {args.command}: error: {error}", file=sys.stderr)
        return EXIT_ERRORS
    except OSError as error:
        where = f"{error.filename}: " if error.filename else ""
        print(f"tinman {args.command}: error: {where}{error.strerror or error}", file=sys.stderr)
        return EXIT_ERRORS
    except KeyboardInterrupt:
        return 130
    except Exception as error:
        dataset = sys.modules.get("tinman.dataset")  # imported only by the commands that read images
        if dataset is not None and isinstance(error, dataset.DatasetError):
            print(f"tinman {args.command}: error: {error}", file=sys.stderr)
            return EXIT_ERRORS
        if os.environ.get("TINMAN_DEBUG"):
            raise
        print(f"tinman: internal error: {type(error).__name__}: {error} "
              "(set TINMAN_DEBUG=1 for a traceback, and please report it)", file=sys.stderr)
        return EXIT_BUG


def run() -> NoReturn:
    """The console script's entry point."""
    sys.exit(main())


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tinman", description=(
        "TinMan's tools: run RGB-D visual odometry over a TUM sequence, evaluate "
        "trajectories as the TUM benchmark does, and write synthetic sequences."))
    parser.add_argument("--version", action="version", version=version_line())
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    vo_eval = commands.add_parser(
        "vo-eval", help="run visual odometry over a TUM RGB-D sequence and print its ATE",
        description="Run visual odometry over a TUM RGB-D sequence (a real one or a synthetic one) "
                    "and print the absolute trajectory error against its groundtruth.txt.")
    vo_eval.add_argument("dataset", metavar="DATASET", help="the sequence's directory (with rgb.txt, depth.txt)")
    vo_eval.add_argument("--max-frames", type=_positive_int, metavar="N", help="use only the first N frames")
    vo_eval.add_argument("--save", type=Path, metavar="FILE",
                         help="write the estimated trajectory (TUM format: t tx ty tz qx qy qz qw)")
    vo_eval.add_argument("--features", type=_positive_int, default=1000, metavar="N",
                         help="ORB features per frame (default 1000)")
    vo_eval.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    vo_eval.set_defaults(run=_vo_eval)

    ate = commands.add_parser(
        "ate", help="absolute trajectory error of an estimate, as the TUM benchmark's evaluate_ate.py",
        description="Associate the two trajectories' stamps, align the estimate to the ground truth "
                    "(Horn's method, no scale) and print the translational error statistics.")
    ate.add_argument("groundtruth", metavar="GROUNDTRUTH", help="TUM trajectory file (t tx ty tz qx qy qz qw)")
    ate.add_argument("estimate", metavar="ESTIMATE", help="TUM trajectory file of the estimate")
    ate.add_argument("--offset", type=float, default=0.0, metavar="S",
                     help="time offset added to the estimate's stamps (default 0)")
    ate.add_argument("--max-difference", type=float, default=0.02, metavar="S",
                     help="largest stamp difference that still matches (default 0.02 s)")
    ate.add_argument("--scale", type=float, default=1.0, metavar="F",
                     help="scale applied to the estimate's positions (default 1)")
    ate.set_defaults(run=_ate)

    generate = commands.add_parser(
        "generate", help="write a synthetic TUM RGB-D sequence of TinMan's mission",
        description="Render the default mission in the default room and write it as a TUM RGB-D "
                    "sequence (rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt).")
    generate.add_argument("directory", metavar="DIR", help="where to write the sequence")
    generate.add_argument("--duration", type=_positive_float, default=30.0, metavar="S",
                          help="seconds of mission (default 30)")
    generate.add_argument("--world", choices=("easy", "realistic"), default=None,
                          help="the room's look: easy (procedural textures, the default) or realistic "
                               "(photographs, plain walls, repeated patterns, flickering lamps, motion blur)")
    generate.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    generate.set_defaults(run=_generate)
    return parser


# ---- commands -----------------------------------------------------------------------------

def _vo_eval(args: argparse.Namespace) -> int:
    from .dataset import TumSequence  # here, so 'tinman ate' needs no image reading
    from .progress import FrameProgress
    from .vo import run_sequence

    sequence = TumSequence.open(args.dataset)
    if len(sequence) == 0:
        raise CommandError(f"{args.dataset}: no frames (rgb.txt and depth.txt have no stamps in common)")
    with FrameProgress("visual odometry", sys.stderr, enabled=not args.quiet) as progress:
        result = run_sequence(sequence, max_frames=args.max_frames, features=args.features, progress=progress)
    frames = len(result.stats)
    ms = np.array([s.ms for s in result.stats])
    print(f"frames          {frames} ({result.failures} failed, {_count(result.keyframes, 'keyframe')})")
    print(f"speed           {result.fps:.1f} fps (median {np.median(ms):.1f} ms per frame, "
          f"max {ms.max():.1f} ms; reading images not counted)")
    if args.save is not None:
        tum.write_trajectory(args.save, result.stamps, result.poses,
                             comment=f"tinman vo-eval {args.dataset} ({frames} frames)")
        print(f"saved           {args.save}")
    truth = sequence.groundtruth
    if truth is None:
        print("ATE             no groundtruth.txt in the sequence")
        return EXIT_OK
    _print_ate(_evaluate(truth, (result.stamps, result.poses)))
    return EXIT_OK


def _ate(args: argparse.Namespace) -> int:
    truth = _trajectory(args.groundtruth)
    estimate = _trajectory(args.estimate)
    _print_ate(_evaluate(truth, estimate, offset=args.offset, max_difference=args.max_difference,
                         scale=args.scale))
    return EXIT_OK


def _generate(args: argparse.Namespace) -> int:
    try:
        from . import sequences
    except ImportError as error:
        raise CommandError(f"synthetic sequences are not available in this build ({error})") from None
    from .progress import FrameProgress

    options = {} if args.world is None else {"look": args.world}
    with FrameProgress("rendering", sys.stderr, enabled=not args.quiet) as progress:
        path = sequences.generate(Path(args.directory), duration=args.duration, progress=progress, **options)
    print(f"wrote {path}")
    return EXIT_OK


def _print_ate(result: AteResult) -> None:
    # The quantities and names evaluate_ate.py --verbose prints, then the length and ratio.
    print(f"pairs           {result.pairs}")
    print(f"ATE RMSE        {result.rmse:.4f} m")
    print(f"ATE mean        {result.mean:.4f} m")
    print(f"ATE median      {result.median:.4f} m")
    print(f"ATE std         {result.std:.4f} m")
    print(f"ATE min         {result.min:.4f} m")
    print(f"ATE max         {result.max:.4f} m")
    print(f"length          {result.length:.3f} m")
    print(f"ATE / length    {result.percent:.2f} %")


# ---- helpers ------------------------------------------------------------------------------

def _count(number: int, noun: str) -> str:
    return f"{number} {noun}{'' if number == 1 else 's'}"


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1, got {value}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text}")
    return value


def _trajectory(path: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        return tum.read_trajectory(path)
    except ValueError as error:  # the message names the file and the line
        raise CommandError(str(error)) from None


def _evaluate(truth: tuple[np.ndarray, np.ndarray], estimate: tuple[np.ndarray, np.ndarray],
              **options: float) -> AteResult:
    try:
        return evaluate_ate(truth[0], truth[1][:, :3, 3], estimate[0], estimate[1][:, :3, 3], **options)
    except ValueError as error:  # too few stamps match
        raise CommandError(str(error)) from None
