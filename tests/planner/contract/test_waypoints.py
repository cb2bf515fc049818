"""Goals as MAVLink mission items and QGC WPL 110 files (planner/contract/waypoints.py, docs/missions.md)."""

from __future__ import annotations

import argparse
import os
import random
import struct
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavwp  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from planner.contract.arguments import CommandParser  # noqa: E402
from planner.contract.errors import MissionError, LrauvError  # noqa: E402
from planner.contract.mission import MAX_GOALS, MissionGoal, goals_to_items, items_to_goals, load_mission  # noqa: E402
from planner.contract.settings import Goal  # noqa: E402
from planner.contract.waypoints import (  # noqa: E402
    COMMAND_NAMES,
    MissionResult,
    WaypointError,
    parse_wpl,
    read_wpl,
    wpl_frame,
    write_wpl,
)
from planner.cli.waypoints import add_parser, run  # noqa: E402
from planner.shore.waypoints import replace_goals  # noqa: E402
from tests.support import REPO

DEMO = REPO / "missions" / "demo.yaml"
HOME = {"home_lat_deg": 33.45, "home_lon_deg": -118.1}


def goal(lat: float, lon: float, depth: float, radius: int = 1, on_arrival: str = "hold") -> MissionGoal:
    return MissionGoal(goal=Goal(lon_deg=lon, lat_deg=lat, depth_m=depth, radius_cells=radius), on_arrival=on_arrival)  # type: ignore[arg-type]


GOALS = (
    goal(33.40, -117.80, 0.0),
    goal(33.5123456, -117.9876543, 12.3, 2, "surface"),
    goal(-33.6, 151.2, 15.0, 0, "drift"),
    goal(33.45, -118.0000001, 5.0, 3, "next"),
)


def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


# Encoding.

def test_goals_round_trip_through_items_with_the_documented_encoding():
    items = goals_to_items(GOALS, **HOME)
    assert len(items) == len(GOALS) + 1
    home = items[0]
    assert (home.seq, home.frame, home.command, home.current, home.autocontinue, home.z) == (0, 0, 16, 1, 1, 0.0)
    assert (home.x_lat_e7, home.y_lon_e7) == (334500000, -1181000000)
    second = items[2]
    assert (second.seq, second.frame, second.command, second.current) == (2, 6, 16, 0)
    assert (second.param1, second.param2, second.param3, second.param4) == (0.0, 2.0, 1.0, 0.0)
    assert (second.x_lat_e7, second.y_lon_e7, second.z) == (335123456, -1179876543, -12.3)
    assert [it.param3 for it in items[1:]] == [0.0, 1.0, 2.0, 3.0]
    assert items_to_goals(items) == GOALS


def test_float32_on_the_wire_decodes_to_the_typed_depth():
    items = goals_to_items(GOALS, **HOME)
    wire = tuple(replace(it, z=_f32(it.z), param2=_f32(it.param2), param3=_f32(it.param3)) for it in items)
    assert wire[2].z != -12.3  # float32 of 12.3 is 12.300000190734863
    assert items_to_goals(wire) == GOALS


def test_goals_to_items_refuses_a_longitude_that_does_not_fit():
    with pytest.raises(WaypointError, match=r"goal 0: longitude 200"):
        goals_to_items((goal(33.0, 200.0, 0.0),), **HOME)


def _bad(items, **change):  # type: ignore[no-untyped-def]
    """The goal items with item 2 changed."""
    out = list(items)
    out[2] = replace(out[2], **change)
    return tuple(out)


