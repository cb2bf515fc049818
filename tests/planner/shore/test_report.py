"""The post-dive report (``planner.shore.replay.report``) on a real closed-loop log, and its track segmentation by hand.

The log is the shared real closed-loop run (``dive_log`` in conftest.py): ``lrauv
sim`` and ``lrauv exec`` over UDP on 127.0.0.1 at 1000x, from two cells west of
the demo goal to the goal.
"""

from __future__ import annotations

import html
import json
import re
import struct
from pathlib import Path

import numpy as np
import pytest

from planner.shore.replay.audit import logged_tables
from planner.shore.replay.dive import Track, load_dive
from planner.shore.replay.divelog import open_dive
from planner.shore.replay.report import ActionRun, action_runs, track_segments, write_report
from planner.contract.actions import Action
from planner.shore.plots.style import ACTION_COLORS


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SUMMARY = "goal       reached <after> 0.4 h & 1.2 Wh\n\"quoted\" 'text'"


@pytest.fixture(scope="module")
def dive(dive_log):  # type: ignore[no-untyped-def]
    return load_dive(open_dive(dive_log))


def _png_size(path: Path) -> tuple[int, int]:
    """(width, height) from the IHDR chunk, after checking the signature."""
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path.name} is not a PNG"
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def _check_pictures(index: Path, expected: set[str]) -> str:
    page = index.read_text(encoding="utf-8")
    assert set(re.findall(r'<img src="([^"]+)"', page)) == expected
    for name in expected:
        width, height = _png_size(index.parent / name)
        assert 600 <= width <= 3000 and 400 <= height <= 3000, (name, width, height)
        image = pytest.importorskip("matplotlib.image").imread(index.parent / name)
        assert image.shape[:2] == (height, width)
        assert float(np.ptp(image[..., :3])) > 0.5  # not a blank picture
    assert not list(index.parent.glob(".*.tmp"))  # atomic writes left no temporary file
    return page


def test_report_with_the_plan(dive, demo_plan, tmp_path):
    assert len(dive.track) > 50 and any(a == "FORWARD" for a in dive.track.action)
    index = write_report(dive, tmp_path / "report", tables=logged_tables(dive.log), plan=demo_plan,
                         summary_text=SUMMARY)
    assert index == tmp_path / "report" / "index.html"
    page = _check_pictures(index, {"track.png", "timeseries.png", "cost.png"})
    assert f"<pre>{html.escape(SUMMARY)}</pre>" in page
    assert "<after>" not in page
    assert dive.log.path.name in page
    assert "not drawn" not in page and "pass --forecast" not in page


def test_report_without_the_plan_notes_what_is_missing(dive, tmp_path):
    index = write_report(dive, tmp_path, tables=logged_tables(dive.log), plan=None, summary_text=SUMMARY)
    page = _check_pictures(index, {"track.png", "timeseries.png"})
    assert not (tmp_path / "cost.png").exists()
    notes = page[page.index("<h2>Notes</h2>"):page.index("<h2>Pictures</h2>")]
    assert "cost.png</code>: not drawn: the predicted cost-to-go needs the planning forecast" in notes
    assert "track.png</code>: drawn without currents and the nominal path" in notes
    assert "map</code>: the map has no currents: they need the planning forecast" in notes
    assert notes.count("pass --forecast") == 3
    assert f"<pre>{html.escape(SUMMARY)}</pre>" in page


def test_report_replaces_an_earlier_one(dive, demo_plan, tmp_path):
    tables = logged_tables(dive.log)
    write_report(dive, tmp_path, tables=tables, plan=None, summary_text="report one")
    index = write_report(dive, tmp_path, tables=tables, plan=demo_plan, summary_text="report two")
    page = _check_pictures(index, {"track.png", "timeseries.png", "cost.png"})
    assert "<pre>report two</pre>" in page and "report one" not in page


def test_report_with_a_plan_of_a_table_the_dive_never_used(dive, demo_plan, tmp_path):
    """No logged table has the plan's actions (none is given): no prediction; the map comes from the plan's table."""
    assert set(dive.track.table_crc32) == {f"{demo_plan.table.crc32:08x}"}
    index = write_report(dive, tmp_path, tables={}, plan=demo_plan, summary_text="")
    page = _check_pictures(index, {"track.png", "timeseries.png"})
    assert f"cost.png</code>: not drawn: no decision under the planned table ({demo_plan.table.crc32:08x})" in page
    assert "track.png</code>: drawn without the nominal path" in page


