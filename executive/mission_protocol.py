"""The MAVLink mission protocol, both ends, as pure state machines (https://mavlink.io/en/services/mission.html).

No sockets and no pymavlink import: messages come in as plain values (peer,
seq, count, ``MissionItem``, ``now_s``) and every handler returns a tuple of
outgoing value objects (``RequestItem``, ``Ack``, ``Count``, ``Item``,
``RequestList``, ``StatusText``). ``encode`` turns one into a pymavlink
message with a ``MAVLink`` instance; ``dispatch`` feeds a received pymavlink
message to a ``MissionReceiver``. A peer is a ``(system, component)`` tuple.

- ``MissionReceiver``: the vehicle's side (the executive, system 1 component
  191). Upload ("Upload a Mission to the Vehicle"): MISSION_COUNT ->
  MISSION_REQUEST_INT(0..count-1) <- MISSION_ITEM_INT -> MISSION_ACK; the
  ``accept`` hook judges the whole list before anything replaces the current
  one ("Mission update must be robust!"). Download ("Download a Mission from
  the Vehicle"): MISSION_REQUEST_LIST -> MISSION_COUNT, then each
  MISSION_REQUEST_INT / legacy MISSION_REQUEST -> MISSION_ITEM_INT, so
  ``wp list`` in MAVProxy works. MISSION_CLEAR_ALL and a count of 0 clear
  ("Clear Missions"), subject to ``accept(())``.
- ``MissionSender``: the ground side of an upload (``lrauv`` uploads).
- ``MissionDownloader``: the ground side of a download.

Timeouts and retries follow "Timeouts and Retries": 1500 ms by default, 250 ms
for mission items, 5 retries, then the operation is cancelled
(MAV_MISSION_OPERATION_CANCELLED) and the machine is idle again.

Deliberate choices: an item *ahead* of the expected one is dropped and the
expected one re-requested ("Mission items must be received in order"); a
duplicate of an item already stored is dropped without a re-request (the
timeout recovers a lost request; re-requesting on every duplicate would keep
both ends sending everything twice after one loss). Legacy MISSION_ITEM
(float degrees, about 1 m resolution in float32) is accepted through
``item_from_message``; items are always sent as MISSION_ITEM_INT ("Deprecated
Types: MISSION_ITEM"). Only mission_type 0 (a flight plan) is supported:
fence and rally transfers are answered MAV_MISSION_UNSUPPORTED. MISSION_ACK
carries no text, so a refusal's reason (and a cancelled upload's) also goes out
as STATUSTEXT just before the ACK, in MAVLink 2 chunks of ``STATUSTEXT_LEN``
UTF-8 bytes (``status_chunks``).

Addressing (``addressed_to``): a target system or component of 0 is a
broadcast, so a message is ours when each target is 0 or our own id.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import IntEnum, unique
from typing import Any, Union

from planner.contract.errors import LrauvError
from planner.contract.waypoints import MAX_GOALS, MissionItem, MissionResult, to_e7

__all__ = [
    "RECEIVER_MESSAGES", "STATUSTEXT_LEN", "Ack", "Count", "Item", "Current", "MissionDownloader", "MissionReceiver",
    "MissionResult", "MissionSender", "MissionType", "Outgoing", "Peer", "RequestItem", "RequestList", "StatusText",
    "addressed_to", "dispatch", "encode", "item_from_message", "status_chunks",
]

log = logging.getLogger(__name__)

Peer = tuple[int, int]  # (system id, component id)

DEFAULT_TIMEOUT_S = 1.5  # "Timeouts and Retries": timeout (default)
ITEM_TIMEOUT_S = 0.25  # timeout (mission items)
MAX_RETRIES = 5
STATUSTEXT_LEN = 50  # STATUSTEXT.text: char[50], UTF-8 bytes; a shorter chunk ends a chunked text
MAV_SEVERITY_WARNING = 4
_INT32_MAX = 2**31 - 1


@unique
class MissionType(IntEnum):
    """MAV_MISSION_TYPE."""

    MISSION = 0
    FENCE = 1
    RALLY = 2
    ALL = 255


# Outgoing value objects: what to send, to whom. `encode` makes the MAVLink message.


@dataclass(frozen=True)
class RequestItem:
    """MISSION_REQUEST_INT: send me item ``seq``."""

    peer: Peer
    seq: int
    mission_type: int = MissionType.MISSION


@dataclass(frozen=True)
class Ack:
    """MISSION_ACK with a MAV_MISSION_RESULT."""

    peer: Peer
    result: MissionResult
    mission_type: int = MissionType.MISSION


@dataclass(frozen=True)
class Count:
    """MISSION_COUNT: starts an upload, or answers MISSION_REQUEST_LIST."""

    peer: Peer
    count: int
    mission_type: int = MissionType.MISSION


@dataclass(frozen=True)
class Item:
    """MISSION_ITEM_INT."""

    peer: Peer
    item: MissionItem


@dataclass(frozen=True)
class RequestList:
    """MISSION_REQUEST_LIST: starts a download."""

    peer: Peer
    mission_type: int = MissionType.MISSION


@dataclass(frozen=True)
class StatusText:
    """STATUSTEXT (broadcast): one chunk of at most ``STATUSTEXT_LEN`` UTF-8 bytes; ``chunk_id`` 0 means a single chunk."""

    text: str
    severity: int = MAV_SEVERITY_WARNING
    chunk_id: int = 0
    chunk_seq: int = 0


@dataclass(frozen=True)
class Current:
    """MISSION_CURRENT: the active item, the answer to MISSION_SET_CURRENT."""

    peer: Peer
    seq: int


Outgoing = Union[RequestItem, Ack, Count, Item, RequestList, StatusText, Current]


def status_chunks(text: str, *, chunk_id: int, severity: int = MAV_SEVERITY_WARNING) -> tuple[StatusText, ...]:
    """``text`` as STATUSTEXT chunks (mavlink.io STATUSTEXT ``id``/``chunk_seq``), split on its UTF-8 bytes.

    A text of at most ``STATUSTEXT_LEN`` bytes is one chunk with id 0. Otherwise every
    chunk but the last is exactly ``STATUSTEXT_LEN`` bytes and the last is shorter (an
    empty one when the text is an exact multiple): "a null character in the text field
    ... means this was the last chunk". A chunk never ends inside a character; where a
    multi-byte character would straddle the boundary it starts the next chunk and the
    chunk before it is filled up with spaces, so that it does not read as the last.
    """
    data = text.encode("utf-8")
    if len(data) <= STATUSTEXT_LEN:
        return (StatusText(text, severity),)
    parts = []
    start = 0
    while len(data) - start >= STATUSTEXT_LEN:
        end = _char_boundary(data, start + STATUSTEXT_LEN)
        parts.append(data[start:end].decode("utf-8") + " " * (start + STATUSTEXT_LEN - end))
        start = end
    parts.append(data[start:].decode("utf-8"))  # shorter than STATUSTEXT_LEN: the end (possibly empty)
    return tuple(StatusText(p, severity, chunk_id, n) for n, p in enumerate(parts))


def _char_boundary(data: bytes, end: int) -> int:
    """The largest index <= ``end`` that does not cut a UTF-8 character of ``data``."""
    while 0 < end < len(data) and data[end] & 0xC0 == 0x80:  # a continuation byte: inside a character
        end -= 1
    return end


@dataclass
class _Upload:
    peer: Peer
    count: int
    items: list[MissionItem] = field(default_factory=list)
    deadline_s: float = 0.0
    requests: int = 1  # MISSION_REQUEST_INT sent for the expected item


@dataclass(frozen=True)
class _Finished:
    peer: Peer
    count: int
    acks: tuple[Outgoing, ...]


class MissionReceiver:
    """The vehicle's side: receives uploads (judged by ``accept``) and serves downloads of the accepted list.

    ``accept(items)`` is called once with the complete list (``()`` to clear)
    and returns None to accept or a reason string to refuse with MAV_MISSION_ERROR.
    Raising ``LrauvError`` refuses with its message (and the ``result`` of a
    ``WaypointError``); any other exception refuses with MAV_MISSION_ERROR and the
    exception's text (and is logged), so a bug in the hook never breaks the protocol.
    """

    def __init__(self, accept: Callable[[tuple[MissionItem, ...]], str | None], *, items: Sequence[MissionItem] = (),
                 item_timeout_s: float = ITEM_TIMEOUT_S, retries: int = MAX_RETRIES, max_items: int = MAX_GOALS + 1,
                 serve: Callable[[], tuple[MissionItem, ...]] | None = None,
                 set_current: Callable[[int], str | None] | None = None) -> None:
        self._accept = accept
        self._serve = serve
        self._set_current = set_current
        self._items = tuple(items)
        self.item_timeout_s = item_timeout_s
        self.retries = retries
        self.max_items = max_items
        self._upload: _Upload | None = None
        self._finished: _Finished | None = None  # to answer a re-sent last item whose ACK was lost
        self._text_id = 0
        self._download: tuple[MissionItem, ...] | None = None

    @property
    def items(self) -> tuple[MissionItem, ...]:
        """The accepted list."""
        return self._items

    def served(self) -> tuple[MissionItem, ...]:
        """The list a download returns: what ``serve`` says is flown, else the accepted list."""
        return self._items if self._serve is None else self._serve()

    def on_set_current(self, peer: Peer, seq: int, now_s: float) -> tuple[Outgoing, ...]:
        """MISSION_SET_CURRENT: the active item changes, answered with MISSION_CURRENT (or refused with STATUSTEXT)."""
        if self._set_current is None:
            return self._texts(f"MISSION_SET_CURRENT {seq} refused: not supported here")
        try:
            reason = self._set_current(seq)
        except LrauvError as exc:
            reason = str(exc)
        if reason is not None:
            return self._texts(f"MISSION_SET_CURRENT {seq} refused: {reason}")
        return (Current(peer, seq),)

    def on_count(self, peer: Peer, count: int, mission_type: int, now_s: float) -> tuple[Outgoing, ...]:
        """MISSION_COUNT: start (or restart) an upload; a count of 0 clears."""
        if mission_type != MissionType.MISSION:
            return self._refuse(peer, MissionResult.UNSUPPORTED, f"mission_type {mission_type} is not supported; "
                                "only missions (0)", mission_type)
        if self._upload is not None and self._upload.peer != peer:
            return (Ack(peer, MissionResult.DENIED),)  # busy with another peer's upload
        self._upload = None
        if count > self.max_items:
            return self._refuse(peer, MissionResult.NO_SPACE, f"{count} items: at most {self.max_items}")
        if count <= 0:
            return self._finish(peer, ())
        self._finished = None
        self._upload = _Upload(peer, count, deadline_s=now_s + self.item_timeout_s)
        return (RequestItem(peer, 0),)

    def on_item(self, peer: Peer, item: MissionItem, now_s: float) -> tuple[Outgoing, ...]:
        """MISSION_ITEM_INT (or legacy MISSION_ITEM, see ``item_from_message``)."""
        up = self._upload
        if up is None or up.peer != peer:
            done = self._finished
            if up is None and done is not None and done.peer == peer and item.seq == done.count - 1:
                return done.acks  # the ACK was lost and the last item re-sent
            return ()
        if item.mission_type != MissionType.MISSION:
            return ()
        expected = len(up.items)
        if item.seq != expected:
            if item.seq > expected:  # out of sequence: drop it, re-request the expected one
                up.requests += 1
                up.deadline_s = now_s + self.item_timeout_s
                return (RequestItem(peer, expected),)
            return ()  # a duplicate of a stored item
        up.items.append(item)
        if len(up.items) == up.count:
            self._upload = None
            return self._finish(peer, tuple(up.items))
        up.requests = 1
        up.deadline_s = now_s + self.item_timeout_s
        return (RequestItem(peer, expected + 1),)

    def on_request_list(self, peer: Peer, mission_type: int, now_s: float) -> tuple[Outgoing, ...]:
        """MISSION_REQUEST_LIST: answer with the count of the accepted list."""
        if mission_type != MissionType.MISSION:
            return (Ack(peer, MissionResult.UNSUPPORTED, mission_type),)
        self._download = self.served()  # the items of one download come from one list, however the plan moves on
        return (Count(peer, len(self._download)),)

    def on_request(self, peer: Peer, seq: int, now_s: float, mission_type: int = MissionType.MISSION) -> tuple[Outgoing, ...]:
        """MISSION_REQUEST_INT or MISSION_REQUEST during a download: the item, always as MISSION_ITEM_INT."""
        if mission_type != MissionType.MISSION:
            return (Ack(peer, MissionResult.UNSUPPORTED, mission_type),)
        items = self._download if self._download is not None else self.served()
        if not 0 <= seq < len(items):
            return (Ack(peer, MissionResult.INVALID_SEQUENCE),)
        return (Item(peer, items[seq]),)

    def on_ack(self, peer: Peer, result: int, mission_type: int, now_s: float) -> tuple[Outgoing, ...]:
        """MISSION_ACK: ends a download; an error from the uploading peer cancels its upload."""
        up = self._upload
        if up is not None and up.peer == peer and result != MissionResult.ACCEPTED and mission_type == MissionType.MISSION:
            self._upload = None
        return ()

    def on_clear_all(self, peer: Peer, mission_type: int, now_s: float) -> tuple[Outgoing, ...]:
        """MISSION_CLEAR_ALL: the same as uploading an empty mission."""
        return self.on_count(peer, 0, mission_type, now_s)

    def tick(self, now_s: float) -> tuple[Outgoing, ...]:
        """Re-request the expected item after a timeout; cancel (with the reason as STATUSTEXT) after ``retries``."""
        up = self._upload
        if up is None or now_s < up.deadline_s:
            return ()
        expected = len(up.items)
        if up.requests > self.retries:
            self._upload = None
            return self._refuse(up.peer, MissionResult.OPERATION_CANCELLED, f"upload from {up.peer[0]}/{up.peer[1]} "
                                f"timed out: no item {expected} after {up.requests} requests")
        up.requests += 1
        up.deadline_s = now_s + self.item_timeout_s
        return (RequestItem(up.peer, expected),)

    def _finish(self, peer: Peer, items: tuple[MissionItem, ...]) -> tuple[Outgoing, ...]:
        result, reason = self._judge(items)
        if result == MissionResult.ACCEPTED:
            self._items = items
            acks: tuple[Outgoing, ...] = (Ack(peer, result),)
        else:
            acks = self._refuse(peer, result, reason)
        self._finished = _Finished(peer, len(items), acks)
        return acks

    def _refuse(self, peer: Peer, result: MissionResult, reason: str,
                mission_type: int = MissionType.MISSION) -> tuple[Outgoing, ...]:
        return (*self._texts(f"mission refused: {reason}"), Ack(peer, result, mission_type))

    def _texts(self, text: str) -> tuple[Outgoing, ...]:
        self._text_id = self._text_id % 65535 + 1
        return status_chunks(text, chunk_id=self._text_id)

    def _judge(self, items: tuple[MissionItem, ...]) -> tuple[MissionResult, str]:
        """``accept``'s verdict; never raises: an exception from the hook is a refusal."""
        try:
            reason = self._accept(items)
        except LrauvError as exc:
            return _refusal_result(exc), str(exc)
        except Exception as exc:  # the hook's bug must not take the protocol down
            log.warning("mission accept hook raised; refusing the mission", exc_info=True)
            return MissionResult.ERROR, f"{type(exc).__name__}: {exc}"
        if reason is None:
            return MissionResult.ACCEPTED, ""
        return MissionResult.ERROR, str(reason)


