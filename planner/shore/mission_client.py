"""Upload goals to, and download them from, the executive over a pymavlink connection (mavlink.io Mission Protocol).

The protocol itself is ``executive.mission_protocol``'s pure state machines;
this module only moves their messages through ``conn`` (a
``mavutil.mavlink_connection``) and keeps time with ``time.monotonic``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from executive.mavlink_bridge import EXECUTIVE_COMPONENT, EXECUTIVE_SYSTEM
from executive.mission_protocol import (
    DEFAULT_TIMEOUT_S,
    ITEM_TIMEOUT_S,
    MAX_RETRIES,
    STATUSTEXT_LEN,
    MissionDownloader,
    MissionSender,
    Outgoing,
    addressed_to,
    encode,
    item_from_message,
)
from planner.contract.errors import ShoreError
from planner.contract.waypoints import MissionItem, MissionResult

_POLL_S = 0.02
_LINGER_S = 0.1  # after a refusal, how long to wait for the STATUSTEXT that says why

_Handler = Callable[[Any, float], tuple[Outgoing, ...]]


class MissionTransferError(ShoreError):
    """A mission transfer that failed; ``result`` is the vehicle's MAV_MISSION_RESULT (None on a timeout)."""

    def __init__(self, message: str, result: MissionResult | None = None, reason: str = "") -> None:
        super().__init__(message)
        self.result = result
        self.reason = reason


class MissionUploadError(MissionTransferError):
    """The vehicle refused the upload, or did not answer."""


class MissionDownloadError(MissionTransferError):
    """The vehicle refused the download, or did not answer."""


class StatusTexts:
    """STATUSTEXT from the target, chunks (MAVLink 2 ``id``/``chunk_seq``) joined.

    Chunks are joined as UTF-8 bytes; a chunk shorter than ``STATUSTEXT_LEN`` bytes is
    the last ("a null character in the text field ... means this was the last chunk").
    """

    def __init__(self) -> None:
        self.lines: list[str] = []
        self._chunks: dict[int, dict[int, bytes]] = {}

    def add(self, msg: Any) -> None:
        data = _text_bytes(msg)
        chunk_id = int(getattr(msg, "id", 0))
        if chunk_id == 0:
            self.lines.append(data.decode("utf-8", "replace"))
            return
        parts = self._chunks.setdefault(chunk_id, {})
        parts[int(getattr(msg, "chunk_seq", 0))] = data
        if len(data) < STATUSTEXT_LEN:  # the last chunk
            self.lines.append(b"".join(parts[k] for k in sorted(parts)).decode("utf-8", "replace"))
            del self._chunks[chunk_id]

    def reason(self, prefix: str = "mission refused: ") -> str:
        """The last text that starts with ``prefix``, without it; "" when none came."""
        refusals = [t.removeprefix(prefix) for t in self.lines if t.startswith(prefix)]
        return refusals[-1] if refusals else ""


def _text_bytes(msg: Any) -> bytes:
    """STATUSTEXT.text as the bytes sent, up to the first NUL.

    pymavlink keeps the raw field as ``_text_raw`` and decodes ``text`` as ASCII (every
    other byte becomes U+FFFD), so the raw field is the one to join and decode as UTF-8.
    """
    raw = getattr(msg, "_text_raw", None)
    if not isinstance(raw, (bytes, bytearray)):
        raw = msg.text if isinstance(msg.text, (bytes, bytearray)) else str(msg.text).encode("utf-8")
    return bytes(raw).split(b"\0", 1)[0]


def _send(conn: Any, outs: tuple[Outgoing, ...]) -> None:
    for out in outs:
        conn.mav.send(encode(conn.mav, out))


def _from_target(msg: Any, target: tuple[int, int], me: tuple[int, int]) -> bool:
    return (msg.get_srcSystem(), msg.get_srcComponent()) == target and addressed_to(msg, *me)


def _transfer(conn: Any, machine: MissionSender | MissionDownloader, start: Callable[[float], tuple[Outgoing, ...]],
              handlers: dict[str, _Handler], target: tuple[int, int]) -> None:
    """Drive ``machine`` until it is done: messages from ``target`` go to ``handlers`` by type, ticks re-send.

    No overall deadline: the machine ends itself (done, with ``error`` after its
    retries), so a long transfer that keeps progressing is never cut short.
    """
    me = (conn.mav.srcSystem, conn.mav.srcComponent)
    _send(conn, start(time.monotonic()))
    while not machine.done:
        msg = conn.recv_match(blocking=True, timeout=_POLL_S)
        now = time.monotonic()
        outs: tuple[Outgoing, ...] = ()
        handler = None if msg is None else handlers.get(msg.get_type())
        if handler is not None and _from_target(msg, target, me):
            outs = handler(msg, now)
        _send(conn, outs + machine.tick(now))


