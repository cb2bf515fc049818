"""The log's one clock: MCAP log times in UTC nanoseconds, from the autopilot's time.

The loop runs on vehicle time since boot (``executive.clock``); a log in that time opens in
Foxglove on 1970-01-01. So every record's log time is UTC: vehicle time plus the offset
the autopilot's SYSTEM_TIME gives (``time_unix_usec`` - ``time_boot_ms``; ArduPilot's clock is
set from GPS time, or by a ground station's SYSTEM_TIME). The vehicle time stays in the
payload (``boot_time_s``, ``executive.log_topics``).

Before the first SYSTEM_TIME with a UTC, no date is known, and a record is not written with a
wrong one: it is *held* here (at most ``max_records`` records, ``max_bytes`` bytes or
``max_wall_s`` seconds of wall time; holding is an append, it never waits) and written once the
offset is known. When a bound is reached or the log closes first, the host's clock stands in:
the offset is taken from ``time.time_ns()`` at that moment against the newest held record, and
the log's metadata ``clock`` says so (``source``: ``host clock``). A later SYSTEM_TIME still sets
the autopilot's offset from there on.

The offset is kept until one differs from it by more than ``STEP_NS``: the autopilot rebooted
(vehicle time restarted; until its next SYSTEM_TIME the last offset goes on) or its clock was
corrected (GPS time found). Smaller differences are SYSTEM_TIME's own jitter (the two fields are
sampled microseconds apart) and are not steps. Log times may then step back: MCAP allows that,
and readers order by log time.

Standard library only.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any, Literal

__all__ = ["ClockSource", "LogClock", "STEP_NS"]

# Where the log's UTC came from: the autopilot, the host's clock standing in, or the writer's caller.
ClockSource = Literal["autopilot SYSTEM_TIME", "host clock", "given"]
STEP_NS = 1_000_000_000  # an offset this far from the last is a reboot or a corrected clock


class LogClock:
    """Vehicle time -> UTC ns for the log; records held while UTC is unknown."""

    def __init__(self, offset_ns: int | None = None, *, max_records: int = 5000, max_bytes: int = 8 * 1024 * 1024,
                 max_wall_s: float = 60.0) -> None:
        self.offset_ns = offset_ns
        self.source: ClockSource | None = None if offset_ns is None else "given"
        self.changes = 0  # offsets adopted after the first
        self.held_total = 0  # records written late, once a clock was known
        self._held: list[tuple[int, Any]] = []  # (vehicle ns, item), in write order
        self._held_bytes = 0
        self._held_since_wall = 0.0
        self._limits = (max_records, max_bytes, max_wall_s)

    @property
    def known(self) -> bool:
        return self.offset_ns is not None

    def hold(self, vehicle_ns: int, item: Any, nbytes: int) -> bool:
        """Keep ``item`` until a clock is known; True when a bound is now reached (call ``fall_back``)."""
        if not self._held:
            self._held_since_wall = time.monotonic()
        self._held.append((vehicle_ns, item))
        self._held_bytes += nbytes
        max_records, max_bytes, max_wall_s = self._limits
        return (len(self._held) >= max_records or self._held_bytes >= max_bytes
                or time.monotonic() - self._held_since_wall >= max_wall_s)

    def adopt(self, offset_ns: int, source: ClockSource) -> bool:
        """Use ``offset_ns`` from now on unless it is within ``STEP_NS`` of the one in use; True when adopted."""
        if self.offset_ns is not None and abs(offset_ns - self.offset_ns) <= STEP_NS and source == self.source:
            return False
        if self.offset_ns is not None:
            self.changes += 1
        self.offset_ns, self.source = offset_ns, source
        return True

    def fall_back(self, latest_vehicle_ns: int | None = None) -> None:
        """No UTC from the autopilot in time: the host's clock, taken now against the newest record."""
        newest = max((ns for ns, _ in self._held), default=0) if latest_vehicle_ns is None else latest_vehicle_ns
        self.adopt(time.time_ns() - newest, "host clock")

    def release(self) -> Iterator[tuple[int, Any]]:
        """The held records with their UTC log time (vehicle ns + offset), in write order; none are kept."""
        assert self.offset_ns is not None
        held, self._held, self._held_bytes = self._held, [], 0
        self.held_total += len(held)
        for vehicle_ns, item in held:
            yield max(vehicle_ns + self.offset_ns, 0), item

    @property
    def holding(self) -> int:
        return len(self._held)

    def metadata(self) -> dict[str, str]:
        """The log's ``clock`` metadata record: which clock its log times are in."""
        assert self.source is not None and self.offset_ns is not None
        return {
            "log_time": "UTC, nanoseconds since the Unix epoch; boot_time_s in each payload is vehicle time since boot",
            "source": self.source,
            "utc_offset_ns": str(self.offset_ns),  # UTC = vehicle time + this (the latest; see changes)
            "held_records": str(self.held_total),
            "changes": str(self.changes),
        }
