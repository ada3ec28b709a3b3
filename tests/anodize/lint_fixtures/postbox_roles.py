"""The consumer reads the postbox through the module; the producer is imported."""

import postbox
from postbox_producer import producer  # noqa: F401  (a role: 'postbox_roles:producer')


def consumer(ep):
    ep.recv("P")
    return postbox.MAILBOX.get()
