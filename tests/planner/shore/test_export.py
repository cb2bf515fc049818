"""CSV, GeoJSON and GPX of a dive, read back with the standard parsers and compared with its ``Track``.

The dive is a real one: ``lrauv sim`` and ``lrauv exec`` as processes over UDP
on 127.0.0.1, from two cells west of the goal to the goal (``dive_log`` in
conftest.py, made once per session). The same log without
its SYSTEM_TIME messages is the dive whose UTC is unknown. Edge cases use small
logs written by the real ``Recorder``.
"""

from __future__ import annotations

import csv
import json
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from planner.shore.replay.dive import Dive, load_dive
from planner.shore.replay.divelog import LogMessage, open_dive
from planner.shore.replay.export import CSV_COLUMNS, GPX_NAMESPACE, write_csv, write_geojson, write_gpx
from planner.shore.replay.summary import distance_to_polyline_m
from executive.recorder import LogError, Recorder, Topic
from planner.contract.geodesy import EARTH_RADIUS_M

GPX = f"{{{GPX_NAMESPACE}}}"

def copy_log(src: Path, dst: Path, keep: Callable[[LogMessage], bool]) -> Path:
    """``src`` rewritten by the real Recorder with only the messages ``keep`` accepts (same times, metadata)."""
    log = open_dive(src)
    with Recorder(dst, metadata=log.metadata) as rec:
        for m in log.messages():
            if keep(m):
                rec.write(m.topic, m.log_time_s, m.payload, publish_time_s=m.publish_time_s)
    return dst


@pytest.fixture(scope="module")
def real_dive(dive_log) -> Dive:
    return load_dive(open_dive(dive_log))


@pytest.fixture(scope="module")
def dive_without_utc(tmp_path_factory, real_dive) -> Dive:
    """The real dive as if the autopilot had never sent SYSTEM_TIME."""
    path = copy_log(real_dive.log.path, tmp_path_factory.mktemp("noutc") / "noutc.mcap",
                    lambda m: not (m.topic is Topic.MAVLINK_RX and m.payload["name"] == "SYSTEM_TIME"))
    return load_dive(open_dive(path))


def _decision(t: float, lat: float | None, lon: float | None, depth: float | None, *, situation: str = "following",
              action: str | None = "FORWARD") -> dict:
    """An ``/executive/decision`` payload as ``helm.Decision.to_record`` writes it."""
    return {"time_s": t, "lat_deg": lat, "lon_deg": lon, "depth_m": depth, "heading_deg": 90.0,
            "cell": [0, 3, 4, 0], "situation": situation, "action": action,
            "mode": "GUIDED", "changed": False}


def _expected_points(dive: Dive) -> list[int]:
    """Rows with lat, lon and depth known, without repeats of the previous kept position."""
    t = dive.track
    out: list[int] = []
    for r in range(len(t)):
        p = (t.lon_deg[r], t.lat_deg[r], t.depth_m[r])
        if all(math.isfinite(v) for v in p) and (not out or p != (t.lon_deg[out[-1]], t.lat_deg[out[-1]],
                                                                    t.depth_m[out[-1]])):
            out.append(r)
    return out


def _float_or_nan(text: str) -> float:
    return float(text) if text else math.nan


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.array_equal(a, b, equal_nan=True))


# -- the real dive ---------------------------------------------------------------------------------


