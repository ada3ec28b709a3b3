"""Transports: how messages travel between roles.

A transport provides one FIFO channel per ordered pair of roles that the
global type connects, and a way to tell every receiver that a peer failed or
that the run is stopping. ``inproc`` (threads of one process) is the first.
"""
