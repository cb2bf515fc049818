"""Pictures of a plan: flow fields, a policy slice and a nominal path (paper Figs. 3, 5, 6).

Each public function draws one figure and writes it as one PNG, atomically (a
temporary file in the same folder, then ``os.replace``), and returns its path.

Matplotlib is imported inside the functions, and figures are built with
``matplotlib.figure.Figure`` on an explicit Agg canvas: importing this module is
cheap, and nothing here touches pyplot's global state or the process backend.

Arrays follow the planner's conventions: currents ``(L, ny, nx)`` indexed
``[l, j, i]`` with NaN for land (spec section 1); solution arrays ``(L, ny, nx, 8)``
indexed ``[l, j, i, k]`` with ``k`` counter-clockwise from east (spec section 2).
"""

from __future__ import annotations

import math
import os
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.atomic import atomic_target
from planner.contract.errors import ShoreError
from planner.contract.headings import DI, DJ, N_HEADINGS, Direction

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.grid import Grid
    from planner.physical.model import PhysicalModel
    from planner.physical.solve import PhysicalSolution, PhysicalStep
    from planner.contract.settings import Goal
    from planner.paper.solve import PathStep, Solution
    from planner.paper.transitions import TransitionModel

    AnySolution = Solution | PhysicalSolution

__all__ = [
    "ACTION_COLORS",
    "default_start",
    "plot_all",
    "plot_flow_fields",
    "plot_nominal_path",
    "plot_policy",
    "plot_track",
]

DPI = 150
LAND_COLOR = "#d9c39a"  # tan
WATER_COLOR = "#eef4f9"  # very light sea blue, for the path picture
GOAL_COLOR = "#1a9850"  # green (paper Fig. 6: green goal)
START_COLOR = "#e41a1c"  # red (paper Fig. 6: red start)
FLOW_ARROW_COLOR = "#8c96a3"
# One colour per action code (spec section 5), Okabe-Ito based; none is pure red or green.
ACTION_COLORS: dict[Action, str] = {
    Action.DRIFT: "#0072b2",
    Action.FORWARD: "#d55e00",
    Action.FORWARD_LEFT: "#a6430a",  # physical plans' course offsets: darker and lighter FORWARD
    Action.FORWARD_RIGHT: "#f08a4b",
    Action.ROTATE_LEFT: "#cc79a7",
    Action.ROTATE_RIGHT: "#e69f00",
    Action.UP: "#009e73",
    Action.DOWN: "#6a3d9a",
    Action.AT_GOAL: GOAL_COLOR,
    Action.UNREACHABLE: "#7f7f7f",
}
_ROTATE_MARKER = {Action.ROTATE_LEFT: r"$\circlearrowleft$", Action.ROTATE_RIGHT: r"$\circlearrowright$"}
_STILL_MARKER = {Action.DRIFT: "o", Action.FORWARD: "o", Action.FORWARD_LEFT: "o", Action.FORWARD_RIGHT: "o",
                 Action.UP: "^", Action.DOWN: "v"}
_MAX_ARROWS_PER_AXIS = 40  # thin out arrows on big grids so they stay readable
_MAX_FLOW_ARROWS_PER_PANEL = 28


# --------------------------------------------------------------------------- public API