def _refusal_result(exc: LrauvError) -> MissionResult:
    """A ``WaypointError``'s own result; MAV_MISSION_ERROR for any other error (or a result that is not a refusal)."""
    try:
        result = MissionResult(getattr(exc, "result", MissionResult.ERROR))
    except (TypeError, ValueError):
        return MissionResult.ERROR
    return MissionResult.ERROR if result == MissionResult.ACCEPTED else result


class _GroundSide:
    """What both ground machines share: one message in flight, re-sent after a timeout, at most ``retries`` times.

    The first message (MISSION_COUNT, MISSION_REQUEST_LIST) waits ``timeout_s``, the
    items and their requests ``item_timeout_s``. After the last re-send times out the
    machine is done with ``error`` set.
    """

    def __init__(self, target: Peer, *, timeout_s: float = DEFAULT_TIMEOUT_S, item_timeout_s: float = ITEM_TIMEOUT_S,
                 retries: int = MAX_RETRIES) -> None:
        self.target = target
        self.timeout_s = timeout_s
        self.item_timeout_s = item_timeout_s
        self.retries = retries
        self._last: Outgoing | None = None
        self._sends = 0
        self._deadline_s = float("inf")
        self._done = False
        self._error: str | None = None

    @property
    def done(self) -> bool:
        return self._done

    @property
    def error(self) -> str | None:
        """Why the transfer failed, or None."""
        return self._error

    def tick(self, now_s: float) -> tuple[Outgoing, ...]:
        """Re-send the message in flight after its timeout; give up after ``retries`` re-sends."""
        if self._done or self._last is None or now_s < self._deadline_s:
            return ()
        if self._sends > self.retries:
            self._done = True
            self._error = f"timed out: {self._silence()}"
            return ()
        self._sends += 1
        self._deadline_s = now_s + self._timeout(self._last)
        return (self._last,)

    def _send(self, out: Outgoing, now_s: float) -> tuple[Outgoing, ...]:
        """Send ``out`` in answer to progress; only ``tick`` counts re-sends."""
        self._last, self._sends, self._deadline_s = out, 1, now_s + self._timeout(out)
        return (out,)

    def _timeout(self, out: Outgoing) -> float:
        return self.timeout_s if isinstance(out, (Count, RequestList)) else self.item_timeout_s

    def _silence(self) -> str:
        """What did not come, after how many sends (for ``error``)."""
        raise NotImplementedError


