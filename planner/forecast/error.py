"""How wrong a forecast's currents are likely to be, measured from data (docs/time-varying.md).

The physical model perturbs the current by ``current_error_m_s`` per component
(``planner.physical.sampling.member_offsets_m_s``). With ``current_error_m_s: measured`` that
size comes from the data at hand, in this order:

1. **An ensemble's spread**, for a plan on the members' mean (``planner.forecast.ensemble``):
   the members' standard deviation about their mean (M - 1 in the denominator) over the steps
   within the plan's horizon, the water nodes of the planning grid and both components, times
   ``sqrt(1 + 1/M)``: if the truth is one more draw of the members' spread, that is the
   standard deviation of its difference from the mean of M members.
2. **A previous issue** of the forecast: the root mean square of the difference between the
   two issues' currents at the valid times they share within the plan's horizon, over the water
   nodes of the planning grid and both components. Successive issues differ by about the older
   one's error, so this is an estimate from above for the newer one.
3. **The forecast's own change** (a stationary plan only): the root mean square of
   ``u(t) - u(t0)`` over the steps ``t`` within the horizon. A stationary plan assumes the current
   of ``t0`` lasts, so this change is the error it plans with; a time-varying plan carries the
   change in its state, and this is no error to it.
4. Otherwise the setting's default, said so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from planner.forecast.model import Forecast
from planner.forecast.resample import resample
from planner.grid import Grid

ErrorSource = Literal["ensemble spread", "previous issue", "forecast change", "default"]


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


def _spread(members: Sequence[Forecast], grid: Grid, steps: list[int]) -> ErrorEstimate | None:
    """The members' spread about their mean as the error of a plan on that mean (source 1)."""
    m = len(members)
    total, count = 0.0, 0
    for n in steps:
        fields = [resample(f, grid, time_index=f.step_index(n)) for f in members]
        for comp in (0, 1):
            stack = np.stack([f[comp] for f in fields])
            wet = stack[:, np.all(np.isfinite(stack), axis=0)]  # (members, water nodes)
            total += float(np.sum((wet - np.mean(wet, axis=0)) ** 2))
            count += wet.shape[1]
    if count == 0:
        return None
    sigma = math.sqrt(total / ((m - 1) * count))
    return ErrorEstimate(current_error_m_s=sigma * math.sqrt(1.0 + 1.0 / m), source="ensemble spread",
                         detail=f"standard deviation of {m} members about their mean, {sigma:.3f} m/s over "
                                f"{len(steps)} step(s) and {count:,} values, times sqrt(1 + 1/{m}) for a plan on "
                                "the mean")


def measure_error(forecast: Forecast, grid: Grid, index: int, horizon_h: float, *, time_varying: bool,
                  previous: Forecast | None = None, members: Sequence[Forecast] = (),
                  default_m_s: float) -> ErrorEstimate:
    """The forecast error for a plan from step ``index`` over ``horizon_h`` hours (module docstring).

    ``members``: the ensemble members whose mean ``forecast`` is (same steps), when it is one.
    """
    times = _absolute_s(forecast)
    t0 = times[index]
    steps = [n for n in range(index, times.size) if times[n] - t0 <= horizon_h * 3600.0 + 1e-6]
    if len(members) > 1:
        spread = _spread(members, grid, steps)
        if spread is not None:
            return spread
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