def test_report_header_names_the_mission_the_utc_times_the_verdict_and_links_the_exports(dive, demo_plan, tmp_path):
    from planner.shore.replay.export import write_csv, write_geojson

    exports = [write_csv(dive, tmp_path / "out" / "dive.csv"), write_geojson(dive, tmp_path / "out" / "dive.geojson")]
    verdict = "audit      12 decisions run again with 1 logged table(s), 0 swap(s): no difference"
    index = write_report(dive, tmp_path / "report", tables=logged_tables(dive.log), plan=demo_plan,
                         summary_text=SUMMARY, audit_text=verdict, exports=exports)
    page = index.read_text(encoding="utf-8")
    head = page[page.index('<table class="head">'):page.index("</table>")]
    mission = dive.log.metadata["executive"]["mission"]
    assert f"<tr><th>Mission</th><td>{html.escape(mission)}</td></tr>" in head
    start = np.datetime64(round(dive.utc_s(float(dive.track.time_s[0]))), "s")
    end = np.datetime64(round(dive.utc_s(float(np.max(dive.track.time_s)))), "s")
    assert f"<tr><th>Start</th><td>{str(start).replace('T', ' ')} UTC" in head
    assert f"<tr><th>End</th><td>{str(end).replace('T', ' ')} UTC" in head
    assert '<span class="ok">12 decisions run again with 1 logged table(s), 0 swap(s): no difference</span>' in head
    links = re.findall(r'<a href="([^"]+)">', head)
    assert links == ["../out/dive.csv", "../out/dive.geojson"]
    assert all((index.parent / link).resolve() == e.resolve() for link, e in zip(links, exports))
    # The executive's and the autopilot's failsafes have their own section, before the map.
    assert page.index("Failsafes and autopilot messages") < page.index('<svg id="dive-map"')
    assert "failsafes  0 (none from the autopilot or the executive)" in page
    without = write_report(dive, tmp_path / "plain", tables=logged_tables(dive.log), plan=None, summary_text="")
    head = without.read_text(encoding="utf-8").split("</table>")[0]
    assert "<tr><th>Audit</th><td>not run (--no-audit)</td></tr>" in head and "none written" in head


def test_report_map_is_interactive_self_contained_and_draws_track_goal_geofence_currents(dive, demo_plan, tmp_path):
    index = write_report(dive, tmp_path, tables=logged_tables(dive.log), plan=demo_plan, summary_text=SUMMARY)
    page = index.read_text(encoding="utf-8")
    # Offline: nothing is fetched. No URL at all, no external script, style sheet, font or frame.
    assert not re.search(r"https?:|//[a-z]", page, flags=re.IGNORECASE)
    assert not re.search(r"<(script|link|iframe|object|embed)[^>]*\b(src|href)=", page, flags=re.IGNORECASE)
    assert not re.search(r"@import|url\(|fetch\(|XMLHttpRequest", page)
    assert set(re.findall(r'\bsrc="([^"]+)"', page)) == {"track.png", "timeseries.png", "cost.png"}
    svg = page[page.index('<svg id="dive-map"'):page.index("</svg>")]
    for layer in ("map-land", "map-currents", "map-geofence", "map-goal", "map-track", "map-ends"):
        assert f'id="{layer}"' in svg, layer
    # The track: a polyline per run of one action, coloured by it, the rows' order kept.
    runs = re.findall(r'<polyline class="track" data-action="([^"]*)" points="([^"]+)" stroke="(#[0-9a-f]{6})"', svg)
    assert [a for a, _, _ in runs] == [s.action or "" for s in track_segments(dive.track)]
    assert {c for a, _, c in runs if a == "FORWARD"} == {ACTION_COLORS[Action.FORWARD]}
    # The goal marker sits on the goal of the table, in the map's metres; the fence is the helm's.
    fence = json.loads(dive.log.metadata["helm"]["config"])["geofence"]
    assert len(re.search(r'id="map-geofence" points="([^"]+)"', svg).group(1).split()) == len(fence)
    assert len(re.findall(r"<path d=", svg)) > 20  # current arrows
    assert "forecast of " + demo_plan.table.forecast_time in page
    # Pan and zoom: a script that moves the viewBox on wheel and drag, and buttons.
    script = page[page.index("<script>"):page.index("</script>")]
    assert "viewBox" in script and '"wheel"' in script and '"pointermove"' in script
    assert page.count('<button type="button" data-zoom=') == 3


