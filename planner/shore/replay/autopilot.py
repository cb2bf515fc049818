"""What the autopilot itself said during a dive: its STATUSTEXT by severity, its failsafes, its critical states.

The executive has its own failsafes (``executive.state.Situation``); the autopilot
has others, which it announces in STATUSTEXT (MAVLink common.xml, severity
``MAV_SEVERITY``) and shows in its HEARTBEAT's ``system_status`` (``MAV_STATE``):
ArduSub reports ``MAV_STATE_CRITICAL`` while any failsafe is active. Both come from
the autopilot's ``/mavlink/rx`` records (component 1, ``MAV_COMP_ID_AUTOPILOT1``).

Failsafe texts are matched against the ones ArduPilot sends (ArduSub/failsafe.cpp,
AP_BattMonitor, and the ``GCS Failsafe`` wording of the other vehicles and of this
project's simulator, vehicle_sim/autopilot.py). A text that says a failsafe cleared
or was regained is counted as a clearance, not an onset.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

__all__ = ["AutopilotLog", "AutopilotReader", "FailsafeKind", "StatePeriod", "StatusText", "failsafe_kind",
           "severity_name"]

AUTOPILOT_COMPONENT = 1  # MAV_COMP_ID_AUTOPILOT1
# MAV_SEVERITY (common.xml), 0 .. 7
SEVERITIES = ("EMERGENCY", "ALERT", "CRITICAL", "ERROR", "WARNING", "NOTICE", "INFO", "DEBUG")
# MAV_STATE (common.xml) values a failsafe shows as
_ALARM_STATES = {5: "CRITICAL", 6: "EMERGENCY", 8: "FLIGHT_TERMINATION"}
_STATUSTEXT_CHARS = 50  # the text field; a shorter chunk ended with a NUL: the last one (MAVLink 2 chunking)


class FailsafeKind(StrEnum):
    GCS = "GCS heartbeat lost"
    BATTERY = "battery low or critical"
    EKF = "EKF bad"
    LEAK = "leak detected"
    PILOT_INPUT = "pilot input lost"
    INTERNAL_PRESSURE = "internal pressure critical"
    INTERNAL_TEMPERATURE = "internal temperature critical"
    DEPTH_SENSOR = "depth sensor error"
    CRASH = "crash detected"
    TERRAIN = "terrain data missing"
    RADIO = "radio (RC) lost"
    OTHER = "other failsafe"


# ArduSub/failsafe.cpp: "MYGCS: %u, heartbeat lost", "EKF bad", "Leak Detected", "Lost manual control",
# "Internal pressure critical!", "Internal temperature critical!", "Depth sensor error!", "Crash detected",
# "Failsafe terrain triggered"; AP_BattMonitor: "Battery %d is %s %.2fV used %.0f mAh" (low, critical).
_PATTERNS = (
    (FailsafeKind.GCS, re.compile(r"GCS Failsafe|MYGCS: *\d+, heartbeat lost|heartbeat lost", re.I)),
    (FailsafeKind.BATTERY, re.compile(r"Battery \d+ is (low|critical)|battery failsafe", re.I)),
    (FailsafeKind.EKF, re.compile(r"EKF bad|EKF failsafe|EKF variance", re.I)),
    (FailsafeKind.LEAK, re.compile(r"Leak Detected", re.I)),
    (FailsafeKind.PILOT_INPUT, re.compile(r"Lost manual control", re.I)),
    (FailsafeKind.INTERNAL_PRESSURE, re.compile(r"Internal pressure critical", re.I)),
    (FailsafeKind.INTERNAL_TEMPERATURE, re.compile(r"Internal temperature critical", re.I)),
    (FailsafeKind.DEPTH_SENSOR, re.compile(r"Depth sensor error", re.I)),
    (FailsafeKind.CRASH, re.compile(r"Crash detected", re.I)),
    (FailsafeKind.TERRAIN, re.compile(r"Failsafe terrain", re.I)),
    (FailsafeKind.RADIO, re.compile(r"Radio failsafe|RC failsafe|Throttle failsafe", re.I)),
    (FailsafeKind.OTHER, re.compile(r"failsafe", re.I)),
)
_CLEARED = re.compile(r"\b(cleared|regained|resolved|recovered|OK now)\b", re.I)


def failsafe_kind(text: str) -> tuple[FailsafeKind, bool] | None:
    """The failsafe a STATUSTEXT announces and whether it says it cleared; None for any other text."""
    for kind, pattern in _PATTERNS:
        if pattern.search(text):
            return kind, bool(_CLEARED.search(text))
    return None


def severity_name(severity: int) -> str:
    return SEVERITIES[severity] if 0 <= severity < len(SEVERITIES) else f"severity {severity}"


@dataclass(frozen=True, slots=True)
class StatusText:
    time_s: float  # vehicle time of its (last) record
    severity: int  # MAV_SEVERITY
    text: str


@dataclass(frozen=True, slots=True)
class StatePeriod:
    """Heartbeats in one alarm state (``MAV_STATE``), from the first to the first heartbeat in another state."""

    state: str
    start_s: float
    end_s: float  # the next heartbeat's time, or the last heartbeat's when the log ends in this state
    ended: bool


@dataclass(frozen=True, kw_only=True)
class AutopilotLog:
    texts: tuple[StatusText, ...] = ()
    heartbeats: int = 0
    periods: tuple[StatePeriod, ...] = ()

    def by_severity(self) -> dict[str, int]:
        """Text counts by severity name, most severe first."""
        counts = Counter(t.severity for t in self.texts)
        return {severity_name(s): counts[s] for s in sorted(counts)}

    def failsafes(self) -> dict[FailsafeKind, list[StatusText]]:
        """The texts that announced a failsafe (not its clearance), by kind, in order of first occurrence."""
        out: dict[FailsafeKind, list[StatusText]] = {}
        for t in self.texts:
            found = failsafe_kind(t.text)
            if found is not None and not found[1]:
                out.setdefault(found[0], []).append(t)
        return out

    def cleared(self) -> dict[FailsafeKind, int]:
        """How many texts said each kind of failsafe cleared."""
        found = (failsafe_kind(t.text) for t in self.texts)
        return dict(Counter(f[0] for f in found if f is not None and f[1]))

    def failsafe_count(self) -> int:
        return sum(len(v) for v in self.failsafes().values())


class AutopilotReader:
    """Fed the autopilot's ``/mavlink/rx`` payloads in file order; ``result()`` gives the ``AutopilotLog``."""

    def __init__(self) -> None:
        self.texts: list[StatusText] = []
        self.heartbeats = 0
        self.periods: list[StatePeriod] = []
        self._chunks: dict[int, tuple[float, int, list[str]]] = {}
        self._alarm: tuple[str, float] | None = None
        self._last_heartbeat_s = 0.0

    def feed(self, time_s: float, payload: Mapping[str, Any]) -> None:
        if payload.get("src_component") != AUTOPILOT_COMPONENT:
            return
        fields = payload.get("fields") or {}
        if payload.get("name") == "STATUSTEXT":
            self._text(time_s, fields)
        elif payload.get("name") == "HEARTBEAT" and fields.get("autopilot") != 8:  # MAV_AUTOPILOT_INVALID
            self._heartbeat(time_s, fields)

    def _text(self, time_s: float, fields: Mapping[str, Any]) -> None:
        text, severity = str(fields.get("text", "")), int(fields.get("severity", 6))
        chunk_id = int(fields.get("id", 0) or 0)
        if chunk_id == 0:
            self.texts.append(StatusText(time_s, severity, text))
            return
        _, _, parts = self._chunks.setdefault(chunk_id, (time_s, severity, []))
        parts.append(text)
        if len(text) < _STATUSTEXT_CHARS:  # the NUL-ended chunk is the last one
            del self._chunks[chunk_id]
            self.texts.append(StatusText(time_s, severity, "".join(parts)))

    def _heartbeat(self, time_s: float, fields: Mapping[str, Any]) -> None:
        self.heartbeats += 1
        self._last_heartbeat_s = time_s
        state = _ALARM_STATES.get(int(fields.get("system_status", 0)))
        if self._alarm is not None and state != self._alarm[0]:
            self.periods.append(StatePeriod(self._alarm[0], self._alarm[1], time_s, True))
            self._alarm = None
        if state is not None and self._alarm is None:
            self._alarm = (state, time_s)

    def result(self) -> AutopilotLog:
        texts = list(self.texts)
        texts += [StatusText(t, s, "".join(p)) for t, s, p in self._chunks.values()]  # a cut log's unfinished text
        periods = list(self.periods)
        if self._alarm is not None:
            periods.append(StatePeriod(self._alarm[0], self._alarm[1], self._last_heartbeat_s, False))
        return AutopilotLog(texts=tuple(texts), heartbeats=self.heartbeats,
                            periods=tuple(periods))
