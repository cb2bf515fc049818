"""Time series of a logged dive (``lrauv replay --report``): ``timeseries.png`` and ``cost.png``.

``timeseries.png``: depth, heading, the action decided and the energy used;
``cost.png`` (with a plan only): the predicted cost-to-go of the state at each
decision (spec section 8; for a physical plan the energy still to spend, Wh, on
the same scale as the energy spent) against the energy actually spent.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.shore.plots.dive_track import action_color, action_name, action_order, action_runs
from planner.shore.plots.currents import utc_iso
from planner.shore.plots.style import load_matplotlib, new_figure, save_png
from planner.shore.plots.time_axis import heading_axis, time_axis, time_values, wrapped

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.pipeline import PlanResult
    from planner.shore.replay.dive import Dive

__all__ = ["MAX_SERIES_POINTS", "cost_figure", "plot_cost", "plot_timeseries", "timeseries_figure"]

MAX_SERIES_POINTS = 5000  # points per line in the time series


def _thin(n: int, max_points: int) -> NDArray[np.int64]:
    """Evenly spaced row indices, at most about ``max_points``, always with the first and last rows."""
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.arange(0, n, max(1, math.ceil(n / max_points)), dtype=np.int64)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def timeseries_figure(dive: Dive) -> tuple[Any, str]:
    """The figure of ``timeseries.png`` and its caption: depth, heading, action and energy against time.

    The time axis is UTC when the log has the autopilot's UTC (``Dive.unix_offset_s``), else vehicle
    time since boot, and says which. Heading runs on ``HEADING_LIMITS_DEG`` (0 and 360 inside the
    frame), its line broken where it wraps past north.
    """
    track = dive.track
    n = len(track)
    mpl = load_matplotlib()
    x = time_values(mpl, track.time_s, dive.unix_offset_s)
    rows = _thin(n, MAX_SERIES_POINTS)
    fig = new_figure(mpl, 9.5, 8.6)
    ax_depth, ax_head, ax_act, ax_energy = fig.subplots(4, 1, sharex=True, height_ratios=[1.1, 1.0, 0.9, 1.0])

    ax_depth.plot(x[rows], track.depth_m[rows], color="#0072b2", linewidth=1.2)
    if np.isfinite(track.depth_m).any():  # at least 1 m deep, so that surface noise does not fill the panel
        deepest = max(1.0, float(np.nanmax(track.depth_m)) * 1.05)
        ax_depth.set_ylim(deepest, min(0.0, float(np.nanmin(track.depth_m))) - 0.02 * deepest)
    else:
        ax_depth.invert_yaxis()
    ax_depth.set_ylabel("depth (m)")

    heading_line, = ax_head.plot(*wrapped(x[rows], track.heading_deg[rows]), color="#cc79a7", linewidth=1.0)
    heading_line.set_gid("heading")
    heading_axis(ax_head)
    ax_head.set_ylabel("heading (\u00b0 true)")

    runs = action_runs(track.action)
    order = action_order(track.action)
    ends = np.append(x[1:], x[-1])  # a decision holds until the next one
    for y, a in enumerate(order):
        spans = [(x[r.start], max(ends[r.stop - 1] - x[r.start], 0.0)) for r in runs if r.action == a]
        color = action_color(a)
        # Edges drawn in the fill colour keep a run of a few seconds visible on an axis of hours.
        ax_act.broken_barh(spans, (y - 0.38, 0.76), facecolors=color, edgecolors=color, linewidth=0.6)
    ax_act.set_yticks(range(len(order)), [action_name(a) for a in order], fontsize=8)
    ax_act.set_ylim(len(order) - 0.5, -0.5)
    ax_act.set_ylabel("action")

    energy = track.energy_used_wh
    ax_energy.plot(x[rows], energy[rows], color="#d55e00", linewidth=1.3)
    ax_energy.set_ylabel("energy used (Wh)")
    if n:
        time_axis(mpl, ax_energy, dive.unix_offset_s, float(track.time_s[0]))
    if np.isfinite(energy).any():
        ax_energy.set_ylim(bottom=min(0.0, float(np.nanmin(energy))))

    for ax in (ax_depth, ax_head, ax_act, ax_energy):
        ax.grid(True, color="0.9", linewidth=0.6)
        ax.set_axisbelow(True)
        ax.tick_params(labelsize=8.5)
    start = dive.utc_s(float(track.time_s[0])) if n else None
    when = ", first decision at " + utc_iso(start) if isinstance(start, float) and math.isfinite(start) else ""
    fig.suptitle(f"{dive.log.path.name}: {n:,} decisions{when}", fontsize=12)
    against = "UTC" if dive.unix_offset_s is not None else "vehicle time since boot (the log has no UTC)"
    return fig, f"Depth, heading, the action decided and the energy used, against {against}."


def plot_timeseries(dive: Dive, path: Path) -> str:
    """Draw ``timeseries.png`` (``timeseries_figure``); returns its caption."""
    fig, caption = timeseries_figure(dive)
    save_png(fig, path)
    return caption


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


def cost_figure(dive: Dive, cost: NDArray[np.float64], plan: PlanResult, whole: bool) -> tuple[Any, str]:
    """The figure of ``cost.png`` and its caption (``whole``: the planned table drove every decision); time as
    in ``timeseries_figure``."""
    track = dive.track
    pick = _thin(len(track), MAX_SERIES_POINTS)
    energy = track.energy_used_wh
    mpl = load_matplotlib()
    t_h = time_values(mpl, track.time_s[pick], dive.unix_offset_s)
    fig = new_figure(mpl, 9.5, 4.8)
    ax = fig.subplots()
    gaps = "no table state or unreachable" if whole else "another table, no table state or unreachable"
    line_cost, = ax.plot(t_h, cost[pick], color="#0072b2", linewidth=1.5, drawstyle="steps-post",
                         label=f"predicted cost-to-go of the state (gaps: {gaps})")
    physical = plan.table.model == "physical"
    ax.set_ylabel("predicted cost-to-go (Wh)" if physical else "predicted cost-to-go (plan cost units)", color="#0072b2")
    ax.set_ylim(bottom=0.0)
    time_axis(mpl, ax, dive.unix_offset_s, float(track.time_s[0]))
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
    what = "energy still to spend, in Wh" if physical else "cost-to-go"
    caption = (f"The plan's predicted {what}, of the state at each decision (it falls to 0 at the goal),"
               " and the energy the battery reports used")
    return fig, caption + ("." if whole else f"; only the decisions under table {plan.table.crc32:08x} have a prediction.")


def plot_cost(dive: Dive, cost: NDArray[np.float64], plan: PlanResult, whole: bool, path: Path) -> str:
    """Draw ``cost.png`` (``cost_figure``); returns its caption."""
    fig, caption = cost_figure(dive, cost, plan, whole)
    save_png(fig, path)
    return caption