@pytest.mark.parametrize(
    ("change", "message", "result"),
    [
        ({"command": 22}, "item 2: command 22 (NAV_TAKEOFF) is not a goal; expected 16 (NAV_WAYPOINT)",
         MissionResult.UNSUPPORTED),
        ({"frame": 10}, "item 2: frame 10 (GLOBAL_TERRAIN_ALT) is not supported", MissionResult.UNSUPPORTED_FRAME),
        ({"z": 5.0}, "item 2: z 5 m is above the surface; expected z <= 0", MissionResult.INVALID_PARAM7),
        ({"x_lat_e7": 950000000}, "item 2: latitude 95.0000000 deg is out of range", MissionResult.INVALID_PARAM5_X),
        ({"y_lon_e7": -1900000000}, "item 2: longitude -190.0000000 deg is out of range", MissionResult.INVALID_PARAM6_Y),
        ({"param2": 1.5}, "item 2: param2 (radius_cells) 1.5 is not a whole number >= 0", MissionResult.INVALID_PARAM2),
        ({"param2": -1.0}, "item 2: param2 (radius_cells) -1 is not a whole number >= 0", MissionResult.INVALID_PARAM2),
        ({"param3": 7.0}, "item 2: param3 (on_arrival) 7 is not a known code; expected 0 hold, 1 surface, 2 drift, 3 next",
         MissionResult.INVALID_PARAM3),
        ({"param1": 5.0}, "item 2: param1 (hold time) 5 s is not supported", MissionResult.INVALID_PARAM1),
        ({"seq": 5}, "item 5: out of sequence; expected seq 2", MissionResult.INVALID_SEQUENCE),
        ({"mission_type": 1}, "item 2: mission_type 1 is not a mission", MissionResult.UNSUPPORTED),
    ],
)
def test_items_to_goals_names_the_item_and_what_is_wrong(change, message, result):  # type: ignore[no-untyped-def]
    with pytest.raises(WaypointError) as info:
        items_to_goals(_bad(goals_to_items(GOALS, **HOME), **change))
    assert str(info.value).startswith(message)
    assert info.value.result == result
    assert isinstance(info.value, LrauvError)


def test_items_to_goals_needs_one_to_max_goals_goals():
    items = goals_to_items(GOALS, **HOME)
    with pytest.raises(WaypointError, match="no goals") as info:
        items_to_goals(items[:1])
    assert info.value.result == MissionResult.INVALID
    with pytest.raises(WaypointError, match="clearing the goals is not supported") as info:
        items_to_goals(())  # MISSION_CLEAR_ALL
    assert info.value.result == MissionResult.UNSUPPORTED
    many = goals_to_items([GOALS[0]] * (MAX_GOALS + 1), **HOME)
    with pytest.raises(WaypointError, match=f"{MAX_GOALS + 1} goals: expected at most {MAX_GOALS}") as info:
        items_to_goals(many)
    assert info.value.result == MissionResult.NO_SPACE
    assert len(items_to_goals(many[:-1])) == MAX_GOALS


def test_tables_agree_with_pymavlink():
    for code, name in COMMAND_NAMES.items():
        assert mavlink.enums["MAV_CMD"][code].name == f"MAV_CMD_{name}"
    for result in MissionResult:
        assert mavlink.enums["MAV_MISSION_RESULT"][result.value].name == result.mav_name


def test_the_onboard_modules_stay_light():
    probe = ("import sys\nimport planner.contract.waypoints, executive.mission_protocol\n"
             "print(','.join(m for m in ('xarray', 'scipy', 'numba', 'numpy', 'yaml', 'pymavlink', 'planner.contract.mission')"
             " if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=REPO).stdout
    assert loaded.strip() == ""


# QGC WPL 110 files.

def test_wpl_write_read_round_trip_is_exact(tmp_path):
    rnd = random.Random(7)
    goals = tuple(goal(rnd.uniform(-90, 90), rnd.uniform(-180, 180), rnd.choice([0.0, 2.5, 7.25, 14.9]),
                       rnd.randrange(4), rnd.choice(["hold", "surface", "drift", "next"])) for _ in range(200))
    items = goals_to_items(goals, home_lat_deg=-12.3456789, home_lon_deg=179.9999999)
    path = write_wpl(tmp_path / "m.waypoints", items)
    text = path.read_text()
    assert text.startswith("QGC WPL 110\n0\t1\t0\t16\t")
    assert "\t3\t16\t" in text.splitlines()[1 + 1]  # goals in frame 3, as QGC writes
    back = read_wpl(path)
    assert back == tuple(replace(it, frame=wpl_frame(it.frame)) for it in items)  # degE7 exact: 1e-7 degree
    assert items_to_goals(back) == tuple(
        goal(round(g.goal.lat_deg * 1e7) / 1e7, round(g.goal.lon_deg * 1e7) / 1e7, g.goal.depth_m,
             g.goal.radius_cells, g.on_arrival) for g in goals)
    assert not list(tmp_path.glob(".*.tmp"))  # atomic write leaves nothing behind


def test_a_written_file_loads_in_pymavlink_mavwp_with_the_same_items(tmp_path):
    items = goals_to_items(GOALS, **HOME)
    path = write_wpl(tmp_path / "m.waypoints", items)
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(path)) == len(items)
    for it in items:
        w = loader.wp(it.seq)
        assert (w.seq, w.frame, w.command, w.current, w.autocontinue) == (it.seq, wpl_frame(it.frame), it.command,
                                                                          it.current, it.autocontinue)
        assert (w.param1, w.param2, w.param3, w.param4, w.z) == (it.param1, it.param2, it.param3, it.param4, it.z)
        assert round(w.x * 1e7) == it.x_lat_e7 and round(w.y * 1e7) == it.y_lon_e7


