"""How wrong a forecast's currents are likely to be, measured from data (docs/time-varying.md).

The physical model perturbs the current by ``current_error_m_s`` per component
(``planner.physical.sampling.member_offsets_m_s``). With ``current_error_m_s: measured`` that
size comes from the data at hand, in this order:

1. **A previous issue** of the forecast: the root mean square of the difference between the
   two issues' currents at the valid times they share within the plan's horizon, over the water
   nodes of the planning grid and both components. Successive issues differ by about the older
   one's error, so this is an estimate from above for the newer one.
2. **The forecast's own change** (a stationary plan only): the root mean square of
   ``u(t) - u(t0)`` over the steps ``t`` within the horizon. A stationary plan assumes the current
   of ``t0`` lasts, so this change is the error it plans with; a time-varying plan carries the
   change in its state, and this is no error to it.
3. Otherwise the setting's default, said so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from planner.forecast.model import Forecast
from planner.forecast.resample import resample
from planner.grid import Grid

ErrorSource = Literal["previous issue", "forecast change", "default"]


@dataclass(frozen=True, kw_only=True)
class ErrorEstimate:
    """The forecast error chosen for a plan, where it came from and on how much data."""

    current_error_m_s: float
    source: ErrorSource
    detail: str

    def describe(self) -> str:
        return f"{self.current_error_m_s:.3f} m/s per component, {self.source}: {self.detail}"


def _rms(diffs: list[np.ndarray]) -> tuple[float, int]:
    values = np.concatenate([d[np.isfinite(d)] for d in diffs]) if diffs else np.empty(0)
    return (float(math.sqrt(np.mean(values**2))) if values.size else math.nan), int(values.size)


def _absolute_s(forecast: Forecast) -> np.ndarray:
    """Each step's time in Unix seconds (or the file's own seconds when it gives no date)."""
    if forecast.time_origin is None:
        return forecast.time_s.astype(np.float64)
    origin = np.datetime64(forecast.time_origin.rstrip("Z"), "s").astype(np.int64)
    return forecast.time_s.astype(np.float64) + float(origin)


def measure_error(forecast: Forecast, grid: Grid, index: int, horizon_h: float, *, time_varying: bool,
                  previous: Forecast | None = None, default_m_s: float) -> ErrorEstimate:
    """The forecast error for a plan from step ``index`` over ``horizon_h`` hours (module docstring)."""
    times = _absolute_s(forecast)
    t0 = times[index]
    steps = [n for n in range(index, times.size) if times[n] - t0 <= horizon_h * 3600.0 + 1e-6]
    if previous is not None:
        prev_times = _absolute_s(previous)
        diffs: list[np.ndarray] = []
        shared = 0
        for n in steps:
            match = np.flatnonzero(np.abs(prev_times - times[n]) < 1.0)
            if match.size == 0:
                continue
            shared += 1
            u, v = resample(forecast, grid, time_index=forecast.step_index(n))
            pu, pv = resample(previous, grid, time_index=previous.step_index(int(match[0])))
            diffs += [u - pu, v - pv]
        value, count = _rms(diffs)
        if shared and math.isfinite(value):
            return ErrorEstimate(current_error_m_s=value, source="previous issue",
                                 detail=f"RMS difference from {previous.source} at the {shared} valid time(s) both "
                                        f"issues give within {horizon_h:g} h ({count:,} values)")
    if not time_varying and len(steps) > 1:
        u0, v0 = resample(forecast, grid, time_index=forecast.step_index(steps[0]))
        diffs = []
        for n in steps[1:]:
            u, v = resample(forecast, grid, time_index=forecast.step_index(n))
            diffs += [u - u0, v - v0]
        value, count = _rms(diffs)
        if math.isfinite(value):
            span_h = (times[steps[-1]] - t0) / 3600.0
            return ErrorEstimate(current_error_m_s=value, source="forecast change",
                                 detail=f"RMS change of the current from step {index} over the next {span_h:g} h "
                                        f"({len(steps) - 1} steps, {count:,} values): a stationary plan assumes it lasts")
    why = ("a time-varying plan carries the forecast's change, and no previous issue was given" if time_varying
           else "the forecast has one step within the horizon and no previous issue was given")
    return ErrorEstimate(current_error_m_s=default_m_s, source="default", detail=f"nothing to measure it from: {why}")