class MissionSender(_GroundSide):
    """The ground side of an upload: MISSION_COUNT, then each requested item, until MISSION_ACK.

    On a timeout the last message is re-sent (MISSION_COUNT until the first
    request, then the last item); after ``retries`` re-sends the upload fails.
    """

    def __init__(self, target: Peer, *, timeout_s: float = DEFAULT_TIMEOUT_S, item_timeout_s: float = ITEM_TIMEOUT_S,
                 retries: int = MAX_RETRIES) -> None:
        super().__init__(target, timeout_s=timeout_s, item_timeout_s=item_timeout_s, retries=retries)
        self._items: tuple[MissionItem, ...] = ()
        self._highest = -1  # highest seq requested so far
        self._result: MissionResult | None = None

    @property
    def result(self) -> MissionResult | None:
        """The vehicle's MAV_MISSION_RESULT; None while running or after a timeout."""
        return self._result

    def start(self, items: Sequence[MissionItem], now_s: float) -> tuple[Outgoing, ...]:
        """Begin an upload of ``items`` (seq 0..n-1, in order)."""
        items = tuple(items)
        for n, it in enumerate(items):
            if it.seq != n:
                raise ValueError(f"item {n} has seq {it.seq}; expected {n}")
        self._items, self._highest, self._done, self._result, self._error = items, -1, False, None, None
        return self._send(Count(self.target, len(items)), now_s)

    def on_request(self, seq: int, now_s: float, mission_type: int = MissionType.MISSION) -> tuple[Outgoing, ...]:
        """MISSION_REQUEST_INT (or MISSION_REQUEST): send that item."""
        if self._done or self._last is None or mission_type != MissionType.MISSION or not 0 <= seq < len(self._items):
            return ()
        self._highest = max(self._highest, seq)
        return self._send(Item(self.target, self._items[seq]), now_s)

    def on_ack(self, result: int, now_s: float, mission_type: int = MissionType.MISSION) -> tuple[Outgoing, ...]:
        """MISSION_ACK: the end, accepted or not."""
        if self._done or self._last is None or mission_type != MissionType.MISSION:
            return ()
        if result == MissionResult.ACCEPTED and self._highest < len(self._items) - 1:
            return ()  # a stale ACCEPTED from an earlier upload: not every item has been asked for
        self._done = True
        try:
            self._result = MissionResult(result)
        except ValueError:
            self._result = MissionResult.ERROR
        if self._result != MissionResult.ACCEPTED:
            self._error = f"{self._result.mav_name} ({self._result.description})"
        return ()

    def _silence(self) -> str:
        what = "no MISSION_REQUEST for item 0" if isinstance(self._last, Count) else (
            "no MISSION_ACK" if self._highest == len(self._items) - 1 else f"no request after item {self._highest}")
        return f"{what} after sending it {self._sends} times"


