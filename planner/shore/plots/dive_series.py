"""Time series of a logged dive (``lrauv replay --report``): ``timeseries.png`` and ``cost.png``.

``timeseries.png``: depth, heading, the action decided and the energy used;
``cost.png`` (with a plan only): the predicted cost-to-go of the state at each
decision (spec section 8; for a physical plan the energy still to spend, Wh, on
the same scale as the energy spent) against the energy actually spent.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.shore.plots.dive_track import action_color, action_name, action_order, action_runs
from planner.shore.plots.style import load_matplotlib, new_figure, save_png

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.pipeline import PlanResult
    from planner.shore.replay.dive import Dive

__all__ = ["MAX_SERIES_POINTS", "plot_cost", "plot_timeseries"]

MAX_SERIES_POINTS = 5000  # points per line in the time series


def thin(n: int, max_points: int) -> NDArray[np.int64]:
    """Evenly spaced row indices, at most about ``max_points``, always with the first and last rows."""
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.arange(0, n, max(1, math.ceil(n / max_points)), dtype=np.int64)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def plot_timeseries(dive: Dive, path: Path) -> str:
    """Draw ``timeseries.png``; returns its caption."""
    track = dive.track
    n = len(track)
    t_h = track.time_s / 3600.0
    rows = thin(n, MAX_SERIES_POINTS)
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
    order = action_order(track.action)
    ends = np.append(t_h[1:], t_h[-1])  # a decision holds until the next one
    for y, a in enumerate(order):
        spans = [(t_h[r.start], max(ends[r.stop - 1] - t_h[r.start], 0.0)) for r in runs if r.action == a]
        color = action_color(a)
        # Edges drawn in the fill colour keep a run of a few seconds visible on an axis of hours.
        ax_act.broken_barh(spans, (y - 0.38, 0.76), facecolors=color, edgecolors=color, linewidth=0.6)
    ax_act.set_yticks(range(len(order)), [action_name(a) for a in order], fontsize=8)
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


def plan_label(plan: PlanResult) -> str:
    """The plan's model, criterion and costs, for titles."""
    t = plan.table
    if t.model == "physical":
        v = (t.physical or {}).get("vehicle", {})
        figures = f"; {v['cruise_speed_m_s']:g} m/s, hotel {v['hotel_w']:g} W" if {"cruise_speed_m_s", "hotel_w"} <= set(v) else ""
        return f"physical model, {t.criterion}; costs in Wh{figures}"
    c = t.costs
    return (f"{t.criterion}; costs drift {c.get('drift')}, forward {c.get('forward')}, rotate {c.get('rotate')},"
            f" glide {c.get('glide')}")


def plot_cost(dive: Dive, cost: NDArray[np.float64], plan: PlanResult, whole: bool, path: Path) -> str:
    """Draw ``cost.png`` (``whole``: the planned table drove every decision); returns its caption."""
    track = dive.track
    pick = thin(len(track), MAX_SERIES_POINTS)
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
                 f"plan {plan.table.crc32:08x} ({plan_label(plan)})", fontsize=11)
    save_png(fig, path)
    what = "energy still to spend, in Wh" if physical else "cost-to-go"
    caption = (f"The plan's predicted {what}, of the state at each decision (it falls to 0 at the goal),"
               " and the energy the battery reports used")
    return caption + ("." if whole else f"; only the decisions under table {plan.table.crc32:08x} have a prediction.")
