"""A post-dive report: pictures of a logged dive and one HTML page that shows them (``lrauv replay --report``).

``write_report`` draws, from an ``planner.shore.replay.dive.Dive``, the tables attached to
its log and, when the planning forecast was found, the plan made again from it
(``planner.shore.replay.nominal.plan_again``):

- ``track.png``: the track coloured by the action decided, over land (the
  table's water mask, layer 0) and, with a plan, the surface-layer currents of
  the planning forecast and the nominal path from the first decision's state;
- ``timeseries.png``: depth, heading, action and energy used against vehicle time;
- ``cost.png`` (with a plan only): the predicted cost-to-go of the state at each
  decision (spec section 8; for a physical plan the energy still to spend, Wh, on
  the same scale as the energy spent) against the energy actually spent;
- ``index.html``: the pictures with the summary text, and a note for each
  picture that could not be drawn (or was drawn without something).

The pictures use the figure set-up and colours of ``planner.shore.plots.style``
and the map helpers of ``planner.shore.plots.map_axes`` (matplotlib on an
explicit Agg canvas, imported lazily). A long dive (the demo log has 132,207
decisions) is thinned for drawing: the track becomes one polyline per run of
one action, with at most a few thousand points in all.
Every file is written atomically (``planner.contract.atomic``).
"""

from __future__ import annotations

import html
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.atomic import write_atomic
from planner.contract.errors import LrauvError
from planner.grid import Grid
from planner.shore.plots.map_axes import cell_edges, cos_lat, draw_land, draw_outline, geo_axes
from planner.shore.plots.style import (
    ACTION_COLORS,
    FLOW_ARROW_COLOR,
    GOAL_COLOR,
    LAND_COLOR,
    START_COLOR,
    WATER_COLOR,
    action_label,
    load_matplotlib,
    new_figure,
    nice_speed,
    save_png,
)

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.shore.replay.dive import Dive, Track
    from planner.pipeline import PlanResult
    from planner.contract.table import PolicyTable

__all__ = ["ActionRun", "TrackSegment", "action_runs", "track_segments", "write_report"]

TRACK_PNG = "track.png"
TIMESERIES_PNG = "timeseries.png"
COST_PNG = "cost.png"
INDEX_HTML = "index.html"

NOT_FOLLOWING_COLOR = "#3b3b3b"  # safe behaviours (action None): near black, unlike any action colour
OTHER_ACTION_COLOR = "#b15928"  # an action name this version does not know
MAX_TRACK_POINTS = 4000  # points drawn on the map, all runs together (about)
MAX_SERIES_POINTS = 5000  # points per line in the time series
_MAX_CURRENT_ARROWS_PER_AXIS = 28
_DRAWN_ACTIONS = (Action.FORWARD, Action.FORWARD_LEFT, Action.FORWARD_RIGHT, Action.DRIFT, Action.ROTATE_LEFT,
                  Action.ROTATE_RIGHT, Action.UP, Action.DOWN, Action.AT_GOAL, Action.UNREACHABLE)
_NEED_FORECAST = "the planning forecast (pass --forecast)"


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


# --------------------------------------------------------------------------- the report


