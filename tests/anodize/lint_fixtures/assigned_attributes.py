"""Attributes assigned by one role and read by another: a class's and a user module's."""

import postbox


class Tuning:
    speed = 1  # a constant until a role assigns it


def producer(ep):
    Tuning.speed = 2
    postbox.flag = True
    ep.send("C", "stop")


def consumer(ep):
    ep.recv("P")
    return Tuning.speed, postbox.flag, postbox.totals
