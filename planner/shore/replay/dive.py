"""A dive as columns: what the executive saw and decided, pulled out of its log in one pass.

``load_dive`` turns a ``DiveLog`` into a ``Dive``: the track (one row per
decision: vehicle time, wall time, position, heading, situation, action, the
table's state, energy and battery), the plan changes (``/executive/policy``)
and the events (``/log``), and what the autopilot said (STATUSTEXT, HEARTBEAT states:
``planner.shore.replay.autopilot``). Summary, report, export and re-stream all start from
it. numpy and the standard library only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner.contract.progress import SILENT, Progress
from planner.shore.replay.autopilot import AutopilotLog, AutopilotReader
from planner.shore.replay.divelog import DiveLog
from planner.shore.replay.track_filter import WINDOW_S, FilteredTrack, filter_track, path_length_m
from executive.recorder import LogLevel, Topic

__all__ = ["Dive", "Event", "Segment", "Track", "load_dive", "path_length_m"]


@dataclass(frozen=True, eq=False, kw_only=True)
class Track:
    """One row per logged decision, in log order. Unknown values are NaN (numbers) or None."""

    time_s: NDArray[np.float64]  # vehicle time since boot
    wall_s: NDArray[np.float64]  # Unix time the decision was logged
    lat_deg: NDArray[np.float64]
    lon_deg: NDArray[np.float64]
    depth_m: NDArray[np.float64]
    heading_deg: NDArray[np.float64]  # compass, clockwise from north
    situation: tuple[str, ...]  # executive.state.Situation values
    action: tuple[str | None, ...]  # planner.contract.actions.Action names; None when not following the table
    mode: tuple[str, ...]  # ArduSub mode the helm asked for
    cell: NDArray[np.int64]  # (n, 4): table state (l, j, i, k); -1 where none
    energy_used_wh: NDArray[np.float64]  # the latest BATTERY_STATUS figure at that time
    battery_pct: NDArray[np.float64]
    goal_index: NDArray[np.int64]  # the active goal of the mission
    changed: NDArray[np.bool_]  # a new activity started at this decision
    table_crc32: tuple[str | None, ...]  # the table in use (hex CRC), None with none

    def __len__(self) -> int:
        return int(self.time_s.size)

    def segments(self) -> list[Segment]:
        """Stretches of rows under one table and goal, in order (a new one at every swap)."""
        out: list[Segment] = []
        start = 0
        for row in range(1, len(self) + 1):
            if row == len(self) or (self.table_crc32[row], self.goal_index[row]) != (
                    self.table_crc32[start], self.goal_index[start]):
                out.append(Segment(start, row, self.table_crc32[start], int(self.goal_index[start])))
                start = row
        return out

    def filtered(self, window_s: float = WINDOW_S) -> FilteredTrack:
        """The positions without their noise (``track_filter.filter_track``: medians over ``window_s``)."""
        return filter_track(self.time_s, self.lat_deg, self.lon_deg, self.depth_m, window_s=window_s)

    def distance_m(self, window_s: float = WINDOW_S) -> float:
        """Distance over ground along the filtered track, great circles between its points (spec section 1 radius)."""
        return self.filtered(window_s).length_m()

    def fix_distance_m(self) -> float:
        """Great circles between every decision's position: the noise of each fix adds to it."""
        return path_length_m(self.lat_deg, self.lon_deg)


@dataclass(frozen=True, slots=True)
class Segment:
    """Rows ``start`` to ``stop`` (exclusive) of a track, driven by one table towards one goal."""

    start: int
    stop: int
    table_crc32: str | None
    goal_index: int


@dataclass(frozen=True, slots=True)
class Event:
    time_s: float
    level: str  # debug, info, warning, error
    text: str


@dataclass(frozen=True, eq=False, kw_only=True)
class Dive:
    log: DiveLog
    track: Track
    policy: tuple[dict[str, Any], ...]  # /executive/policy records: loaded, received, swapped, refused
    events: tuple[Event, ...]
    states: int  # /vehicle/state records read
    # UTC (Unix s) = vehicle time + this, from the autopilot's first SYSTEM_TIME with UTC; after an
    # autopilot reboot (vehicle time restarts) later times are off by the uptime before it.
    unix_offset_s: float | None
    autopilot: AutopilotLog = AutopilotLog()  # its STATUSTEXT and HEARTBEAT states

    def utc_s(self, time_s: float | NDArray[np.float64]) -> float | NDArray[np.float64] | None:
        """Unix time of vehicle time ``time_s``, or None when the autopilot never sent UTC."""
        return None if self.unix_offset_s is None else time_s + self.unix_offset_s


