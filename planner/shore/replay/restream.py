"""A logged dive sent again as live MAVLink 2, paced by its log time, so a ground station can watch it.

What goes out: everything the autopilot sent (``/mavlink/rx`` from component 1:
HEARTBEAT, GLOBAL_POSITION_INT, ATTITUDE, VFR_HUD, SYS_STATUS, BATTERY_STATUS,
SYSTEM_TIME, STATUSTEXT, ...) and, unless told not to, the executive's own
HEARTBEAT and STATUSTEXT (``/mavlink/tx`` from component 191), never its
commands (a ground station could route them on to a real vehicle). Each message
is rebuilt from its logged fields (``rebuild``, the inverse of
``mavlink_bridge.describe``) and sent with its original system and component
ids, one sequence counter per source, so the ground station sees the vehicle
as it was.

Pacing: a message at log time t goes out at start + (t - t0) / speed. Log times
are vehicle time and not monotonic in file order: messages without
``time_boot_ms`` are logged at the executive's extrapolated clock, which runs
ahead by seconds at high simulator speedups (up to 8 s in the demo log at
1000x), and an autopilot reboot starts them again near zero. So the pace
follows the newest time seen; a message behind it goes at once, and only a
step back of more than ``_REBOOT_BACKSTEP_S`` restarts the pace from there.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from executive import mavlink_bridge as bridge
from planner.shore.replay.divelog import DiveLog, LogMessage
from planner.shore.replay.payloads import mavlink_value
from executive.recorder import LogError, Topic

__all__ = ["RestreamResult", "rebuild", "restream"]

mavlink = bridge.mavlink  # the ardupilotmega dialect, MAVLink 2 framing

# The executive's messages a ground station should see; commands and protocol replies stay out.
_EXECUTIVE_MESSAGES = frozenset({"HEARTBEAT", "STATUSTEXT"})
# Larger than the clock extrapolation's overshoot in a log (8 s seen), far smaller than a dive.
_REBOOT_BACKSTEP_S = 60.0
# The executive's clock reads exactly 0 before the first time_boot_ms: no vehicle time to pace by.
_UNSYNCED_S = 0.0


@dataclass(frozen=True, kw_only=True)
class RestreamResult:
    """What ``restream`` sent."""

    messages_sent: int
    skipped: Mapping[str, int]  # messages that could not be rebuilt, by name
    vehicle_s: float  # log time covered by what was sent (steps back not counted)
    wall_s: float


def restream(log: DiveLog, address: str, *, speed: float = 10.0, stop: threading.Event | None = None,
             on_message: Callable[[LogMessage], None] | None = None, executive: bool = True) -> RestreamResult:
    """Send ``log``'s telemetry to ``address``, a pymavlink address to send to (``udpout:HOST:PORT``, ``tcp:``).

    ``speed`` is vehicle seconds per wall second; ``stop`` ends the stream early
    (also during a wait); ``on_message`` is called after each message sent;
    ``executive=False`` leaves out the executive's own heartbeat and status text.
    Raises ``LogError`` for a bad speed or an address that cannot be opened.
    """
    if isinstance(speed, bool) or not isinstance(speed, int | float) or not (math.isfinite(speed) and speed > 0):
        raise LogError(f"--speed: expected a finite number of vehicle seconds per wall second > 0; got {speed!r}")
    conn = _connect(address)
    encoders: dict[tuple[int, int], Any] = {}  # (system, component) -> MAVLink, for its ids and sequence
    skipped: dict[str, int] = {}
    pace = _Pace()
    sent = 0
    vehicle_s = 0.0
    last_text: tuple[float, Any] | None = None
    start = time.monotonic()
    try:
        for m in log.messages((Topic.MAVLINK_RX, Topic.MAVLINK_TX), keep_undecodable=True):
            p = m.payload
            if not _wanted(m.topic, p, executive=executive):
                continue
            if m.topic is Topic.MAVLINK_TX and p["name"] == "STATUSTEXT":
                if last_text == (m.log_time_s, p.get("fields")):
                    continue  # the same text sent on the ground-station link too: once is enough
                last_text = (m.log_time_s, p.get("fields"))
            due_s = pace.advance(m.log_time_s)
            source = (p["src_system"], p["src_component"])
            mav = encoders.get(source)
            if mav is None:
                mav = encoders[source] = mavlink.MAVLink(None, srcSystem=source[0], srcComponent=source[1])
            try:
                frame = rebuild(p).pack(mav)
            except (ValueError, struct.error):  # not a message of the dialect, or a value out of its range
                skipped[str(p.get("name"))] = skipped.get(str(p.get("name")), 0) + 1
                continue
            if _wait(start + due_s / speed, stop):
                break
            try:
                conn.write(frame)
            except OSError as exc:
                raise LogError(f"{address}: sending failed: {exc.strerror or exc}") from None
            mav.seq = (mav.seq + 1) % 256  # what MAVLink.send does after writing
            sent += 1
            vehicle_s = due_s
            if on_message is not None:
                on_message(m)
    finally:
        conn.close()
    return RestreamResult(messages_sent=sent, skipped=skipped, vehicle_s=vehicle_s, wall_s=time.monotonic() - start)


def rebuild(payload: Mapping[str, Any]) -> Any:
    """The pymavlink message a ``/mavlink/*`` record describes (``mavlink_bridge.describe``'s inverse).

    Text fields go back to UTF-8 bytes, null floats (NaN in the log) to NaN;
    extension fields the record lacks take the dialect's defaults. Raises
    ``ValueError`` for a record that does not describe a message of the dialect.
    """
    name, msg_id, fields = payload.get("name"), payload.get("msg_id"), payload.get("fields")
    cls = mavlink.mavlink_map.get(msg_id) if isinstance(msg_id, int) else None
    if cls is None or cls.msgname != name:
        raise ValueError(f"{name} (id {msg_id}): not a message of the ardupilotmega dialect")
    if not isinstance(fields, Mapping):
        raise ValueError(f"{name}: no fields")
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    kwargs = {f: mavlink_value(name, f, fields[f], kind, lengths[f])
              for f, kind in zip(cls.fieldnames, cls.fieldtypes, strict=True) if f in fields}
    try:
        return cls(**kwargs)
    except TypeError as exc:  # a required field missing from the record
        raise ValueError(f"{name}: {exc}") from None


# -- internals -------------------------------------------------------------------------------


@dataclass(slots=True)
class _Pace:
    """Vehicle seconds since the start at which each message is due, from its log time."""

    elapsed_s: float = 0.0
    _newest_s: float | None = None

    def advance(self, log_time_s: float) -> float:
        t = log_time_s
        if t == _UNSYNCED_S:
            return self.elapsed_s
        if self._newest_s is None or t < self._newest_s - _REBOOT_BACKSTEP_S:
            self._newest_s = t  # the first timed message, or a reboot: pace on from here
        elif t > self._newest_s:
            self.elapsed_s += t - self._newest_s
            self._newest_s = t
        return self.elapsed_s  # behind the newest time: due at once


def _wanted(topic: Topic, payload: Mapping[str, Any], *, executive: bool) -> bool:
    component = payload.get("src_component")
    if not isinstance(payload.get("src_system"), int) or not isinstance(component, int):
        return False
    if topic is Topic.MAVLINK_RX:
        return component == bridge.AUTOPILOT_COMPONENT
    return executive and component == bridge.EXECUTIVE_COMPONENT and payload.get("name") in _EXECUTIVE_MESSAGES


def _wait(due_wall_s: float, stop: threading.Event | None) -> bool:
    """Sleep until ``due_wall_s`` (``time.monotonic``); True when ``stop`` is set first."""
    delay = due_wall_s - time.monotonic()
    if stop is None:
        if delay > 0:
            time.sleep(delay)
        return False
    return stop.wait(delay) if delay > 0 else stop.is_set()


def _connect(address: str) -> Any:
    from pymavlink import mavutil  # transport only; frames are packed here with per-message source ids

    try:
        return mavutil.mavlink_connection(address, source_system=bridge.AUTOPILOT_SYSTEM,
                                          source_component=bridge.AUTOPILOT_COMPONENT)
    except (OSError, ValueError) as exc:
        raise LogError(f"{address}: cannot open the MAVLink link: {exc}") from None
