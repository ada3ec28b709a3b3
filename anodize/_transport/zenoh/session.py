"""One group's Zenoh session: opened with the run's configuration, its liveliness token
declared, the run's tokens watched (:mod:`.peers`)."""

from __future__ import annotations

from collections.abc import Callable

from ..links import StartBarrierError
from ..started import since_process_start
from .binding import LivelinessToken, Session, ZError, close, open_session, reason, token
from .peers import Peers
from .settings import ZenohSettings, session_config, tls_hint

__all__ = ["GroupSession"]


class GroupSession:
    """The Zenoh session of one group's process.

    Args:
        settings: the run's Zenoh settings (``host`` is this group's host).
        name, incarnation: this group.
        report: called with a line for the group's report.

    Raises:
        StartBarrierError: the session could not be opened (a client whose routers did not answer
            within the wait, an endpoint that cannot be listened on).
    """

    def __init__(self, settings: ZenohSettings, name: str, incarnation: int,
                 report: Callable[[str], None] = lambda line: None) -> None:
        self.settings = settings
        self.name = name
        self.incarnation = incarnation
        self.report = report
        # A token gone for this long is a failed peer: Zenoh drops a dead session's tokens
        # within about a lease; the outage allowed on top lets a router restart be ridden through.
        self.grace = settings.lease + settings.outage
        config = session_config(settings)
        left = max(0.1, settings.wait - since_process_start())  # --wait bounds the group's whole start
        if settings.mode == "client":  # its routers must answer within what is left of the wait
            config["connect"]["timeout_ms"] = int(left * 1000)
        try:
            self.session: Session = open_session(config)
        except ZError as error:
            where = ", ".join(settings.connect) or "peers found by scouting"
            answer = (f"no router answered within the wait ({settings.wait:g} s from the group's start)"
                      if settings.mode == "client" else reason(error))
            listening = ", ".join(settings.listen) or ("none" if settings.tls is not None else "default")
            raise StartBarrierError(f"group {name}: cannot open a Zenoh session in {settings.mode} mode "
                                    f"(connect {where}; listen {listening}): {answer}: is the router running, "
                                    f"and reachable from host {settings.host}{tls_hint(settings) or '?'}") from None
        self.peers = Peers(self.session, settings)
        self._tokens: list[LivelinessToken] = [token(self.session, settings.alive_key(name, incarnation,
                                                                                      settings.host))]

    def declare(self, key: str) -> LivelinessToken:
        """Declare a liveliness token of this session (the end of a channel)."""
        declared = token(self.session, key)
        self._tokens.append(declared)
        return declared

    def close(self) -> None:
        """Close the session: its tokens vanish for everyone at once."""
        self.peers.close()
        close(self.session)