def test_a_file_saved_by_mavwp_reads_back(tmp_path):
    items = goals_to_items(GOALS, **HOME)
    loader = mavwp.MAVWPLoader()
    loader.load(str(write_wpl(tmp_path / "a.waypoints", items)))
    loader.save(str(tmp_path / "b.waypoints"))  # MAVProxy's `wp save`: %f, 6 decimals
    back = read_wpl(tmp_path / "b.waypoints")
    assert items_to_goals(back)[0] == GOALS[0]
    assert [g.on_arrival for g in items_to_goals(back)] == [g.on_arrival for g in GOALS]


def test_comments_blank_lines_crlf_and_nan_yaw_are_read(tmp_path):
    text = ("QGC WPL 110\r\n# home\r\n0\t1\t0\t16\t0\t0\t0\t0\t33.4\t-117.8\t0\t1\r\n\r\n"
            "1\t0\t3\t16\t0\t1\t2\tnan\t33.41\t-117.81\t-5\t1\r\n")
    (tmp_path / "q.waypoints").write_bytes(text.encode())
    items = read_wpl(tmp_path / "q.waypoints")
    assert items_to_goals(items) == (goal(33.41, -117.81, 5.0, 1, "drift"),)


@pytest.mark.parametrize(
    ("text", "where", "message"),
    [
        ("", ":1:", "header missing; expected 'QGC WPL 110'"),
        ("QGC WPL 100\n", ":1:", "header 'QGC WPL 100' is not supported"),
        ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t33.4\t-117.8\t0\n", ":2:", "11 columns; expected 12 tab-separated"),
        ("QGC WPL 110\n# c\n0\t1\t0\t16\t0\t0\t0\t0\tabc\t-117.8\t0\t1\n", ":3:", "LAT 'abc' is not a number"),
        ("QGC WPL 110\n0\t1\t0.5\t16\t0\t0\t0\t0\t33\t-117.8\t0\t1\n", ":2:", "COORD_FRAME '0.5' is not a whole number"),
        ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t33\t-117.8\t0\t1\n2\t0\t3\t16\t0\t0\t0\t0\t33\t-117.8\t0\t1\n", ":3:",
         "INDEX 2 out of sequence; expected 1"),
        ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\tnan\t-117.8\t0\t1\n", ":2:", "LAT 'nan' is not a position in degrees"),
    ],
)
def test_file_errors_name_the_file_and_line(tmp_path, text, where, message):  # type: ignore[no-untyped-def]
    path = tmp_path / "bad.waypoints"
    path.write_text(text)
    with pytest.raises(WaypointError) as info:
        read_wpl(path)
    assert str(info.value).startswith(f"{path}{where} {message}")


def test_missing_file_is_named(tmp_path):
    with pytest.raises(WaypointError, match="nope.waypoints: no such waypoint file"):
        read_wpl(tmp_path / "nope.waypoints")
    assert parse_wpl("QGC WPL 110\n") == ()


# lrauv waypoints export / import.

def _cli(argv: list[str]) -> int:
    parser = CommandParser(prog="lrauv")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    assert isinstance(args, argparse.Namespace)
    return run(args)


def _mission_with_goals(tmp_path: Path, goals_text: str, forecast: str = "synthetic: {seed: 0, hours: 24}") -> Path:
    text = DEMO.read_text()
    start = text.index("goals:")
    end = text.index("replanning:")
    text = text[:start] + goals_text + text[end:]
    text = text.replace("synthetic: {seed: 0, hours: 72}", forecast)
    path = tmp_path / "base" / "base.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(text)
    return path