def write_report(
    dive: Dive,
    out_dir: str | os.PathLike[str],
    *,
    tables: Mapping[str, PolicyTable],
    plan: PlanResult | None,
    summary_text: str,
) -> Path:
    """Write the dive's pictures and ``index.html`` into ``out_dir`` (created if needed); returns the page's path.

    ``tables``: the log's tables by CRC (``planner.shore.replay.audit.logged_tables``); land
    comes from the first table the track used, each goal's marker from the
    table of its goal's first segment. ``plan``: one of those tables planned
    again on its forecast (``planner.shore.replay.nominal.plan_again``), or None when the
    forecast is not at hand; without it the track has no currents or nominal
    path and ``cost.png`` is not drawn, and the page says so. The prediction
    covers the decisions made under that table (one with the plan's actions).
    ``summary_text`` is shown as it is, escaped, in a ``<pre>`` block.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    track = dive.track
    drawn: list[tuple[str, str]] = []  # (file name, caption)
    notes: list[tuple[str, str]] = []  # (file name, why it is missing or incomplete)
    has_position = bool(np.any(np.isfinite(track.lat_deg) & np.isfinite(track.lon_deg)))

    first = _first_table(dive, tables, plan)
    plan_rows = np.zeros(len(track), dtype=bool) if plan is None else _plan_rows(dive, tables, plan)
    if first is None:
        notes.append((TRACK_PNG, "not drawn: the log has no policy table attached, so there is no map to draw on"))
    elif not has_position:
        notes.append((TRACK_PNG, "not drawn: no decision in the log has a position"))
    else:
        caption, missing = _plot_track(dive, first, _goal_tables(dive, tables, first), plan, plan_rows,
                                       out / TRACK_PNG)
        drawn.append((TRACK_PNG, caption))
        if missing:
            notes.append((TRACK_PNG, missing))

    if len(track):
        drawn.append((TIMESERIES_PNG, _plot_timeseries(dive, out / TIMESERIES_PNG)))
    else:
        notes.append((TIMESERIES_PNG, "not drawn: the log has no decision"))

    if plan is None:
        notes.append((COST_PNG, f"not drawn: the predicted cost-to-go needs {_NEED_FORECAST}"))
    else:
        cost = _cost_along_track(track, plan, plan_rows)
        if not np.isfinite(cost).any():
            notes.append((COST_PNG, f"not drawn: no decision under the planned table ({plan.table.crc32:08x}) had a"
                                    " reachable table state"))
        else:
            drawn.append((COST_PNG, _plot_cost(dive, cost, plan, bool(plan_rows.all()), out / COST_PNG)))

    index = out / INDEX_HTML
    write_atomic(index, _page(dive, summary_text, drawn, notes).encode("utf-8"))
    return index


def _page(dive: Dive, summary_text: str, drawn: list[tuple[str, str]], notes: list[tuple[str, str]]) -> str:
    e = html.escape
    name = dive.log.path.name
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        f"<title>Dive report: {e(name)}</title>",
        "<style>",
        "body { font-family: sans-serif; margin: 1.5em auto; max-width: 1400px; padding: 0 1em; color: #222; }",
        "pre { background: #f5f5f5; border: 1px solid #ddd; padding: 0.8em; overflow-x: auto; }",
        "figure { margin: 1.5em 0; }",
        "img { max-width: 100%; height: auto; border: 1px solid #ddd; }",
        "figcaption { color: #555; margin-top: 0.3em; }",
        ".notes li { color: #8a4b00; }",
        "</style>",
        "</head>",
        "<body>",
        f"<h1>Dive report: {e(name)}</h1>",
        f"<p>Log: <code>{e(str(dive.log.path))}</code></p>",
        "<h2>Summary</h2>",
        f"<pre>{e(summary_text)}</pre>",
    ]
    if notes:
        parts.append("<h2>Notes</h2>")
        parts.append('<ul class="notes">')
        parts.extend(f"<li><code>{e(file)}</code>: {e(text)}</li>" for file, text in notes)
        parts.append("</ul>")
    parts.append("<h2>Pictures</h2>")
    for file, caption in drawn:
        parts.append("<figure>")
        parts.append(f'<a href="{e(file)}"><img src="{e(file)}" alt="{e(caption)}"></a>')
        parts.append(f"<figcaption>{e(caption)}</figcaption>")
        parts.append("</figure>")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


# --------------------------------------------------------------------------- which table


def _first_table(dive: Dive, tables: Mapping[str, PolicyTable], plan: PlanResult | None) -> PolicyTable | None:
    """The first table the track used, else the first one loaded (POLICY records), else any logged, else the plan's."""
    for crc in dict.fromkeys(dive.track.table_crc32):
        if crc is not None and crc in tables:
            return tables[crc]
    for p in dive.policy:
        logged = p.get("table_crc32")
        if p.get("reason") in ("loaded", "swapped") and logged is not None and logged in tables:
            return tables[logged]
    if tables:
        return next(iter(tables.values()))
    return None if plan is None else plan.table


def _goal_tables(dive: Dive, tables: Mapping[str, PolicyTable], first: PolicyTable) -> list[PolicyTable]:
    """A table for each goal the track went for (the table of its first segment), each goal position once."""
    out: list[PolicyTable] = []
    seen: set[tuple[float, float]] = set()
    for seg in dive.track.segments():
        t = tables.get(seg.table_crc32) if seg.table_crc32 is not None else None
        if t is not None and (t.goal_lon_deg, t.goal_lat_deg) not in seen:
            seen.add((t.goal_lon_deg, t.goal_lat_deg))
            out.append(t)
    return out or [first]


