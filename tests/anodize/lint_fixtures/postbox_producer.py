"""Writes to the postbox module's queue; its role function is re-exported by postbox_roles."""

from postbox import MAILBOX, totals


def producer(ep):
    MAILBOX.put("behind the protocol's back")
    totals["sent"] += 1
    ep.send("C", "stop")
