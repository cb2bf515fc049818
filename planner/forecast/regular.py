"""Regular lon/lat grids (HYCOM/RTOFS, Copernicus, any CF lon/lat product): 1-D axes, east/north components.

Descending axes are flipped to ascending and a repeated +360 deg column dropped (spec section 1
grids). With ``bbox=`` only the lon/lat window that resampling the bbox uses is read, plus
``WINDOW_MARGIN_NODES`` nodes on each side (docs/forecasts-large.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.errors import CoverageError, ForecastError
from planner.forecast.cf import axis_variable, numbers
from planner.forecast.layout import Components
from planner.forecast.model import MAX_ABS_LON_DEG, is_periodic_lon, lon_shifts
from planner.forecast.request import Context, Fields, Want
from planner.forecast.structured import StructuredHeader, read_velocities

if TYPE_CHECKING:
    from planner.contract.geodesy import BBox

# Nodes kept beyond the ones that the interpolation of a bbox uses, on each side (spec section 1).
WINDOW_MARGIN_NODES = 2


def read_regular(
    ctx: Context, u_var: xr.DataArray, v_var: xr.DataArray, header: StructuredHeader, want: Want, notes: list[str]
) -> Fields:
    """The velocities on ascending lon/lat axes; only the bbox's window of them with ``want.bbox``."""
    ds, label = ctx.ds, ctx.label
    xdim, ydim = header.roles["X"], header.roles["Y"]
    xcoord, ycoord = axis_variable(ds, xdim), axis_variable(ds, ydim)
    assert xcoord is not None and ycoord is not None  # Layout.REGULAR
    later = list(header.notes)
    select = dict(header.select)
    part = list(header.part)
    orient = _orientation(
        numbers(xcoord, f"coordinate {xdim}", label), numbers(ycoord, f"coordinate {ydim}", label),
        label, xdim, ydim, later,
    )
    x0, x1, y0, y1 = 0, orient.lon.size, 0, orient.lat.size
    if want.bbox is not None:
        x0, x1, y0, y1 = regular_window(orient.lon, orient.lat, want.bbox, label)
        part.append(
            f"lon {orient.lon[x0]:.6g}..{orient.lon[x1 - 1]:.6g} ({x1 - x0} of {orient.lon.size} points), "
            f"lat {orient.lat[y0]:.6g}..{orient.lat[y1 - 1]:.6g} ({y1 - y0} of {orient.lat.size})"
        )
    if want.partial:  # a whole read reads the repeated column too and drops it afterwards, as always
        select[xdim] = orient.file_slice(x0, x1, axis="x")
        select[ydim] = orient.file_slice(y0, y1, axis="y")
    u, v = read_velocities(ctx, u_var, v_var, header, want, notes, select=select, part="; ".join(part))
    notes.extend(later)
    u, v = orient.apply(u, whole=not want.partial), orient.apply(v, whole=not want.partial)
    lon, lat = orient.lon, orient.lat
    if want.bbox is not None:
        lon, lat = lon[x0:x1], lat[y0:y1]
    components = header.velocities.components
    if components is Components.GRID_XY:
        notes.append("x/y components on a regular lon/lat grid: x is east and y is north, no rotation")
    elif components is Components.UNKNOWN:
        notes.append("no standard_name on the velocities: taken as eastward/northward on the lon/lat grid")
    windowed = want.bbox is not None
    return Fields(
        u=u,
        v=v,
        lon=np.ascontiguousarray(lon),
        lat=np.ascontiguousarray(lat),
        depth=header.depth,
        time_s=header.time_s,
        time_origin=header.time_origin,
        file_n_times=header.file_n_times,
        part="; ".join(part),
        lon_index=(x0, x1) if windowed else None,
        lat_index=(y0, y1) if windowed else None,
        file_lon=orient.lon if windowed else None,
        file_lat=orient.lat if windowed else None,
    )


@dataclass(frozen=True, eq=False)
class _Orientation:
    """How a regular file's lon/lat axes become the Forecast's: flips to ascending, a repeated wrap column dropped."""

    lon: NDArray[np.float64]  # the Forecast's axes (ascending, wrap column dropped)
    lat: NDArray[np.float64]
    flip_x: bool
    flip_y: bool
    drop_last_x: bool
    n_x_file: int
    n_y_file: int

    def file_slice(self, start: int, stop: int, *, axis: str) -> slice:
        """The file's index range of the Forecast's ``[start, stop)`` along lon ('x') or lat ('y')."""
        flip, n = (self.flip_x, self.n_x_file) if axis == "x" else (self.flip_y, self.n_y_file)
        return slice(n - stop, n - start) if flip else slice(start, stop)

    def apply(self, a: NDArray[np.float64], *, whole: bool) -> NDArray[np.float64]:
        """(T, Z, Y, X) values in file order -> the Forecast's order; ``whole``: all file columns were read."""
        if self.flip_y:
            a = a[:, :, ::-1, :]
        if self.flip_x:
            a = a[:, :, :, ::-1]
        if whole and self.drop_last_x:
            a = a[..., :-1]
        return np.ascontiguousarray(a)