def plot_flow_fields(
    u_m_s: NDArray[np.float64],
    v_m_s: NDArray[np.float64],
    model: TransitionModel | PhysicalModel,
    path: str | os.PathLike[str],
    *,
    goal: Goal | None = None,
) -> Path:
    """Currents of every layer, one panel per layer (paper Fig. 3; spec sections 1 and 3).

    ``u_m_s``, ``v_m_s``: eastward and northward current on the planning grid,
    shape ``(L, ny, nx)``, NaN for land. Arrows are coloured and scaled by speed
    (one colour scale for all layers), land is filled, calm cells (spec section 3)
    are dotted, and the goal cell, if ``goal`` is given, is starred.
    """
    grid = model.grid
    u, v = _check_currents(u_m_s, v_m_s, grid)
    goal_ijl = _goal_cell(grid, goal) if goal is not None else None
    mpl = _matplotlib()
    L = grid.n_layers
    ncols = {1: 1, 2: 2, 3: 3, 4: 2}.get(L, 3)
    nrows = math.ceil(L / ncols)
    panel_w = 6.4 if ncols == 1 else (4.6 if ncols == 2 else 3.9)
    panel_h = _panel_height(grid, panel_w)
    fig = _figure(mpl, ncols * panel_w + 1.0, nrows * panel_h + 1.3)
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True)

    speed = np.hypot(u, v)
    vmax = float(np.nanmax(speed)) if np.isfinite(speed).any() else 0.0
    vmax = vmax if vmax > 0 else 1.0
    # Arrow lengths: the 98th percentile speed spans 0.9 of the arrow spacing, the fastest at most 1.5.
    v98 = float(np.nanpercentile(speed, 98)) if np.isfinite(speed).any() else vmax
    norm = mpl.colors.Normalize(vmin=0.0, vmax=vmax)
    cmap = _truncated(mpl, "viridis", 0.0, 0.9)
    stride = _stride(grid, _MAX_FLOW_ARROWS_PER_PANEL)
    jj, ii = np.meshgrid(np.arange(0, grid.ny, stride), np.arange(0, grid.nx, stride), indexing="ij")
    x, y = grid.lon_deg[ii], grid.lat_deg[jj]
    # Arrow length in x (longitude) units; the axes aspect makes them isotropic.
    cell_x = min(grid.dlon_deg, grid.dlat_deg / _cos_lat(grid))
    scale = max(v98 / (0.9 * stride * cell_x), vmax / (1.5 * stride * cell_x), 1e-12)
    shaft = float(np.clip(0.09 / math.ceil(grid.nx / stride), 0.002, 0.008))  # fraction of the axes width
    quiver = None
    for l in range(L):
        ax = axes[l // ncols, l % ncols]
        _draw_land(mpl, ax, grid, ~model.water[l])
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
        _geo_axes(mpl, ax, grid, xlabel=l // ncols == nrows - 1, ylabel=l % ncols == 0)
    for extra in range(L, nrows * ncols):
        axes[extra // ncols, extra % ncols].set_axis_off()
    cbar = fig.colorbar(quiver, ax=axes.ravel().tolist(), shrink=0.85, pad=0.02)
    cbar.set_label("current speed (m/s)")
    key_speed = _nice_speed(0.5 * v98 if v98 > 0 else 0.5 * vmax)
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
    fig.suptitle(f"Currents on the planning grid ({grid.nx} \u00d7 {grid.ny} cells{suffix})", fontsize=12)
    return _save(fig, path)


def plot_policy(
    solution: AnySolution,
    path: str | os.PathLike[str],
    *,
    heading: int = 0,
    layer: int | None = None,
) -> Path:
    """The policy for one heading in one layer (paper Fig. 5; spec sections 5 to 7).

    One symbol per water cell (thinned on big grids): moves are arrows along the
    nominal outcome's displacement (spec section 5, outcome ``d``; length
    proportional to the tiles moved), rotations are circular arrows, moves that
    stay in the cell are dots or triangles (UP/DOWN), goal cells are dots inside
    a green outline, unreachable cells are crosses. The background is the
    cost-to-go of the state ``(l, j, i, heading)``. ``layer`` defaults to the
    goal layer. For a physical plan the arrows follow each action's most likely
    outcome and the cost-to-go is in Wh.
    """
    model = solution.model
    grid = model.grid
    k = _check_heading(heading)
    l = solution.goal_cells.l if layer is None else _check_layer(layer, grid)
    mpl = _matplotlib()
    width = 7.2
    fig = _figure(mpl, width + 1.6, _panel_height(grid, width) + 1.6)
    ax = fig.subplots()

    cost = np.ma.masked_invalid(solution.cost[l, :, :, k])
    lon_e, lat_e = _edges(grid)
    finite = cost.compressed()
    cmap = _truncated(mpl, "Greys", 0.04, 0.55).with_extremes(bad="white")
    vmax = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
    mesh = ax.pcolormesh(lon_e, lat_e, cost, cmap=cmap, vmin=0.0, vmax=vmax, zorder=1)
    _draw_land(mpl, ax, grid, ~model.water[l])
    _draw_outline(mpl, ax, grid, solution.goal_cells.mask[l], color=GOAL_COLOR, linewidth=2.2)

    stride = _stride(grid, _MAX_ARROWS_PER_AXIS)
    cell_pt = stride * _cell_points(grid, width)  # displayed spacing of the symbols
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
            if a in _ROTATE_MARKER:
                markers.setdefault((a, _ROTATE_MARKER[a]), []).append((x, y))
                continue
            di, dj = _nominal_displacement(solution, l, j, i, k, a)
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
        size = marker_pt * {Action.AT_GOAL: 0.45, Action.UNREACHABLE: 0.7}.get(a, 1.0 if a in _ROTATE_MARKER else 0.75)
        ax.plot(arr[:, 0], arr[:, 1], linestyle="none", marker=marker, markersize=size, color=ACTION_COLORS[a],
                markerfacecolor=ACTION_COLORS[a] if marker != "o" or a == Action.AT_GOAL else "none",
                markeredgewidth=1.2, zorder=4)
    _geo_axes(mpl, ax, grid)
    cbar = fig.colorbar(mesh, ax=ax, shrink=0.9, pad=0.02)
    unit = "Wh" if _is_physical(solution) else "energy units"
    cbar.set_label(f"cost-to-go with heading {Direction(k).name} ({unit})")

    handles = []
    for a in Action:
        if a in arrows:
            handles.append(mpl.lines.Line2D([], [], linestyle="none", marker=r"$\rightarrow$", markersize=13,
                                            color=ACTION_COLORS[a], label=_action_label(a)))
        for (b, marker) in markers:
            if b != a:
                continue
            label = _action_label(a)
            if marker in ("o", "^", "v") and a not in (Action.AT_GOAL,):
                label += " (stays in cell)"
            handles.append(mpl.lines.Line2D([], [], linestyle="none", marker=marker, markersize=10 if
                                            a in _ROTATE_MARKER else 7, color=ACTION_COLORS[a], label=label,
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
           if _is_physical(solution) else
           f"{model.settings.criterion}, {model.settings.uncertainty} uncertainty; "
           f"arrows: nominal move, length \u221d tiles{thin}"),
        fontsize=11,
    )
    return _save(fig, path)


def plot_nominal_path(
    solution: AnySolution,
    start: tuple[int, int, int, int],
    path: str | os.PathLike[str],
) -> Path:
    """The nominal path from ``start`` ``(l, j, i, k)`` to the goal (paper Fig. 6).

    The path is ``planner.paper.solve.nominal_path``: the policy followed with each
    action's nominal outcome (spec section 5). It is drawn through the cell
    centres over the planner's flow directions and land of the layer where it
    spends most steps; segments are coloured by the action taken, rotations are
    circular arrows, layer changes are labelled with their depths, and steps in
    another layer are dashed. Red marks the start, green the goal (paper Fig. 6).
    For a physical plan the path is ``PhysicalSolution.nominal`` (each action's
    most likely outcome) and the costs are in Wh.
    """
    model = solution.model
    grid = model.grid
    start = _check_state(start, solution)
    steps = _nominal_steps(solution, start)
    layers_visited = Counter(s.l for s in steps)
    gl = solution.goal_cells.l
    lb = max(layers_visited, key=lambda ll: (layers_visited[ll], ll == gl, -ll))
    mpl = _matplotlib()
    width = 7.0
    fig = _figure(mpl, width + 3.2, max(_panel_height(grid, width) + 1.0, 5.2))
    gs = fig.add_gridspec(1, 2, width_ratios=[width, 3.0])
    ax = fig.add_subplot(gs[0, 0])
    side = fig.add_subplot(gs[0, 1])
    side.set_axis_off()

    ax.set_facecolor(WATER_COLOR)
    _draw_land(mpl, ax, grid, ~model.water[lb])
    _draw_flow_directions(mpl, ax, grid, model.flow_dir[lb])
    _draw_outline(mpl, ax, grid, solution.goal_cells.mask[lb], color=GOAL_COLOR, linewidth=2.0)

    x = np.array([grid.lon_deg[s.i] for s in steps])
    y = np.array([grid.lat_deg[s.j] for s in steps])
    pe = mpl.patheffects
    segs, colors, other = [], [], []
    for s0, s1, x0, y0, x1, y1 in zip(steps[:-1], steps[1:], x[:-1], y[:-1], x[1:], y[1:]):
        if (x0, y0) == (x1, y1):
            continue
        segs.append([(x0, y0), (x1, y1)])
        colors.append(ACTION_COLORS[s0.action])
        other.append(not (s0.l == lb and s1.l == lb))
    # Coloured by action (dashed where a step leaves or is outside the drawn layer),
    # under a thin black line through the cell centres.
    for dashed in (False, True):
        sel = [n for n, o in enumerate(other) if o == dashed]
        if sel:
            ax.add_collection(mpl.collections.LineCollection(
                [segs[n] for n in sel], colors=[colors[n] for n in sel], linewidths=6.0, zorder=5,
                linestyles=(0, (1.0, 0.6)) if dashed else "solid", capstyle="butt" if dashed else "round",
                joinstyle="round"))
    if len(steps) > 1:
        ax.plot(x, y, color="black", linewidth=1.3, solid_capstyle="round", solid_joinstyle="round", zorder=6)
    rot_count: Counter[tuple[int, int, Action]] = Counter()
    for s in steps:
        if s.action in _ROTATE_MARKER:
            rot_count[(s.i, s.j, s.action)] += 1
    for (i, j, a), n in rot_count.items():
        dx = -0.18 if a == Action.ROTATE_LEFT else 0.18
        px, py = grid.lon_deg[i] + dx * grid.dlon_deg, grid.lat_deg[j] + 0.22 * grid.dlat_deg
        ax.plot(px, py, linestyle="none", marker=_ROTATE_MARKER[a], markersize=15, color=ACTION_COLORS[a],
                zorder=8, clip_on=False, path_effects=[pe.withStroke(linewidth=2.5, foreground="white")])
        if n > 1:
            ax.annotate(f"\u00d7{n}", (px, py), xytext=(7, 4), textcoords="offset points", fontsize=8,
                        color=ACTION_COLORS[a], zorder=8)
    for s0 in steps[:-1]:
        if s0.action in (Action.UP, Action.DOWN):
            ax.plot(grid.lon_deg[s0.i], grid.lat_deg[s0.j], linestyle="none",
                    marker="^" if s0.action == Action.UP else "v", markersize=9, color=ACTION_COLORS[s0.action],
                    markeredgecolor="white", zorder=8)
    l0, j0, i0, k0 = start
    ax.plot(grid.lon_deg[i0], grid.lat_deg[j0], linestyle="none", marker="o", markersize=13,
            markerfacecolor=START_COLOR, markeredgecolor="black", markeredgewidth=1.2, zorder=10, clip_on=False)
    gc = solution.goal_cells
    ax.plot(grid.lon_deg[gc.i], grid.lat_deg[gc.j], linestyle="none", marker="*", markersize=20,
            markerfacecolor=GOAL_COLOR, markeredgecolor="black", markeredgewidth=1.0, zorder=10, clip_on=False)
    _geo_axes(mpl, ax, grid)
    ax.set_title(f"Nominal path from the start (heading {Direction(k0).name}, {grid.depth_m[l0]:g} m) to the goal\n"
                 f"over the flow directions and land of layer {lb} ({grid.depth_m[lb]:g} m)", fontsize=11)

    handles = [
        mpl.lines.Line2D([], [], linestyle="none", marker="o", markersize=10, markerfacecolor=START_COLOR,
                         markeredgecolor="black", label="start"),
        mpl.lines.Line2D([], [], linestyle="none", marker="*", markersize=14, markerfacecolor=GOAL_COLOR,
                         markeredgecolor="black", label="goal"),
        mpl.lines.Line2D([], [], color=GOAL_COLOR, linewidth=2.0, label="goal cells"),
    ]
    used = [a for a in Action if any(s.action == a for s in steps[:-1])]
    for a in used:
        if a in _ROTATE_MARKER:
            handles.append(mpl.lines.Line2D([], [], linestyle="none", marker=_ROTATE_MARKER[a], markersize=12,
                                            color=ACTION_COLORS[a], label=_action_label(a)))
        else:
            handles.append(mpl.lines.Line2D([], [], color=ACTION_COLORS[a], linewidth=6.0, label=_action_label(a)))
    if any(other):
        handles.append(mpl.lines.Line2D([], [], color="0.45", linewidth=6.0, linestyle=(0, (2.0, 1.5)),
                                        label="step in another layer"))
    handles.append(mpl.lines.Line2D([], [], color=FLOW_ARROW_COLOR, marker=r"$\rightarrow$", linestyle="none",
                                    markersize=12, label="flow direction (paper model)" if _is_physical(solution)
                                    else "flow direction (planner)"))
    if (model.flow_dir[lb] == -1).any():
        handles.append(mpl.lines.Line2D([], [], linestyle="none", marker=".", markersize=6,
                                        color=FLOW_ARROW_COLOR, label="calm"))
    if (~model.water[lb]).any():
        handles.append(mpl.patches.Patch(facecolor=LAND_COLOR, edgecolor="0.5", label="land"))
    handles.insert(3, mpl.lines.Line2D([], [], color="black", linewidth=1.3, label="path through cell centres"))
    side.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.0, 0.99), frameon=False, fontsize=9,
                borderaxespad=0.0, handlelength=3.0)
    keep_clear = [(float(grid.lon_deg[i0]), float(grid.lat_deg[j0]), 11.0),
                  (float(grid.lon_deg[gc.i]), float(grid.lat_deg[gc.j]), 11.0)]
    keep_clear += [(float(xx), float(yy), 4.0) for xx, yy in zip(x, y)]
    _place_labels(fig, ax, _layer_change_labels(steps, grid), keep_clear)
    side.text(0.02, 0.02, _path_summary(solution, start, steps), transform=side.transAxes, va="bottom", ha="left",
              fontsize=8.5, family="monospace",
              bbox={"boxstyle": "round,pad=0.5", "facecolor": "white", "edgecolor": "0.6"})
    return _save(fig, path)


def default_start(solution: AnySolution) -> tuple[int, int, int, int]:
    """A reachable, non-goal state far from the goal, ``(l, j, i, k)``, for demos.

    Among the reachable water states of the goal layer with heading east, the
    one farthest from the goal cell in metres (spec section 1 cell sizes), then
    with the largest cost-to-go, then the most steps, then the lowest index; if
    that slice has none, the same over every layer and heading. Raises
    ``ShoreError`` when only goal states are reachable.
    """
    grid = solution.model.grid
    gc = solution.goal_cells
    cost = solution.cost
    steps = solution.steps
    dx_m, dy_m = grid.cell_size_m()
    jj, ii = np.meshgrid(np.arange(grid.ny), np.arange(grid.nx), indexing="ij")
    dist = np.hypot((ii - gc.i) * dx_m[:, None], (jj - gc.j) * dy_m)  # (ny, nx)
    dist = np.broadcast_to(dist[None, :, :, None], cost.shape)
    ok = np.isfinite(cost) & ~gc.mask[..., None]
    east = np.zeros_like(ok)
    east[gc.l, :, :, Direction.E] = True
    for cand in (ok & east, ok):
        if cand.any():
            flat = np.flatnonzero(cand)
            # np.lexsort sorts by its last key first, and is stable: ties go to the lowest index.
            order = np.lexsort((-steps.ravel()[flat], -cost.ravel()[flat], -np.round(dist.ravel()[flat], 3)))
            l, j, i, k = np.unravel_index(int(flat[order[0]]), cost.shape)
            return (int(l), int(j), int(i), int(k))
    raise ShoreError(
        "default start: expected a reachable state outside the goal cells; "
        f"got none (goal layer {gc.l}, {int(gc.mask.sum())} goal cells)"
    )


def plot_all(
    u_m_s: NDArray[np.float64],
    v_m_s: NDArray[np.float64],
    solution: AnySolution,
    out_dir: str | os.PathLike[str],
    *,
    start: tuple[int, int, int, int] | None = None,
    heading: int = 0,
    layer: int | None = None,
) -> list[Path]:
    """Write ``flow_fields.png``, ``policy_k{heading}_l{layer}.png`` and ``nominal_path.png``.

    ``out_dir`` is created if needed; ``start`` defaults to ``default_start``
    and ``layer`` to the goal layer. Returns the three paths in that order.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    k = _check_heading(heading)
    l = solution.goal_cells.l if layer is None else _check_layer(layer, solution.model.grid)
    return [
        plot_flow_fields(u_m_s, v_m_s, solution.model, out / "flow_fields.png", goal=solution.goal),
        plot_policy(solution, out / f"policy_k{k}_l{l}.png", heading=k, layer=l),
        plot_nominal_path(solution, default_start(solution) if start is None else start, out / "nominal_path.png"),
    ]


# --------------------------------------------------------------------------- checks


# ArduSub modes (executive.state.SubMode) as the executive uses them: GUIDED = thrusting
# (forward or turning), ALT_HOLD = drifting or gliding, SURFACE = safe behaviour.
_MODE_STYLE = {4: ("GUIDED (forward, rotate, hold)", "#d55e00"), 2: ("ALT_HOLD (drift, glide)", "#0072b2"),
               9: ("SURFACE", "#7f7f7f"), 19: ("MANUAL", "#cc79a7")}


def plot_track(table: Any, lon_deg: Any, lat_deg: Any, mode: Any, path: str | os.PathLike[str]) -> Path:
    """A vehicle track over the table's land and goal, coloured by autopilot mode.

    ``table`` is a ``planner.contract.table.PolicyTable``; ``lon_deg``, ``lat_deg`` and ``mode``
    (ArduSub custom mode numbers) are equal-length sequences of track samples.
    """
    from planner.grid import Grid

    lon, lat, modes = (np.asarray(a, dtype=np.float64) for a in (lon_deg, lat_deg, mode))
    if not (lon.shape == lat.shape == modes.shape and lon.ndim == 1 and lon.size >= 1):
        raise ShoreError(f"track: expected equal-length 1-D lon/lat/mode; got {lon.shape}, {lat.shape}, {modes.shape}")
    grid = Grid(lon_deg=table.lon_deg, lat_deg=table.lat_deg, depth_m=np.asarray(table.depth_m))
    mpl = _matplotlib()
    width = 7.0
    fig = _figure(mpl, width, _panel_height(grid, width - 1.0) + 1.2)
    ax = fig.subplots()
    ax.set_facecolor(WATER_COLOR)
    _draw_land(mpl, ax, grid, ~table.water[0])
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
    _geo_axes(mpl, ax, grid)
    return _save(fig, path)


def _check_currents(u_m_s: Any, v_m_s: Any, grid: Grid) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    u = np.asarray(u_m_s, dtype=np.float64)
    v = np.asarray(v_m_s, dtype=np.float64)
    want = (grid.n_layers, grid.ny, grid.nx)
    if u.shape != want or v.shape != want:
        raise ShoreError(
            f"plot currents: expected u and v of shape (L, ny, nx) = {want}; got {u.shape} and {v.shape}"
        )
    return u, v


def _check_heading(heading: int) -> int:
    if not isinstance(heading, int | np.integer) or isinstance(heading, bool) or not 0 <= heading < N_HEADINGS:
        raise ShoreError(f"plot heading: expected a grid direction k in 0..7 (0 = E, 2 = N); got {heading!r}")
    return int(heading)


def _check_layer(layer: int, grid: Grid) -> int:
    if not isinstance(layer, int | np.integer) or isinstance(layer, bool) or not 0 <= layer < grid.n_layers:
        raise ShoreError(f"plot layer: expected a layer index in 0..{grid.n_layers - 1}; got {layer!r}")
    return int(layer)


def _check_state(state: tuple[int, int, int, int], solution: AnySolution) -> tuple[int, int, int, int]:
    shape = solution.model.grid.shape
    try:
        l, j, i, k = (int(x) for x in state)
    except (TypeError, ValueError):
        raise ShoreError(f"plot start: expected a state (l, j, i, k); got {state!r}") from None
    if not all(0 <= x < n for x, n in zip((l, j, i, k), shape)):
        raise ShoreError(f"plot start: expected (l, j, i, k) within the state shape {shape}; got {state!r}")
    if not solution.model.water[l, j, i]:
        raise ShoreError(f"plot start: state {state!r} is on land (layer {l}, cell i={i}, j={j})")
    return (l, j, i, k)


def _goal_cell(grid: Grid, goal: Goal) -> tuple[int, int, int]:
    i, j, _ = grid.nearest_cell(goal.lon_deg, goal.lat_deg)
    return i, j, grid.nearest_layer(goal.depth_m)


# --------------------------------------------------------------------------- drawing helpers


def _matplotlib() -> Any:
    """Import the matplotlib pieces used here, lazily; returns the package."""
    import matplotlib
    import matplotlib.backends.backend_agg
    import matplotlib.collections
    import matplotlib.colors
    import matplotlib.figure
    import matplotlib.lines
    import matplotlib.patches
    import matplotlib.patheffects
    import matplotlib.ticker

    return matplotlib


def _figure(mpl: Any, width_in: float, height_in: float) -> Any:
    """A Figure on its own Agg canvas: no pyplot, no global backend switch."""
    fig = mpl.figure.Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    mpl.backends.backend_agg.FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically; returns the path."""
    with atomic_target(path) as tmp:
        fig.savefig(tmp, format="png", dpi=DPI, facecolor="white")
    return Path(path)


def _cos_lat(grid: Grid) -> float:
    return float(np.cos(np.radians(0.5 * (grid.lat_deg[0] + grid.lat_deg[-1]))))


def _panel_height(grid: Grid, width_in: float) -> float:
    """Axes height that keeps the map's metric aspect for an axes ``width_in`` wide."""
    ratio = grid.ny * grid.dlat_deg / (grid.nx * grid.dlon_deg * _cos_lat(grid))
    return float(np.clip(width_in * ratio, 2.4, 9.0))


def _cell_points(grid: Grid, width_in: float) -> float:
    """Approximate displayed size of one cell, in points, on a map axes ``width_in`` wide."""
    ratio = grid.ny * grid.dlat_deg / (grid.nx * grid.dlon_deg * _cos_lat(grid))  # map height / width
    map_w = min(width_in, _panel_height(grid, width_in) / ratio)
    return 72.0 * min(map_w / grid.nx, map_w * ratio / grid.ny)


def _stride(grid: Grid, max_per_axis: int) -> int:
    return max(1, math.ceil(max(grid.nx, grid.ny) / max_per_axis))


def _edges(grid: Grid) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Cell edges: centres lie on the bbox edges, so edges extend half a cell beyond (spec section 1)."""
    lon_e = np.concatenate([grid.lon_deg - 0.5 * grid.dlon_deg, [grid.lon_deg[-1] + 0.5 * grid.dlon_deg]])
    lat_e = np.concatenate([grid.lat_deg - 0.5 * grid.dlat_deg, [grid.lat_deg[-1] + 0.5 * grid.dlat_deg]])
    return lon_e, lat_e


def _truncated(mpl: Any, name: str, lo: float, hi: float) -> Any:
    base = mpl.colormaps[name]
    return mpl.colors.ListedColormap(base(np.linspace(lo, hi, 256)), name=f"{name}_{lo:g}_{hi:g}")


def _draw_land(mpl: Any, ax: Any, grid: Grid, land: NDArray[np.bool_]) -> None:
    if not land.any():
        return
    lon_e, lat_e = _edges(grid)
    ax.pcolormesh(lon_e, lat_e, np.ma.masked_where(~land, np.ones(land.shape)),
                  cmap=mpl.colors.ListedColormap([LAND_COLOR]), vmin=0.0, vmax=1.0, zorder=2)
    _draw_outline(mpl, ax, grid, land, color="#8c7a55", linewidth=0.8)


def _draw_outline(mpl: Any, ax: Any, grid: Grid, mask: NDArray[np.bool_], *, color: str, linewidth: float) -> None:
    """Outline the union of the cells where ``mask`` is true (edges between in and out)."""
    if not mask.any():
        return
    lon_e, lat_e = _edges(grid)
    padded = np.pad(mask, 1)
    segs = []
    # Vertical edges: between columns i-1 and i (padded index shift).
    vert = padded[1:-1, 1:] != padded[1:-1, :-1]  # (ny, nx + 1)
    for j, i in zip(*np.nonzero(vert)):
        segs.append([(lon_e[i], lat_e[j]), (lon_e[i], lat_e[j + 1])])
    horiz = padded[1:, 1:-1] != padded[:-1, 1:-1]  # (ny + 1, nx)
    for j, i in zip(*np.nonzero(horiz)):
        segs.append([(lon_e[i], lat_e[j]), (lon_e[i + 1], lat_e[j])])
    ax.add_collection(mpl.collections.LineCollection(segs, colors=color, linewidths=linewidth, zorder=3.5,
                                                     capstyle="projecting"))


def _draw_flow_directions(mpl: Any, ax: Any, grid: Grid, flow_dir: NDArray[np.int8]) -> None:
    """The planner's flow direction ``w`` of each cell (spec section 3) as faint arrows; calm as dots."""
    stride = _stride(grid, _MAX_ARROWS_PER_AXIS)
    jj, ii = np.meshgrid(np.arange(0, grid.ny, stride), np.arange(0, grid.nx, stride), indexing="ij")
    w = flow_dir[jj, ii].astype(np.int64)
    moving = w >= 0
    x, y = grid.lon_deg[ii][moving], grid.lat_deg[jj][moving]
    wm = w[moving]
    length = 0.55 * stride
    dx = DI[wm] * grid.dlon_deg * length
    dy = DJ[wm] * grid.dlat_deg * length
    diag = (DI[wm] != 0) & (DJ[wm] != 0)
    dx = np.where(diag, dx / math.sqrt(2), dx)
    dy = np.where(diag, dy / math.sqrt(2), dy)
    if x.size:
        ax.quiver(x, y, dx, dy, color=FLOW_ARROW_COLOR, angles="xy", scale_units="xy", scale=1.0, pivot="middle",
                  width=0.0035, headwidth=3.5, headlength=4.0, headaxislength=3.5, zorder=3)
    calm = w == -1
    if calm.any():
        ax.plot(grid.lon_deg[ii][calm], grid.lat_deg[jj][calm], linestyle="none", marker=".", markersize=4,
                color=FLOW_ARROW_COLOR, zorder=3)


def _geo_axes(mpl: Any, ax: Any, grid: Grid, *, xlabel: bool = True, ylabel: bool = True) -> None:
    """Lon/lat axes in degrees with hemisphere letters and aspect 1/cos(lat) (spec section 1)."""
    lon_e, lat_e = _edges(grid)
    ax.set_xlim(lon_e[0], lon_e[-1])
    ax.set_ylim(lat_e[0], lat_e[-1])
    ax.set_aspect(1.0 / _cos_lat(grid))
    ax.xaxis.set_major_locator(mpl.ticker.MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]))
    ax.yaxis.set_major_locator(mpl.ticker.MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]))
    ax.xaxis.set_major_formatter(_degree_formatter(mpl, "E", "W"))
    ax.yaxis.set_major_formatter(_degree_formatter(mpl, "N", "S"))
    ax.tick_params(labelsize=8.5)
    if xlabel:
        ax.set_xlabel("longitude")
    if ylabel:
        ax.set_ylabel("latitude")


