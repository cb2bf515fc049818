"""The policy for one heading in one layer over its cost-to-go (paper Fig. 5; spec sections 5 to 7).

Solution arrays are ``(L, ny, nx, 8)`` indexed ``[l, j, i, k]`` with ``k``
counter-clockwise from east (spec section 2).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from planner.contract.actions import Action
from planner.contract.errors import ShoreError
from planner.contract.headings import N_HEADINGS, Direction
from planner.shore.plots.map_axes import (
    MAX_ARROWS_PER_AXIS,
    arrow_stride,
    cell_edges,
    cell_points,
    draw_land,
    draw_outline,
    geo_axes,
    panel_height,
)
from planner.shore.plots.solutions import is_physical, nominal_displacement
from planner.shore.plots.style import (
    ACTION_COLORS,
    DPI,
    GOAL_COLOR,
    LAND_COLOR,
    ROTATE_MARKERS,
    action_label,
    load_matplotlib,
    new_figure,
    save_png,
    truncated_cmap,
)

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.shore.plots.currents import ForecastMoment
    from planner.grid import Grid
    from planner.shore.plots.solutions import AnySolution

__all__ = ["check_heading", "check_layer", "plot_policy", "policy_figure"]

_STILL_MARKER = {Action.DRIFT: "o", Action.FORWARD: "o", Action.FORWARD_LEFT: "o", Action.FORWARD_RIGHT: "o",
                 Action.UP: "^", Action.DOWN: "v"}


def plot_policy(
    solution: AnySolution,
    path: str | os.PathLike[str],
    *,
    heading: int = 0,
    layer: int | None = None,
    when: ForecastMoment | None = None,
) -> Path:
    """``policy_figure`` written as a PNG at ``path``."""
    return save_png(policy_figure(solution, heading=heading, layer=layer, when=when), path)


def policy_figure(
    solution: AnySolution,
    *,
    heading: int = 0,
    layer: int | None = None,
    when: ForecastMoment | None = None,
) -> Any:
    """The policy for one heading in one layer (paper Fig. 5; spec sections 5 to 7).

    One symbol per water cell (thinned on big grids): moves are arrows along the
    nominal outcome's displacement (spec section 5, outcome ``d``; length
    proportional to the tiles moved), rotations are circular arrows, moves that
    stay in the cell are dots or triangles (UP/DOWN), goal cells are dots inside
    a green outline, unreachable cells are crosses. The background is the
    cost-to-go of the state ``(l, j, i, heading)``. ``layer`` defaults to the
    goal layer. For a physical plan the arrows follow each action's most likely
    outcome and the cost-to-go is in Wh. ``when``: the forecast step planned on,
    named in the title.
    """
    model = solution.model
    grid = model.grid
    k = check_heading(heading)
    l = solution.goal_cells.l if layer is None else check_layer(layer, grid)
    mpl = load_matplotlib()
    width = 7.2
    fig = new_figure(mpl, width + 1.6, panel_height(grid, width) + 1.6)
    ax = fig.subplots()

    cost = np.ma.masked_invalid(solution.cost[l, :, :, k])
    lon_e, lat_e = cell_edges(grid)
    finite = cost.compressed()
    cmap = truncated_cmap(mpl, "Greys", 0.04, 0.55).with_extremes(bad="white")
    vmax = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
    mesh = ax.pcolormesh(lon_e, lat_e, cost, cmap=cmap, vmin=0.0, vmax=vmax, zorder=1)
    draw_land(mpl, ax, grid, ~model.water[l])
    draw_outline(mpl, ax, grid, solution.goal_cells.mask[l], color=GOAL_COLOR, linewidth=2.2)

    stride = arrow_stride(grid, MAX_ARROWS_PER_AXIS)
    cell_pt = stride * cell_points(grid, width)  # displayed spacing of the symbols
    arrows: dict[Action, list[tuple[float, float, float, float]]] = {}
    markers: dict[tuple[Action, str], list[tuple[float, float]]] = {}
    for j in range(0, grid.ny, stride):
        for i in range(0, grid.nx, stride):
            if not model.water[l, j, i]:
                continue
            a = Action(int(solution.action[l, j, i, k]))
            x, y = float(grid.lon_deg[i]), float(grid.lat_deg[j])
            if a in (Action.AT_GOAL, Action.UNREACHABLE):
                markers.setdefault((a, "o" if a == Action.AT_GOAL else "x"), []).append((x, y))
                continue
            if a in ROTATE_MARKERS:
                markers.setdefault((a, ROTATE_MARKERS[a]), []).append((x, y))
                continue
            di, dj = nominal_displacement(solution, l, j, i, k, a)
            if di == 0 and dj == 0:
                markers.setdefault((a, _STILL_MARKER[a]), []).append((x, y))
                continue
            # The arrow spans 0.42 symbol spacing per tile moved (1 or 2), centred on the cell.
            f = 0.42 * stride
            arrows.setdefault(a, []).append((x, y, f * di * grid.dlon_deg, f * dj * grid.dlat_deg))
    width_pt = float(np.clip(0.085 * cell_pt, 1.0, 3.2))
    for a, rows in arrows.items():
        arr = np.array(rows)
        ax.quiver(arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3], color=ACTION_COLORS[a], angles="xy",
                  scale_units="xy", scale=1.0, pivot="middle", units="dots", width=width_pt * DPI / 72.0,
                  headwidth=3.2, headlength=3.4, headaxislength=3.0, zorder=4)
    marker_pt = float(np.clip(0.5 * cell_pt, 4.0, 16.0))
    for (a, marker), pts in markers.items():
        arr = np.array(pts)
        size = marker_pt * {Action.AT_GOAL: 0.45, Action.UNREACHABLE: 0.7}.get(a, 1.0 if a in ROTATE_MARKERS else 0.75)
        ax.plot(arr[:, 0], arr[:, 1], linestyle="none", marker=marker, markersize=size, color=ACTION_COLORS[a],
                markerfacecolor=ACTION_COLORS[a] if marker != "o" or a == Action.AT_GOAL else "none",
                markeredgewidth=1.2, zorder=4)
    geo_axes(mpl, ax, grid)
    cbar = fig.colorbar(mesh, ax=ax, shrink=0.9, pad=0.02)
    unit = "Wh" if is_physical(solution) else "energy units"
    cbar.set_label(f"cost-to-go with heading {Direction(k).name} ({unit})")

    handles = []
    for a in Action:
        if a in arrows:
            handles.append(mpl.lines.Line2D([], [], linestyle="none", marker=r"$\rightarrow$", markersize=13,
                                            color=ACTION_COLORS[a], label=action_label(a)))
        for (b, marker) in markers:
            if b != a:
                continue
            label = action_label(a)
            if marker in ("o", "^", "v") and a not in (Action.AT_GOAL,):
                label += " (stays in cell)"
            handles.append(mpl.lines.Line2D([], [], linestyle="none", marker=marker, markersize=10 if
                                            a in ROTATE_MARKERS else 7, color=ACTION_COLORS[a], label=label,
                                            markerfacecolor=ACTION_COLORS[a] if marker != "o" or
                                            a == Action.AT_GOAL else "none"))
    handles.append(mpl.lines.Line2D([], [], color=GOAL_COLOR, linewidth=2.2, label="goal cells"))
    if (~model.water[l]).any():
        handles.append(mpl.patches.Patch(facecolor=LAND_COLOR, edgecolor="0.5", label="land"))
    fig.legend(handles=handles, loc="outside lower center", ncols=min(4, len(handles)), frameon=False, fontsize=9)
    bearing = float(grid.bearings_deg()[grid.ny // 2, k])
    thin = f"; every {stride} cells" if stride > 1 else ""
    ax.set_title(
        f"Policy for heading {Direction(k).name} (k = {k}, bearing {bearing:.0f}\u00b0), "
        f"layer {l} ({grid.depth_m[l]:g} m)\n"
        + (f"physical model, {model.settings.criterion}; arrows: most likely move, length \u221d tiles{thin}"
           if is_physical(solution) else
           f"{model.settings.criterion}, {model.settings.uncertainty} uncertainty; "
           f"arrows: nominal move, length \u221d tiles{thin}")
        + (f"\nplanned on the {when.label()}" if when is not None else ""),
        fontsize=11,
    )
    return fig


def check_heading(heading: int) -> int:
    """``heading`` as an int grid direction ``k`` (spec section 2); ``ShoreError`` otherwise."""
    if not isinstance(heading, int | np.integer) or isinstance(heading, bool) or not 0 <= heading < N_HEADINGS:
        raise ShoreError(f"plot heading: expected a grid direction k in 0..7 (0 = E, 2 = N); got {heading!r}")
    return int(heading)


def check_layer(layer: int, grid: Grid) -> int:
    """``layer`` as an int layer index of ``grid``; ``ShoreError`` otherwise."""
    if not isinstance(layer, int | np.integer) or isinstance(layer, bool) or not 0 <= layer < grid.n_layers:
        raise ShoreError(f"plot layer: expected a layer index in 0..{grid.n_layers - 1}; got {layer!r}")
    return int(layer)
