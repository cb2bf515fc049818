"""Upload goals to, and download them from, the executive over a pymavlink connection (mavlink.io Mission Protocol).

The protocol itself is ``executive.mission_protocol``'s pure state machines;
this module only moves their messages through ``conn`` (a
``mavutil.mavlink_connection``) and keeps time with ``time.monotonic``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from executive.mission_protocol import (
    DEFAULT_TIMEOUT_S,
    ITEM_TIMEOUT_S,
    MAX_RETRIES,
    MissionDownloader,
    MissionSender,
    Outgoing,
    encode,
    item_from_message,
)
from planner.errors import PlannerError
from planner.waypoints import MissionItem, MissionResult

EXECUTIVE_SYSTEM = 1
EXECUTIVE_COMPONENT = 191  # MAV_COMP_ID_ONBOARD_COMPUTER
_POLL_S = 0.02
_LINGER_S = 0.1  # after a refusal, how long to wait for the STATUSTEXT that says why


class MissionTransferError(PlannerError):
    """A mission transfer that failed; ``result`` is the vehicle's MAV_MISSION_RESULT (None on a timeout)."""

    def __init__(self, message: str, result: MissionResult | None = None, reason: str = "") -> None:
        super().__init__(message)
        self.result = result
        self.reason = reason


class MissionUploadError(MissionTransferError):
    """The vehicle refused the upload, or did not answer."""


class MissionDownloadError(MissionTransferError):
    """The vehicle refused the download, or did not answer."""


class _Texts:
    """STATUSTEXT from the target, chunks (MAVLink 2 ``id``/``chunk_seq``) joined."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self._chunks: dict[int, dict[int, str]] = {}

    def add(self, msg: Any) -> None:
        text = msg.text if isinstance(msg.text, str) else msg.text.decode("utf-8", "replace")
        text = text.rstrip("\x00")
        chunk_id = int(getattr(msg, "id", 0))
        if chunk_id == 0:
            self.lines.append(text)
            return
        parts = self._chunks.setdefault(chunk_id, {})
        parts[int(getattr(msg, "chunk_seq", 0))] = text
        if len(text) < 50:  # the last chunk
            self.lines.append("".join(parts[k] for k in sorted(parts)))
            del self._chunks[chunk_id]

    def reason(self) -> str:
        refusals = [t.removeprefix("mission refused: ") for t in self.lines if t.startswith("mission refused: ")]
        return refusals[-1] if refusals else ""


def _send(conn: Any, outs: tuple[Outgoing, ...]) -> None:
    for out in outs:
        conn.mav.send(encode(conn.mav, out))


def _from_target(msg: Any, target: tuple[int, int], me: tuple[int, int]) -> bool:
    if (msg.get_srcSystem(), msg.get_srcComponent()) != target:
        return False
    ts = getattr(msg, "target_system", None)
    return ts is None or (ts in (0, me[0]) and getattr(msg, "target_component", 0) in (0, me[1]))


def upload_goals(conn: Any, items: Sequence[MissionItem], *, target_system: int = EXECUTIVE_SYSTEM,
                 target_component: int = EXECUTIVE_COMPONENT, timeout_s: float = 10.0,
                 count_timeout_s: float = DEFAULT_TIMEOUT_S, item_timeout_s: float = ITEM_TIMEOUT_S,
                 retries: int = MAX_RETRIES) -> None:
    """Upload ``items`` (``goals_to_items``) to the executive; MissionUploadError names the result and the reason."""
    target = (target_system, target_component)
    me = (conn.mav.srcSystem, conn.mav.srcComponent)
    sender = MissionSender(target, timeout_s=count_timeout_s, item_timeout_s=item_timeout_s, retries=retries)
    texts = _Texts()
    start = time.monotonic()
    _send(conn, sender.start(items, start))
    while not sender.done:
        now = time.monotonic()
        if now - start > timeout_s:
            raise MissionUploadError(f"upload to system {target_system} component {target_component}: "
                                     f"no MISSION_ACK within {timeout_s:g} s")
        msg = conn.recv_match(blocking=True, timeout=_POLL_S)
        now = time.monotonic()
        outs: tuple[Outgoing, ...] = ()
        if msg is not None and msg.get_type() != "BAD_DATA" and _from_target(msg, target, me):
            kind = msg.get_type()
            if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                outs = sender.on_request(int(msg.seq), now, int(getattr(msg, "mission_type", 0)))
            elif kind == "MISSION_ACK":
                outs = sender.on_ack(int(msg.type), now, int(getattr(msg, "mission_type", 0)))
            elif kind == "STATUSTEXT":
                texts.add(msg)
        _send(conn, outs + sender.tick(now))
    if sender.result == MissionResult.ACCEPTED:
        return
    if sender.result is None:
        raise MissionUploadError(f"upload to system {target_system} component {target_component}: {sender.error}")
    _linger(conn, texts, target, me)
    reason = texts.reason()
    raise MissionUploadError(
        f"system {target_system} component {target_component} refused the mission: {sender.error}"
        + (f": {reason}" if reason else ""), sender.result, reason)


def _linger(conn: Any, texts: _Texts, target: tuple[int, int], me: tuple[int, int]) -> None:
    """Read what is already on its way (the STATUSTEXT sent just before the ACK may come late)."""
    end = time.monotonic() + _LINGER_S
    while time.monotonic() < end and not texts.reason():
        msg = conn.recv_match(type="STATUSTEXT", blocking=True, timeout=_POLL_S)
        if msg is not None and _from_target(msg, target, me):
            texts.add(msg)


def download_items(conn: Any, *, target_system: int = EXECUTIVE_SYSTEM, target_component: int = EXECUTIVE_COMPONENT,
                   timeout_s: float = 10.0, count_timeout_s: float = DEFAULT_TIMEOUT_S,
                   item_timeout_s: float = ITEM_TIMEOUT_S, retries: int = MAX_RETRIES) -> tuple[MissionItem, ...]:
    """The executive's current mission items (item 0 is home); MissionDownloadError on refusal or timeout."""
    target = (target_system, target_component)
    me = (conn.mav.srcSystem, conn.mav.srcComponent)
    fetch = MissionDownloader(target, timeout_s=count_timeout_s, item_timeout_s=item_timeout_s, retries=retries)
    start = time.monotonic()
    _send(conn, fetch.start(start))
    while not fetch.done:
        now = time.monotonic()
        if now - start > timeout_s:
            raise MissionDownloadError(f"download from system {target_system} component {target_component}: "
                                       f"not complete within {timeout_s:g} s")
        msg = conn.recv_match(blocking=True, timeout=_POLL_S)
        now = time.monotonic()
        outs: tuple[Outgoing, ...] = ()
        if msg is not None and msg.get_type() != "BAD_DATA" and _from_target(msg, target, me):
            kind = msg.get_type()
            if kind == "MISSION_COUNT":
                outs = fetch.on_count(int(msg.count), now, int(getattr(msg, "mission_type", 0)))
            elif kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
                outs = fetch.on_item(item_from_message(msg), now)
            elif kind == "MISSION_ACK":
                outs = fetch.on_ack(int(msg.type), now, int(getattr(msg, "mission_type", 0)))
        _send(conn, outs + fetch.tick(now))
    if fetch.error is not None:
        raise MissionDownloadError(f"download from system {target_system} component {target_component}: {fetch.error}")
    return fetch.items
