"""Projected and curvilinear structured grids (e.g. ROMS output interpolated to z-levels, NorKyst-800).

Lon/lat are 2-D: read from the file or the grid file, or computed from X/Y with the CF
``grid_mapping`` (pyproj, imported only here and only when needed). Grid x/y components are
rotated to east/north with the projection or an ``angle`` variable (spec section 1: "Products
that store grid-relative components ... are rotated to east/north when they are read").
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.errors import ForecastError
from planner.forecast.cf import attr, axis_variable, is_lat_like, is_lon_like, numbers
from planner.forecast.layout import Components
from planner.forecast.request import Context, Fields, Want
from planner.forecast.structured import StructuredHeader, read_velocities


def read_projected(
    ctx: Context, u_var: xr.DataArray, v_var: xr.DataArray, header: StructuredHeader, want: Want, notes: list[str]
) -> Fields:
    """The velocities as east/north on the file's whole horizontal grid, with 2-D lon/lat (``bbox`` is not used)."""
    ds, label = ctx.ds, ctx.label
    u_name, v_name = header.velocities.u_name, header.velocities.v_name
    components = header.velocities.components
    ydim, xdim = header.roles["Y"], header.roles["X"]
    xcoord, ycoord = axis_variable(ds, xdim), axis_variable(ds, ydim)
    grid_mapping = _grid_mapping_var(ds, u_var)
    part = "; ".join(header.part)
    u, v = read_velocities(ctx, u_var, v_var, header, want, notes, select=dict(header.select), part=part)
    notes.extend(header.notes)

    ny, nx = int(u_var.sizes[ydim]), int(u_var.sizes[xdim])
    lonlat = _find_2d_lonlat(ctx, u_var, ydim, xdim)
    crs = None
    xy: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
    if grid_mapping is not None and xcoord is not None and ycoord is not None:
        crs = _crs_from_grid_mapping(grid_mapping, label)
        xy = (numbers(xcoord, f"coordinate {xdim}", label), numbers(ycoord, f"coordinate {ydim}", label))
    if lonlat is not None:
        lon, lat, where = lonlat
        notes.append(f"2-D lon/lat from {where}")
    elif crs is not None and xy is not None:
        assert grid_mapping is not None
        lon, lat = _lonlat_from_projection(crs, xy[0], xy[1])
        notes.append(f"no lon/lat variables: computed from {xdim}/{ydim} with grid_mapping {grid_mapping.name!r}")
    else:
        raise ForecastError(
            f"{label}: no longitude/latitude for {u_name} on ({ydim}, {xdim}): expected 1-D lon/lat coordinate "
            "variables, 2-D lon/lat variables (e.g. named in the 'coordinates' attribute), or X/Y coordinates with a "
            "CF grid_mapping to compute them; add them to the file or pass --grid-file GRID.nc with 2-D lon/lat"
        )
    if not np.any(np.isfinite(lon) & np.isfinite(lat)):
        raise ForecastError(f"{label}: lon/lat for {u_name} are all missing; expected finite degrees")

    if components is Components.EAST_NORTH:
        pass
    elif crs is not None and xy is not None:
        assert grid_mapping is not None
        cos_x, sin_x, cos_y, sin_y = _projection_axes(crs, xy[0], xy[1])
        u, v = u * cos_x + v * cos_y, u * sin_x + v * sin_y
        between = np.arctan2(sin_y * cos_x - cos_y * sin_x, cos_y * cos_x + sin_y * sin_x)  # angle x-axis -> y-axis
        skew = float(np.degrees(np.nanmax(np.abs(between - np.pi / 2))))
        notes.append(
            f"rotated projection x/y components to east/north with grid_mapping {grid_mapping.name!r} "
            f"({_crs_text(crs)}): local x-axis direction from the projection at every point"
            + (f"; axes depart from perpendicular by up to {skew:.3g} deg" if skew > 1e-6 else "")
        )
        if components is Components.UNKNOWN:
            notes.append("no standard_name on the velocities: taken as projection x/y components (projected grid)")
    else:
        found = ctx.find(("angle",), (ny, nx))
        if found is None:
            raise ForecastError(
                f"{label}: {u_name}/{v_name} are grid-relative (x/y) components on a curvilinear grid but there is no "
                "grid_mapping and no 'angle' variable to rotate them to east/north; pass --grid-file GRID.nc with "
                "'angle', or --variables with eastward/northward variables"
            )
        angle = np.asarray(found[1].values, dtype=np.float64)
        u, v = rotate(u, v, angle)
        notes.append(f"rotated grid x/y components to east/north by 'angle' from {found[2]}")
    return Fields(
        u=u,
        v=v,
        lon=lon,
        lat=lat,
        depth=header.depth,
        time_s=header.time_s,
        time_origin=header.time_origin,
        file_n_times=header.file_n_times,
        part=part,
    )


