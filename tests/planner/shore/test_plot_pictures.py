"""Pictures that say what they show: forecast times in titles, currents under tracks, legends of what occurs,
the nominal path from the real start, a smooth coastline, headings inside the frame, UTC time axes.

The figures are checked as matplotlib objects (titles, collections and their zorder, legend labels, line
vertices, contour paths, axis limits and tick labels), on the demo plan of a real synthetic netCDF forecast
and on the shared real closed-loop dive (``dive_log`` in conftest.py).
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as dt
import re

import numpy as np
import pytest
import xarray as xr

from planner.grid import Grid
from planner.shore.plots.currents import ForecastMoment, currents_at, moment_of_plan, utc_iso
from planner.shore.plots.dive_series import cost_figure, timeseries_figure
from planner.shore.plots.dive_track import dive_track_figure, track_segments
from planner.shore.plots.flow import flow_figure
from planner.shore.plots.nominal_path import nominal_path_figure
from planner.shore.plots.policy import policy_figure
from planner.shore.plots.track import track_figure
from planner.shore.replay.audit import logged_tables
from planner.shore.replay.dive import load_dive
from planner.shore.replay.divelog import open_dive
from tests.support.helpers import start_west_of_goal

ISO_UTC = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ")


@pytest.fixture(scope="module")
def dive(dive_log):  # type: ignore[no-untyped-def]
    return load_dive(open_dive(dive_log))


def _texts(fig) -> str:  # type: ignore[no-untyped-def]
    """Every title of the figure (suptitle and axes titles, all locations), one string."""
    parts = [fig._suptitle.get_text()] if fig._suptitle is not None else []
    for ax in fig.axes:
        parts += [ax.get_title(loc) for loc in ("left", "center", "right")]
    return "\n".join(parts)


def _legend_labels(fig) -> list[str]:  # type: ignore[no-untyped-def]
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    return [t.get_text() for lg in legends for t in lg.get_texts()]


def _by_gid(ax, gid):  # type: ignore[no-untyped-def]
    return [a for a in ax.get_children() if a.get_gid() == gid]


def _step_nearest(path, unix_s: float) -> str:  # type: ignore[no-untyped-def]
    """The forecast file's step nearest ``unix_s``, read with xarray's own time decoding."""
    with xr.open_dataset(path) as ds:
        times = ds["time"].values.astype("datetime64[s]").astype(np.int64)
    return utc_iso(float(times[np.argmin(np.abs(times - unix_s))]))


# --------------------------------------------------------------------------- plan pictures


def test_plan_pictures_name_the_forecast_step_in_their_titles(demo_plan):
    when = moment_of_plan(demo_plan)
    assert when.time_utc == demo_plan.table.forecast_time and ISO_UTC.fullmatch(when.time_utc)
    sol = demo_plan.solution
    start = (0, 2, 3, 0)
    for fig in (flow_figure(demo_plan.u_m_s, demo_plan.v_m_s, demo_plan.model, goal=sol.goal, when=when),
                policy_figure(sol, when=when), nominal_path_figure(sol, start, when=when)):
        assert f"scb.nc at {when.time_utc}" in _texts(fig)


def test_a_time_varying_step_names_its_slice():
    label = ForecastMoment("/data/forecast.nc", "2026-01-15T03:00:00Z", 3, 13).label()
    assert label == "forecast forecast.nc at 2026-01-15T03:00:00Z (slice 4 of 13 of the time-varying plan)"
    assert "no reference date" in ForecastMoment("f.nc", None).label()


def test_land_is_bounded_by_a_smooth_coastline_not_a_staircase(demo_plan):
    fig = flow_figure(demo_plan.u_m_s, demo_plan.v_m_s, demo_plan.model)
    ax = fig.axes[0]
    coast = _by_gid(ax, "coastline")
    assert len(coast) == 1 and coast[0].get_paths()
    vertices = np.concatenate([p.vertices for p in coast[0].get_paths()])
    steps = np.diff(vertices, axis=0)
    # A staircase has only horizontal and vertical edges; the contour cuts the cells' corners.
    assert np.count_nonzero((np.abs(steps[:, 0]) > 1e-9) & (np.abs(steps[:, 1]) > 1e-9)) > 3
    assert _by_gid(ax, "land")


def test_the_nominal_path_starts_at_the_vehicle_s_start(demo_plan):
    table = demo_plan.table
    lon, lat = start_west_of_goal(table, cells=4)
    lon, lat = lon + 0.3 * table.dlon_deg, lat - 0.2 * table.dlat_deg  # off the cell's centre
    l, j, i = table.locate(lat, lon, 0.0)
    fig = nominal_path_figure(demo_plan.solution, (l, j, i, table.heading_index(j, 90.0)), start_lon_lat=(lon, lat))
    path, = _by_gid(fig.axes[0], "nominal path")
    assert tuple(path.get_xydata()[0]) == pytest.approx((lon, lat))
    assert tuple(path.get_xydata()[1]) == pytest.approx((table.lon_deg[i], table.lat_deg[j]))


# --------------------------------------------------------------------------- the demo's track.png


def test_demo_track_runs_over_the_truth_currents_with_utc_marks_and_only_the_modes_drawn(demo_plan, synthetic_forecast):
    table = demo_plan.table
    lon0, lat = start_west_of_goal(table, cells=4)
    n = 181
    time_s = np.linspace(0.0, 6 * 3600.0, n)  # six hours: hourly marks
    lon = np.linspace(lon0, table.goal_lon_deg, n)
    mode = np.where(np.arange(n) < 90, 4, 2)
    mode[-1] = 9  # SURFACE at the last sample only: no segment is drawn in it
    grid = Grid(lon_deg=table.lon_deg, lat_deg=table.lat_deg, depth_m=np.asarray(table.depth_m))
    with xr.open_dataset(synthetic_forecast) as ds:
        start_unix_s = float(ds["time"].values[0].astype("datetime64[s]").astype(np.int64))
    currents = currents_at(synthetic_forecast, grid, start_unix_s + 3 * 3600.0)
    fig = track_figure(table, lon, np.full(n, lat), mode, time_s=time_s, start_unix_s=start_unix_s,
                       currents=currents)
    ax = fig.axes[0]
    labels = _legend_labels(fig)
    assert [x for x in labels if x in ("GUIDED", "ALT_HOLD", "SURFACE", "MANUAL")] == ["GUIDED", "ALT_HOLD"]
    quiver, = _by_gid(ax, "currents")
    track, = _by_gid(ax, "track")
    assert len(quiver.U) > 20 and quiver.get_zorder() < track.get_zorder()
    assert _step_nearest(synthetic_forecast, start_unix_s + 3 * 3600.0) in _texts(fig)
    marks = [t.get_text() for t in ax.texts]
    first = dt.datetime.fromtimestamp(start_unix_s, dt.UTC)
    assert f"{first:%H:%M}" in marks and len(_by_gid(ax, "time marks")[0].get_xdata()) == 7  # 0 to 6 h


def test_draw_track_reads_the_simulator_csv_and_the_truth(demo_plan, synthetic_forecast, tmp_path):
    from planner.shore.demo import draw_track

    lon, lat = start_west_of_goal(demo_plan.table, cells=2)
    csv_path = tmp_path / "track.csv"
    with open(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time_s", "lat_deg", "lon_deg", "depth_m", "heading_deg", "mode", "armed", "energy_used_wh"])
        for n in range(5):
            w.writerow([n * 1800.0, lat, lon + 0.002 * n, 0.0, 90.0, 4, 1, float(n)])
    table_path = tmp_path / "t.lrpt"
    demo_plan.table.save(table_path)
    out = draw_track(table_path, csv_path, tmp_path / "track.png", truth=synthetic_forecast)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --------------------------------------------------------------------------- the dive report's pictures


def test_dive_map_has_the_forecast_currents_at_the_dive_s_time_under_the_track(dive, demo_plan, synthetic_forecast):
    track = dive.track
    table = next(iter(logged_tables(dive.log).values()))
    fig, caption, missing = dive_track_figure(dive, table, [table], demo_plan, np.ones(len(track), dtype=bool))
    assert missing == ""
    ax = fig.axes[0]
    quiver, = _by_gid(ax, "currents")
    track_line, = _by_gid(ax, "track")
    assert len(quiver.U) > 20 and quiver.get_zorder() < track_line.get_zorder()
    ok = np.flatnonzero(np.isfinite(track.lat_deg))
    middle = float(dive.unix_offset_s) + 0.5 * (track.time_s[ok[0]] + track.time_s[ok[-1]])
    assert f"scb.nc at {_step_nearest(synthetic_forecast, middle)}" in _texts(fig)
    # The legend: exactly the actions of the drawn (two or more point) segments.
    drawn = {s.action for s in track_segments(track) if s.rows.size > 1}
    names = {a.lower().replace("_", " ") for a in drawn if a is not None}
    action_words = {"forward", "forward left", "forward right", "drift", "rotate left", "rotate right", "up", "down",
                    "at goal", "unreachable"}
    assert {x for x in _legend_labels(fig) if x in action_words} == names
    # The nominal path begins where the vehicle was at the first decision, not at a cell centre.
    path, = _by_gid(ax, "nominal path")
    first = int(np.flatnonzero(np.all(track.cell >= 0, axis=1) & np.isfinite(track.lat_deg))[0])
    assert tuple(path.get_xydata()[0]) == pytest.approx((track.lon_deg[first], track.lat_deg[first]))
    assert _by_gid(ax, "time marks")
    assert any(re.fullmatch(r"\d\d:\d\d", t.get_text()) for t in ax.texts)


def _utc_ticks_check(fig, ax) -> None:  # type: ignore[no-untyped-def]
    import matplotlib.dates

    fig.canvas.draw()
    assert "UTC" in ax.get_xlabel()
    ticks = [(x, t.get_text()) for x, t in zip(ax.get_xticks(), ax.get_xticklabels()) if t.get_text()]
    hhmm = [(x, text) for x, text in ticks if re.fullmatch(r"\d\d:\d\d", text)]
    assert hhmm
    for x, text in hhmm:  # each label is the UTC clock time of its tick
        assert matplotlib.dates.num2date(x, tz=dt.UTC).strftime("%H:%M") == text


def test_timeseries_in_utc_with_the_heading_inside_the_frame(dive):
    fig, caption = timeseries_figure(dive)
    ax_head = next(ax for ax in fig.axes if ax.get_ylabel().startswith("heading"))
    low, high = ax_head.get_ylim()
    assert low < 0.0 and high > 360.0
    line, = _by_gid(ax_head, "heading")
    y = line.get_ydata()
    assert np.nanmin(y) >= 0.0 and np.nanmax(y) < 360.0
    _utc_ticks_check(fig, fig.axes[-1])
    assert "against UTC" in caption


def test_without_utc_the_axis_says_it_is_time_since_boot(dive):
    fig, caption = timeseries_figure(dataclasses.replace(dive, unix_offset_s=None))
    label = fig.axes[-1].get_xlabel()
    assert "since the autopilot booted" in label and "UTC unknown" in label
    assert "(the log has no UTC)" in caption


def test_cost_picture_time_axis_is_utc(dive, demo_plan):
    fig, _ = cost_figure(dive, np.linspace(10.0, 0.0, len(dive.track)), demo_plan, True)
    _utc_ticks_check(fig, fig.axes[0])
