"""The live view: a run's channels served to the Foxglove app as it runs (``anodize run --foxglove``).

The groups tap their channels (:mod:`.tap`) and send what they tap to the supervisor,
which serves it over Foxglove's WebSocket protocol (:mod:`.server`, foxglove-sdk: the
``ros`` extra, imported only when a live view is opened). What a client publishes on a
channel's topic reaches the role that sends on it (:func:`client_input`). See
docs/recording.md, "Live view in Foxglove".
"""

from .inputs import ClientInput, client_input
from .plan import STATUS_TOPIC, LiveLabel, LivePlan, live_plan
from .server import DEFAULT_PORT, LiveView, open_live_view
from .tap import LiveTap

__all__ = ["open_live_view", "LiveView", "DEFAULT_PORT", "client_input", "ClientInput", "LivePlan", "LiveLabel",
           "live_plan", "LiveTap", "STATUS_TOPIC"]