def _degree_formatter(mpl: Any, pos_letter: str, neg_letter: str) -> Any:
    """Tick labels like ``118.15°W`` with as few decimals as the tick spacing needs."""

    class DegreeFormatter(mpl.ticker.Formatter):  # type: ignore[misc, name-defined]
        decimals = 2

        def format_ticks(self, values: Any) -> list[str]:
            locs = np.asarray(values, dtype=np.float64)
            self.decimals = 0
            while self.decimals < 5 and np.any(np.abs(np.round(locs, self.decimals) - locs) > 1e-9):
                self.decimals += 1
            return [self(x, n) for n, x in enumerate(locs)]

        def __call__(self, x: float, pos: int | None = None) -> str:
            letter = pos_letter if x > 0 else neg_letter if x < 0 else ""
            return f"{abs(x):.{self.decimals}f}\u00b0{letter}"

    return DegreeFormatter()


def _nice_speed(x: float) -> float:
    """A round speed near ``x`` for the arrow key (1, 2 or 5 times a power of ten)."""
    if x <= 0:
        return 0.1
    p = 10.0 ** math.floor(math.log10(x))
    return float(min((m * p for m in (1, 2, 5, 10)), key=lambda c: abs(c - x)))


def _action_label(a: Action) -> str:
    return a.name.replace("_", " ").lower()


