"""A dive's track for other tools: CSV (spreadsheets), GeoJSON (GIS, web maps) and GPX (charting software).

All three start from ``planner.shore.replay.dive.Dive`` and are written atomically
(``planner.contract.atomic``); a file that cannot be written raises ``LogError`` naming
it. Times are UTC where the autopilot sent it (``SYSTEM_TIME``), otherwise
left out. Depth goes in as a negative altitude (metres, up positive, the sea
surface taken as the WGS84 ellipsoid), as in the log's ``foxglove.LocationFix``.

The GeoJSON track is the track filtered of position noise (``track_filter``: the
median fix of every 30 s) simplified by Douglas-Peucker to a tolerance in metres
(``SIMPLIFY_M`` by default): the demo dive's 59,000 fixes become some 50 vertices
at 2 m. CSV and GPX keep every decision and every fix.

Standard library and numpy only, like the rest of the executive's readers.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import xml.etree.ElementTree as ET
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner.shore.replay.dive import Dive, Track
from planner.shore.replay.track_filter import SIMPLIFY_M, WINDOW_S, local_xyz_m, simplify
from executive.recorder import LogError
from executive.state import Situation
from planner.contract.atomic import write_atomic

__all__ = ["CSV_COLUMNS", "GPX_NAMESPACE", "goals_reached", "track_points", "write_csv", "write_geojson", "write_gpx"]

CSV_COLUMNS = ("time_s", "utc", "lat_deg", "lon_deg", "depth_m", "heading_deg", "situation", "action", "mode",
               "l", "j", "i", "k", "energy_used_wh", "battery_pct", "goal_index")
GPX_NAMESPACE = "http://www.topografix.com/GPX/1/1"
_GPX_SCHEMA = "http://www.topografix.com/GPX/1/1/gpx.xsd"
_XSI = "http://www.w3.org/2001/XMLSchema-instance"
_CREATOR = "lrauv planner.shore.replay.export"
_ALTITUDE = "third coordinate = -depth_m (metres, up positive; sea surface = WGS84 ellipsoid)"


def write_csv(dive: Dive, path: str | os.PathLike[str]) -> Path:
    """One row per decision, columns ``CSV_COLUMNS``; empty cells for unknown values."""
    t = dive.track
    utc = _utc_strings(dive, t.time_s)
    buf = io.StringIO(newline="")
    out = csv.writer(buf, lineterminator="\n")
    out.writerow(CSV_COLUMNS)
    for r in range(len(t)):
        cell = [str(int(c)) if c >= 0 else "" for c in t.cell[r]]
        out.writerow([_num(t.time_s[r]), utc[r], _num(t.lat_deg[r]), _num(t.lon_deg[r]), _num(t.depth_m[r]),
                      _num(t.heading_deg[r]), t.situation[r], t.action[r] or "", t.mode[r], *cell,
                      _num(t.energy_used_wh[r]), _num(t.battery_pct[r]), str(int(t.goal_index[r]))])
    return _write(path, buf.getvalue().encode("utf-8"))


def write_geojson(dive: Dive, path: str | os.PathLike[str], *, tolerance_m: float = SIMPLIFY_M,
                  window_s: float = WINDOW_S) -> Path:
    """A FeatureCollection (RFC 7946): the track as a LineString, and Points at start, end and each goal reached.

    The track is ``track_filter.filter_track`` (median fix of every ``window_s``) simplified
    by Douglas-Peucker in east/north/up metres: every filtered point lies within
    ``tolerance_m`` of the line. Positions are ``[lon_deg, lat_deg, -depth_m]``; the
    track's properties say so, and give the filter, the tolerance and the counts.
    """
    t = dive.track
    rows = track_points(t)
    f = t.filtered(window_s)
    known = np.isfinite(f.depth_m)
    kept = simplify(local_xyz_m(f.lat_deg[known], f.lon_deg[known], f.depth_m[known]), tolerance_m)
    lon, lat, depth = (a[known][kept] for a in (f.lon_deg, f.lat_deg, f.depth_m))
    coords = [[float(x), float(y), 0.0 - float(d)] for x, y, d in zip(lon, lat, depth)]  # 0.0 - : no -0.0
    ends = t.time_s[[0, -1]] if len(t) else np.full(2, np.nan)
    start_utc, end_utc = (u or None for u in _utc_strings(dive, ends))
    track = {
        "type": "Feature",
        # A LineString needs two positions (RFC 7946 section 3.1.4); with fewer the feature has no geometry.
        "geometry": {"type": "LineString", "coordinates": coords} if len(coords) >= 2 else None,
        "properties": {
            "kind": "track",
            "name": dive.log.path.name,
            "decisions": len(t),
            "points": len(coords),
            "fixes": int(rows.size),
            "filter": f"median fix of every {window_s:g} s of vehicle time, with the first and last fix",
            "simplified_m": tolerance_m,
            "simplified": "Douglas-Peucker: every filtered point within simplified_m of the line (east/north/up)",
            "start_time_s": _or_none(ends[0]),
            "end_time_s": _or_none(ends[1]),
            "start_utc": start_utc,
            "end_utc": end_utc,
            "distance_m": f.length_m(),
            "altitude": _ALTITUDE,
        },
    }
    points = []
    if rows.size:
        points.append(_point(dive, int(rows[0]), kind="start"))
        points.append(_point(dive, int(rows[-1]), kind="end"))
    points += [_point(dive, r, kind="goal") for r in goals_reached(t)]
    doc = {"type": "FeatureCollection", "features": [track, *points]}
    text = json.dumps(doc, allow_nan=False, separators=(",", ":"))
    return _write(path, (text + "\n").encode("utf-8"))


def write_gpx(dive: Dive, path: str | os.PathLike[str]) -> Path:
    """GPX 1.1: one track, one segment, a ``trkpt`` per ``track_points`` row with ``ele`` = -depth_m.

    ``time`` (UTC) only when the autopilot sent UTC; GPX has no other clock.
    """
    t = dive.track
    rows = track_points(t)
    utc = _utc_strings(dive, t.time_s[rows])
    # Plain tag names under a default xmlns on the root: the same document as qualified names, without
    # touching ElementTree's global prefix registry (register_namespace).
    gpx = ET.Element("gpx", {"xmlns": GPX_NAMESPACE, "xmlns:xsi": _XSI, "version": "1.1", "creator": _CREATOR,
                             "xsi:schemaLocation": f"{GPX_NAMESPACE} {_GPX_SCHEMA}"})
    meta = ET.SubElement(gpx, "metadata")
    ET.SubElement(meta, "name").text = dive.log.path.name  # no metadata/time: GPX means the file's creation
    trk = ET.SubElement(gpx, "trk")
    ET.SubElement(trk, "name").text = dive.log.path.stem
    seg = ET.SubElement(trk, "trkseg")
    for n, r in enumerate(rows):
        pt = ET.SubElement(seg, "trkpt", {"lat": repr(float(t.lat_deg[r])), "lon": repr(float(t.lon_deg[r]))})
        ET.SubElement(pt, "ele").text = repr(0.0 - float(t.depth_m[r]))  # wptType order: ele, then time
        if utc[n]:
            ET.SubElement(pt, "time").text = utc[n]
    xml = ET.tostring(gpx, encoding="utf-8", xml_declaration=True)
    return _write(path, xml + b"\n")


def track_points(track: Track) -> NDArray[np.int64]:
    """Rows with a known position and depth, each differing from the previous kept row."""
    pos = np.column_stack([track.lon_deg, track.lat_deg, track.depth_m]).reshape(-1, 3)
    rows = np.flatnonzero(np.isfinite(pos).all(axis=1))
    if rows.size < 2:
        return rows
    kept = pos[rows]
    new = np.concatenate([[True], (kept[1:] != kept[:-1]).any(axis=1)])
    return rows[new]


def goals_reached(track: Track) -> list[int]:
    """The first ``at_goal`` row of each goal index, in order."""
    seen: set[int] = set()
    out = []
    for r, situation in enumerate(track.situation):
        goal = int(track.goal_index[r])
        if situation == Situation.AT_GOAL.value and goal not in seen:
            seen.add(goal)
            out.append(r)
    return out


# -- helpers -----------------------------------------------------------------------------


def _point(dive: Dive, row: int, *, kind: str) -> dict[str, Any]:
    t = dive.track
    lon, lat, depth = (_or_none(v) for v in (t.lon_deg[row], t.lat_deg[row], t.depth_m[row]))
    geometry = None
    if lon is not None and lat is not None:
        geometry = {"type": "Point", "coordinates": [lon, lat] if depth is None else [lon, lat, 0.0 - depth]}
    return {"type": "Feature", "geometry": geometry, "properties": {
        "kind": kind, "time_s": _or_none(t.time_s[row]), "utc": _utc_strings(dive, t.time_s[row:row + 1])[0] or None,
        "goal_index": int(t.goal_index[row]), "situation": t.situation[row], "depth_m": depth,
    }}


def _utc_strings(dive: Dive, time_s: NDArray[np.float64]) -> list[str]:
    """ISO 8601 UTC (ms, ``Z``) of each vehicle time; empty strings where UTC is unknown."""
    if dive.unix_offset_s is None:
        return [""] * len(time_s)
    return [_iso(float(t) + dive.unix_offset_s) if math.isfinite(t) else "" for t in time_s]


def _iso(unix_s: float) -> str:
    # Rounded to the millisecond first: isoformat truncates.
    return datetime.fromtimestamp(round(unix_s, 3), UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _num(value: float) -> str:
    """Exact (shortest round-trip) decimal, or empty for NaN/inf."""
    v = float(value)
    return repr(v) if math.isfinite(v) else ""


def _or_none(value: float) -> float | None:
    v = float(value)
    return v if math.isfinite(v) else None


def _write(path: str | os.PathLike[str], data: bytes) -> Path:
    try:
        return write_atomic(path, data)
    except OSError as exc:
        raise LogError(f"{path}: cannot write: {exc.strerror or exc}") from None