_LEVEL_NAMES: dict[object, str] = {int(v): v.name.lower() for v in LogLevel}  # looked up with whatever was logged


def load_dive(log: DiveLog, *, meter: Progress = SILENT) -> Dive:
    """Read the decisions, vehicle states, policy records and events of ``log`` in one pass;
    ``meter`` hears the decisions read, of those the log holds."""
    rows: dict[str, list[Any]] = {k: [] for k in ("time_s", "wall_s", "lat_deg", "lon_deg", "depth_m", "heading_deg",
                                                 "situation", "action", "mode", "cell", "energy", "battery", "goal",
                                                 "changed", "table")}
    policy: list[dict[str, Any]] = []
    events: list[Event] = []
    energy = battery = math.nan
    goal = int(log.metadata.get("helm", {}).get("goal_index", "0"))
    table: str | None = None
    states = 0
    offset: float | None = None
    autopilot = AutopilotReader()
    topics = (Topic.DECISION, Topic.STATE, Topic.POLICY, Topic.LOG, Topic.MAVLINK_RX)
    wanted = (b'"name":"SYSTEM_TIME"', b'"name":"STATUSTEXT"', b'"name":"HEARTBEAT"')
    total = log.counts.get(Topic.DECISION, 0)
    meter.update("reading decisions", 0, total, unit="decisions")
    for m in log.messages(topics, containing={Topic.MAVLINK_RX: wanted}):
        p = m.payload
        if m.topic is Topic.MAVLINK_RX:
            fields = p.get("fields", {})
            if p.get("name") != "SYSTEM_TIME":
                autopilot.feed(m.log_time_s, p)
            elif offset is None and fields.get("time_unix_usec", 0) > 0:
                offset = fields["time_unix_usec"] / 1e6 - fields.get("time_boot_ms", 0) / 1e3
        elif m.topic is Topic.DECISION:
            rows["time_s"].append(_num(p.get("time_s", m.log_time_s)))
            rows["wall_s"].append(m.publish_time_s)
            for key in ("lat_deg", "lon_deg", "depth_m", "heading_deg"):
                rows[key].append(_num(p.get(key)))
            rows["situation"].append(str(p.get("situation") or "unknown"))
            rows["action"].append(p.get("action"))
            rows["mode"].append(str(p.get("mode") or "unknown"))
            cell = p.get("cell")
            rows["cell"].append(cell if isinstance(cell, list) and len(cell) == 4 else [-1, -1, -1, -1])
            rows["energy"].append(energy)
            rows["battery"].append(battery)
            rows["goal"].append(goal)
            rows["changed"].append(bool(p.get("changed")))
            rows["table"].append(table)
            meter.update("reading decisions", len(rows["table"]), total, unit="decisions")
        elif m.topic is Topic.STATE:
            states += 1
            energy = _num(p.get("energy_used_wh"), energy)
            battery = _num(p.get("battery_pct"), battery)
        elif m.topic is Topic.POLICY:
            policy.append(p)
            reason = p.get("reason")
            if reason == "swapped" or (reason == "loaded" and table is None and p.get("goal_index", 0) == goal):
                goal = p["goal_index"] if isinstance(p.get("goal_index"), int) else goal
                table = p.get("table_crc32")
        else:
            events.append(Event(m.log_time_s, _LEVEL_NAMES.get(p.get("level"), "unknown"), str(p.get("message", ""))))
    meter.update("reading decisions", total, total, unit="decisions")
    f64 = np.float64
    track = Track(
        time_s=np.asarray(rows["time_s"], f64), wall_s=np.asarray(rows["wall_s"], f64),
        lat_deg=np.asarray(rows["lat_deg"], f64), lon_deg=np.asarray(rows["lon_deg"], f64),
        depth_m=np.asarray(rows["depth_m"], f64), heading_deg=np.asarray(rows["heading_deg"], f64),
        situation=tuple(rows["situation"]), action=tuple(rows["action"]), mode=tuple(rows["mode"]),
        cell=np.asarray(rows["cell"], np.int64).reshape(-1, 4),
        energy_used_wh=np.asarray(rows["energy"], f64), battery_pct=np.asarray(rows["battery"], f64),
        goal_index=np.asarray(rows["goal"], np.int64), changed=np.asarray(rows["changed"], bool),
        table_crc32=tuple(rows["table"]),
    )
    return Dive(log=log, track=track, policy=tuple(policy), events=tuple(events), states=states, unix_offset_s=offset,
                autopilot=autopilot.result())


def _num(value: Any, default: float = math.nan) -> float:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else default
