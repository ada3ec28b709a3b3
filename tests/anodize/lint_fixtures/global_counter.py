"""A counter rebound with 'global' by one role and read by another."""

count = 0


def producer(ep):
    global count
    count += 1
    ep.send("C", "stop")


def consumer(ep):
    ep.recv("P")
    return count
