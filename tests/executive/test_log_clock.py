"""The log's one clock (``executive.log_clock``): UTC log times from the autopilot's SYSTEM_TIME, vehicle time in
``boot_time_s``, records held until UTC is known, the host clock standing in (and saying so), reboots; and what
the loop logs for Foxglove: LocationFix heading and velocity, the map layers, a swap replacing the plan layer.

Real files read back with the official mcap reader; the loop's part with a real ``Executive`` fed parsed MAVLink
messages in this thread (``tests.executive.test_timeline.Vehicle``), so nothing depends on the machine's speed.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from executive import goal_tables
from executive.loop import Executive
from executive.recorder import Recorder, Topic
from tests.executive.test_timeline import T0, Vehicle

NS = 1_000_000_000
UNIX_US = 1_780_000_000_000_000  # the autopilot's UTC at vehicle time 2 s (2026-05-28)


def _raw(path: Path) -> tuple[list[tuple[str, int, dict[str, Any]]], list[tuple[str, dict[str, str]]]]:
    """(topic, log_time, payload) in file order, and the metadata records in order."""
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        messages = [(c.topic, m.log_time, json.loads(m.data)) for _, c, m in reader.iter_messages(log_time_order=False)]
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
    return messages, metadata


@pytest.mark.parametrize("background", [False, True])
def test_records_before_system_time_wait_for_it_and_get_its_utc(tmp_path, background):
    path = tmp_path / "held.mcap"
    rec = Recorder(path, background=background)
    rec.write(Topic.STATE, 0.0, {"time_s": 0.0})
    rec.location_fix(1.5, lat_deg=33.5, lon_deg=-118.0, depth_m=2.0)
    rec.log(1.75, "info", "before UTC")
    assert rec.clock_source is None and rec.messages_written == 0  # held, not written with a wrong date
    rec.system_time(0, 1.9)  # the autopilot has no UTC yet: nothing known
    assert rec.clock_source is None
    rec.system_time(UNIX_US, 2.0)
    rec.write(Topic.STATE, 3.0, {"time_s": 3.0})
    rec.close()
    messages, metadata = _raw(path)
    offset = UNIX_US * 1000 - 2 * NS
    assert [(t, log_time, p["boot_time_s"]) for t, log_time, p in messages] == [
        ("/vehicle/state", offset, 0.0), ("/vehicle/fix", offset + 1_500_000_000, 1.5),
        ("/log", offset + 1_750_000_000, 1.75), ("/vehicle/state", offset + 3 * NS, 3.0)]
    for _, log_time, p in messages[1:3]:  # Foxglove's timestamp is the log time, not the wall clock
        assert p["timestamp"] == {"sec": log_time // NS, "nsec": log_time % NS}
    assert metadata == [("clock", {"log_time": metadata[0][1]["log_time"], "source": "autopilot SYSTEM_TIME",
                                   "utc_offset_ns": str(offset), "held_records": "3", "changes": "0"})]


def test_without_system_time_the_host_clock_stands_in_and_the_log_says_so(tmp_path):
    path = tmp_path / "host.mcap"
    rec = Recorder(path)
    rec.write(Topic.STATE, 5.0, {"time_s": 5.0})
    rec.write(Topic.STATE, 6.0, {"time_s": 6.0})
    before = time.time_ns()
    rec.close()
    after = time.time_ns()
    (_, first, _), (_, last, _) = _raw(path)[0]
    assert before <= last <= after and last - first == NS  # the newest record at the host's clock when it closed
    [(name, clock)] = _raw(path)[1]
    assert (name, clock["source"], clock["held_records"]) == ("clock", "host clock", "2")


def test_the_hold_is_bounded_and_the_autopilot_clock_takes_over_later(tmp_path):
    path = tmp_path / "bound.mcap"
    rec = Recorder(path, max_held_records=3)
    for t in (1.0, 2.0):
        rec.write(Topic.STATE, t, {"time_s": t})
    assert rec.messages_written == 0
    rec.write(Topic.STATE, 3.0, {"time_s": 3.0})  # the bound: written at once, at the host's clock
    assert rec.messages_written == 3 and rec.clock_source == "host clock"
    rec.system_time(UNIX_US, 4.0)
    rec.write(Topic.STATE, 4.0, {"time_s": 4.0})
    rec.close()
    messages, metadata = _raw(path)
    assert messages[-1][1] == UNIX_US * 1000  # from SYSTEM_TIME on, its UTC
    assert [(n, m["source"], m["changes"]) for n, m in metadata] == [
        ("clock", "host clock", "0"), ("clock", "autopilot SYSTEM_TIME", "1")]  # readers keep the last


def test_jitter_keeps_the_offset_and_a_reboot_steps_it(tmp_path):
    path = tmp_path / "reboot.mcap"
    with Recorder(path) as rec:
        rec.system_time(UNIX_US, 2.0)
        rec.write(Topic.STATE, 100.0, {"time_s": 100.0})
        rec.system_time(UNIX_US + 98_000_400, 100.0)  # 400 us of SYSTEM_TIME jitter: the same clock
        rec.write(Topic.STATE, 101.0, {"time_s": 101.0})
        rec.write(Topic.STATE, 1.0, {"time_s": 1.0})  # rebooted: the last offset goes on
        rec.system_time(UNIX_US + 120 * 1_000_000, 2.0)  # the new boot's UTC
        rec.write(Topic.STATE, 3.0, {"time_s": 3.0})
    times = [log_time for _, log_time, _ in _raw(path)[0]]
    offset = UNIX_US * 1000 - 2 * NS
    assert times == [offset + 100 * NS, offset + 101 * NS, offset + NS, offset + 120 * NS + 3 * NS]


# -- the loop ---------------------------------------------------------------------------------


def test_the_loop_logs_at_the_autopilots_utc_with_heading_and_map_layers(demo_plan, tmp_path):
    table = demo_plan.table
    g = goal_tables.single(table).goals[0]
    # The second goal's table carries a nominal path (lrauv plan --start): it is drawn once that plan runs.
    path = ((-118.0, 33.5), (-117.9, 33.45), (table.goal_lon_deg, table.goal_lat_deg))
    plan = goal_tables.MissionPlan(goals=(g, g), tables=(table, replace(table, nominal_path=path)))
    v = Vehicle(table, tmp_path / "single.mcap")
    v.executive.close()
    v.executive = Executive(replace(v.executive.config, log_path=tmp_path / "exec.mcap"), plan)
    try:
        v.heartbeat()
        v.position()  # before SYSTEM_TIME: held
        v.system_time(T0 + v.time_ms / 1000.0)
        v.position()
        v._feed(v.mav.global_position_int_encode(v.time_ms + 500, 334_000_000, -1_180_000_000, -2_000, -2_000,
                                                 120, -50, 10, 27_000))  # NED cm/s, heading 270 deg
        ex = v.executive
        ex._propose(replace(plan, index=1), {"source": "next goal"})
        ex._swap(ex.clock.now_s(time.monotonic()))
        ex._write_later()
    finally:
        v.close()
    messages, metadata = _raw(tmp_path / "exec.mcap")
    system_time = next(p for t, _, p in messages if t == "/mavlink/rx" and p["name"] == "SYSTEM_TIME")
    offset = system_time["fields"]["time_unix_usec"] * 1000 - system_time["fields"]["time_boot_ms"] * 1_000_000
    assert offset == T0 * NS
    # One clock: every record's log time is its vehicle time plus the autopilot's offset, those before it too.
    assert all(log_time == round(p["boot_time_s"] * NS) + offset for _, log_time, p in messages)
    assert dict(metadata)["clock"]["source"] == "autopilot SYSTEM_TIME"

    fixes = [p for t, _, p in messages if t == "/vehicle/fix"]
    assert fixes[-1]["heading"] == pytest.approx(math.radians(270.0))  # radians clockwise from north
    assert fixes[-1]["velocity"] == {"x": -0.5, "y": 1.2, "z": -0.1}  # east, north, up in m/s
    assert all(0.0 <= f["heading"] < 2 * math.pi for f in fixes)

    layers: dict[str, list[dict[str, Any]]] = {}
    for t, _, p in messages:
        if t.startswith("/map/"):
            layers.setdefault(t, []).append(json.loads(p["geojson"]))
    fence, = layers["/map/geofence"]
    assert fence == {"type": "FeatureCollection", "features": []}  # this mission has none
    goals = layers["/map/goals"]
    assert [[f["properties"]["active"] for f in g["features"]] for g in goals] == [[True, False], [False, True]]
    assert goals[0]["features"][0]["geometry"]["coordinates"] == [table.goal_lon_deg, table.goal_lat_deg]  # lon, lat
    plans = layers["/map/plan"]  # written again at the swap: Foxglove shows the latest
    assert [[f["properties"]["name"] for f in p["features"]][-2:] for p in plans] == [
        ["goal cells", "goal 0 (running)"], ["goal 1 (running)", "nominal path"]]
    assert plans[1]["features"][-1]["geometry"] == {"type": "LineString", "coordinates": [list(p) for p in path]}
