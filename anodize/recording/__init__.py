"""Recordings of runs (MCAP, rosbag2), and what anodize does with them: verify, replay.

See docs/recording.md.
"""
