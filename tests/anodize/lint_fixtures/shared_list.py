"""Two roles use one module-level list: a channel the protocol does not know about."""

import threading  # an imported module is not state

buffer = []
LIMIT = 10


def producer(ep):
    for i in range(LIMIT):
        buffer.append(i)
        ep.send("C", "data", i)
    ep.send("C", "stop")


def consumer(ep):
    while ep.recv("P").label == "data":
        if buffer:
            threading.current_thread()