class MissionDownloader(_GroundSide):
    """The ground side of a download: MISSION_REQUEST_LIST, MISSION_COUNT, each item in order, then MISSION_ACK."""

    def __init__(self, target: Peer, *, timeout_s: float = DEFAULT_TIMEOUT_S, item_timeout_s: float = ITEM_TIMEOUT_S,
                 retries: int = MAX_RETRIES) -> None:
        super().__init__(target, timeout_s=timeout_s, item_timeout_s=item_timeout_s, retries=retries)
        self._count: int | None = None
        self._items: list[MissionItem] = []

    @property
    def items(self) -> tuple[MissionItem, ...]:
        return tuple(self._items)

    def start(self, now_s: float) -> tuple[Outgoing, ...]:
        self._count, self._items, self._done, self._error = None, [], False, None
        return self._send(RequestList(self.target), now_s)

    def on_count(self, count: int, now_s: float, mission_type: int = MissionType.MISSION) -> tuple[Outgoing, ...]:
        if self._done or self._count is not None or mission_type != MissionType.MISSION:
            return ()
        self._count = count
        return self._next(now_s)

    def on_item(self, item: MissionItem, now_s: float) -> tuple[Outgoing, ...]:
        if self._done or self._count is None or item.mission_type != MissionType.MISSION:
            return ()
        if item.seq != len(self._items):
            return self._send(RequestItem(self.target, len(self._items)), now_s) if item.seq > len(self._items) else ()
        self._items.append(item)
        return self._next(now_s)

    def on_ack(self, result: int, now_s: float, mission_type: int = MissionType.MISSION) -> tuple[Outgoing, ...]:
        if self._done or mission_type != MissionType.MISSION or result == MissionResult.ACCEPTED:
            return ()
        self._done = True
        try:
            r = MissionResult(result)
            self._error = f"{r.mav_name} ({r.description})"
        except ValueError:
            self._error = f"MISSION_ACK {result}"
        return ()

    def _next(self, now_s: float) -> tuple[Outgoing, ...]:
        assert self._count is not None
        if len(self._items) >= self._count:
            self._done = True
            return (Ack(self.target, MissionResult.ACCEPTED),)
        return self._send(RequestItem(self.target, len(self._items)), now_s)

    def _silence(self) -> str:
        what = "no MISSION_COUNT" if self._count is None else f"no item {len(self._items)}"
        return f"{what} after {self._sends} requests"