def _mission_type(msg: Any) -> int:
    return int(getattr(msg, "mission_type", 0))


def upload_goals(conn: Any, items: Sequence[MissionItem], *, target_system: int = EXECUTIVE_SYSTEM,
                 target_component: int = EXECUTIVE_COMPONENT, count_timeout_s: float = DEFAULT_TIMEOUT_S,
                 item_timeout_s: float = ITEM_TIMEOUT_S, retries: int = MAX_RETRIES) -> None:
    """Upload ``items`` (``goals_to_items``) to the executive; MissionUploadError names the result and the reason.

    Each message waits ``count_timeout_s`` (MISSION_COUNT) or ``item_timeout_s`` (an
    item) for its answer and is re-sent at most ``retries`` times; there is no overall
    deadline, so a long upload that keeps progressing is never cut off.
    """
    target = (target_system, target_component)
    sender = MissionSender(target, timeout_s=count_timeout_s, item_timeout_s=item_timeout_s, retries=retries)
    texts = StatusTexts()

    def status(msg: Any, _now: float) -> tuple[Outgoing, ...]:
        texts.add(msg)
        return ()

    request: _Handler = lambda msg, now: sender.on_request(int(msg.seq), now, _mission_type(msg))  # noqa: E731
    _transfer(conn, sender, lambda now: sender.start(items, now), {
        "MISSION_REQUEST_INT": request,
        "MISSION_REQUEST": request,
        "MISSION_ACK": lambda msg, now: sender.on_ack(int(msg.type), now, _mission_type(msg)),
        "STATUSTEXT": status,
    }, target)
    if sender.result == MissionResult.ACCEPTED:
        return
    if sender.result is None:
        raise MissionUploadError(f"upload to system {target_system} component {target_component}: {sender.error}")
    linger(conn, texts, target, (conn.mav.srcSystem, conn.mav.srcComponent))
    reason = texts.reason()
    raise MissionUploadError(
        f"system {target_system} component {target_component} refused the mission: {sender.error}"
        + (f": {reason}" if reason else ""), sender.result, reason)


def linger(conn: Any, texts: StatusTexts, target: tuple[int, int], me: tuple[int, int],
           prefix: str = "mission refused: ") -> None:
    """Read what is already on its way (the STATUSTEXT sent just before the ACK may come late)."""
    end = time.monotonic() + _LINGER_S
    while time.monotonic() < end and not texts.reason(prefix):
        msg = conn.recv_match(type="STATUSTEXT", blocking=True, timeout=_POLL_S)
        if msg is not None and _from_target(msg, target, me):
            texts.add(msg)


def download_items(conn: Any, *, target_system: int = EXECUTIVE_SYSTEM, target_component: int = EXECUTIVE_COMPONENT,
                   count_timeout_s: float = DEFAULT_TIMEOUT_S, item_timeout_s: float = ITEM_TIMEOUT_S,
                   retries: int = MAX_RETRIES) -> tuple[MissionItem, ...]:
    """The executive's current mission items (item 0 is home); MissionDownloadError on refusal or timeout."""
    target = (target_system, target_component)
    fetch = MissionDownloader(target, timeout_s=count_timeout_s, item_timeout_s=item_timeout_s, retries=retries)
    item: _Handler = lambda msg, now: fetch.on_item(item_from_message(msg), now)  # noqa: E731
    _transfer(conn, fetch, fetch.start, {
        "MISSION_COUNT": lambda msg, now: fetch.on_count(int(msg.count), now, _mission_type(msg)),
        "MISSION_ITEM_INT": item,
        "MISSION_ITEM": item,
        "MISSION_ACK": lambda msg, now: fetch.on_ack(int(msg.type), now, _mission_type(msg)),
    }, target)
    if fetch.error is not None:
        raise MissionDownloadError(f"download from system {target_system} component {target_component}: {fetch.error}")
    return fetch.items
