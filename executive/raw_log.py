"""Which of the autopilot's messages the raw MAVLink log keeps (docs/executive.md, "Links").

ArduSub streams about 36 message types at 91 messages a vehicle second by default (its SRn_*
stream-rate parameters), where the executive uses a handful. Logging all of them raw made
26 MB a vehicle hour. The log keeps every message the executive reads (decisions, health,
acknowledgements, text, time, protocol traffic) and those it asked rates for, and of the
others only a count per type, written as one debug line per ``REPORT_PERIOD_S`` of vehicle
time. Messages from anyone but the autopilot are always kept (uploads, commands).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable

# The autopilot messages the executive reads (executive.mavlink_bridge.apply, the loop, the lockstep
# handshake and the protocols a ground station may route through the autopilot).
READ_KINDS = frozenset({
    "HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "EKF_STATUS_REPORT", "BATTERY_STATUS", "SYS_STATUS",
    "SYSTEM_TIME", "COMMAND_ACK", "COMMAND_LONG", "STATUSTEXT", "TIMESYNC", "AUTOPILOT_VERSION",
    "FILE_TRANSFER_PROTOCOL", "MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_REQUEST_INT", "MISSION_REQUEST",
    "MISSION_ACK", "MISSION_REQUEST_LIST", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "MISSION_CURRENT",
})
REPORT_PERIOD_S = 60.0  # vehicle seconds between the counts of messages not kept


class RawFilter:
    """Keeps the messages the executive reads; counts the rest by type."""

    def __init__(self, asked: Iterable[str] = ()) -> None:
        self.kinds = READ_KINDS | frozenset(asked)
        self.skipped_total = 0
        self._skipped: Counter[str] = Counter()
        self._reported_s: float | None = None

    def keep(self, kind: str) -> bool:
        """Whether an autopilot message of this type goes into the raw log (else it is counted)."""
        if kind in self.kinds:
            return True
        self._skipped[kind] += 1
        self.skipped_total += 1
        return False

    def report(self, now_s: float) -> str | None:
        """The counts since the last report, once ``REPORT_PERIOD_S`` has passed (None otherwise)."""
        if self._reported_s is None or now_s < self._reported_s:
            self._reported_s = now_s  # the first call, or an autopilot reboot: count from here
            return None
        if now_s - self._reported_s < REPORT_PERIOD_S or not self._skipped:
            return None
        since = now_s - self._reported_s
        counts = ", ".join(f"{kind} {n}" for kind, n in sorted(self._skipped.items(), key=lambda kv: (-kv[1], kv[0])))
        self._skipped.clear()
        self._reported_s = now_s
        return f"not logged raw (unused autopilot messages) in the last {since:.0f} s: {counts}"