# The pymavlink edge: duck-typed messages in, messages from a `MAVLink` instance out.


def encode(mav: Any, out: Outgoing) -> Any:
    """The MAVLink message for an outgoing value object, built with ``mav`` (a pymavlink ``MAVLink``)."""
    if isinstance(out, Item):
        it, (ts, tc) = out.item, out.peer
        return mav.mission_item_int_encode(ts, tc, it.seq, it.frame, it.command, it.current, it.autocontinue,
                                           it.param1, it.param2, it.param3, it.param4, it.x_lat_e7, it.y_lon_e7,
                                           it.z, it.mission_type)
    if isinstance(out, RequestItem):
        return mav.mission_request_int_encode(*out.peer, out.seq, out.mission_type)
    if isinstance(out, Ack):
        return mav.mission_ack_encode(*out.peer, int(out.result), out.mission_type)
    if isinstance(out, Count):
        return mav.mission_count_encode(*out.peer, out.count, out.mission_type)
    if isinstance(out, RequestList):
        return mav.mission_request_list_encode(*out.peer, out.mission_type)
    if isinstance(out, Current):
        return mav.mission_current_encode(out.seq)
    if isinstance(out, StatusText):
        text = out.text.encode("utf-8")
        return mav.statustext_encode(out.severity, text[:_char_boundary(text, STATUSTEXT_LEN)], out.chunk_id,
                                     out.chunk_seq)
    raise TypeError(f"not a mission protocol message: {out!r}")


