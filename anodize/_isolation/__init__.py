"""What keeps groups apart on one machine: priorities and CPU sets (:mod:`.sched`),
memory bounds and accounting (:mod:`.memory`), and the real-time watchdog
(:mod:`.watchdog`) that demotes a SCHED_FIFO group before it can starve the rest.
"""
