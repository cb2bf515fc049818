"""The dive summary ``lrauv replay`` prints: time, distance, energy, decisions, plans, failsafes, goals.

Pure: ``summarise`` takes a ``Dive`` (and, when the planning forecast was found,
the nominal path of each plan segment) and returns a ``DiveSummary``;
``format_summary`` turns it into the text. Energy is the autopilot's
BATTERY_STATUS figure, attributed to the action in force between two decisions.
Distance is along the track filtered of position noise (``track_filter``);
failsafes are the executive's and the autopilot's (``autopilot``: its STATUSTEXT
and HEARTBEAT states).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from planner.shore.replay.autopilot import AutopilotLog, severity_name
from planner.shore.replay.dive import Dive, Segment
from planner.contract.geodesy import EARTH_RADIUS_M

__all__ = ["DiveSummary", "Deviation", "executive_failsafes", "failsafe_lines", "format_summary", "slices_text",
           "status_text_lines", "summarise"]

_NORMAL = ("following", "at_goal")  # situations that are not a failsafe


class Polyline(Protocol):
    lon_deg: NDArray[np.float64]
    lat_deg: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Failsafe:
    situation: str
    start_s: float
    end_s: float  # vehicle time of the last decision in it


@dataclass(frozen=True, slots=True)
class GoalReached:
    goal_index: int
    time_s: float  # vehicle time of the first at-goal decision
    after_s: float  # since the first decision that followed the policy


@dataclass(frozen=True, slots=True)
class Deviation:
    """The largest distance of the track from the nominal path of its plan segment."""

    distance_m: float
    time_s: float
    lat_deg: float
    lon_deg: float
    segment: int


@dataclass(frozen=True, kw_only=True)
class DiveSummary:
    log: str
    where_it_ends: str
    vehicle_s: float  # first to last decision
    wall_s: float
    distance_m: float  # along the filtered track
    fix_distance_m: float  # summing every fix, noise and all
    filter_window_s: float
    decisions: int
    action_starts: Mapping[str, int]  # decisions that started a new activity, by action
    decisions_by_action: Mapping[str, int]
    time_by_action_s: Mapping[str, float]
    energy_by_action_wh: Mapping[str, float]
    energy_used_wh: float | None
    plans: tuple[Mapping[str, Any], ...]  # swapped and refused policy records
    failsafes: tuple[Failsafe, ...]
    errors: tuple[str, ...]  # error events, with their vehicle time
    goals_loaded: tuple[int, ...]
    goals_reached: tuple[GoalReached, ...]
    deviation: Deviation | None
    deviation_note: str | None  # why there is none
    ignored_channels: Mapping[str, int]
    loaded_time_varying: tuple[Mapping[str, Any], ...] = ()  # loaded policy records of time-varying tables
    autopilot: AutopilotLog = AutopilotLog()


def summarise(dive: Dive, *, nominal: Mapping[int, Polyline] | None = None, nominal_note: str | None = None
              ) -> DiveSummary:
    """``nominal`` maps a segment's position in ``dive.track.segments()`` to its nominal path."""
    tr = dive.track
    n = len(tr)
    labels = [a if a is not None else s.upper() for a, s in zip(tr.action, tr.situation)]
    # Position and attitude decisions interleave slightly out of time order, and a reboot steps
    # time back: durations are steps of the running latest time, so they add up to the span.
    latest = np.maximum.accumulate(tr.time_s) if n else tr.time_s
    dt = np.diff(latest, append=latest[-1] if n else 0.0)
    de = np.diff(tr.energy_used_wh, append=tr.energy_used_wh[-1] if n else 0.0)
    time_by: dict[str, float] = {}
    energy_by: dict[str, float] = {}
    for label, t, e in zip(labels, dt, de):
        time_by[label] = time_by.get(label, 0.0) + float(t)
        if math.isfinite(e):
            energy_by[label] = energy_by.get(label, 0.0) + float(e)
    starts = Counter(label for label, c in zip(labels, tr.changed) if c)
    energy = tr.energy_used_wh[np.isfinite(tr.energy_used_wh)]
    following = np.flatnonzero(np.asarray(tr.situation) == "following") if n else np.array([], int)
    t_follow = float(tr.time_s[following[0]]) if following.size else (float(tr.time_s[0]) if n else 0.0)
    deviation, note = _deviation(tr, nominal or {}, nominal_note)
    filtered = tr.filtered()
    return DiveSummary(
        log=str(dive.log.path), where_it_ends=dive.log.where_it_ends(),
        vehicle_s=float(latest[-1] - tr.time_s[0]) if n else 0.0,
        wall_s=float(tr.wall_s[-1] - tr.wall_s[0]) if n else 0.0,
        distance_m=filtered.length_m(), fix_distance_m=tr.fix_distance_m(), filter_window_s=filtered.window_s,
        decisions=n, action_starts=dict(starts),
        decisions_by_action=dict(Counter(labels)), time_by_action_s=time_by, energy_by_action_wh=energy_by,
        energy_used_wh=float(energy[-1] - energy[0]) if energy.size else None,
        plans=tuple(p for p in dive.policy if p.get("reason") in ("swapped", "refused")),
        failsafes=executive_failsafes(tr.situation, tr.time_s),
        errors=tuple(f"{e.time_s:.1f} s {e.text}" for e in dive.events if e.level == "error"),
        goals_loaded=tuple(sorted({int(p.get("goal_index", 0)) for p in dive.policy if p.get("reason") == "loaded"})),
        goals_reached=_goals(tr.situation, tr.goal_index, tr.time_s, t_follow),
        deviation=deviation, deviation_note=note, ignored_channels=dict(dive.log.unknown),
        loaded_time_varying=tuple(p for p in dive.policy
                                  if p.get("reason") == "loaded" and isinstance(p.get("slices"), dict)),
        autopilot=dive.autopilot,
    )


