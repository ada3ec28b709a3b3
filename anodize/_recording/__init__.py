"""Recordings of runs (MCAP, rosbag2), and what anodize does with them: verify, replay.

:class:`Recording` is the channel tap that records a run:
``System.run(taps=[Recording("run.mcap")])``. See docs/recording.md.
"""

from .run import Recording

__all__ = ["Recording"]
