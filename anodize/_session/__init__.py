"""What a role holds: its monitored endpoint, the monitor, payload checks, typed states.

The endpoint steps the role's state machine on every send and receive; the
channels beneath it come from a transport through the small interface of
:mod:`.channel`.
"""

from .endpoint import Endpoint, Message
from .monitor import TIMEOUT, Monitor
from .statistics import EndpointStatistics
from .typed import State

__all__ = ["TIMEOUT", "Endpoint", "EndpointStatistics", "Message", "Monitor", "State"]
