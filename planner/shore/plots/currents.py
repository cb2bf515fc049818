"""Which forecast a current map shows, and currents drawn under a track (thinned grey arrows).

Every picture that draws currents says which forecast step they are from: the
file, the step's time in ISO 8601 UTC and, for a time-varying plan, the slice
(``ForecastMoment``). Under a dive's track the currents are the forecast's at
the dive's time (``currents_at``): the step nearest the middle of the dive,
resampled onto the map's grid as the planner resamples (spec section 1).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.shore.plots.map_axes import cos_lat
from planner.shore.plots.style import FLOW_ARROW_COLOR, nice_speed

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.grid import Grid
    from planner.pipeline import PlanResult

__all__ = ["CURRENT_ZORDER", "CurrentMap", "ForecastMoment", "currents_at", "draw_current_arrows", "draw_currents_with_key",
           "moment_of_plan",
           "step_unix_s", "utc_iso"]

CURRENT_ZORDER = 3  # under land outlines (3.5), tracks (5 and up) and markers
_MAX_ARROWS_PER_AXIS = 28


def utc_iso(unix_s: float) -> str:
    """Unix seconds as ISO 8601 UTC to the second, e.g. ``2026-01-15T06:00:00Z``."""
    return str(np.datetime64(int(round(unix_s)), "s")) + "Z"


@dataclass(frozen=True, slots=True)
class ForecastMoment:
    """The forecast step a map shows: the file, the step's time and, for a time-varying plan, its slice."""

    source: str  # the forecast file (shown by name)
    time_utc: str | None  # ISO 8601 UTC; None when the file's times have no reference date
    slice_index: int | None = None  # time-varying plan: the slice drawn (0 = the first)
    n_slices: int = 1

    def label(self) -> str:
        """E.g. ``forecast scb.nc at 2026-01-15T00:00:00Z (slice 1 of 13)``."""
        when = self.time_utc or "an undated step (the file's times have no reference date)"
        text = f"forecast {Path(self.source).name} at {when}"
        if self.slice_index is not None:
            text += f" (slice {self.slice_index + 1} of {self.n_slices} of the time-varying plan)"
        return text


def moment_of_plan(result: PlanResult) -> ForecastMoment:
    """The step ``result``'s currents and first policy come from; a time-varying plan's first slice."""
    table = result.table
    if table.time_varying:
        return ForecastMoment(result.forecast.source, table.slice_times[0], 0, table.n_slices)
    return ForecastMoment(result.forecast.source, table.forecast_time)


@dataclass(frozen=True, eq=False, slots=True)
class CurrentMap:
    """One layer of currents on ``grid``'s cells, ``(ny, nx)`` east/north m/s with NaN for land, and its step."""

    grid: Grid
    u_m_s: NDArray[np.float64]
    v_m_s: NDArray[np.float64]
    depth_m: float
    moment: ForecastMoment

    def label(self) -> str:
        return f"currents at {self.depth_m:g} m, {self.moment.label()}"


def currents_at(forecast: str | os.PathLike[str], grid: Grid, unix_s: float | None, *, depth_m: float = 0.0
                ) -> CurrentMap:
    """The forecast file's currents at ``depth_m`` on ``grid``'s cells, at the step nearest ``unix_s``.

    ``unix_s`` None, or a file without a reference date: its first step. Only that step and the
    grid's window are read (``open_forecast(time_index=, bbox=)``). Errors are the forecast
    reader's ``ForecastError``.
    """
    from planner.forecast import open_forecast
    from planner.forecast.resample import resample
    from planner.grid import Grid

    steps_s = step_unix_s(forecast)
    index, when = 0, None
    if steps_s is not None:
        index = 0 if unix_s is None else int(np.argmin(np.abs(steps_s - unix_s)))
        when = utc_iso(float(steps_s[index]))
    layer = Grid(lon_deg=grid.lon_deg, lat_deg=grid.lat_deg, depth_m=np.array([float(depth_m)]))
    read = open_forecast(forecast, time_index=index, bbox=layer.bbox)
    u, v = resample(read, layer, time_index=0)
    return CurrentMap(grid=layer, u_m_s=u[0], v_m_s=v[0], depth_m=float(depth_m),
                      moment=ForecastMoment(os.fspath(forecast), when))


def step_unix_s(forecast: str | os.PathLike[str]) -> NDArray[np.float64] | None:
    """The Unix times of the forecast file's steps (its time axis only is read); None without a reference date."""
    from planner.forecast import forecast_times
    from planner.forecast.model import parse_origin

    times = forecast_times(forecast)
    if times.time_origin is None:
        return None
    origin_ms = parse_origin(times.time_origin, times.source).astype("datetime64[ms]").astype(np.int64)
    return float(origin_ms) / 1e3 + np.asarray(times.time_s, dtype=np.float64)


def draw_current_arrows(mpl: Any, ax: Any, currents: CurrentMap, extent: tuple[float, float, float, float]) -> Any:
    """``currents`` in ``extent`` (west, east, south, north) as grey arrows scaled by speed, thinned to at most
    28 a side, at ``CURRENT_ZORDER``; returns the quiver, or None when there is nothing to draw."""
    grid = currents.grid
    u, v = np.asarray(currents.u_m_s, dtype=np.float64), np.asarray(currents.v_m_s, dtype=np.float64)
    speed = np.hypot(u, v)
    if not np.isfinite(speed).any() or float(np.nanmax(speed)) <= 0:
        return None
    west, east, south, north = extent
    cols = np.flatnonzero((grid.lon_deg >= west) & (grid.lon_deg <= east))
    rows = np.flatnonzero((grid.lat_deg >= south) & (grid.lat_deg <= north))
    if cols.size == 0 or rows.size == 0:
        return None
    stride = max(1, math.ceil(max(cols.size, rows.size) / _MAX_ARROWS_PER_AXIS))
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
    quiver = ax.quiver(x[ok], y[ok], us[ok], vs[ok], color=FLOW_ARROW_COLOR, angles="uv", scale_units="x",
                       scale=scale, width=shaft, headwidth=3.5, headlength=4.0, headaxislength=3.5, pivot="middle",
                       zorder=CURRENT_ZORDER)
    quiver.set_gid("currents")
    return quiver


def draw_currents_with_key(mpl: Any, ax: Any, currents: CurrentMap, extent: tuple[float, float, float, float],
                           source: str) -> Any:
    """``draw_current_arrows`` with a speed key above the map's top right; returns the legend handle (its
    label names the depth and ``source``, e.g. "truth"), or None when no arrow was drawn."""
    quiver = draw_current_arrows(mpl, ax, currents, extent)
    if quiver is None:
        return None
    key = nice_speed(0.5 * float(np.nanpercentile(np.hypot(currents.u_m_s, currents.v_m_s), 98)))
    ax.quiverkey(quiver, 0.88, 1.012, key, f"{key:g} m/s", labelpos="E", coordinates="axes", color="0.3",
                 fontproperties={"size": 8})
    return mpl.lines.Line2D([], [], color=FLOW_ARROW_COLOR, marker=r"$\rightarrow$", linestyle="none", markersize=12,
                            label=f"current at {currents.depth_m:g} m ({source})")
