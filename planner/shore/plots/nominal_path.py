"""The nominal path from a start state to the goal (paper Fig. 6), and a default start for demos.

The path follows the policy with each action's nominal outcome (spec section 5;
for a physical plan, the most likely outcome) and is drawn over the planner's
flow directions (spec section 3) and land.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.errors import ShoreError
from planner.contract.headings import DI, DJ, Direction
from planner.shore.plots.map_axes import (
    MAX_ARROWS_PER_AXIS,
    arrow_stride,
    draw_land,
    draw_outline,
    geo_axes,
    panel_height,
)
from planner.shore.plots.solutions import NominalStep, is_physical, nominal_steps
from planner.shore.plots.style import (
    ACTION_COLORS,
    FLOW_ARROW_COLOR,
    GOAL_COLOR,
    LAND_COLOR,
    ROTATE_MARKERS,
    START_COLOR,
    WATER_COLOR,
    action_label,
    load_matplotlib,
    new_figure,
    save_png,
)

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.shore.plots.currents import ForecastMoment
    from planner.grid import Grid
    from planner.paper.solve import PathStep, Solution
    from planner.physical.solve import PhysicalSolution, PhysicalStep
    from planner.shore.plots.solutions import AnySolution

__all__ = ["default_start", "nominal_path_figure", "plot_nominal_path"]


def plot_nominal_path(
    solution: AnySolution,
    start: tuple[int, int, int, int],
    path: str | os.PathLike[str],
    *,
    start_lon_lat: tuple[float, float] | None = None,
    when: ForecastMoment | None = None,
) -> Path:
    """``nominal_path_figure`` written as a PNG at ``path``."""
    return save_png(nominal_path_figure(solution, start, start_lon_lat=start_lon_lat, when=when), path)


def nominal_path_figure(
    solution: AnySolution,
    start: tuple[int, int, int, int],
    *,
    start_lon_lat: tuple[float, float] | None = None,
    when: ForecastMoment | None = None,
) -> Any:
    """The nominal path from ``start`` ``(l, j, i, k)`` to the goal (paper Fig. 6).

    The path is ``planner.paper.solve.nominal_path``: the policy followed with each
    action's nominal outcome (spec section 5). It is drawn through the cell
    centres over the planner's flow directions and land of the layer where it
    spends most steps; segments are coloured by the action taken, rotations are
    circular arrows, layer changes are labelled with their depths, and steps in
    another layer are dashed. Red marks the start, green the goal (paper Fig. 6).
    For a physical plan the path is ``PhysicalSolution.nominal`` (each action's
    most likely outcome) and the costs are in Wh. ``start_lon_lat``: where the
    vehicle really starts (in ``start``'s cell); the path then begins there, not
    at the cell's centre. ``when``: the forecast step planned on, in the title.
    """
    model = solution.model
    grid = model.grid
    start = _check_state(start, solution)
    steps: Sequence[NominalStep]
    if is_physical(solution):
        physical_steps = nominal_steps(solution, start)
        steps, summary = physical_steps, _physical_path_summary(solution, start, physical_steps)
    else:
        paper_steps = nominal_steps(solution, start)
        steps, summary = paper_steps, _paper_path_summary(solution, start, paper_steps)
    layers_visited = Counter(s.l for s in steps)
    gl = solution.goal_cells.l
    lb = max(layers_visited, key=lambda ll: (layers_visited[ll], ll == gl, -ll))
    mpl = load_matplotlib()
    width = 7.0
    fig = new_figure(mpl, width + 3.2, max(panel_height(grid, width) + 1.0, 5.2))
    gs = fig.add_gridspec(1, 2, width_ratios=[width, 3.0])
    ax = fig.add_subplot(gs[0, 0])
    side = fig.add_subplot(gs[0, 1])
    side.set_axis_off()

    ax.set_facecolor(WATER_COLOR)
    draw_land(mpl, ax, grid, ~model.water[lb])
    _draw_flow_directions(mpl, ax, grid, model.flow_dir[lb])
    draw_outline(mpl, ax, grid, solution.goal_cells.mask[lb], color=GOAL_COLOR, linewidth=2.0)

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
    l0, j0, i0, k0 = start
    sx, sy = (float(grid.lon_deg[i0]), float(grid.lat_deg[j0])) if start_lon_lat is None else start_lon_lat
    if start_lon_lat is not None:  # the vehicle's own position first, then the cell centres
        x, y = np.concatenate([[sx], x]), np.concatenate([[sy], y])
    if x.size > 1:
        centre_line, = ax.plot(x, y, color="black", linewidth=1.3, solid_capstyle="round", solid_joinstyle="round",
                               zorder=6)
        centre_line.set_gid("nominal path")
    rot_count: Counter[tuple[int, int, Action]] = Counter()
    for s in steps:
        if s.action in ROTATE_MARKERS:
            rot_count[(s.i, s.j, s.action)] += 1
    for (i, j, a), n in rot_count.items():
        dx = -0.18 if a == Action.ROTATE_LEFT else 0.18
        px, py = grid.lon_deg[i] + dx * grid.dlon_deg, grid.lat_deg[j] + 0.22 * grid.dlat_deg
        ax.plot(px, py, linestyle="none", marker=ROTATE_MARKERS[a], markersize=15, color=ACTION_COLORS[a],
                zorder=8, clip_on=False, path_effects=[pe.withStroke(linewidth=2.5, foreground="white")])
        if n > 1:
            ax.annotate(f"\u00d7{n}", (px, py), xytext=(7, 4), textcoords="offset points", fontsize=8,
                        color=ACTION_COLORS[a], zorder=8)
    for s0 in steps[:-1]:
        if s0.action in (Action.UP, Action.DOWN):
            ax.plot(grid.lon_deg[s0.i], grid.lat_deg[s0.j], linestyle="none",
                    marker="^" if s0.action == Action.UP else "v", markersize=9, color=ACTION_COLORS[s0.action],
                    markeredgecolor="white", zorder=8)
    ax.plot(sx, sy, linestyle="none", marker="o", markersize=13,
            markerfacecolor=START_COLOR, markeredgecolor="black", markeredgewidth=1.2, zorder=10, clip_on=False)
    gc = solution.goal_cells
    ax.plot(grid.lon_deg[gc.i], grid.lat_deg[gc.j], linestyle="none", marker="*", markersize=20,
            markerfacecolor=GOAL_COLOR, markeredgecolor="black", markeredgewidth=1.0, zorder=10, clip_on=False)
    geo_axes(mpl, ax, grid)
    where = "the vehicle's start" if start_lon_lat is not None else "the start cell's centre"
    ax.set_title(f"Nominal path from {where} (heading {Direction(k0).name}, {grid.depth_m[l0]:g} m) to the goal\n"
                 f"over the flow directions and land of layer {lb} ({grid.depth_m[lb]:g} m)"
                 + (f"\nplanned on the {when.label()}" if when is not None else ""), fontsize=10)

    handles = [
        mpl.lines.Line2D([], [], linestyle="none", marker="o", markersize=10, markerfacecolor=START_COLOR,
                         markeredgecolor="black", label="start"),
        mpl.lines.Line2D([], [], linestyle="none", marker="*", markersize=14, markerfacecolor=GOAL_COLOR,
                         markeredgecolor="black", label="goal"),
        mpl.lines.Line2D([], [], color=GOAL_COLOR, linewidth=2.0, label="goal cells"),
    ]
    used = [a for a in Action if any(s.action == a for s in steps[:-1])]
    for a in used:
        if a in ROTATE_MARKERS:
            handles.append(mpl.lines.Line2D([], [], linestyle="none", marker=ROTATE_MARKERS[a], markersize=12,
                                            color=ACTION_COLORS[a], label=action_label(a)))
        else:
            handles.append(mpl.lines.Line2D([], [], color=ACTION_COLORS[a], linewidth=6.0, label=action_label(a)))
    if any(other):
        handles.append(mpl.lines.Line2D([], [], color="0.45", linewidth=6.0, linestyle=(0, (2.0, 1.5)),
                                        label="step in another layer"))
    handles.append(mpl.lines.Line2D([], [], color=FLOW_ARROW_COLOR, marker=r"$\rightarrow$", linestyle="none",
                                    markersize=12, label="flow direction (paper model)" if is_physical(solution)
                                    else "flow direction (planner)"))
    if (model.flow_dir[lb] == -1).any():
        handles.append(mpl.lines.Line2D([], [], linestyle="none", marker=".", markersize=6,
                                        color=FLOW_ARROW_COLOR, label="calm"))
    if (~model.water[lb]).any():
        handles.append(mpl.patches.Patch(facecolor=LAND_COLOR, edgecolor="0.5", label="land"))
    handles.insert(3, mpl.lines.Line2D([], [], color="black", linewidth=1.3, label="path through cell centres"))
    side.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.0, 0.99), frameon=False, fontsize=9,
                borderaxespad=0.0, handlelength=3.0)
    keep_clear = [(sx, sy, 11.0),
                  (float(grid.lon_deg[gc.i]), float(grid.lat_deg[gc.j]), 11.0)]
    keep_clear += [(float(xx), float(yy), 4.0) for xx, yy in zip(x, y)]
    _place_labels(fig, ax, _layer_change_labels(steps, grid), keep_clear)
    side.text(0.02, 0.02, summary, transform=side.transAxes, va="bottom", ha="left",
              fontsize=8.5, family="monospace",
              bbox={"boxstyle": "round,pad=0.5", "facecolor": "white", "edgecolor": "0.6"})
    return fig


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


def _draw_flow_directions(mpl: Any, ax: Any, grid: Grid, flow_dir: NDArray[np.int8]) -> None:
    """The planner's flow direction ``w`` of each cell (spec section 3) as faint arrows; calm as dots."""
    stride = arrow_stride(grid, MAX_ARROWS_PER_AXIS)
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


def _layer_change_labels(steps: Sequence[NominalStep], grid: Grid) -> list[tuple[float, float, str, str]]:
    """Depth labels ``(lon, lat, text, colour)`` for the path's UP/DOWN actions.

    Layer changes within two cells of the previous one share a label, e.g.
    ``↓ 0 → 5 → 10 m``, so that a dive through several layers reads as one.
    """
    clusters: list[list[tuple[NominalStep, NominalStep]]] = []
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


def _paper_path_summary(solution: Solution, start: tuple[int, int, int, int], steps: list[PathStep]) -> str:
    """The side text of the nominal path picture for a paper plan: costs in the plan's energy units."""
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


def _start_and_goal(solution: AnySolution, start: tuple[int, int, int, int]) -> list[str]:
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
    return [f"  {action_label(a):<13}{counts[a]:>4}" for a in Action if counts[a]]