def test_export_then_import_gives_the_same_goals_and_keeps_the_rest(tmp_path, capsys):
    base = _mission_with_goals(tmp_path, (
        "goals:\n"
        "  # three goals\n"
        "  - lat_deg: 33.4\n    lon_deg: -117.8\n    depth_m: 0\n"
        "  - {lat_deg: 33.5123456, lon_deg: -117.9876543, depth_m: 12.3, radius_cells: 2, on_arrival: surface}\n"
        "  - {lat_deg: 33.6, lon_deg: -118.2, depth_m: 15, radius_cells: 0, on_arrival: next}  # last\n"))
    mission = load_mission(base)
    wpl = tmp_path / "out" / "m.waypoints"
    assert _cli(["waypoints", "export", str(base), str(wpl), "--home", "-118.1,33.45"]) == 0
    assert "home and 3 goals" in " ".join(capsys.readouterr().out.split())  # lines over 100 columns wrap
    assert read_wpl(wpl)[0].x_lat_e7 == 334500000
    out = tmp_path / "new" / "new.yaml"
    assert _cli(["waypoints", "import", str(wpl), "--mission", str(base), "--out", str(out)]) == 0
    imported = load_mission(out)
    assert imported.goals == mission.goals
    assert repr((imported.region, imported.vehicle, imported.safety, imported.settings)) == repr(
        (mission.region, mission.vehicle, mission.safety, mission.settings))  # BBox compares by identity
    before, after = base.read_text().splitlines(), out.read_text().splitlines()
    keep = [line for line in before if not line.startswith(("  -", "    ", "  #"))]
    assert [line for line in after if not line.startswith("  - {")] == [
        line for line in keep if line != "  - {lat_deg: 33.6, lon_deg: -118.2, depth_m: 15, radius_cells: 0, on_arrival: next}  # last"]
    assert "  - {lat_deg: 33.5123456, lon_deg: -117.9876543, depth_m: 12.3, radius_cells: 2, on_arrival: surface}" in after


def test_export_puts_home_at_the_first_goal_by_default(tmp_path):
    wpl = tmp_path / "demo.waypoints"
    assert _cli(["waypoints", "export", str(DEMO), str(wpl)]) == 0
    items = read_wpl(wpl)
    assert (items[0].x_lat_e7, items[0].y_lon_e7) == (items[1].x_lat_e7, items[1].y_lon_e7) == (334000000, -1178000000)


def test_import_into_another_folder_rebases_relative_forecast_paths(tmp_path):
    base = _mission_with_goals(tmp_path, "goals: [{lat_deg: 33.4, lon_deg: -117.8, depth_m: 0}]\n",
                               forecast="file: data/forecast.nc")
    wpl = write_wpl(tmp_path / "m.waypoints", goals_to_items(GOALS[:1], **HOME))
    out = tmp_path / "elsewhere" / "deeper" / "new.yaml"
    _cli(["waypoints", "import", str(wpl), "--mission", str(base), "--out", str(out)])
    assert load_mission(out).forecast.file.resolve() == load_mission(base).forecast.file.resolve()
    assert '"../../base/data/forecast.nc"' in out.read_text()
    same = tmp_path / "base" / "same.yaml"
    _cli(["waypoints", "import", str(wpl), "--mission", str(base), "--out", str(same)])
    assert "file: data/forecast.nc" in same.read_text()


def test_replace_goals_handles_flow_and_end_of_file_lists():
    g = (goal(1.5, 2.25, 3.0, 1, "drift"),)
    assert replace_goals("name: x\ngoals: [{lat_deg: 1}]  # c\nsafety: {}\n", g) == (
        "name: x\ngoals:\n  - {lat_deg: 1.5, lon_deg: 2.25, depth_m: 3, radius_cells: 1, on_arrival: drift}  # c\nsafety: {}\n")
    assert replace_goals("name: x\ngoals:\n- {a: 1}\n- {a: 2}", g).endswith("on_arrival: drift}")
    with pytest.raises(MissionError, match="no top-level goals"):
        replace_goals("name: x\n", g)