def _is_physical(solution: Any) -> bool:
    return getattr(solution.model.settings, "model", "paper") == "physical"


def _nominal_steps(solution: AnySolution, start: tuple[int, int, int, int]) -> list[Any]:
    """The nominal path: ``planner.paper.solve.nominal_path`` (paper) or ``PhysicalSolution.nominal``."""
    if _is_physical(solution):
        return solution.nominal(start)  # type: ignore[union-attr]
    from planner.paper.solve import nominal_path

    return nominal_path(solution, start)  # type: ignore[arg-type]


def _nominal_displacement(solution: AnySolution, l: int, j: int, i: int, k: int, a: Action) -> tuple[int, int]:
    """Horizontal displacement ``(di, dj)`` of the action's nominal outcome (spec section 5); for a physical
    plan, of the policy's pair's most likely outcome (ties: the first listed)."""
    model = solution.model
    if _is_physical(solution):
        pair = int(solution.policy_pair[model.state_index(l, j, i, k)])  # type: ignore[union-attr]
        if pair < 0:
            return (0, 0)
        (_, jj, ii, _), _, _ = max(model.outcomes(pair), key=lambda o: o[1])  # type: ignore[call-arg, arg-type]
        return (ii - i, jj - j)
    outs = model.outcomes(l, j, i, k, a)  # type: ignore[call-arg]
    if not outs:
        return (0, 0)
    _, jj, ii, _ = outs[0]
    return (ii - i, jj - j)


