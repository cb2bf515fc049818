"""Uploads addressed to the executive: goals by the mission protocol, files by MAVLink FTP.

This is the only place that knows which messages belong to which service. It routes
each message addressed to us (system 1, component 191, or broadcast) to the protocol's
state machine (``executive.mission_protocol``, ``executive.ftp``) and encodes the replies
for the link the request came on. What to do with a finished upload is the loop's
business: the two ``accept`` hooks return None to take it or a reason to refuse it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from executive import mavlink_bridge as bridge
from executive import mission_protocol as mp
from executive.ftp import FtpServer
from planner.contract.errors import LrauvError
from planner.contract.mission import items_to_goals

class Uploads:
    """Mission-protocol and FTP servers behind one ``handle``; replies go back on the caller's link."""

    MESSAGES = mp.RECEIVER_MESSAGES | {"FILE_TRANSFER_PROTOCOL"}

    def __init__(self, *, accept_goals: Callable[[tuple[Any, ...]], str | None],
                 accept_file: Callable[[str, bytes], str | None], refused: Callable[[str, str], object]) -> None:
        self._accept_goals = accept_goals
        self._refused = refused
        self.ftp = FtpServer(accept=accept_file)
        self.missions = mp.MissionReceiver(accept=self._accept_items)
        self._mav: Any = None  # the link of the last mission-protocol peer, for retries

    def _accept_items(self, items: tuple[mp.MissionItem, ...]) -> str | None:
        try:
            goals = items_to_goals(items)
        except LrauvError as exc:  # the protocol answers with the error's own MAV_MISSION_RESULT
            self._refused("mission", str(exc))
            raise
        return self._accept_goals(goals)

    def handle(self, msg: Any, mav: Any, wall_s: float) -> list[Any]:
        """Replies (encoded with ``mav``) to one message; [] when it is not for us."""
        kind = msg.get_type()
        if kind == "FILE_TRANSFER_PROTOCOL":
            if not mp.addressed_to(msg, bridge.EXECUTIVE_SYSTEM, bridge.EXECUTIVE_COMPONENT):
                return []
            peer = (msg.get_srcSystem(), msg.get_srcComponent())
            reply = self.ftp.handle(bytes(msg.payload))
            if reply is None:
                return []
            return [mav.file_transfer_protocol_encode(0, peer[0], peer[1], reply)]
        outs = mp.dispatch(self.missions, msg, wall_s, system=bridge.EXECUTIVE_SYSTEM,
                           component=bridge.EXECUTIVE_COMPONENT)
        if outs:
            self._mav = mav
        return [mp.encode(mav, out) for out in outs]

    def tick(self, wall_s: float) -> list[tuple[Any, Any]]:
        """(link, message) pairs due by time: mission-protocol re-requests and give-ups."""
        if self._mav is None:
            return []
        return [(self._mav, mp.encode(self._mav, out)) for out in self.missions.tick(wall_s)]