@pytest.mark.slow
def test_csv_has_one_row_per_decision_with_the_tracks_values(real_dive, tmp_path):
    t = real_dive.track
    assert len(t) > 100 and real_dive.unix_offset_s is not None
    path = write_csv(real_dive, tmp_path / "dive.csv")
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0]) == CSV_COLUMNS
    cols = {name: [row[c] for row in rows[1:]] for c, name in enumerate(rows[0])}
    assert len(rows) - 1 == len(t) == real_dive.log.counts[Topic.DECISION]
    for name in ("time_s", "lat_deg", "lon_deg", "depth_m", "heading_deg", "energy_used_wh", "battery_pct"):
        assert _same(np.array([_float_or_nan(v) for v in cols[name]]), getattr(t, name)), name
    assert tuple(cols["situation"]) == t.situation and tuple(cols["mode"]) == t.mode
    assert [v or None for v in cols["action"]] == list(t.action)
    cell = np.array([[int(v) if v else -1 for v in (cols["l"][r], cols["j"][r], cols["i"][r], cols["k"][r])]
                     for r in range(len(t))])
    assert np.array_equal(cell, t.cell)
    assert [int(v) for v in cols["goal_index"]] == t.goal_index.tolist()
    # UTC: ISO 8601 in Z, the decision's vehicle time plus the SYSTEM_TIME offset, to the millisecond.
    utc = np.array([np.datetime64(v.rstrip("Z"), "ms").astype(np.int64) / 1e3 for v in cols["utc"]])
    assert np.allclose(utc, t.time_s + real_dive.unix_offset_s, rtol=0, atol=5.01e-4)
    assert all(v.endswith("Z") for v in cols["utc"])


@pytest.mark.slow
def test_geojson_is_a_feature_collection_of_lon_lat_minus_depth(real_dive, tmp_path):
    t = real_dive.track
    doc = json.loads(write_geojson(real_dive, tmp_path / "dive.geojson").read_text())
    assert doc["type"] == "FeatureCollection"
    track, *points = doc["features"]
    assert track["type"] == "Feature" and track["geometry"]["type"] == "LineString"
    coords = track["geometry"]["coordinates"]
    assert all(-90 <= lat <= 90 and -180 <= lon <= 180 for lon, lat, _ in coords)
    props = track["properties"]
    assert props["name"] == real_dive.log.path.name and props["decisions"] == len(t)
    assert props["points"] == len(coords) and props["fixes"] == len(_expected_points(real_dive))
    assert "-depth_m" in props["altitude"] and "median fix of every 30 s" in props["filter"]
    assert props["start_time_s"] == t.time_s[0] and props["end_time_s"] == t.time_s[-1]
    assert props["start_utc"].endswith("Z") and props["end_utc"] > props["start_utc"]
    assert props["distance_m"] == pytest.approx(real_dive.track.distance_m())
    kinds = [p["properties"]["kind"] for p in points]
    assert kinds[:2] == ["start", "end"]
    assert points[0]["geometry"]["coordinates"] == coords[0]
    assert points[1]["geometry"]["coordinates"] == coords[-1]
    # The dive reached its one goal: one goal point, at the first at_goal decision.
    goals = [p for p in points if p["properties"]["kind"] == "goal"]
    first = t.situation.index("at_goal")
    assert len(goals) == 1 and goals[0]["properties"]["time_s"] == t.time_s[first]
    assert goals[0]["geometry"]["coordinates"] == [t.lon_deg[first], t.lat_deg[first], -t.depth_m[first]]


@pytest.mark.slow
@pytest.mark.parametrize("tolerance_m", [0.5, 2.0, 20.0])
def test_geojson_track_is_the_filtered_track_simplified_to_the_tolerance(real_dive, tmp_path, tolerance_m):
    """Far fewer vertices than fixes, and every filtered position within the tolerance of the line."""
    doc = json.loads(write_geojson(real_dive, tmp_path / "dive.geojson", tolerance_m=tolerance_m).read_text())
    track = doc["features"][0]
    coords = np.array(track["geometry"]["coordinates"])
    f = real_dive.track.filtered()
    assert track["properties"]["simplified_m"] == tolerance_m
    assert 2 <= len(coords) <= len(f) and len(coords) < len(_expected_points(real_dive)) / 20
    d = distance_to_polyline_m(f.lat_deg, f.lon_deg, coords[:, 1], coords[:, 0])
    assert float(d.max()) <= tolerance_m + 1e-6
    # Depth, the third coordinate, is simplified within the tolerance too: each vertex is a filtered point's.
    kept = {(round(x, 9), round(y, 9), round(z, 6)) for x, y, z in zip(f.lon_deg, f.lat_deg, -f.depth_m)}
    assert all((round(x, 9), round(y, 9), round(z, 6)) in kept for x, y, z in coords)