def _find_2d_lonlat(
    ctx: Context, var: xr.DataArray, ydim: str, xdim: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], str] | None:
    ds = ctx.ds
    names = str(var.attrs.get("coordinates", "")).split() + [str(n) for n in ds.variables]
    for dset, where in ((ds, ctx.label), (ctx.grid_ds, ctx.grid_label)):
        if dset is None:
            continue
        lon_name = lat_name = None
        for name in names if dset is ds else [str(n) for n in dset.variables]:
            if name not in dset.variables:
                continue
            cand = dset.variables[name]
            if cand.ndim != 2 or tuple(cand.shape) != (var.sizes[ydim], var.sizes[xdim]):
                continue
            if lon_name is None and is_lon_like(name, cand):
                lon_name = name
            elif lat_name is None and is_lat_like(name, cand):
                lat_name = name
        if lon_name and lat_name:
            lon = numbers(dset.variables[lon_name], f"longitude {lon_name}", str(where))
            lat = numbers(dset.variables[lat_name], f"latitude {lat_name}", str(where))
            if dset.variables[lon_name].dims == (xdim, ydim) and ydim != xdim:
                lon, lat = lon.T, lat.T
            return lon, lat, f"{lon_name}/{lat_name} in {where}"
    return None


def _grid_mapping_var(ds: xr.Dataset, var: xr.DataArray) -> xr.DataArray | None:
    name = attr(var, "grid_mapping")
    if not name:
        return None
    name = name.split(":")[0].split()[0]
    return ds[name] if name in ds.variables else None


def _crs_from_grid_mapping(gm: xr.DataArray, label: str) -> Any:
    import pyproj  # lazily: only projected grids need it

    attrs = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in gm.attrs.items()}
    attempts: list[str] = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for key in ("crs_wkt", "spatial_ref", "proj4", "proj4text", "proj4_string"):
            if key in attrs:
                try:
                    return pyproj.CRS.from_user_input(attrs[key])
                except pyproj.exceptions.CRSError as exc:
                    attempts.append(f"{key}: {exc}")
        try:
            return pyproj.CRS.from_cf(attrs)
        except (pyproj.exceptions.CRSError, KeyError, ValueError, TypeError) as exc:
            attempts.append(f"CF attributes: {exc}")
    raise ForecastError(
        f"{label}: grid_mapping {gm.name!r}: cannot build a projection ({'; '.join(attempts)}); expected CF "
        "grid_mapping attributes or a proj4/crs_wkt attribute"
    )


def _crs_text(crs: Any) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return str(crs.to_proj4())
        except Exception:  # noqa: BLE001 - only for a note; the CRS itself is valid
            return str(crs.name)


def _lonlat_from_projection(
    crs: Any, x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    import pyproj

    transformer = pyproj.Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True)
    xx, yy = np.meshgrid(x, y)
    lon, lat = transformer.transform(xx, yy)
    return np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)


def _projection_axes(
    crs: Any, x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Unit vectors (east, north components) of the projection's +X and +Y axes at every (Y, X) point.

    Central differences of a step 1e-3 of the grid spacing, mapped to the local east/north
    plane; velocity east = u*cos_x + v*cos_y, north = u*sin_x + v*sin_y (exact rotation for
    conformal projections such as polar stereographic).
    """
    import pyproj

    transformer = pyproj.Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True)
    xx, yy = np.meshgrid(x, y)
    spacing = [np.median(np.abs(np.diff(a))) for a in (x, y) if a.size > 1]
    step = 1e-3 * (min(spacing) if spacing else 1.0)

    def direction(dx: float, dy: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        lon_p, lat_p = transformer.transform(xx + dx, yy + dy)
        lon_m, lat_m = transformer.transform(xx - dx, yy - dy)
        dlon = (np.asarray(lon_p) - np.asarray(lon_m) + 180.0) % 360.0 - 180.0
        dlat = np.asarray(lat_p) - np.asarray(lat_m)
        east = dlon * np.cos(np.radians(0.5 * (np.asarray(lat_p) + np.asarray(lat_m))))
        norm = np.hypot(east, dlat)
        return east / norm, dlat / norm

    cos_x, sin_x = direction(step, 0.0)
    cos_y, sin_y = direction(0.0, step)
    return cos_x, sin_x, cos_y, sin_y


def rotate(
    u: NDArray[np.float64], v: NDArray[np.float64], angle: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Grid xi/eta components to east/north; ``angle`` is from east to the xi axis (ROMS convention)."""
    c, s = np.cos(angle), np.sin(angle)
    return u * c - v * s, u * s + v * c