def _plan_rows(dive: Dive, tables: Mapping[str, PolicyTable], plan: PlanResult) -> NDArray[np.bool_]:
    """Rows driven by the table ``plan`` was made again from: one whose actions are the plan's, state for state.

    (``plan_again`` guarantees equal actions; the CRC may differ, as the header
    names the forecast file by its path.)
    """
    mine = {crc for crc, t in tables.items()
            if crc == f"{plan.table.crc32:08x}"
            or (t.actions.shape == plan.table.actions.shape and np.array_equal(t.actions, plan.table.actions))}
    return np.fromiter((c in mine for c in dive.track.table_crc32), dtype=bool, count=len(dive.track))


def _goal_mask(table: PolicyTable) -> tuple[int, NDArray[np.bool_]] | None:
    """Goal layer and the goal cells of that layer (spec section 6: water within ``goal_radius`` cells, Chebyshev)."""
    cell = table.locate(table.goal_lat_deg, table.goal_lon_deg, table.goal_depth_m)
    if cell is None:
        return None
    l, jg, ig = cell
    r = table.goal_radius_cells
    jj, ii = np.meshgrid(np.arange(table.ny), np.arange(table.nx), indexing="ij")
    return l, (np.maximum(np.abs(ii - ig), np.abs(jj - jg)) <= r) & table.water[l]


# --------------------------------------------------------------------------- track.png


def _action_color(action: str | None) -> str:
    if action is None:
        return NOT_FOLLOWING_COLOR
    try:
        return ACTION_COLORS[Action[action]]
    except KeyError:
        return OTHER_ACTION_COLOR


def _action_name(action: str | None) -> str:
    if action is None:
        return "not following (safe behaviour)"
    try:
        return action_label(Action[action])
    except KeyError:
        return action


def _action_order(actions: Sequence[str | None]) -> list[str | None]:
    """The distinct actions of ``actions`` in legend order: table actions, then None, then unknown names."""
    present = set(actions)
    order: list[str | None] = [a.name for a in _DRAWN_ACTIONS if a.name in present]
    if None in present:
        order.append(None)
    order += sorted(a for a in present if a is not None and a not in order)
    return order


def _start_state(track: Track, rows: NDArray[np.bool_]) -> tuple[int, int, int, int] | None:
    """The first table state among ``rows`` (a mask), or None."""
    valid = np.flatnonzero(rows & np.all(track.cell >= 0, axis=1))
    if valid.size == 0:
        return None
    l, j, i, k = (int(x) for x in track.cell[valid[0]])
    return (l, j, i, k)


