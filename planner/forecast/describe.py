"""The text of ``lrauv forecast info FILE``: what a ``Forecast`` holds, in a few lines."""

from __future__ import annotations

import numpy as np

from planner.forecast.model import Forecast, iso_time


def describe(forecast: Forecast) -> str:
    """Multi-line summary for ``lrauv forecast info FILE``."""
    n_t, n_z, n_y, n_x = forecast.shape
    lines = [f"source:     {forecast.source}", f"identity:   {forecast.identity}"]
    if forecast.is_regular:
        lines.append(f"layout:     regular lon/lat grid, {n_x} x {n_y} (lon x lat)")
    else:
        lines.append(f"layout:     curvilinear grid with 2-D lon/lat, {n_x} x {n_y} (x x y)")
    if forecast.variables:
        lines.append(f"variables:  {', '.join(forecast.variables)} -> eastward, northward (m/s)")
    times = forecast.time_s
    step = f", step {_duration(float(np.median(np.diff(times))))}" if times.size > 1 else ""
    if forecast.time_origin is not None:
        lines.append(f"time:       {n_t} steps, {iso_time(forecast, times[0])} .. {iso_time(forecast, times[-1])}{step}")
    else:
        lines.append(f"time:       {n_t} steps, {times[0]:g} .. {times[-1]:g} s (no reference date){step}")
    depth = forecast.depth_m
    if depth is None:
        lines.append("depth:      none (the field applies to every layer)")
    elif depth.ndim == 1:
        lines.append(f"depth:      {depth.size} level(s): {', '.join(f'{d:g}' for d in depth)} m")
    else:
        d0 = depth[0]
        lines.append(
            f"depth:      {n_z} terrain-following levels per column; at time 0 the first level lies at "
            f"{np.nanmin(d0[0]):.3g}..{np.nanmax(d0[0]):.3g} m, "
            f"the last at {np.nanmin(d0[-1]):.3g}..{np.nanmax(d0[-1]):.3g} m"
            + ("" if forecast.covers_surface else "; above the first level: not covered (land)")
        )
    lines.append(
        f"lon:        {np.nanmin(forecast.lon_deg):.4f} .. {np.nanmax(forecast.lon_deg):.4f} deg E; "
        f"lat: {np.nanmin(forecast.lat_deg):.4f} .. {np.nanmax(forecast.lat_deg):.4f} deg N"
    )
    u, v = forecast.u_east_m_s, forecast.v_north_m_s
    water0 = np.isfinite(u[0, 0]) & np.isfinite(v[0, 0])
    lines.append(f"land:       {100.0 * (1.0 - water0.mean()):.1f} % of points at time 0, first level")
    speed = np.hypot(u, v)
    speed = speed[np.isfinite(speed)]
    if speed.size:
        p50, p90, p99 = np.percentile(speed, [50, 90, 99])
        lines.append(f"speed:      p50 {p50:.3f}, p90 {p90:.3f}, p99 {p99:.3f}, max {speed.max():.3f} m/s")
    else:
        lines.append("speed:      no water points")
    if forecast.notes:
        lines.append("notes:")
        lines.extend(f"  - {n}" for n in forecast.notes)
    return "\n".join(lines)


def _duration(seconds: float) -> str:
    for unit, size in (("d", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size and abs(seconds / size - round(seconds / size)) < 1e-9:
            return f"{seconds / size:g} {unit}"
    return f"{seconds:g} s"
