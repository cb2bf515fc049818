"""The map of a logged dive (``track.png`` of ``lrauv replay --report``): the track coloured by the action decided.

Drawn from a ``planner.shore.replay.dive.Dive``, the first table the track used
(land and goal cells) and, when the planning forecast was found, the plan made
again from it (``planner.shore.replay.nominal.plan_again``): its currents and the
nominal path. A long dive (the demo log has 132,207 decisions) is thinned for
drawing: the track becomes one polyline per run of one action, with at most a
few thousand points in all.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.errors import LrauvError
from planner.grid import Grid
from planner.shore.plots.currents import CurrentMap, currents_at, draw_currents_with_key, moment_of_plan, utc_iso
from planner.shore.plots.map_axes import cell_edges, cos_lat, draw_land, draw_outline, geo_axes
from planner.shore.plots.style import (
    ACTION_COLORS,
    GOAL_COLOR,
    LAND_COLOR,
    START_COLOR,
    WATER_COLOR,
    action_label,
    load_matplotlib,
    new_figure,
    save_png,
)
from planner.shore.plots.time_axis import draw_time_marks, marks_legend, time_marks

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.contract.table import PolicyTable
    from planner.pipeline import PlanResult
    from planner.shore.replay.dive import Dive, Track

__all__ = [
    "MAX_TRACK_POINTS",
    "NEED_FORECAST",
    "NOT_FOLLOWING_COLOR",
    "OTHER_ACTION_COLOR",
    "ActionRun",
    "TrackSegment",
    "action_color",
    "action_name",
    "action_order",
    "action_runs",
    "dive_track_figure",
    "goal_mask",
    "plot_dive_track",
    "track_segments",
]

NOT_FOLLOWING_COLOR = "#3b3b3b"  # safe behaviours (action None): near black, unlike any action colour
OTHER_ACTION_COLOR = "#b15928"  # an action name this version does not know
MAX_TRACK_POINTS = 4000  # points drawn on the map, all runs together (about)
_DRAWN_ACTIONS = (Action.FORWARD, Action.FORWARD_LEFT, Action.FORWARD_RIGHT, Action.DRIFT, Action.ROTATE_LEFT,
                  Action.ROTATE_RIGHT, Action.UP, Action.DOWN, Action.AT_GOAL, Action.UNREACHABLE)
NEED_FORECAST = "the planning forecast (pass --forecast)"

# --------------------------------------------------------------------------- runs and segments


@dataclass(frozen=True, slots=True)
class ActionRun:
    """Consecutive rows ``start .. stop - 1`` that logged the same action (None: not following the table)."""

    start: int
    stop: int
    action: str | None


def action_runs(actions: Sequence[str | None]) -> list[ActionRun]:
    """Split ``actions`` into runs of equal consecutive values, in order; empty input gives no run."""
    runs: list[ActionRun] = []
    start = 0
    for n in range(1, len(actions) + 1):
        if n == len(actions) or actions[n] != actions[start]:
            runs.append(ActionRun(start, n, actions[start]))
            start = n
    return runs


@dataclass(frozen=True, eq=False, slots=True)
class TrackSegment:
    """One polyline of the drawn track: the track rows it passes through, in order, and their action."""

    action: str | None
    rows: NDArray[np.int64]  # indices into the Track; the last is the next run's first row, if any


def track_segments(track: Track, *, max_points: int = MAX_TRACK_POINTS) -> list[TrackSegment]:
    """The track as one polyline per run of one action, thinned to about ``max_points`` points.

    Rows without a position (NaN) are left out. Each run keeps its first and
    last rows and, evenly spaced, rows between them; its polyline goes on to the
    next run's first row, so the line has no gaps and the stretch between two
    decisions has the colour of the earlier one (the action held until the next
    decision). A dive with more than ``max_points / 2`` runs (one that switches
    on nearly every decision) is thinned evenly first and its runs are found
    among the rows kept, so that the number of points stays bounded.
    """
    rows = np.flatnonzero(np.isfinite(track.lat_deg) & np.isfinite(track.lon_deg)).astype(np.int64)
    if rows.size == 0:
        return []
    limit = max(2, int(max_points))
    runs = action_runs([track.action[r] for r in rows])
    keep = np.zeros(rows.size, dtype=bool)
    keep[:: max(1, math.ceil(rows.size / limit))] = True
    keep[-1] = True
    if 2 * len(runs) <= limit:
        for run in runs:
            keep[run.start] = keep[run.stop - 1] = True
    else:
        rows = rows[keep]
        keep = np.ones(rows.size, dtype=bool)
        runs = action_runs([track.action[r] for r in rows])
    kept = np.flatnonzero(keep)
    segments = []
    for run in runs:
        lo, hi = np.searchsorted(kept, [run.start, run.stop])
        segments.append(TrackSegment(run.action, rows[kept[lo:hi + 1]]))
    return segments


def goal_mask(table: PolicyTable) -> tuple[int, NDArray[np.bool_]] | None:
    """Goal layer and the goal cells of that layer (spec section 6: water within ``goal_radius`` cells, Chebyshev)."""
    cell = table.locate(table.goal_lat_deg, table.goal_lon_deg, table.goal_depth_m)
    if cell is None:
        return None
    l, jg, ig = cell
    r = table.goal_radius_cells
    jj, ii = np.meshgrid(np.arange(table.ny), np.arange(table.nx), indexing="ij")
    return l, (np.maximum(np.abs(ii - ig), np.abs(jj - jg)) <= r) & table.water[l]


# --------------------------------------------------------------------------- track.png


def action_color(action: str | None) -> str:
    if action is None:
        return NOT_FOLLOWING_COLOR
    try:
        return ACTION_COLORS[Action[action]]
    except KeyError:
        return OTHER_ACTION_COLOR


def action_name(action: str | None) -> str:
    if action is None:
        return "not following (safe behaviour)"
    try:
        return action_label(Action[action])
    except KeyError:
        return action


def action_order(actions: Sequence[str | None]) -> list[str | None]:
    """The distinct actions of ``actions`` in legend order: table actions, then None, then unknown names."""
    present = set(actions)
    order: list[str | None] = [a.name for a in _DRAWN_ACTIONS if a.name in present]
    if None in present:
        order.append(None)
    order += sorted(a for a in present if a is not None and a not in order)
    return order


def _start_state(track: Track, rows: NDArray[np.bool_]) -> tuple[int, tuple[int, int, int, int]] | None:
    """The first row among ``rows`` (a mask) with a table state and a position, and that state; or None."""
    valid = np.flatnonzero(rows & np.all(track.cell >= 0, axis=1) & np.isfinite(track.lat_deg)
                           & np.isfinite(track.lon_deg))
    if valid.size == 0:
        return None
    l, j, i, k = (int(x) for x in track.cell[valid[0]])
    return int(valid[0]), (l, j, i, k)


def _dive_currents(dive: Dive, plan: PlanResult, valid: NDArray[np.int64]) -> tuple[CurrentMap, str]:
    """The planning forecast's top-layer currents at the dive's middle (UTC), and how that step was chosen.

    Without UTC in the log, or when the file cannot be read again, the plan's own step.
    """
    grid = plan.grid
    middle = dive.utc_s(0.5 * float(dive.track.time_s[valid[0]] + dive.track.time_s[valid[-1]]))
    own = CurrentMap(grid=grid, u_m_s=np.asarray(plan.u_m_s[0]), v_m_s=np.asarray(plan.v_m_s[0]),
                     depth_m=float(grid.depth_m[0]), moment=moment_of_plan(plan))
    if not isinstance(middle, float):
        return own, "the plan's step: the log has no UTC"
    try:
        return currents_at(plan.forecast.source, grid, middle, depth_m=float(grid.depth_m[0])), \
            "the step nearest the dive's middle"
    except LrauvError as exc:
        return own, f"the plan's step: {exc}"


def dive_track_figure(dive: Dive, table: PolicyTable, goals: list[PolicyTable], plan: PlanResult | None,
                      plan_rows: NDArray[np.bool_]) -> tuple[Any, str, str]:
    """The figure of ``track.png``, its caption, and what is missing from it ('' when nothing).

    Land and goal cells come from ``table`` (layer 0); with ``plan``, the currents are the planning
    forecast's at the dive's time (``_dive_currents``) and the nominal path starts at the position of
    the first decision under the planned table (``plan_rows``), then follows cell centres. Marks at
    round UTC times (hourly on a dive of up to 12 h) run along the track.
    """
    from planner.shore.replay.nominal import nominal_from

    track = dive.track
    grid = Grid(lon_deg=table.lon_deg, lat_deg=table.lat_deg, depth_m=np.asarray(table.depth_m))
    valid = np.flatnonzero(np.isfinite(track.lat_deg) & np.isfinite(track.lon_deg))
    missing = []
    nominal_xy = None
    if plan is not None:
        start = _start_state(track, plan_rows)
        if start is None:
            missing.append("the nominal path (no decision under the planned table had a table state)")
        else:
            try:
                nominal = nominal_from(plan, start[1])
            except LrauvError as exc:
                missing.append(f"the nominal path ({exc})")
            else:  # from where the vehicle was, then through the cell centres the plan predicts
                row = start[0]
                nominal_xy = (np.concatenate([[track.lon_deg[row]], nominal.lon_deg]),
                              np.concatenate([[track.lat_deg[row]], nominal.lat_deg]))
    else:
        missing.append("currents")
        missing.append("the nominal path")
    xs = [track.lon_deg[valid]] + [np.array([t.goal_lon_deg]) for t in goals]
    ys = [track.lat_deg[valid]] + [np.array([t.goal_lat_deg]) for t in goals]
    if nominal_xy is not None:
        xs.append(nominal_xy[0])
        ys.append(nominal_xy[1])
    radius = max(t.goal_radius_cells for t in goals)
    extent = _map_extent(grid, np.concatenate(xs), np.concatenate(ys), margin_cells=radius + 2.5)
    mpl = load_matplotlib()
    width = 7.2
    ratio = (extent[3] - extent[2]) / ((extent[1] - extent[0]) * cos_lat(grid))
    fig = new_figure(mpl, width + 0.8, float(np.clip(width * ratio, 3.0, 8.5)) + 2.0)
    ax = fig.subplots()
    ax.set_facecolor(WATER_COLOR)
    draw_land(mpl, ax, grid, ~table.water[0])
    handles: list[Any] = []

    over = over_short = "over land from the policy table (no forecast given)"
    if plan is not None:
        currents, chosen = _dive_currents(dive, plan, valid)
        key = draw_currents_with_key(mpl, ax, currents, extent, "forecast")
        handles += [key] if key is not None else []
        over = f"over the {currents.label()} ({chosen})"
        over_short = f"currents at {currents.depth_m:g} m: {currents.moment.label()}\n({chosen})"

    segments = [s for s in track_segments(track) if s.rows.size > 1]  # a single row draws nothing
    lines = [np.column_stack([track.lon_deg[s.rows], track.lat_deg[s.rows]]) for s in segments]
    colors = [action_color(s.action) for s in segments]
    # A white casing under the coloured line keeps it readable over arrows and land.
    ax.add_collection(mpl.collections.LineCollection(lines, colors="white", linewidths=4.2, zorder=5,
                                                     capstyle="round", joinstyle="round"))
    track_line = mpl.collections.LineCollection(lines, colors=colors, linewidths=2.4, zorder=6, capstyle="round",
                                                joinstyle="round")
    track_line.set_gid("track")
    ax.add_collection(track_line)
    for a in action_order([s.action for s in segments]):
        handles.append(mpl.lines.Line2D([], [], color=action_color(a), linewidth=3.0, label=action_name(a)))
    marks = time_marks(track.time_s[valid], track.lon_deg[valid], track.lat_deg[valid], dive.unix_offset_s)
    if draw_time_marks(mpl, ax, marks, label_gap_deg=0.07 * (extent[1] - extent[0])) is not None:
        handles.append(mpl.lines.Line2D([], [], linestyle="none", marker="o", markersize=4.5, markerfacecolor="black",
                                        markeredgecolor="white", label=marks_legend(marks)))

    if nominal_xy is not None:
        path_line, = ax.plot(*nominal_xy, color="black", linewidth=1.3, linestyle=(0, (4, 2.5)), marker="o",
                             markersize=2.5, zorder=7)
        path_line.set_gid("nominal path")
        handles.append(mpl.lines.Line2D([], [], color="black", linewidth=1.3, linestyle=(0, (4, 2.5)), marker="o",
                                        markersize=2.5, label="nominal path from the first decision's position"))

    for t in goals:
        goal = goal_mask(t)
        if goal is not None:
            draw_outline(mpl, ax, grid, goal[1], color=GOAL_COLOR, linewidth=2.0)
        ax.plot(t.goal_lon_deg, t.goal_lat_deg, linestyle="none", marker="*", markersize=16,
                markerfacecolor=GOAL_COLOR, markeredgecolor="black", markeredgewidth=1.0, zorder=9)
    handles.append(mpl.lines.Line2D([], [], linestyle="none", marker="*", markersize=13, markerfacecolor=GOAL_COLOR,
                                    markeredgecolor="black", label="goal" if len(goals) == 1 else "goals"))
    handles.append(mpl.lines.Line2D([], [], color=GOAL_COLOR, linewidth=2.0,
                                    label=f"goal cells (within {radius} cell{'s' if radius != 1 else ''})"))

    i0, i1 = int(valid[0]), int(valid[-1])
    ax.plot(track.lon_deg[i0], track.lat_deg[i0], linestyle="none", marker="o", markersize=10,
            markerfacecolor=START_COLOR, markeredgecolor="black", markeredgewidth=1.1, zorder=10)
    ax.plot(track.lon_deg[i1], track.lat_deg[i1], linestyle="none", marker="s", markersize=7,
            markerfacecolor="white", markeredgecolor="black", markeredgewidth=1.3, zorder=10)
    handles.insert(0, mpl.lines.Line2D([], [], linestyle="none", marker="o", markersize=8, markerfacecolor=START_COLOR,
                                       markeredgecolor="black", label="start (first decision)"))
    handles.insert(1, mpl.lines.Line2D([], [], linestyle="none", marker="s", markersize=6, markerfacecolor="white",
                                       markeredgecolor="black", label="end of the log"))
    half_x, half_y = 0.5 * table.dlon_deg, 0.5 * table.dlat_deg  # cells that reach into the map
    in_view = np.ix_((table.lat_deg + half_y > extent[2]) & (table.lat_deg - half_y < extent[3]),
                     (table.lon_deg + half_x > extent[0]) & (table.lon_deg - half_x < extent[1]))
    if (~table.water[0][in_view]).any():
        handles.append(mpl.patches.Patch(facecolor=LAND_COLOR, edgecolor="0.5", label="land (policy table)"))

    geo_axes(mpl, ax, grid)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    fig.legend(handles=handles, loc="outside lower center", ncols=3, frameon=False, fontsize=8.5)
    hours = (track.time_s[i1] - track.time_s[i0]) / 3600.0
    when = f"{hours:.1f} h"
    t0, t1 = dive.utc_s(float(track.time_s[i0])), dive.utc_s(float(track.time_s[i1]))
    if isinstance(t0, float) and isinstance(t1, float):
        when = f"{utc_iso(t0)} to {utc_iso(t1)} ({hours:.1f} h)"
    ax.set_title(f"{dive.log.path.name}: the track by action decided, {when}\n{over_short}", fontsize=9.5,
                 loc="left")
    caption = "The track, coloured by the action the executive decided"
    caption += f", {over}" if plan is not None else ", over land from the policy table"
    if nominal_xy is not None:
        caption += ", with the nominal path the plan predicted from the first decision's position"
    note = f"drawn without {' and '.join(missing)}" if missing else ""
    if plan is None:
        note += f": they need {NEED_FORECAST}"
    return fig, caption + ".", note


def plot_dive_track(dive: Dive, table: PolicyTable, goals: list[PolicyTable], plan: PlanResult | None,
                    plan_rows: NDArray[np.bool_], path: Path) -> tuple[str, str]:
    """Draw ``track.png`` (``dive_track_figure``); returns its caption and what is missing from it."""
    fig, caption, note = dive_track_figure(dive, table, goals, plan, plan_rows)
    save_png(fig, path)
    return caption, note


def _map_extent(grid: Grid, lon: NDArray[np.float64], lat: NDArray[np.float64], *,
                margin_cells: float) -> tuple[float, float, float, float]:
    """``(west, east, south, north)`` around the points with a margin, within the grid unless the points leave it.

    The map shows where the dive went rather than the whole planning region; it
    is at least 8 cells across each way so that the currents around stay readable.
    """
    lon_e, lat_e = cell_edges(grid)
    dx, dy = grid.dlon_deg, grid.dlat_deg
    x0, x1 = _span(float(lon.min()), float(lon.max()), margin_cells * dx, 8 * dx)
    y0, y1 = _span(float(lat.min()), float(lat.max()), margin_cells * dy, 8 * dy)
    x0 = max(x0, min(lon_e[0], float(lon.min()) - dx))
    x1 = min(x1, max(lon_e[-1], float(lon.max()) + dx))
    y0 = max(y0, min(lat_e[0], float(lat.min()) - dy))
    y1 = min(y1, max(lat_e[-1], float(lat.max()) + dy))
    return x0, x1, y0, y1


def _span(lo: float, hi: float, margin: float, least: float) -> tuple[float, float]:
    """``lo .. hi`` widened by ``margin`` each side, then about its middle to at least ``least``."""
    lo, hi = lo - margin, hi + margin
    pad = max(0.0, 0.5 * (least - (hi - lo)))
    return lo - pad, hi + pad