def _plot_track(dive: Dive, table: PolicyTable, goals: list[PolicyTable], plan: PlanResult | None,
                plan_rows: NDArray[np.bool_], path: Path) -> tuple[str, str]:
    """Draw ``track.png``; returns its caption and what is missing from it ('' when nothing)."""
    from planner.shore.replay.nominal import nominal_from

    track = dive.track
    grid = Grid(lon_deg=table.lon_deg, lat_deg=table.lat_deg, depth_m=np.asarray(table.depth_m))
    valid = np.flatnonzero(np.isfinite(track.lat_deg) & np.isfinite(track.lon_deg))
    missing = []
    nominal = None
    if plan is not None:
        start = _start_state(track, plan_rows)
        if start is None:
            missing.append("the nominal path (no decision under the planned table had a table state)")
        else:
            try:
                nominal = nominal_from(plan, start)
            except LrauvError as exc:
                missing.append(f"the nominal path ({exc})")
    else:
        missing.append("currents")
        missing.append("the nominal path")
    xs = [track.lon_deg[valid]] + [np.array([t.goal_lon_deg]) for t in goals]
    ys = [track.lat_deg[valid]] + [np.array([t.goal_lat_deg]) for t in goals]
    if nominal is not None:
        xs.append(nominal.lon_deg)
        ys.append(nominal.lat_deg)
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

    if plan is not None:
        quiver = _draw_currents(mpl, ax, plan, extent)
        if quiver is not None:
            key = nice_speed(0.5 * float(np.nanpercentile(np.hypot(plan.u_m_s[0], plan.v_m_s[0]), 98)))
            ax.quiverkey(quiver, 0.86, 1.012, key, f"{key:g} m/s", labelpos="E", coordinates="axes", color="0.3",
                         fontproperties={"size": 8})
            handles.append(mpl.lines.Line2D([], [], color=FLOW_ARROW_COLOR, marker=r"$\rightarrow$", linestyle="none",
                                            markersize=12, label=f"current at {plan.grid.depth_m[0]:g} m (forecast)"))

    segments = track_segments(track)
    lines = [np.column_stack([track.lon_deg[s.rows], track.lat_deg[s.rows]]) for s in segments if s.rows.size > 1]
    colors = [_action_color(s.action) for s in segments if s.rows.size > 1]
    # A white casing under the coloured line keeps it readable over arrows and land.
    ax.add_collection(mpl.collections.LineCollection(lines, colors="white", linewidths=4.2, zorder=5,
                                                     capstyle="round", joinstyle="round"))
    ax.add_collection(mpl.collections.LineCollection(lines, colors=colors, linewidths=2.4, zorder=6,
                                                     capstyle="round", joinstyle="round"))
    for a in _action_order([s.action for s in segments]):
        handles.append(mpl.lines.Line2D([], [], color=_action_color(a), linewidth=3.0, label=_action_name(a)))

    if nominal is not None:
        ax.plot(nominal.lon_deg, nominal.lat_deg, color="black", linewidth=1.3, linestyle=(0, (4, 2.5)),
                marker="o", markersize=2.5, zorder=7)
        handles.append(mpl.lines.Line2D([], [], color="black", linewidth=1.3, linestyle=(0, (4, 2.5)),
                                        marker="o", markersize=2.5, label="nominal path from the first decision's cell"))

    for t in goals:
        goal = _goal_mask(t)
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
    over = (f"over the {plan.grid.depth_m[0]:g} m currents of the planning forecast" if plan is not None
            else "over land from the policy table (no forecast given)")
    ax.set_title(f"{dive.log.path.name}: track coloured by the action decided, {hours:.1f} h\n{over}", fontsize=11)
    save_png(fig, path)
    caption = "The track, coloured by the action the executive decided"
    caption += ", over the planning forecast's surface currents" if plan is not None else ", over land from the policy table"
    if nominal is not None:
        caption += ", with the nominal path the plan predicted from the first decision's state"
    note = f"drawn without {' and '.join(missing)}" if missing else ""
    if plan is None:
        note += f": they need {_NEED_FORECAST}"
    return caption + ".", note


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


def _draw_currents(mpl: Any, ax: Any, plan: PlanResult, extent: tuple[float, float, float, float]) -> Any:
    """The planning forecast's top-layer current in ``extent`` as grey arrows scaled by speed (as ``plot_flow_fields``)."""
    grid = plan.grid
    u, v = np.asarray(plan.u_m_s[0], dtype=np.float64), np.asarray(plan.v_m_s[0], dtype=np.float64)
    speed = np.hypot(u, v)
    if not np.isfinite(speed).any() or float(np.nanmax(speed)) <= 0:
        return None
    west, east, south, north = extent
    cols = np.flatnonzero((grid.lon_deg >= west) & (grid.lon_deg <= east))
    rows = np.flatnonzero((grid.lat_deg >= south) & (grid.lat_deg <= north))
    if cols.size == 0 or rows.size == 0:
        return None
    stride = max(1, math.ceil(max(cols.size, rows.size) / _MAX_CURRENT_ARROWS_PER_AXIS))
    jj, ii = np.meshgrid(rows[::stride], cols[::stride], indexing="ij")
    x, y = grid.lon_deg[ii], grid.lat_deg[jj]
    us, vs = u[jj, ii], v[jj, ii]
    ok = np.isfinite(us) & np.isfinite(vs)
    # Arrow lengths: the 98th percentile speed (of the whole layer) spans 0.9 of the arrow spacing, the fastest 1.5.
    v98 = float(np.nanpercentile(speed, 98))
    vmax = float(np.nanmax(speed))
    cell_x = min(grid.dlon_deg, grid.dlat_deg / cos_lat(grid))
    scale = max(v98 / (0.9 * stride * cell_x), vmax / (1.5 * stride * cell_x), 1e-12)
    shaft = float(np.clip(0.06 / math.ceil(cols.size / stride), 0.0018, 0.0035))  # fraction of the axes width
    return ax.quiver(x[ok], y[ok], us[ok], vs[ok], color=FLOW_ARROW_COLOR, angles="uv", scale_units="x", scale=scale,
                     width=shaft, headwidth=3.5, headlength=4.0, headaxislength=3.5, pivot="middle", zorder=3)