def _orientation(
    lon: NDArray[np.float64], lat: NDArray[np.float64], label: str, xdim: str, ydim: str, notes: list[str]
) -> _Orientation:
    """Flip descending axes to ascending and drop a duplicated wrap-around column (spec section 1 grids)."""
    n_x_file, n_y_file = lon.size, lat.size
    for name, axis, bound in ((xdim, lon, MAX_ABS_LON_DEG), (ydim, lat, 90.0)):
        if not np.all(np.isfinite(axis)):
            raise ForecastError(f"{label}: coordinate {name} has missing values; expected finite degrees")
        if axis.min() < -bound or axis.max() > bound:
            raise ForecastError(
                f"{label}: coordinate {name}: values {axis.min():g}..{axis.max():g} lie outside [-{bound:g}, {bound:g}]; "
                "expected degrees (check the variable and its units)"
            )
    flip_y = lat.size > 1 and lat[0] > lat[-1]
    if flip_y:
        lat = lat[::-1]
        notes.append(f"latitude {ydim} was descending: flipped to ascending")
    flip_x = lon.size > 1 and lon[0] > lon[-1]
    if flip_x:
        lon = lon[::-1]
        notes.append(f"longitude {xdim} was descending: flipped to ascending")
    drop = lon.size > 2 and abs(lon[-1] - lon[0] - 360.0) < 1e-6
    if drop:
        lon = lon[:-1]
        notes.append(f"longitude {xdim}: last column repeats the first (+360 deg): dropped")
    for name, axis in ((xdim, lon), (ydim, lat)):
        if axis.size > 1 and np.any(np.diff(axis) <= 0):
            raise ForecastError(
                f"{label}: coordinate {name}: expected strictly monotonic values; got {axis[:8].tolist()}..."
            )
    if is_periodic_lon(lon):
        notes.append("longitude spans 360 deg: treated as periodic (wraps at the date line)")
    return _Orientation(
        lon=np.ascontiguousarray(lon), lat=np.ascontiguousarray(lat), flip_x=bool(flip_x), flip_y=bool(flip_y),
        drop_last_x=bool(drop), n_x_file=int(n_x_file), n_y_file=int(n_y_file),
    )


def _snap_bound(axis: NDArray[np.float64]) -> float:
    """An upper bound of ``planner.forecast.resample``'s snapping tolerance on this axis (a thousandth of its spacing)."""
    if axis.size < 2:
        return 0.0
    return 1e-3 * float(np.min(np.diff(axis)))


def _bracket(axis: NDArray[np.float64], lo: float, hi: float) -> tuple[int, int]:
    """Indices of the last node at or below ``lo`` and the first at or above ``hi`` (clipped to the axis)."""
    i0 = int(np.searchsorted(axis, lo, side="right")) - 1
    i1 = int(np.searchsorted(axis, hi, side="left"))
    return max(i0, 0), min(i1, axis.size - 1)


def regular_window(
    lon: NDArray[np.float64], lat: NDArray[np.float64], bbox: BBox, label: str
) -> tuple[int, int, int, int]:
    """``[x0, x1)`` and ``[y0, y1)`` of the nodes that resampling any grid inside ``bbox`` uses, plus the margin.

    Targets are the bbox's longitudes moved by multiples of 360 deg into the axis' range, as
    ``planner.forecast.resample`` moves them (a periodic axis counts its closing node, first + 360 deg).
    A periodic axis whose window would need the seam keeps every column.
    """
    periodic = is_periodic_lon(lon)
    axis = np.append(lon, lon[0] + 360.0) if periodic else lon
    tol = _snap_bound(axis)
    lo, hi = float(axis[0]) - tol, float(axis[-1]) + tol
    west, east = float(bbox.west_deg), float(bbox.east_deg)
    brackets = []
    if east - west >= 360.0:
        brackets.append((0, axis.size - 1))
    else:
        for k in lon_shifts(west, east, lo, hi):
            p, q = max(west + 360.0 * k, lo), min(east + 360.0 * k, hi)
            if p <= q:
                brackets.append(_bracket(axis, p, q))
    tol_y = _snap_bound(lat)
    p_y, q_y = max(float(bbox.south_deg), float(lat[0]) - tol_y), min(float(bbox.north_deg), float(lat[-1]) + tol_y)
    if not brackets or p_y > q_y:
        raise CoverageError(
            f"{label}: bbox {bbox.west_deg:g},{bbox.south_deg:g},{bbox.east_deg:g},{bbox.north_deg:g} lies outside the "
            f"forecast, which covers lon {lon[0]:.4f}..{lon[-1]:.4f}, lat {lat[0]:.4f}..{lat[-1]:.4f}; expected a bbox "
            "that overlaps it"
        )
    i0, i1 = min(b[0] for b in brackets), max(b[1] for b in brackets)
    if periodic and i1 >= lon.size:  # the closing node is column 0 again: keep the whole circle
        x0, x1 = 0, lon.size
    else:
        x0, x1 = max(i0 - WINDOW_MARGIN_NODES, 0), min(i1 + WINDOW_MARGIN_NODES, lon.size - 1) + 1
    j0, j1 = _bracket(lat, p_y, q_y)
    y0, y1 = max(j0 - WINDOW_MARGIN_NODES, 0), min(j1 + WINDOW_MARGIN_NODES, lat.size - 1) + 1
    return x0, x1, y0, y1
