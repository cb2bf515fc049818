"""A vehicle track over a policy table's land and goal, coloured by autopilot mode (``lrauv demo``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from planner.contract.errors import ShoreError
from planner.shore.plots.map_axes import draw_land, geo_axes, panel_height
from planner.shore.plots.style import GOAL_COLOR, START_COLOR, WATER_COLOR, load_matplotlib, new_figure, save_png

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.contract.table import PolicyTable

__all__ = ["plot_track"]

# ArduSub modes (executive.state.SubMode) as the executive uses them: GUIDED = thrusting
# (forward or turning), ALT_HOLD = drifting or gliding, SURFACE = safe behaviour.
_MODE_STYLE = {4: ("GUIDED (forward, rotate, hold)", "#d55e00"), 2: ("ALT_HOLD (drift, glide)", "#0072b2"),
               9: ("SURFACE", "#7f7f7f"), 19: ("MANUAL", "#cc79a7")}


def plot_track(
    table: PolicyTable, lon_deg: ArrayLike, lat_deg: ArrayLike, mode: ArrayLike, path: str | os.PathLike[str]
) -> Path:
    """A vehicle track over the table's land and goal, coloured by autopilot mode.

    ``table`` is a ``planner.contract.table.PolicyTable``; ``lon_deg``, ``lat_deg`` and ``mode``
    (ArduSub custom mode numbers) are equal-length sequences of track samples.
    """
    from planner.grid import Grid

    lon, lat, modes = (np.asarray(a, dtype=np.float64) for a in (lon_deg, lat_deg, mode))
    if not (lon.shape == lat.shape == modes.shape and lon.ndim == 1 and lon.size >= 1):
        raise ShoreError(f"track: expected equal-length 1-D lon/lat/mode; got {lon.shape}, {lat.shape}, {modes.shape}")
    grid = Grid(lon_deg=table.lon_deg, lat_deg=table.lat_deg, depth_m=np.asarray(table.depth_m))
    mpl = load_matplotlib()
    width = 7.0
    fig = new_figure(mpl, width, panel_height(grid, width - 1.0) + 1.2)
    ax = fig.subplots()
    ax.set_facecolor(WATER_COLOR)
    draw_land(mpl, ax, grid, ~table.water[0])
    points = np.column_stack([lon, lat])
    segs = np.stack([points[:-1], points[1:]], axis=1) if lon.size > 1 else np.empty((0, 2, 2))
    colors = [_MODE_STYLE.get(int(m), ("other", "black"))[1] for m in modes[:-1]]
    ax.add_collection(mpl.collections.LineCollection(segs, colors=colors, linewidths=1.8, zorder=4))
    ax.plot(lon[0], lat[0], linestyle="none", marker="o", markersize=8, color=START_COLOR, zorder=5, label="start")
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
    handles = [mpl.lines.Line2D([], [], color=c, linewidth=2, label=name)
               for code, (name, c) in _MODE_STYLE.items() if np.any(modes == code)]
    ax.legend(handles=handles + ax.get_legend_handles_labels()[0], loc="best", fontsize=8)
    ax.set_title("Executed track (simulated vehicle on the truth currents)", fontsize=11)
    geo_axes(mpl, ax, grid)
    return save_png(fig, path)