@pytest.mark.slow
def test_gpx_is_gpx_1_1_with_one_trkpt_per_position(real_dive, tmp_path):
    t = real_dive.track
    root = ET.parse(write_gpx(real_dive, tmp_path / "dive.gpx")).getroot()
    assert root.tag == f"{GPX}gpx" and root.get("version") == "1.1" and root.get("creator")
    (trk,) = root.findall(f"{GPX}trk")
    (seg,) = trk.findall(f"{GPX}trkseg")
    pts = seg.findall(f"{GPX}trkpt")
    rows = _expected_points(real_dive)
    assert len(pts) == len(rows)
    assert [float(p.get("lat")) for p in pts] == [t.lat_deg[r] for r in rows]
    assert [float(p.get("lon")) for p in pts] == [t.lon_deg[r] for r in rows]
    assert [float(p.find(f"{GPX}ele").text) for p in pts] == [-t.depth_m[r] for r in rows]
    assert [[c.tag for c in p] for p in pts[:1]] == [[f"{GPX}ele", f"{GPX}time"]]  # wptType: ele before time
    times = [np.datetime64(p.find(f"{GPX}time").text.rstrip("Z"), "ms").astype(np.int64) / 1e3 for p in pts]
    assert np.allclose(times, t.time_s[rows] + real_dive.unix_offset_s, rtol=0, atol=5.01e-4)


@pytest.mark.slow
def test_times_are_written_only_when_utc_is_known(dive_without_utc, tmp_path):
    dive = dive_without_utc
    assert dive.unix_offset_s is None and len(dive.track) > 100
    with open(write_csv(dive, tmp_path / "d.csv"), newline="") as f:
        assert {row["utc"] for row in csv.DictReader(f)} == {""}
    root = ET.parse(write_gpx(dive, tmp_path / "d.gpx")).getroot()
    assert root.findall(f".//{GPX}time") == []
    assert len(root.findall(f".//{GPX}trkpt")) == len(_expected_points(dive))
    doc = json.loads(write_geojson(dive, tmp_path / "d.geojson").read_text())
    assert {f["properties"].get("utc", "none") for f in doc["features"][1:]} == {None}
    assert doc["features"][0]["properties"]["start_utc"] is None


