"""The currents of every layer on the planning grid (paper Fig. 3; spec sections 1 and 3).

Currents are ``(L, ny, nx)`` arrays indexed ``[l, j, i]`` with NaN for land
(spec section 1).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import ShoreError
from planner.shore.plots.map_axes import arrow_stride, cos_lat, draw_land, geo_axes, panel_height
from planner.shore.plots.style import (
    GOAL_COLOR,
    LAND_COLOR,
    load_matplotlib,
    new_figure,
    nice_speed,
    save_png,
    truncated_cmap,
)

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.shore.plots.currents import ForecastMoment
    from planner.contract.settings import Goal
    from planner.grid import Grid
    from planner.paper.transitions import TransitionModel
    from planner.physical.model import PhysicalModel

__all__ = ["flow_figure", "plot_flow_fields"]

_MAX_FLOW_ARROWS_PER_PANEL = 28


def plot_flow_fields(
    u_m_s: NDArray[np.float64],
    v_m_s: NDArray[np.float64],
    model: TransitionModel | PhysicalModel,
    path: str | os.PathLike[str],
    *,
    goal: Goal | None = None,
    when: ForecastMoment | None = None,
) -> Path:
    """``flow_figure`` written as a PNG at ``path``."""
    return save_png(flow_figure(u_m_s, v_m_s, model, goal=goal, when=when), path)


def flow_figure(
    u_m_s: NDArray[np.float64],
    v_m_s: NDArray[np.float64],
    model: TransitionModel | PhysicalModel,
    *,
    goal: Goal | None = None,
    when: ForecastMoment | None = None,
) -> Any:
    """Currents of every layer, one panel per layer (paper Fig. 3; spec sections 1 and 3).

    ``u_m_s``, ``v_m_s``: eastward and northward current on the planning grid,
    shape ``(L, ny, nx)``, NaN for land. Arrows are coloured and scaled by speed
    (one colour scale for all layers), land is filled, calm cells (spec section 3)
    are dotted, and the goal cell, if ``goal`` is given, is starred. ``when``: the
    forecast step the currents are from, named in the title.
    """
    grid = model.grid
    u, v = _check_currents(u_m_s, v_m_s, grid)
    goal_ijl = _goal_cell(grid, goal) if goal is not None else None
    mpl = load_matplotlib()
    L = grid.n_layers
    ncols = {1: 1, 2: 2, 3: 3, 4: 2}.get(L, 3)
    nrows = math.ceil(L / ncols)
    panel_w = 6.4 if ncols == 1 else (4.6 if ncols == 2 else 3.9)
    panel_h = panel_height(grid, panel_w)
    fig = new_figure(mpl, ncols * panel_w + 1.0, nrows * panel_h + 1.3)
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True)

    speed = np.hypot(u, v)
    vmax = float(np.nanmax(speed)) if np.isfinite(speed).any() else 0.0
    vmax = vmax if vmax > 0 else 1.0
    # Arrow lengths: the 98th percentile speed spans 0.9 of the arrow spacing, the fastest at most 1.5.
    v98 = float(np.nanpercentile(speed, 98)) if np.isfinite(speed).any() else vmax
    norm = mpl.colors.Normalize(vmin=0.0, vmax=vmax)
    cmap = truncated_cmap(mpl, "viridis", 0.0, 0.9)
    stride = arrow_stride(grid, _MAX_FLOW_ARROWS_PER_PANEL)
    jj, ii = np.meshgrid(np.arange(0, grid.ny, stride), np.arange(0, grid.nx, stride), indexing="ij")
    x, y = grid.lon_deg[ii], grid.lat_deg[jj]
    # Arrow length in x (longitude) units; the axes aspect makes them isotropic.
    cell_x = min(grid.dlon_deg, grid.dlat_deg / cos_lat(grid))
    scale = max(v98 / (0.9 * stride * cell_x), vmax / (1.5 * stride * cell_x), 1e-12)
    shaft = float(np.clip(0.09 / math.ceil(grid.nx / stride), 0.002, 0.008))  # fraction of the axes width
    quiver = None
    for l in range(L):
        ax = axes[l // ncols, l % ncols]
        draw_land(mpl, ax, grid, ~model.water[l])
        us, vs, ss = u[l][jj, ii], v[l][jj, ii], speed[l][jj, ii]
        moving = np.isfinite(ss) & (model.flow_dir[l][jj, ii] >= 0)
        quiver = ax.quiver(
            x[moving], y[moving], us[moving], vs[moving], ss[moving], cmap=cmap, norm=norm,
            angles="uv", scale_units="x", scale=scale, width=shaft, headwidth=3.5, headlength=4.0,
            headaxislength=3.5, pivot="middle", zorder=3,
        )
        calm = model.flow_dir[l][jj, ii] == -1
        if calm.any():
            ax.plot(x[calm], y[calm], linestyle="none", marker=".", markersize=3, color="0.35", zorder=3)
        title = f"Layer {l}: {grid.depth_m[l]:g} m"
        if goal_ijl is not None:
            gi, gj, gl = goal_ijl
            in_goal_layer = gl == l
            ax.plot(
                grid.lon_deg[gi], grid.lat_deg[gj], linestyle="none", marker="*", markersize=15,
                markerfacecolor=GOAL_COLOR if in_goal_layer else "none", markeredgecolor="black" if in_goal_layer
                else GOAL_COLOR, markeredgewidth=1.0 if in_goal_layer else 1.6, zorder=5,
            )
            if in_goal_layer:
                title += " (goal layer)"
        ax.set_title(title, fontsize=11)
        geo_axes(mpl, ax, grid, xlabel=l // ncols == nrows - 1, ylabel=l % ncols == 0)
    for extra in range(L, nrows * ncols):
        axes[extra // ncols, extra % ncols].set_axis_off()
    cbar = fig.colorbar(quiver, ax=axes.ravel().tolist(), shrink=0.85, pad=0.02)
    cbar.set_label("current speed (m/s)")
    key_speed = nice_speed(0.5 * v98 if v98 > 0 else 0.5 * vmax)
    axes[0, 0].quiverkey(quiver, 0.04, 0.025, key_speed, f"{key_speed:g} m/s", labelpos="E",
                         coordinates="figure", color="0.2", fontproperties={"size": 9})
    handles = [
        mpl.patches.Patch(facecolor=LAND_COLOR, edgecolor="0.5", label="land (no current)"),
        mpl.lines.Line2D([], [], linestyle="none", marker=".", markersize=6, color="0.35",
                         label=f"calm (\u2264 {model.settings.calm_speed_m_s:g} m/s)"),
    ]
    if goal_ijl is not None:
        handles.append(mpl.lines.Line2D([], [], linestyle="none", marker="*", markersize=12,
                                        markerfacecolor=GOAL_COLOR, markeredgecolor="black",
                                        label="goal cell"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), frameon=False, fontsize=9)
    suffix = f", every {stride} cells" if stride > 1 else ""
    step = f"\n{when.label()}" if when is not None else ""
    fig.suptitle(f"Currents on the planning grid ({grid.nx} \u00d7 {grid.ny} cells{suffix}){step}", fontsize=12)
    return fig


def _check_currents(u_m_s: Any, v_m_s: Any, grid: Grid) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    u = np.asarray(u_m_s, dtype=np.float64)
    v = np.asarray(v_m_s, dtype=np.float64)
    want = (grid.n_layers, grid.ny, grid.nx)
    if u.shape != want or v.shape != want:
        raise ShoreError(
            f"plot currents: expected u and v of shape (L, ny, nx) = {want}; got {u.shape} and {v.shape}"
        )
    return u, v


def _goal_cell(grid: Grid, goal: Goal) -> tuple[int, int, int]:
    i, j, _ = grid.nearest_cell(goal.lon_deg, goal.lat_deg)
    return i, j, grid.nearest_layer(goal.depth_m)