def item_from_message(msg: Any) -> MissionItem:
    """A MissionItem from MISSION_ITEM_INT, or from legacy MISSION_ITEM (float degrees, rounded to degE7).

    Never raises on the values: a legacy latitude or longitude that is not finite (or
    beyond int32 degE7) becomes INT32_MAX degE7 (214.7 degrees), out of range for both,
    so ``items_to_goals`` refuses the item (MAV_MISSION_INVALID_PARAM5_X / 6_Y).
    """
    legacy = msg.get_type() == "MISSION_ITEM"
    x = _legacy_e7(msg.x) if legacy else int(msg.x)
    y = _legacy_e7(msg.y) if legacy else int(msg.y)
    return MissionItem(int(msg.seq), int(msg.frame), int(msg.command), int(msg.current), int(msg.autocontinue),
                       float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4), x, y, float(msg.z),
                       int(getattr(msg, "mission_type", 0)))


def _legacy_e7(deg: float) -> int:
    e7 = to_e7(deg) if math.isfinite(deg) else _INT32_MAX
    return e7 if -_INT32_MAX - 1 <= e7 <= _INT32_MAX else _INT32_MAX


def addressed_to(msg: Any, system: int, component: int) -> bool:
    """Whether ``msg`` is for (``system``, ``component``): each target is 0 (broadcast) or ours.

    A message without target fields (HEARTBEAT, STATUSTEXT) is addressed to everyone.
    """
    return getattr(msg, "target_system", 0) in (0, system) and getattr(msg, "target_component", 0) in (0, component)


