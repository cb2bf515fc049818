"""The shared dive's log as Foxglove sees it: the dive's UTC, valid GeoJSON layers, a layout naming the log's
topics, schemas equal to the official ones; and an old log (vehicle log times) replaying as before."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from executive.log_topics import FOXGLOVE_SCHEMAS
from executive.recorder import Topic, recover
from planner.cli import main as lrauv
from planner.shore.replay.audit import audit
from planner.shore.replay.dive import load_dive
from planner.shore.replay.divelog import open_dive
from planner.shore.replay.layout import foxglove_layout, layout_topics
from planner.shore.replay.tlog import write_tlog
from tests.planner.shore.mcap_logs import as_old_format
from tests.support import REPO

NS = 1_000_000_000
NODE_DIR = REPO / "tests" / "node"


def _raw(path: Path) -> list[tuple[str, int, dict[str, Any]]]:
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, json.loads(m.data))
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


def test_the_dive_is_logged_at_the_autopilots_utc(dive_log):
    messages = _raw(dive_log)
    times = [p["fields"] for t, _, p in messages if t == "/mavlink/rx" and p["name"] == "SYSTEM_TIME"]
    offsets = [f["time_unix_usec"] * 1000 - f["time_boot_ms"] * 1_000_000 for f in times]
    assert offsets and all(abs(o - offsets[0]) < 1_000_000 for o in offsets)  # one boot, one clock (us jitter)
    assert all(log_time == round(p["boot_time_s"] * NS) + offsets[0] for _, log_time, p in messages)
    decisions = [p for t, _, p in messages if t == "/executive/decision"]
    assert all(d["boot_time_s"] == d["time_s"] for d in decisions)  # boot_time_s is the vehicle time
    assert open_dive(dive_log).clock == "UTC (autopilot SYSTEM_TIME)"


def test_the_map_layers_are_geojson_in_lon_lat_order(dive_log, demo_plan):
    layers = {t: json.loads(p["geojson"]) for t, _, p in _raw(dive_log) if t.startswith("/map/")}
    assert set(layers) == {t.value for t in (Topic.MAP_GOALS, Topic.MAP_GEOFENCE, Topic.MAP_PLAN)}
    table = demo_plan.table
    [goal] = layers["/map/goals"]["features"]
    assert goal["geometry"] == {"type": "Point", "coordinates": [table.goal_lon_deg, table.goal_lat_deg]}
    [fence] = layers["/map/geofence"]["features"]  # missions/demo.yaml's safety.geofence, counter-clockwise
    assert fence["geometry"]["coordinates"] == [[[-118.27, 33.29], [-117.69, 33.29], [-117.69, 33.71],
                                                 [-118.27, 33.71], [-118.27, 33.29]]]
    names = [f["properties"]["name"] for f in layers["/map/plan"]["features"]]
    assert names == ["plan grid", "land", "goal cells", "goal 0 (running)"]
    for layer in layers.values():
        for f in layer["features"]:
            for ring in _rings(f["geometry"]):
                assert ring[0] == ring[-1] and len(ring) >= 4  # closed (RFC 7946 3.1.6)
                assert all(-180 <= lon <= 180 and -90 <= lat <= 90 for lon, lat in ring)


def _rings(geometry: dict[str, Any]) -> list[list[list[float]]]:
    kind, c = geometry["type"], geometry["coordinates"]
    return c if kind == "Polygon" else [r for poly in c for r in poly] if kind == "MultiPolygon" else []


def test_the_layout_beside_the_log_names_its_topics(dive_log, tmp_path, capsys):
    layout = json.loads((Path(dive_log).parent / "demo.foxglove-layout.json").read_text())
    assert layout == foxglove_layout()
    with open(dive_log, "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert layout_topics(layout) <= topics
    assert {key.split("!")[0] for key in layout["configById"]} == {"map", "RosOut", "Plot", "StateTransitions",
                                                                    "RawMessages"}
    leaves: list[str] = []

    def walk(node: Any) -> None:
        if isinstance(node, str):
            leaves.append(node)
        else:
            walk(node["first"])
            walk(node["second"])
    walk(layout["layout"])
    assert sorted(leaves) == sorted(layout["configById"])
    out = tmp_path / "replay.foxglove-layout.json"
    assert lrauv(["replay", str(dive_log), "--no-audit", "--layout", str(out)]) == 0
    assert json.loads(out.read_text()) == layout and out.name in capsys.readouterr().out


def test_an_old_log_with_vehicle_log_times_replays_as_the_new_one(dive_log, tmp_path):
    old = as_old_format(Path(dive_log), tmp_path / "old.mcap")
    new_log, old_log = open_dive(dive_log), open_dive(old)
    assert old_log.clock == "vehicle time since boot"
    assert (old_log.first_log_time_s, old_log.last_log_time_s) == (new_log.first_log_time_s, new_log.last_log_time_s)
    new_dive, old_dive = load_dive(new_log), load_dive(old_log)
    assert list(old_dive.track.time_s) == list(new_dive.track.time_s)
    assert old_dive.unix_offset_s == new_dive.unix_offset_s
    assert [e.time_s for e in old_dive.events] == [e.time_s for e in new_dive.events]
    assert audit(old_log).clean and audit(old_log).decisions == audit(new_log).decisions
    # The .tlog: UTC from SYSTEM_TIME for the old, the log time for the new; the same instants.
    stamps = [_tlog_stamps(write_tlog(log, tmp_path / f"{n}.tlog").path) for n, log in (("old", old_log),
                                                                                         ("new", new_log))]
    assert stamps[0] == pytest.approx(stamps[1], abs=2e-6)
    assert recover(old, tmp_path / "rec.mcap").last_log_time_s == recover(dive_log, tmp_path / "rec2.mcap").last_log_time_s


def _tlog_stamps(path: Path) -> list[float]:
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(path))
    stamps = []
    while (m := conn.recv_match()) is not None:
        stamps.append(m._timestamp)
    conn.close()
    return stamps


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not on PATH: the vendored Foxglove schemas are"
                    " compared with the official package (@foxglove/schemas) under Node.js")
@pytest.mark.skipif(not (NODE_DIR / "node_modules" / "@foxglove" / "schemas" / "package.json").is_file(),
                    reason="tests/node/node_modules lacks @foxglove/schemas: run `make test` (npm ci --prefix tests/node)")
def test_the_vendored_foxglove_schemas_are_the_official_ones():
    node = shutil.which("node")
    assert node is not None
    done = subprocess.run([node, "foxglove_schemas.mjs", "--print"], cwd=NODE_DIR, capture_output=True, text=True,
                          timeout=60, check=True)
    official = json.loads(done.stdout)
    assert list(official) == list(FOXGLOVE_SCHEMAS)
    for name, schema in official.items():
        assert json.loads((REPO / "executive" / "foxglove_schemas" / f"{name}.json").read_text()) == schema, name
    assert Topic.FIX.schema == official["LocationFix"] and Topic.LOG.schema == official["Log"]
    assert Topic.MAP_PLAN.schema == official["GeoJSON"]