def test_import_errors_raise_planner_errors_naming_the_file(tmp_path):
    base = _mission_with_goals(tmp_path, "goals: [{lat_deg: 33.4, lon_deg: -117.8, depth_m: 0}]\n")
    out = tmp_path / "new.yaml"
    items = goals_to_items(GOALS, **HOME)
    takeoff = write_wpl(tmp_path / "takeoff.waypoints", _bad(items, command=22))
    with pytest.raises(WaypointError, match=r"takeoff.waypoints: item 2: command 22 \(NAV_TAKEOFF\) is not a goal"):
        _cli(["waypoints", "import", str(takeoff), "--mission", str(base), "--out", str(out)])
    deep = write_wpl(tmp_path / "deep.waypoints", goals_to_items((goal(33.4, -117.8, 40.0),), **HOME))
    with pytest.raises(WaypointError, match="deep.waypoints: item 1: depth 40 m is deeper than the deepest layer 15 m"):
        _cli(["waypoints", "import", str(deep), "--mission", str(base), "--out", str(out)])
    far = write_wpl(tmp_path / "far.waypoints", goals_to_items((goal(40.0, -117.8, 0.0),), **HOME))
    with pytest.raises(WaypointError, match=r"far.waypoints: item 1: \(-117.8, 40\) lies outside the region "
                                            r"-118.26,33.3,-117.7,33.7 of .*: no plan could reach it"):
        _cli(["waypoints", "import", str(far), "--mission", str(base), "--out", str(out)])
    assert not out.exists()
    bad = tmp_path / "bad.waypoints"
    bad.write_text("QGC WPL 110\n0 1 0\n")
    with pytest.raises(LrauvError, match=r"bad.waypoints:2: 3 columns"):
        _cli(["waypoints", "import", str(bad), "--mission", str(base), "--out", str(out)])
    with pytest.raises(MissionError, match="no such mission file"):
        _cli(["waypoints", "export", str(tmp_path / "none.yaml"), str(tmp_path / "x.waypoints")])
    assert not out.exists()
    with pytest.raises(SystemExit):
        _cli(["waypoints", "export", str(DEMO), str(tmp_path / "x.waypoints"), "--home", "1,2,3"])


def test_a_base_mission_on_0_to_360_longitudes_takes_waypoints_on_minus_180_to_180(tmp_path):
    base = _mission_with_goals(tmp_path, "goals: [{lat_deg: 33.4, lon_deg: 242.2, depth_m: 0}]\n")
    text = base.read_text()
    assert "bbox: [-118.26, 33.30, -117.70, 33.70]" in text
    base.write_text(text.replace("bbox: [-118.26, 33.30, -117.70, 33.70]", "bbox: [241.74, 33.30, 242.30, 33.70]"))
    wpl = write_wpl(tmp_path / "goals.waypoints", goals_to_items((goal(33.4, -117.8, 0.0),), **HOME))
    out = tmp_path / "new.yaml"
    assert _cli(["waypoints", "import", str(wpl), "--mission", str(base), "--out", str(out)]) == 0
    assert "lon_deg: -117.8" in out.read_text()


def test_waypoints_the_planner_would_refuse_are_refused_at_import(tmp_path):
    # A region across 180 deg is planned on the longitudes it is written in (planner.grid.vehicle_longitudes):
    # a waypoint at 179.9 lies on its grid; one at -179.75 (-180..180, as waypoints are) does not, for the
    # planner as for the import.
    from planner.grid import Grid, vehicle_longitudes

    base = _mission_with_goals(tmp_path, "goals: [{lat_deg: 33.4, lon_deg: 180.2, depth_m: 0}]\n")
    base.write_text(base.read_text().replace("bbox: [-118.26, 33.30, -117.70, 33.70]", "bbox: [179.74, 33.30, 180.30, 33.70]"))
    mission = load_mission(base)
    grid = Grid.from_bbox(vehicle_longitudes(mission.region.bbox), nx=mission.region.nx, ny=mission.region.ny,
                          depths_m=list(mission.region.depths_m))
    assert grid.nearest_cell(179.9, 33.4)[2] <= 0.5 < grid.nearest_cell(-179.75, 33.4)[2]
    out = tmp_path / "new.yaml"
    on = write_wpl(tmp_path / "on.waypoints", goals_to_items((goal(33.4, 179.9, 0.0),), **HOME))
    assert _cli(["waypoints", "import", str(on), "--mission", str(base), "--out", str(out)]) == 0
    across = write_wpl(tmp_path / "across.waypoints", goals_to_items((goal(33.4, -179.75, 0.0),), **HOME))
    with pytest.raises(WaypointError, match=r"across.waypoints: item 1: \(-179.75, 33.4\) lies outside the region"):
        _cli(["waypoints", "import", str(across), "--mission", str(base), "--out", str(tmp_path / "x.yaml")])
