"""A vehicle track over a policy table's land and goal, coloured by autopilot mode (``lrauv demo``).

With the simulator's times and truth forecast, the track runs over the truth's
currents at the dive's time (the step nearest its middle) and carries marks at
round UTC times.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from planner.contract.errors import ShoreError
from planner.shore.plots.currents import currents_at, draw_currents_with_key, step_unix_s, utc_iso
from planner.shore.plots.map_axes import cell_edges, draw_land, geo_axes, panel_height
from planner.shore.plots.style import (
    GOAL_COLOR,
    START_COLOR,
    WATER_COLOR,
    load_matplotlib,
    new_figure,
    save_png,
)
from planner.shore.plots.time_axis import draw_time_marks, marks_legend, time_marks

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.contract.table import PolicyTable
    from planner.shore.plots.currents import CurrentMap

__all__ = ["plot_track", "track_figure", "track_times_and_currents"]

# ArduSub modes (executive.state.SubMode) as the executive uses them: GUIDED = thrusting
# (forward or turning), ALT_HOLD = drifting or gliding, SURFACE = safe behaviour.
_MODE_STYLE = {4: ("GUIDED", "#d55e00"), 2: ("ALT_HOLD", "#0072b2"), 9: ("SURFACE", "#7f7f7f"),
               19: ("MANUAL", "#cc79a7")}
_OTHER_MODE_COLOR = "black"


def track_figure(table: PolicyTable, lon_deg: ArrayLike, lat_deg: ArrayLike, mode: ArrayLike, *,
                 time_s: ArrayLike | None = None, start_unix_s: float | None = None,
                 currents: CurrentMap | None = None) -> Any:
    """The figure of ``plot_track``."""
    from planner.grid import Grid

    lon, lat, modes = (np.asarray(a, dtype=np.float64) for a in (lon_deg, lat_deg, mode))
    if not (lon.shape == lat.shape == modes.shape and lon.ndim == 1 and lon.size >= 1):
        raise ShoreError(f"track: expected equal-length 1-D lon/lat/mode; got {lon.shape}, {lat.shape}, {modes.shape}")
    times = None if time_s is None else np.asarray(time_s, dtype=np.float64)
    if times is not None and times.shape != lon.shape:
        raise ShoreError(f"track: expected time_s of the track's length {lon.size}; got shape {times.shape}")
    grid = Grid(lon_deg=table.lon_deg, lat_deg=table.lat_deg, depth_m=np.asarray(table.depth_m))
    mpl = load_matplotlib()
    width = 7.0
    fig = new_figure(mpl, width, panel_height(grid, width - 1.0) + 1.6)
    ax = fig.subplots()
    ax.set_facecolor(WATER_COLOR)
    draw_land(mpl, ax, grid, ~table.water[0])
    lon_e, lat_e = cell_edges(grid)
    handles: list[Any] = []
    if currents is not None:
        key = draw_currents_with_key(mpl, ax, currents, (lon_e[0], lon_e[-1], lat_e[0], lat_e[-1]), "truth")
        handles += [key] if key is not None else []
    points = np.column_stack([lon, lat])
    segs = np.stack([points[:-1], points[1:]], axis=1) if lon.size > 1 else np.empty((0, 2, 2))
    seg_modes = modes[:-1]  # a segment has the mode of its first sample
    colors = [_MODE_STYLE.get(int(m), ("", _OTHER_MODE_COLOR))[1] for m in seg_modes]
    line = mpl.collections.LineCollection(segs, colors=colors, linewidths=1.8, zorder=4)
    line.set_gid("track")
    ax.add_collection(line)
    drawn = set(int(m) for m in seg_modes)
    handles += [mpl.lines.Line2D([], [], color=c, linewidth=2, label=name)
                for code, (name, c) in _MODE_STYLE.items() if code in drawn]
    others = sorted(drawn - set(_MODE_STYLE))
    if others:
        handles.append(mpl.lines.Line2D([], [], color=_OTHER_MODE_COLOR, linewidth=2,
                                        label="mode " + ", ".join(str(m) for m in others)))
    when = ""
    if times is not None:
        marks = time_marks(times, lon, lat, start_unix_s)
        if draw_time_marks(mpl, ax, marks, label_gap_deg=0.07 * (lon_e[-1] - lon_e[0])) is not None:
            handles.append(mpl.lines.Line2D([], [], linestyle="none", marker="o", markersize=4.5,
                                            markerfacecolor="black", markeredgecolor="white",
                                            label=marks_legend(marks)))
        if start_unix_s is not None and np.isfinite(times).any():
            when = f", {utc_iso(start_unix_s + float(np.nanmin(times)))} to {utc_iso(start_unix_s + float(np.nanmax(times)))}"
    start, = ax.plot(lon[0], lat[0], linestyle="none", marker="o", markersize=8, color=START_COLOR, zorder=5,
                     label="start")
    start.set_gid("start")
    ax.plot(table.goal_lon_deg, table.goal_lat_deg, linestyle="none", marker="*", markersize=15,
            markerfacecolor=GOAL_COLOR, markeredgecolor="black", zorder=5, label="goal")
    goal_cell = table.locate(table.goal_lat_deg, table.goal_lon_deg, table.goal_depth_m)
    if goal_cell is not None:  # the goal region of spec section 6: (2r + 1) x (2r + 1) cells
        _, jg, ig = goal_cell
        half = table.goal_radius_cells + 0.5
        ax.add_patch(mpl.patches.Rectangle(
            (table.lon0_deg + (ig - half) * table.dlon_deg, table.lat0_deg + (jg - half) * table.dlat_deg),
            2 * half * table.dlon_deg, 2 * half * table.dlat_deg, fill=False, edgecolor=GOAL_COLOR, linestyle="--",
            linewidth=1.2, zorder=3, label="goal region"))
    ax.legend(handles=handles + ax.get_legend_handles_labels()[0], loc="best", fontsize=7.5)
    title = f"Executed track of the simulated vehicle{when}"
    if currents is not None:
        title += (f"\ntruth currents at {currents.depth_m:g} m: {currents.moment.label()}"
                  "\n(the step nearest the track's middle)")
    ax.set_title(title, fontsize=9.5, loc="left")
    geo_axes(mpl, ax, grid)
    return fig


def plot_track(
    table: PolicyTable, lon_deg: ArrayLike, lat_deg: ArrayLike, mode: ArrayLike, path: str | os.PathLike[str], *,
    time_s: ArrayLike | None = None, start_unix_s: float | None = None, currents: CurrentMap | None = None,
) -> Path:
    """A vehicle track over the table's land and goal, coloured by autopilot mode; writes the PNG at ``path``.

    ``table`` is a ``planner.contract.table.PolicyTable``; ``lon_deg``, ``lat_deg`` and ``mode``
    (ArduSub custom mode numbers) are equal-length sequences of track samples. The legend names
    only the modes the drawn track has. ``time_s`` (the samples' times, s) adds time marks, in
    UTC when ``start_unix_s`` (the Unix time of ``time_s`` = 0) is given, else as hours; with
    ``currents`` (``planner.shore.plots.currents.currents_at``) the track runs over them.
    """
    return save_png(track_figure(table, lon_deg, lat_deg, mode, time_s=time_s, start_unix_s=start_unix_s,
                                 currents=currents), path)


def track_times_and_currents(table: PolicyTable, time_s: ArrayLike, truth: str | os.PathLike[str] | None
                             ) -> tuple[float | None, CurrentMap | None]:
    """For a simulator's track (``time_s`` from 0 at the truth forecast's first step, as ``lrauv sim`` runs
    without ``--start-time``): the Unix time of ``time_s`` = 0 (None when the file is undated), and the truth's
    top-layer currents on the table's cells at the step nearest the track's middle. ``truth`` None: neither."""
    from planner.grid import Grid

    if truth is None:
        return None, None
    steps = step_unix_s(truth)
    start = None if steps is None else float(steps[0])
    t = np.asarray(time_s, dtype=np.float64)
    middle = None if start is None or not np.isfinite(t).any() else start + 0.5 * float(np.nanmin(t) + np.nanmax(t))
    grid = Grid(lon_deg=table.lon_deg, lat_deg=table.lat_deg, depth_m=np.asarray(table.depth_m))
    return start, currents_at(truth, grid, middle, depth_m=float(table.depth_m[0]))
