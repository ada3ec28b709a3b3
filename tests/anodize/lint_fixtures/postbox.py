"""State kept in a module of its own and imported by two role modules."""

import queue

MAILBOX = queue.SimpleQueue()
totals = {"sent": 0}