def _layer_change_labels(steps: list[PathStep] | list[PhysicalStep], grid: Grid) -> list[tuple[float, float, str, str]]:
    """Depth labels ``(lon, lat, text, colour)`` for the path's UP/DOWN actions.

    Layer changes within two cells of the previous one share a label, e.g.
    ``↓ 0 → 5 → 10 m``, so that a dive through several layers reads as one.
    """
    clusters: list[list[tuple[Any, Any]]] = []
    for s0, s1 in zip(steps[:-1], steps[1:]):
        if s0.action not in (Action.UP, Action.DOWN):
            continue
        if clusters:
            last = clusters[-1][-1][0]
            if max(abs(s0.i - last.i), abs(s0.j - last.j)) <= 2:
                clusters[-1].append((s0, s1))
                continue
        clusters.append([(s0, s1)])
    labels = []
    for cl in clusters:
        kinds = {s0.action for s0, _ in cl}
        arrow = "\u2193" if kinds == {Action.DOWN} else "\u2191" if kinds == {Action.UP} else "\u2195"
        depths = [grid.depth_m[cl[0][0].l]] + [grid.depth_m[s1.l] for _, s1 in cl]
        text = f"{arrow} " + " \u2192 ".join(f"{d:g}" for d in depths) + " m"
        color = ACTION_COLORS[next(iter(kinds))] if len(kinds) == 1 else "0.4"
        first = cl[0][0]
        labels.append((float(grid.lon_deg[first.i]), float(grid.lat_deg[first.j]), text, color))
    return labels