def executive_failsafes(situation: Sequence[str], time_s: NDArray[np.float64]) -> tuple[Failsafe, ...]:
    """Stretches of decisions in a situation other than following the plan or at the goal."""
    out: list[Failsafe] = []
    current: tuple[str, float, float] | None = None
    for s, t in zip(situation, time_s):
        if current is not None and s == current[0]:
            current = (s, current[1], float(t))
            continue
        if current is not None:
            out.append(Failsafe(*current))
        current = None if s in _NORMAL else (s, float(t), float(t))
    if current is not None:
        out.append(Failsafe(*current))
    return tuple(out)


def _goals(situation: Sequence[str], goal_index: NDArray[np.int64], time_s: NDArray[np.float64],
           t_follow: float) -> tuple[GoalReached, ...]:
    seen: dict[int, GoalReached] = {}
    for s, g, t in zip(situation, goal_index, time_s):
        if s == "at_goal" and int(g) not in seen:
            seen[int(g)] = GoalReached(int(g), float(t), float(t) - t_follow)
    return tuple(seen.values())


def _deviation(tr: Any, nominal: Mapping[int, Polyline], note: str | None) -> tuple[Deviation | None, str | None]:
    best: Deviation | None = None
    segments: list[Segment] = tr.segments()
    for index, path in nominal.items():
        seg = segments[index]
        lat, lon = tr.lat_deg[seg.start:seg.stop], tr.lon_deg[seg.start:seg.stop]
        d = distance_to_polyline_m(lat, lon, path.lat_deg, path.lon_deg)
        if d.size == 0 or not np.isfinite(d).any():
            continue
        row = int(np.nanargmax(d))
        if best is None or d[row] > best.distance_m:
            best = Deviation(float(d[row]), float(tr.time_s[seg.start + row]), float(lat[row]), float(lon[row]), index)
    if best is None and note is None:
        note = "no plan segment with a nominal path"
    return best, note