# --------------------------------------------------------------------------- segmentation by hand


def _track(actions: list[str | None], lat: list[float]) -> Track:
    n = len(actions)
    f = np.arange(n, dtype=np.float64)
    return Track(time_s=f, wall_s=f, lat_deg=np.asarray(lat, dtype=np.float64), lon_deg=-118.0 + 0.01 * f,
                 depth_m=np.zeros(n), heading_deg=np.full(n, 90.0), situation=("following",) * n,
                 action=tuple(actions), mode=("GUIDED",) * n, cell=np.full((n, 4), -1, dtype=np.int64),
                 energy_used_wh=f, battery_pct=np.full(n, 100.0), goal_index=np.zeros(n, dtype=np.int64),
                 changed=np.ones(n, dtype=bool), table_crc32=("0badc0de",) * n)


def test_action_runs_merge_equal_neighbours():
    assert action_runs([]) == []
    assert action_runs(["FORWARD", "FORWARD", "DRIFT", None, None, "FORWARD"]) == [
        ActionRun(0, 2, "FORWARD"), ActionRun(2, 3, "DRIFT"), ActionRun(3, 5, None), ActionRun(5, 6, "FORWARD")]


def test_track_segments_by_action_join_the_next_run_and_skip_rows_without_position():
    """Rows 0..7: F F F D D - - F with no position at row 1 (not following = None).

    Each polyline runs from its run's first row to the next run's first row, so
    F covers 0, 2, 3 (row 1 has no position), D 3..5, None 5..7, and the last F
    is the single row 7.
    """
    nan = float("nan")
    track = _track(["FORWARD", "FORWARD", "FORWARD", "DRIFT", "DRIFT", None, None, "FORWARD"],
                   [33.0, nan, 33.0, 33.0, 33.0, 33.0, 33.0, 33.0])
    segments = track_segments(track)
    assert [s.action for s in segments] == ["FORWARD", "DRIFT", None, "FORWARD"]
    assert [s.rows.tolist() for s in segments] == [[0, 2, 3], [3, 4, 5], [5, 6, 7], [7]]


def test_track_segments_merge_across_a_row_without_position():
    nan = float("nan")
    track = _track(["DRIFT", "FORWARD", "DRIFT", "DRIFT"], [33.0, nan, 33.0, 33.0])
    segments = track_segments(track)
    assert [(s.action, s.rows.tolist()) for s in segments] == [("DRIFT", [0, 2, 3])]


def test_track_segments_thin_long_runs_but_keep_every_boundary():
    actions = ["DRIFT"] * 5000 + ["ROTATE_LEFT"] * 3 + ["FORWARD"] * 5000
    track = _track(actions, [33.0] * len(actions))
    segments = track_segments(track, max_points=200)
    assert [s.action for s in segments] == ["DRIFT", "ROTATE_LEFT", "FORWARD"]
    drift, rotate, forward = (s.rows.tolist() for s in segments)
    assert drift[0] == 0 and drift[-2:] == [4999, 5000] and len(drift) <= 110
    assert rotate == [5000, 5002, 5003]  # first and last of the run (5001 thinned out), then the next run
    assert forward[0] == 5003 and forward[-1] == 10002 and len(forward) <= 110
    for s in segments:
        assert np.all(np.diff(s.rows) > 0)


def test_track_segments_stay_bounded_when_the_action_changes_every_row():
    actions = ["FORWARD", "DRIFT"] * 5000
    track = _track(actions, [33.0] * len(actions))
    segments = track_segments(track, max_points=300)
    points = sum(s.rows.size for s in segments)
    assert points <= 2 * 300 + 2
    assert segments[0].rows[0] == 0 and segments[-1].rows[-1] == len(actions) - 1
    # Consecutive polylines join: each starts where the previous one ended.
    for a, b in zip(segments[:-1], segments[1:]):
        assert a.rows[-1] == b.rows[0]


def test_track_segments_of_a_track_without_positions_is_empty():
    nan = float("nan")
    assert track_segments(_track(["DRIFT", None], [nan, nan])) == []