def _place_labels(fig: Any, ax: Any, labels: list[tuple[float, float, str, str]],
                  keep_clear: list[tuple[float, float, float]]) -> None:
    """Annotate each point, trying a few offsets to avoid earlier labels and ``keep_clear`` ``(x, y, radius_pt)``."""
    if not labels:
        return
    fig.draw_without_rendering()  # settle the layout so that display positions are final
    renderer = fig.canvas.get_renderer()
    px = fig.dpi / 72.0
    taken = []
    for cx, cy, r in keep_clear:
        dx, dy = ax.transData.transform((cx, cy))
        taken.append((dx - r * px, dy - r * px, dx + r * px, dy + r * px))
    axes_box = ax.get_window_extent(renderer)
    offsets = [(9, -14, "left"), (9, 8, "left"), (-9, 8, "right"), (-9, -14, "right"), (0, 14, "center"),
               (0, -22, "center"), (16, -3, "left"), (-16, -3, "right")]
    for x, y, text, color in labels:
        ann = ax.annotate(text, (x, y), xytext=offsets[0][:2], textcoords="offset points", ha=offsets[0][2],
                          fontsize=8, color="black", zorder=9, annotation_clip=False,
                          bbox={"boxstyle": "round,pad=0.2", "facecolor": "white", "edgecolor": color, "alpha": 0.9})
        ann.set_in_layout(False)
        best, best_overlap = None, None
        for ox, oy, ha in offsets:
            ann.set_position((ox, oy))
            ann.set_horizontalalignment(ha)
            e = ann.get_window_extent(renderer).expanded(1.15, 1.4)
            box = (e.x0, e.y0, e.x1, e.y1)
            overlap = sum(_overlap_area(box, t) for t in taken)
            outside = max(0.0, axes_box.x0 - e.x0) + max(0.0, e.x1 - axes_box.x1) + max(0.0, axes_box.y0 - e.y0) \
                + max(0.0, e.y1 - axes_box.y1)
            score = overlap + 50.0 * outside
            if best_overlap is None or score < best_overlap:
                best, best_overlap = (ox, oy, ha, box), score
            if score == 0:
                break
        assert best is not None
        ann.set_position(best[:2])
        ann.set_horizontalalignment(best[2])
        taken.append(best[3])