def distance_to_polyline_m(lat_deg: NDArray[np.float64], lon_deg: NDArray[np.float64],
                           path_lat_deg: NDArray[np.float64], path_lon_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each point's distance (m) to the polyline, in a local east/north plane about the path's mean latitude."""
    lat0 = math.radians(float(np.mean(path_lat_deg)))
    k = math.radians(1.0) * EARTH_RADIUS_M

    def xy(lat: NDArray[np.float64], lon: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.stack([np.asarray(lon, float) * k * math.cos(lat0), np.asarray(lat, float) * k], axis=-1)

    points = xy(lat_deg, lon_deg)
    v = xy(path_lat_deg, path_lon_deg)
    if len(v) == 1:
        return np.linalg.norm(points - v[0], axis=-1)
    a, b = v[:-1][None], v[1:][None]  # (1, m, 2)
    ab = b - a
    length2 = np.maximum(np.sum(ab * ab, axis=-1), 1e-12)
    out = np.empty(len(points))
    block = max(1, 2_000_000 // len(v))  # bound the (block, m, 2) temporaries
    for s in range(0, len(points), block):
        p = points[s:s + block, None, :]
        t = np.clip(np.sum((p - a) * ab, axis=-1) / length2, 0.0, 1.0)
        out[s:s + block] = np.min(np.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=1)
    return out


def failsafe_lines(autopilot: AutopilotLog, executive: Sequence[Failsafe]) -> list[str]:
    """The failsafes: the autopilot's (announced in STATUSTEXT, its HEARTBEAT state) and the executive's stretches."""
    announced = autopilot.failsafes()
    n = autopilot.failsafe_count()
    if n == 0 and not executive and not autopilot.periods:
        return ["failsafes  0 (none from the autopilot or the executive)"]
    lines = [f"failsafes  {n} from the autopilot, {len(executive)} by the executive"]
    cleared = autopilot.cleared()
    for kind, texts in announced.items():
        again = f"; {cleared[kind]} text(s) said it cleared" if cleared.get(kind) else ""
        lines.append(f"  autopilot  {kind.value}: {len(texts)} time(s), first at {texts[0].time_s:.1f} s,"
                     f" last at {texts[-1].time_s:.1f} s{again}")
    for state in dict.fromkeys(p.state for p in autopilot.periods):
        periods = [p for p in autopilot.periods if p.state == state]
        longest = max(periods, key=lambda p: p.end_s - p.start_s)
        open_end = ", the log ends in it" if not periods[-1].ended else ""
        lines.append(f"  autopilot  HEARTBEAT state {state}: {len(periods)} time(s),"
                     f" {sum(p.end_s - p.start_s for p in periods):.0f} s in all, the longest"
                     f" {longest.end_s - longest.start_s:.0f} s from {longest.start_s:.1f} s{open_end}")
    for f in executive:
        lines.append(f"  {f.start_s:10.1f} s  {f.situation} for {f.end_s - f.start_s:.0f} s")
    return lines


def status_text_lines(autopilot: AutopilotLog, *, most: int = 8) -> list[str]:
    """The autopilot's STATUSTEXT counted by severity, and its most frequent texts."""
    if not autopilot.texts:
        return ["autopilot  no status text"]
    counts = ", ".join(f"{name} {n:,}" for name, n in autopilot.by_severity().items())
    lines = [f"autopilot  {len(autopilot.texts):,} status text(s): {counts}"]
    distinct = Counter((t.severity, t.text) for t in autopilot.texts)
    for (severity, text), n in sorted(distinct.items(), key=lambda kv: (-kv[1], kv[0][0]))[:most]:
        lines.append(f"  {n:6,}  {severity_name(severity):<9} {text}")
    if len(distinct) > most:
        lines.append(f"  ... and {len(distinct) - most} other text(s)")
    return lines


def slices_text(slices: Mapping[str, Any]) -> str:
    """A time-varying table's slices as a policy record gives them (``executive.timeline.slices_record``)."""
    fitted = ", the tide's timing fitted onboard" if slices.get("timing_correction") else ""
    return (f"time-varying, {slices.get('count')} slices from {slices.get('first_utc')} to "
            f"{slices.get('last_utc')}{fitted}")


def _h(seconds: float) -> str:
    return f"{seconds / 3600:.2f} h"


def format_summary(s: DiveSummary) -> str:
    """The text ``lrauv replay`` prints."""
    lines = [f"log        {s.log}: {s.where_it_ends}"]
    if s.ignored_channels:
        lines.append("ignored    channels this version does not read: "
                     + ", ".join(f"{k} ({v:,} messages)" for k, v in s.ignored_channels.items()))
    lines.append(f"duration   {_h(s.vehicle_s)} vehicle time, {s.wall_s:.1f} s wall")
    lines.append(f"distance   {s.distance_m / 1000:.2f} km over ground (the median fix of every {s.filter_window_s:g} s;"
                 f" {s.fix_distance_m / 1000:.2f} km summing every fix)")
    energy = "unknown" if s.energy_used_wh is None else f"{s.energy_used_wh:.1f} Wh"
    lines.append(f"energy     {energy}")
    lines.append(f"decisions  {s.decisions:,}")
    width = max((len(k) for k in s.decisions_by_action), default=0)
    lines.append(f"  {'action':<{width}}  decisions  starts     time   energy")
    for label, count in sorted(s.decisions_by_action.items(), key=lambda kv: -kv[1]):
        t = s.time_by_action_s.get(label, 0.0)
        e = s.energy_by_action_wh.get(label, 0.0)
        bar = "#" * max(1, round(40 * count / max(s.decisions, 1)))
        lines.append(f"  {label:<{width}}  {count:9,}  {s.action_starts.get(label, 0):6,}  {_h(t):>7}  {e:6.1f} Wh  {bar}")
    swaps = [p for p in s.plans if p.get("reason") == "swapped"]
    refused = [p for p in s.plans if p.get("reason") == "refused"]
    lines.append(f"plans      {len(swaps)} swapped in, {len(refused)} refused")
    for p in s.loaded_time_varying:
        lines.append(f"  loaded     goal {p.get('goal_index', 0)}, table {p.get('table_crc32')}: {slices_text(p['slices'])}")
    for p in swaps:
        forecast = p.get("forecast") or {}
        slices = f", {slices_text(p['slices'])}" if isinstance(p.get("slices"), dict) else ""
        lines.append(f"  {p.get('time_s', 0.0):10.1f} s  {p.get('source', '?')}: goal {p.get('goal_index')}, table"
                     f" {(p.get('previous') or {}).get('table_crc32')} -> {p.get('table_crc32')}, forecast"
                     f" {forecast.get('identity') or p.get('forecast_identity')} ({forecast.get('time') or p.get('forecast_time')})"
                     + slices)
    for p in refused:
        lines.append(f"  {p.get('time_s', 0.0):10.1f} s  refused {p.get('refusal')}")
    lines += failsafe_lines(s.autopilot, s.failsafes)
    for error in s.errors:
        lines.append(f"  error  {error}")
    lines += status_text_lines(s.autopilot)
    for reached in s.goals_reached:
        lines.append(f"goal {reached.goal_index:<5} reached at {reached.time_s:.1f} s vehicle time"
                     f" ({_h(reached.after_s)} after the start)")
    missing = [g for g in s.goals_loaded if g not in {r.goal_index for r in s.goals_reached}]
    for goal_index in missing:
        lines.append(f"goal {goal_index:<5} NOT reached")
    if s.deviation is not None:
        d = s.deviation
        lines.append(f"deviation  largest from the nominal path {d.distance_m:.0f} m at {d.time_s:.1f} s"
                     f" (lon, lat {d.lon_deg:.5f}, {d.lat_deg:.5f}), plan segment {d.segment}")
    else:
        lines.append(f"deviation  unknown: {s.deviation_note}")
    return "\n".join(lines)
