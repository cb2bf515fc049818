"""Reading part of a file (docs/forecasts-large.md): size limits checked from the header, lazy selections.

The velocities stay xarray's lazily indexed backend arrays until the time step, the member and the
lon/lat window are selected, so only that part is read: ``isel`` with slices and integers composes
the indexers and reads nothing, and the first ``.values`` reads that hyperslab from the netCDF file.
dask's chunks would read the same part, and importing dask and distributed for them cost a plan
half a second.
"""

from __future__ import annotations

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.errors import ForecastError
from planner.forecast.model import check_time_range
from planner.forecast.request import Want

# The loader reads whole velocity variables and works on float64 copies of them (about ten
# arrays of this size at the peak): a larger file must be subset before planning. Checked
# before anything is read, so a damaged header that claims a huge dimension costs nothing.
MAX_VALUES_PER_VARIABLE = 100_000_000
# With bbox=/time_index=/member=, the limit above applies to the part read, not to the file; the
# 1-D axes still read whole (time, lon, lat) are refused beyond this length (a damaged header).
MAX_AXIS_POINTS = 10_000_000


def check_axes(var: xr.DataArray, name: str, label: str) -> None:
    """Refuse dimensions too long for their 1-D coordinates to be read whole (damaged headers), from the header."""
    for d, size in zip(var.dims, var.shape):
        if int(size) > MAX_AXIS_POINTS:
            n = 1
            for length in var.shape:
                n *= int(length)
            dims = " x ".join(f"{dd} {int(ss):,}" for dd, ss in zip(var.dims, var.shape))
            raise ForecastError(
                f"{label}: variable {name} declares {n:,} values ({dims}), {int(size):,} of them along {d}; expected "
                f"at most {MAX_AXIS_POINTS:,} points along any dimension (its coordinates are read whole to find the "
                "part to read): check a damaged dimension, or subset the file"
            )


def read_ready(var: xr.DataArray) -> xr.DataArray:
    """A selection ready for its one read, in this thread (netCDF reads are not thread-safe): a
    dask-backed one (a caller's own chunks) computed with dask's synchronous scheduler; a lazily
    indexed one as it is, read by its caller's ``.values``. (``load()`` would read the same bytes,
    but first imports dask, a tenth of a second, to ask whether the variable is dask's.)"""
    if var.chunks is None:
        return var
    return var.compute(scheduler="synchronous")


def time_step(time_s: NDArray[np.float64], want: Want, label: str) -> int | None:
    """The time step to keep (None: every step); a partial read checks the whole time axis as a Forecast would."""
    if want.partial:
        check_time_range(time_s, label)
    if want.time_index is None:
        return None
    n = int(time_s.size)
    if want.time_index >= n:
        raise ForecastError(
            f"{label}: time_index {want.time_index} out of range: the file has {n} time step(s); expected "
            f"time_index in 0..{n - 1}"
        )
    return want.time_index


def check_size(var: xr.DataArray, name: str, label: str, *, part: str | None = None) -> None:
    """Refuse a velocity variable (or, with ``part``, the selection from it) too large to load, from its shape alone."""
    n = 1
    for size in var.shape:
        n *= int(size)
    if n > MAX_VALUES_PER_VARIABLE:
        dims = " x ".join(f"{d} {int(s):,}" for d, s in zip(var.dims, var.shape))
        if part is not None:
            raise ForecastError(
                f"{label}: the part of variable {name} to read ({part}) holds {n:,} values ({dims}); expected at "
                f"most {MAX_VALUES_PER_VARIABLE:,}: give a smaller bbox, one time_index and one member"
            )
        raise ForecastError(
            f"{label}: variable {name} declares {n:,} values ({dims}); expected at most "
            f"{MAX_VALUES_PER_VARIABLE:,} per velocity variable: subset the file to the region, depths and times "
            "to plan on (e.g. ncks -d lon,W,E -d lat,S,N -d time,0,N), or check a damaged dimension"
        )