def _overlap_area(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


def _path_summary(solution: AnySolution, start: tuple[int, int, int, int], steps: list[Any]) -> str:
    if _is_physical(solution):
        return _physical_path_summary(solution, start, steps)  # type: ignore[arg-type]
    settings = solution.model.settings
    l, j, i, k = start
    cost, n = solution.value(l, j, i, k)
    counts = Counter(s.action for s in steps[:-1])
    path_cost = sum(int(solution.model.costs[s.action]) for s in steps[:-1])
    case = "worst" if settings.criterion == "robust" else "best"
    last = steps[-1].action
    lines = _start_and_goal(solution, start) + [
        f"plan ({settings.criterion}, {settings.uncertainty})",
        f"predicted from start ({case} case):" if math.isfinite(cost) else "start cannot reach the goal",
    ]
    if math.isfinite(cost):
        lines.append(f"  cost {cost:g}, {n} steps")
    lines.append("nominal path:")
    lines.append(f"  cost {path_cost}, {len(steps) - 1} actions")
    lines += _action_counts(counts)
    if last != Action.AT_GOAL and math.isfinite(cost):
        lines.append("ends before the goal: the plan")
        lines.append("counts on a better outcome")
    return "\n".join(lines)


def _physical_path_summary(solution: PhysicalSolution, start: tuple[int, int, int, int],
                           steps: list[PhysicalStep]) -> str:
    """The side text of the nominal path picture for a physical plan: costs in Wh, times in hours."""
    settings = solution.model.settings
    l, j, i, k = start
    cost = float(solution.value_wh[l, j, i, k])
    hours = float(solution.time_s[l, j, i, k]) / 3600.0
    counts = Counter(s.action for s in steps[:-1])
    path_h = sum(s.duration_s for s in steps[:-1]) / 3600.0
    case = "worst" if settings.criterion == "robust" else "expected"
    last = steps[-1].action
    lines = _start_and_goal(solution, start) + [
        f"plan (physical, {settings.criterion})",
        f"predicted from start ({case} case):" if math.isfinite(cost) else "start cannot reach the goal",
    ]
    if math.isfinite(cost):
        lines.append(f"  {cost:.1f} Wh, {hours:.2f} h to go")
    lines.append("nominal path (most likely):")
    lines.append(f"  {len(steps) - 1} actions, {path_h:.2f} h (mean)")
    lines += _action_counts(counts)
    if last != Action.AT_GOAL and math.isfinite(cost):
        lines.append("ends before the goal: the most")
        lines.append("likely outcome repeats a state")
    return "\n".join(lines)


def _lonlat(lon: float, lat: float) -> str:
    return f"{abs(lon):.4f}\u00b0{'E' if lon >= 0 else 'W'} {abs(lat):.4f}\u00b0{'N' if lat >= 0 else 'S'}"


def _start_and_goal(solution: Any, start: tuple[int, int, int, int]) -> list[str]:
    """The first lines of a nominal path's side text: where it starts and where the goal is."""
    grid = solution.model.grid
    l, j, i, k = start
    gc = solution.goal_cells
    return [
        f"start  {_lonlat(grid.lon_deg[i], grid.lat_deg[j])}",
        f"       {grid.depth_m[l]:g} m, heading {Direction(k).name}",
        f"goal   {_lonlat(grid.lon_deg[gc.i], grid.lat_deg[gc.j])}",
        f"       {grid.depth_m[gc.l]:g} m, radius {solution.goal.radius_cells} cell(s)",
        "",
    ]


def _action_counts(counts: Counter[Action]) -> list[str]:
    return [f"  {_action_label(a):<13}{counts[a]:>4}" for a in Action if counts[a]]