RECEIVER_MESSAGES = frozenset({"MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_REQUEST_LIST",
                               "MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "MISSION_CLEAR_ALL",
                               "MISSION_SET_CURRENT"})
"""The messages ``dispatch`` feeds to a ``MissionReceiver`` (legacy MISSION_ITEM and MISSION_REQUEST included)."""


def dispatch(receiver: MissionReceiver, msg: Any, now_s: float, *, system: int, component: int) -> tuple[Outgoing, ...]:
    """Feed one received pymavlink message to the receiver if it is a mission message addressed to us (or broadcast)."""
    kind = msg.get_type()
    if kind not in RECEIVER_MESSAGES or not addressed_to(msg, system, component):
        return ()
    peer = (msg.get_srcSystem(), msg.get_srcComponent())
    mission_type = int(getattr(msg, "mission_type", 0))
    if kind == "MISSION_COUNT":
        return receiver.on_count(peer, int(msg.count), mission_type, now_s)
    if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
        return receiver.on_item(peer, item_from_message(msg), now_s)
    if kind == "MISSION_REQUEST_LIST":
        return receiver.on_request_list(peer, mission_type, now_s)
    if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
        return receiver.on_request(peer, int(msg.seq), now_s, mission_type)
    if kind == "MISSION_ACK":
        return receiver.on_ack(peer, int(msg.type), mission_type, now_s)
    if kind == "MISSION_SET_CURRENT":
        return receiver.on_set_current(peer, int(msg.seq), now_s)
    return receiver.on_clear_all(peer, mission_type, now_s)
