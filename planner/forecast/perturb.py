"""A forecast made wrong on purpose: a file's currents shifted in time and scaled.

Real forecasts come one issue at a time; to see what a plan does when its forecast's tide turns
early or runs weak (docs/evaluation.md), ``lrauv forecast perturb`` writes a copy of a file in
which both velocity variables carry the same error the synthetic tidal channel's forecast can
have (``planner.forecast.synthetic.tidal.with_forecast_error``): the currents run
``phase_error_h`` hours early, so the copy at valid time t holds the original at t +
``phase_error_h`` (linear in time between the file's steps; before its first step or after its
last, that step's value), and their amplitude is times ``1 + amplitude_error``.

Both are linear in the velocity, so they hold for grid-relative components (a ROMS file's u, v
along its own axes, rotated by its angle when read) as for east and north. Everything else in
the file is copied as it is; the two variables are written as float32 with NaN fill (land stays
land: a node is NaN in the copy where it is NaN in either step it is read from).
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import ForecastError
from planner.forecast.cf import dim_role
from planner.forecast.files import open_dataset
from planner.forecast.layout import find_velocity_variables
from planner.forecast.reader import forecast_times
from planner.forecast.synthetic.cf_writer import write_netcdf


def shifted_in_time(values: NDArray[np.float64], time_s: NDArray[np.float64], axis: int,
                    shift_s: float) -> NDArray[np.float64]:
    """``values`` along ``axis`` (whose steps are at ``time_s``, increasing) read at ``time_s + shift_s``:
    linear between the two steps around it, the first or last step's value beyond them."""
    if shift_s == 0.0 or time_s.size == 1:
        return np.array(values, dtype=np.float64)
    at = np.clip(time_s + shift_s, time_s[0], time_s[-1])
    hi = np.clip(np.searchsorted(time_s, at, side="right"), 1, time_s.size - 1)
    lo = hi - 1
    w = (at - time_s[lo]) / (time_s[hi] - time_s[lo])
    moved = np.moveaxis(np.asarray(values, dtype=np.float64), axis, 0)
    shape = (-1,) + (1,) * (moved.ndim - 1)
    a, b, w = moved[lo], moved[hi], w.reshape(shape)
    # Exactly on a step, that step alone, so land in the next step does not spread to it.
    out = np.where(w == 0.0, a, np.where(w == 1.0, b, (1.0 - w) * a + w * b))
    return np.moveaxis(out, 0, axis)


def write_perturbed(source: str | os.PathLike[str], out: str | os.PathLike[str], *, phase_error_h: float = 0.0,
                    amplitude_error: float = 0.0, variables: tuple[str, str] | None = None) -> Path:
    """Write ``source`` to ``out`` (atomically) with its currents running ``phase_error_h`` hours early and
    their amplitude times ``1 + amplitude_error``; ``variables`` names (u, v) as ``open_forecast`` takes it."""
    label = os.fspath(source)
    if not (isinstance(phase_error_h, (int, float)) and math.isfinite(phase_error_h)):
        raise ForecastError(f"phase_error_h: expected a finite number of hours; got {phase_error_h!r}")
    if not (isinstance(amplitude_error, (int, float)) and math.isfinite(amplitude_error) and amplitude_error >= -1.0):
        raise ForecastError(f"amplitude_error: expected a finite number >= -1 (the amplitude is times 1 + it); "
                            f"got {amplitude_error!r}")
    times = forecast_times(source, variables=variables)  # the reader's own checks, and the steps in seconds
    if phase_error_h != 0.0 and times.time_s.size < 2:
        raise ForecastError(f"{label}: a phase error needs two or more time steps to move the currents between; "
                            "the file has one (an amplitude error alone works)")
    span_h = float(times.time_s[-1] - times.time_s[0]) / 3600.0
    if abs(phase_error_h) >= span_h > 0.0:
        raise ForecastError(f"phase_error_h: {phase_error_h:g} h moves every step of {label} past its first or last "
                            f"(the file spans {span_h:g} h); expected less than that")
    if Path(out).exists() and Path(out).resolve() == Path(source).resolve():
        raise ForecastError(f"{out}: the copy would replace the file it is made from; give another output file")
    ds, label, _path = open_dataset(source, "forecast file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # NaN land in the interpolation
            ds = ds.load()
            names = find_velocity_variables(ds, label, variables)
            encoding: dict[str, dict[str, object]] = {}
            for name in (names.u_name, names.v_name):
                var = ds[name]
                time_axes = [k for k, d in enumerate(var.dims) if dim_role(ds, str(d)) == "T"]
                if phase_error_h != 0.0 and len(time_axes) != 1:
                    raise ForecastError(f"{label}: variable {name} {tuple(var.dims)}: expected one time dimension "
                                        "to shift the currents along")
                values = np.asarray(var.values, dtype=np.float64)
                if time_axes:
                    values = shifted_in_time(values, times.time_s, time_axes[0], phase_error_h * 3600.0)
                attrs = {k: v for k, v in var.attrs.items() if k not in ("scale_factor", "add_offset", "_FillValue",
                                                                          "missing_value", "valid_min", "valid_max",
                                                                          "valid_range")}
                ds[name] = (var.dims, (values * (1.0 + amplitude_error)).astype(np.float32), attrs)
                encoding[name] = {"dtype": "float32", "_FillValue": np.float32(np.nan), "zlib": True, "complevel": 4}
            history = (f"lrauv forecast perturb: currents of {Path(label).name} running {phase_error_h:g} h early, "
                       f"amplitude times {1.0 + amplitude_error:g}")
            ds.attrs["history"] = history + ("\n" + str(ds.attrs["history"]) if "history" in ds.attrs else "")
            return write_netcdf(out, ds, encoding)
    finally:
        ds.close()