@pytest.mark.slow
def test_writes_replace_the_file_and_leave_no_temporary_files(real_dive, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    for write, name in ((write_csv, "d.csv"), (write_geojson, "d.geojson"), (write_gpx, "d.gpx")):
        (out / name).write_text("old")
        assert write(real_dive, out / name) == out / name
        assert (out / name).read_text() != "old"
    assert sorted(p.name for p in out.iterdir()) == ["d.csv", "d.geojson", "d.gpx"]


# -- edge cases on small logs ----------------------------------------------------------------------


@pytest.fixture()
def small_dive(tmp_path) -> Dive:
    """Unknown positions, repeats, a goal reached twice, then the next goal reached, written by the Recorder."""
    path = tmp_path / "small.mcap"
    with Recorder(path, metadata={"helm": {"goal_index": "0"}}) as rec:
        no_position = _decision(10.0, None, None, None, situation="no_position", action=None)
        rec.write(Topic.DECISION, 10.0, {**no_position, "cell": None})
        rec.write(Topic.DECISION, 10.5, _decision(10.5, 33.40, -117.90, 0.0))
        rec.write(Topic.DECISION, 11.0, _decision(11.0, 33.40, -117.90, 0.0))  # same position: one point
        rec.write(Topic.DECISION, 11.5, _decision(11.5, 33.41, -117.90, 5.0, situation="at_goal", action="AT_GOAL"))
        rec.write(Topic.DECISION, 12.0, _decision(12.0, 33.42, -117.90, 5.0, situation="at_goal", action="AT_GOAL"))
        rec.write(Topic.POLICY, 12.2, {"time_s": 12.2, "reason": "swapped", "goal_index": 1,
                                       "table_crc32": "0badf00d"})
        rec.write(Topic.DECISION, 12.5, _decision(12.5, 33.43, -117.90, 2.5))
        rec.write(Topic.DECISION, 13.0, _decision(13.0, 33.43, -117.90, 2.5, situation="at_goal", action="AT_GOAL"))
    return load_dive(open_dive(path))


def test_unknown_positions_and_repeats_are_left_out_and_goals_marked(small_dive, tmp_path):
    doc = json.loads(write_geojson(small_dive, tmp_path / "s.geojson").read_text())
    track, *points = doc["features"]
    # All in one 30 s window: the first fix, the window's median, the last fix, none within 2 m of a line.
    assert track["geometry"]["coordinates"] == [[-117.90, 33.40, 0.0], [-117.90, 33.415, -3.75],
                                                [-117.90, 33.43, -2.5]]
    # 0.03 deg due north in all: three arcs of R * 0.01 deg on a meridian.
    assert track["properties"]["distance_m"] == pytest.approx(3 * EARTH_RADIUS_M * math.radians(0.01), rel=1e-9)
    goals = [(p["properties"]["goal_index"], p["properties"]["time_s"]) for p in points
             if p["properties"]["kind"] == "goal"]
    assert goals == [(0, 11.5), (1, 13.0)]
    with open(write_csv(small_dive, tmp_path / "s.csv"), newline="") as f:
        first = next(csv.DictReader(f))
    assert [first[k] for k in ("lat_deg", "lon_deg", "depth_m", "action", "l", "j", "i", "k", "utc")] == [""] * 9
    gpx = ET.parse(write_gpx(small_dive, tmp_path / "s.gpx")).getroot()
    assert [float(p.get("lat")) for p in gpx.iter(f"{GPX}trkpt")] == [33.40, 33.41, 33.42, 33.43]


def test_a_dive_without_decisions_still_gives_valid_files(tmp_path):
    path = tmp_path / "quiet.mcap"
    with Recorder(path) as rec:
        rec.log(5.0, "info", "executive started")
    dive = load_dive(open_dive(path))
    with open(write_csv(dive, tmp_path / "q.csv"), newline="") as f:
        assert list(csv.reader(f)) == [list(CSV_COLUMNS)]
    doc = json.loads(write_geojson(dive, tmp_path / "q.geojson").read_text())
    assert doc["type"] == "FeatureCollection" and len(doc["features"]) == 1
    assert doc["features"][0]["geometry"] is None and doc["features"][0]["properties"]["distance_m"] == 0.0
    root = ET.parse(write_gpx(dive, tmp_path / "q.gpx")).getroot()
    assert root.findall(f".//{GPX}trkpt") == [] and root.find(f"{GPX}trk/{GPX}trkseg") is not None


@pytest.mark.parametrize("write", [write_csv, write_geojson, write_gpx])
def test_an_unwritable_path_raises_log_error_naming_it(small_dive, tmp_path, write):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    target = blocker / "dive.out"
    with pytest.raises(LogError, match=str(target)):
        write(small_dive, target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file", "small.mcap"]


@pytest.mark.slow
def test_replay_simplifies_the_geojson_to_the_tolerance_it_is_given(dive_log, tmp_path, capsys):
    from planner.cli import main as lrauv

    counts = {}
    for tolerance in ("0", "25"):
        out = tmp_path / f"t{tolerance}.geojson"
        assert lrauv(["replay", str(dive_log), "--no-audit", "--geojson", str(out), "--simplify-m", tolerance]) == 0
        props = json.loads(out.read_text())["features"][0]["properties"]
        assert props["simplified_m"] == float(tolerance)
        counts[tolerance] = props["points"]
    assert counts["25"] < counts["0"]
    capsys.readouterr()
    assert lrauv(["replay", str(dive_log), "--geojson", str(tmp_path / "x.geojson"), "--simplify-m", "-1"]) == 2
    assert "--simplify-m: expected metres >= 0; got -1.0" in capsys.readouterr().err
    assert not (tmp_path / "x.geojson").exists()