# --------------------------------------------------------------------------- timeseries.png


def _thin(n: int, max_points: int) -> NDArray[np.int64]:
    """Evenly spaced row indices, at most about ``max_points``, always with the first and last rows."""
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.arange(0, n, max(1, math.ceil(n / max_points)), dtype=np.int64)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def _plot_timeseries(dive: Dive, path: Path) -> str:
    """Draw ``timeseries.png``; returns its caption."""
    track = dive.track
    n = len(track)
    t_h = track.time_s / 3600.0
    rows = _thin(n, MAX_SERIES_POINTS)
    mpl = load_matplotlib()
    fig = new_figure(mpl, 9.5, 8.6)
    ax_depth, ax_head, ax_act, ax_energy = fig.subplots(4, 1, sharex=True, height_ratios=[1.1, 1.0, 0.9, 1.0])

    ax_depth.plot(t_h[rows], track.depth_m[rows], color="#0072b2", linewidth=1.2)
    if np.isfinite(track.depth_m).any():  # at least 1 m deep, so that surface noise does not fill the panel
        deepest = max(1.0, float(np.nanmax(track.depth_m)) * 1.05)
        ax_depth.set_ylim(deepest, min(0.0, float(np.nanmin(track.depth_m))) - 0.02 * deepest)
    else:
        ax_depth.invert_yaxis()
    ax_depth.set_ylabel("depth (m)")

    heading = track.heading_deg[rows].astype(np.float64)
    th = t_h[rows].astype(np.float64)
    wraps = np.flatnonzero(np.abs(np.diff(heading)) > 180.0) + 1  # break the line where it wraps past north
    ax_head.plot(np.insert(th, wraps, np.nan), np.insert(heading, wraps, np.nan), color="#cc79a7", linewidth=1.0)
    ax_head.set_ylim(0.0, 360.0)
    ax_head.set_yticks([0, 90, 180, 270, 360])
    ax_head.set_ylabel("heading (\u00b0 true)")

    runs = action_runs(track.action)
    order = _action_order(track.action)
    ends = np.append(t_h[1:], t_h[-1])  # a decision holds until the next one
    for y, a in enumerate(order):
        spans = [(t_h[r.start], max(ends[r.stop - 1] - t_h[r.start], 0.0)) for r in runs if r.action == a]
        color = _action_color(a)
        # Edges drawn in the fill colour keep a run of a few seconds visible on an axis of hours.
        ax_act.broken_barh(spans, (y - 0.38, 0.76), facecolors=color, edgecolors=color, linewidth=0.6)
    ax_act.set_yticks(range(len(order)), [_action_name(a) for a in order], fontsize=8)
    ax_act.set_ylim(len(order) - 0.5, -0.5)
    ax_act.set_ylabel("action")

    energy = track.energy_used_wh
    ax_energy.plot(t_h[rows], energy[rows], color="#d55e00", linewidth=1.3)
    ax_energy.set_ylabel("energy used (Wh)")
    ax_energy.set_xlabel("vehicle time since the autopilot booted (h)")
    if np.isfinite(energy).any():
        ax_energy.set_ylim(bottom=min(0.0, float(np.nanmin(energy))))

    for ax in (ax_depth, ax_head, ax_act, ax_energy):
        ax.grid(True, color="0.9", linewidth=0.6)
        ax.set_axisbelow(True)
        ax.tick_params(labelsize=8.5)
    start = dive.utc_s(float(track.time_s[0]))
    when = ""
    if isinstance(start, float) and math.isfinite(start):  # utc_s of a float: a float, or None without UTC
        when = ", first decision at " + str(np.datetime64(int(round(start)), "s")).replace("T", " ") + " UTC"
    fig.suptitle(f"{dive.log.path.name}: {n:,} decisions{when}", fontsize=12)
    save_png(fig, path)
    return "Depth, heading, the action decided and the energy used, against vehicle time."


