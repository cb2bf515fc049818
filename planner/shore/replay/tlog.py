"""A dive's MAVLink frames as a telemetry log (``.tlog``), for mavlogdump, MAVExplorer, UAV Log Viewer and QGC.

The executive keeps each logged message's exact wire bytes, base64 in the ``frame`` key of its
``/mavlink/rx`` and ``/mavlink/tx`` record (``executive.mavlink_bridge.describe``). A ``.tlog`` is
what MAVProxy and QGroundControl write: each frame preceded by its time as an 8-byte big-endian
count of microseconds since the Unix epoch (pymavlink ``mavutil.mavlogfile``). The frames go
out in file order, both directions, as they were on the wire (MAVLink 1 or 2, signatures kept);
the autopilot's streams the executive only counts (``executive.raw_log``) were never logged,
so they are not here either.

The time: the record's log time where it is UTC (``executive.log_clock``: the autopilot's
SYSTEM_TIME, or the host's clock where none came, as the log's ``clock`` metadata says). In an
older log, whose log times are vehicle time, UTC where the log knows it: vehicle time plus the
offset from the autopilot's SYSTEM_TIME (``time_unix_usec`` - ``time_boot_ms``), the first one's
for the frames before it and each later one's from there on (a reboot restarts vehicle time);
else vehicle time since boot (a 1970 date). Log times are not monotonic in file order (the
executive's extrapolated clock runs ahead, a reboot steps back), and tools expect a .tlog's time
not to go back, so a frame never gets an earlier time than the one before it.
"""

from __future__ import annotations

import base64
import binascii
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from executive.recorder import LogError, Topic
from planner.contract.atomic import atomic_target
from planner.shore.replay.divelog import DiveLog

__all__ = ["TlogResult", "write_tlog"]

TlogClock = Literal["utc", "utc (host clock)", "vehicle time since boot"]
_STAMP = struct.Struct(">Q")  # microseconds since the Unix epoch, big-endian (MAVProxy, QGC, pymavlink)


@dataclass(frozen=True, kw_only=True)
class TlogResult:
    """What ``write_tlog`` wrote."""

    path: Path
    frames: int
    without_frame: int  # MAVLink records logged without their bytes (none in a log of this version)
    clock: TlogClock

    def describe(self) -> str:
        """One line for the operator."""
        missing = f"; {self.without_frame:,} records without their frame" if self.without_frame else ""
        return f"{self.frames:,} MAVLink frames, time {self.clock}{missing}"


def write_tlog(log: DiveLog, path: str | os.PathLike[str], *, first_offset_s: float | None = None) -> TlogResult:
    """Write ``log``'s MAVLink frames to ``path`` as a .tlog, atomically.

    ``first_offset_s``: for an older log (vehicle log times), its first SYSTEM_TIME offset
    (``Dive.unix_offset_s``) for the frames before that message; found here when not given. Raises ``LogError`` for a log that holds no
    frames (written before they were kept) or a frame that is not base64; ``path`` is then untouched.
    """
    source = log.metadata.get("clock", {}).get("source")
    if source is None and first_offset_s is None:
        first_offset_s = _first_offset_s(log)
    counts = {"frames": 0, "without": 0, "utc": 0}
    with atomic_target(path) as tmp, open(tmp, "wb") as out:
        for stamp_us, frame in _stamped_frames(log, first_offset_s, counts):
            out.write(_STAMP.pack(stamp_us))
            out.write(frame)
    clock: TlogClock = "vehicle time since boot" if first_offset_s is None and not counts["utc"] else "utc"
    if counts["utc"] and source == "host clock":
        clock = "utc (host clock)"
    return TlogResult(path=Path(path), frames=counts["frames"], without_frame=counts["without"], clock=clock)


def _stamped_frames(log: DiveLog, offset_s: float | None, counts: dict[str, int]) -> Iterator[tuple[int, bytes]]:
    last_us = 0
    for m in log.messages((Topic.MAVLINK_RX, Topic.MAVLINK_TX), keep_undecodable=True):
        p = m.payload
        if m.topic is Topic.MAVLINK_RX and p["name"] == "SYSTEM_TIME" and offset_s is not None:
            offset_s = _offset_of(p) or offset_s
        text = p.get("frame")
        if not isinstance(text, str):
            counts["without"] += 1
            continue
        try:
            frame = base64.b64decode(text, validate=True)
        except (binascii.Error, ValueError):
            raise LogError(f"{log.path}: {m.topic.value} {p['name']} at log time {m.log_time_s:.3f} s: its frame is"
                           " not base64") from None
        if m.utc_s is not None:  # a log with UTC log times
            counts["utc"] += 1
            last_us = max(last_us, round(m.utc_s * 1e6))
        else:
            last_us = max(last_us, round((m.log_time_s + (offset_s or 0.0)) * 1e6))
        counts["frames"] += 1
        yield last_us, frame
    if counts["frames"] == 0:  # raised inside the atomic write: no empty file is left behind
        raise LogError(f"{log.path}: no MAVLink frames in this log ({counts['without']:,} records of decoded fields"
                       " only: written by a version that did not keep the wire bytes), so no .tlog can be made")


def _first_offset_s(log: DiveLog) -> float | None:
    for m in log.messages((Topic.MAVLINK_RX,), containing={Topic.MAVLINK_RX: b'"name":"SYSTEM_TIME"'}):
        offset = _offset_of(m.payload)
        if offset is not None:
            return offset
    return None


def _offset_of(payload: dict[str, object]) -> float | None:
    """UTC (Unix s) minus vehicle time, from a SYSTEM_TIME; None when the autopilot has no UTC yet (0)."""
    fields = payload.get("fields")
    if not isinstance(fields, dict):
        return None
    usec, boot_ms = fields.get("time_unix_usec", 0), fields.get("time_boot_ms", 0)
    if not isinstance(usec, int) or not isinstance(boot_ms, int):
        return None
    return usec / 1e6 - boot_ms / 1e3 if usec > 0 else None