# --------------------------------------------------------------------------- cost.png


def _plan_label(plan: PlanResult) -> str:
    """The plan's model, criterion and costs, for titles."""
    t = plan.table
    if t.model == "physical":
        v = (t.physical or {}).get("vehicle", {})
        figures = f"; {v['cruise_speed_m_s']:g} m/s, hotel {v['hotel_w']:g} W" if {"cruise_speed_m_s", "hotel_w"} <= set(v) else ""
        return f"physical model, {t.criterion}; costs in Wh{figures}"
    c = t.costs
    return (f"{t.criterion}; costs drift {c.get('drift')}, forward {c.get('forward')}, rotate {c.get('rotate')},"
            f" glide {c.get('glide')}")


def _cost_along_track(track: Track, plan: PlanResult, rows: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The plan's cost-to-go of each row's table state (spec section 8), NaN where unreachable, where the row
    has no state, or where the row is not in ``rows`` (a mask: the rows driven by the planned table)."""
    cost_table = plan.solution.cost  # a property that builds the array: read it once
    inside = rows & np.all((track.cell >= 0) & (track.cell < np.asarray(cost_table.shape)), axis=1)
    cost = np.full(len(track), np.nan)
    l, j, i, k = track.cell[inside].T
    cost[inside] = cost_table[l, j, i, k]
    cost[~np.isfinite(cost)] = np.nan
    return cost


def _plot_cost(dive: Dive, cost: NDArray[np.float64], plan: PlanResult, whole: bool, path: Path) -> str:
    """Draw ``cost.png`` (``whole``: the planned table drove every decision); returns its caption."""
    track = dive.track
    pick = _thin(len(track), MAX_SERIES_POINTS)
    t_h = track.time_s[pick] / 3600.0
    energy = track.energy_used_wh
    mpl = load_matplotlib()
    fig = new_figure(mpl, 9.5, 4.8)
    ax = fig.subplots()
    gaps = "no table state or unreachable" if whole else "another table, no table state or unreachable"
    line_cost, = ax.plot(t_h, cost[pick], color="#0072b2", linewidth=1.5, drawstyle="steps-post",
                         label=f"predicted cost-to-go of the state (gaps: {gaps})")
    physical = plan.table.model == "physical"
    ax.set_ylabel("predicted cost-to-go (Wh)" if physical else "predicted cost-to-go (plan cost units)", color="#0072b2")
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("vehicle time since the autopilot booted (h)")
    ax.grid(True, color="0.9", linewidth=0.6)
    twin = ax.twinx()
    line_energy, = twin.plot(t_h, energy[pick], color="#d55e00", linewidth=1.5, label="energy used so far (battery)")
    twin.set_ylabel("energy used (Wh)", color="#d55e00")
    if np.isfinite(energy).any():
        twin.set_ylim(bottom=min(0.0, float(np.nanmin(energy))))
    for a in (ax, twin):
        a.tick_params(labelsize=8.5)
    if physical:  # the same unit on both axes: the prediction is the energy still to spend
        hi = max(float(np.nanmax(cost)), float(np.nanmax(energy)) if np.isfinite(energy).any() else 0.0) * 1.05
        ax.set_ylim(0.0, hi if hi > 0 else 1.0)
        twin.set_ylim(min(0.0, float(np.nanmin(energy))) if np.isfinite(energy).any() else 0.0, hi if hi > 0 else 1.0)
    fig.legend(handles=[line_cost, line_energy], loc="outside lower center", ncols=2, frameon=False, fontsize=8.5)
    ax.set_title(f"{dive.log.path.name}: predicted cost-to-go along the track and the energy spent\n"
                 f"plan {plan.table.crc32:08x} ({_plan_label(plan)})", fontsize=11)
    save_png(fig, path)
    what = "energy still to spend, in Wh" if physical else "cost-to-go"
    caption = (f"The plan's predicted {what}, of the state at each decision (it falls to 0 at the goal),"
               " and the energy the battery reports used")
    return caption + ("." if whole else f"; only the decisions under table {plan.table.crc32:08x} have a prediction.")
