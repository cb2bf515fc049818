"""Reading forecast files: ``open_forecast`` (all of a file or a window of it), ``forecast_times``, ``ensemble_size``.

Finds the current variables and the ensemble member, checks sizes from the header, picks the
layout (``planner.forecast.layout``) and hands the file to that layout's reader; every failure
is a ``ForecastError`` naming the file and what to do.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import xarray as xr

from planner.contract.errors import ForecastError, GridError
from planner.forecast.cf import attr, check_numeric, check_packing, describe_std_names, read_time, velocity_factor
from planner.forecast.cgrid import c_grid_dims, read_c_grid
from planner.forecast.files import LIBRARY_ERRORS, file_identity, open_dataset
from planner.forecast.layout import (
    MEMBER_NAMES,
    MEMBER_STANDARD_NAMES,
    Layout,
    Velocities,
    find_velocity_variables,
    is_c_grid,
    member_dim,
)
from planner.forecast.lazy import check_axes, check_size
from planner.forecast.model import Forecast, ForecastTimes, ForecastWindow, check_time_range
from planner.forecast.projected import read_projected
from planner.forecast.regular import read_regular
from planner.forecast.request import Context, Fields, Want
from planner.forecast.structured import assign_roles, read_header

if TYPE_CHECKING:
    from planner.contract.geodesy import BBox


def open_forecast(
    path: str | os.PathLike[str],
    *,
    variables: tuple[str, str] | None = None,
    grid_file: str | os.PathLike[str] | None = None,
    bbox: BBox | None = None,
    time_index: int | None = None,
    member: int | None = None,
) -> Forecast:
    """Read a current forecast file into a ``Forecast`` (east/north m/s, NaN = land; spec section 1).

    ``variables`` names the (u, v) variables when they cannot be found by CF standard name or
    common name. ``grid_file`` supplies what a ROMS/CROCO output file lacks (lon/lat, masks,
    h, angle). Every failure raises ``ForecastError`` naming the file and what to do.

    Reading part of a file (docs/forecasts-large.md): ``time_index`` keeps one time step (the
    Forecast's ``time_s`` then has that one value), ``member`` one ensemble member (required
    when the file has a member dimension of more than one member), and ``bbox`` (a
    ``planner.grid.BBox``), on regular lon/lat grids, the lon/lat index ranges that the bbox's
    interpolation uses plus ``WINDOW_MARGIN_NODES`` nodes on each side (clipped at the file's
    edges). The velocities stay xarray's lazily indexed arrays until that selection is made, so
    only the selected part is read. ``identity`` stays the whole file's; ``window`` says what was
    kept; resampling the window onto a grid inside the bbox gives the whole file's values bit for
    bit. Curvilinear, projected and ROMS/CROCO files keep their whole horizontal grid (``bbox`` is
    not used there).
    """
    label = os.fspath(path)
    if variables is not None:
        if (
            not isinstance(variables, (tuple, list))
            or len(variables) != 2
            or not all(isinstance(n, str) and n for n in variables)
        ):
            raise ForecastError(f"{label}: variables: expected two variable names (U, V); got {variables!r}")
    want = Want.checked(label, bbox=bbox, time_index=time_index, member=member)
    ds, label, p = open_dataset(path, "forecast file")
    grid_ds: xr.Dataset | None = None
    grid_label: str | None = None
    try:
        if grid_file is not None:
            grid_ds, grid_label, _ = open_dataset(grid_file, "grid file")
        ctx = Context(ds=ds, label=label, grid_ds=grid_ds, grid_label=grid_label)
        with warnings.catch_warnings(), np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            # Damaged values (a fill value that does not fit its type, NaN cast to an integer) must
            # not print numpy warnings beside the CLI's one error line; the notes say what matters.
            warnings.simplefilter("ignore", RuntimeWarning)
            # The file's hash is taken once its header has been checked: a damaged header that
            # claims gigabytes is refused before its bytes are read.
            return _load(ctx, lambda: file_identity(p, label), variables, want)
    except ForecastError:
        raise
    except GridError as exc:
        raise ForecastError(f"{label}: {exc}") from exc
    except LIBRARY_ERRORS as exc:
        raise ForecastError(
            f"{label}: could not read the forecast ({type(exc).__name__}: {exc}); the file may be damaged or "
            "of an unsupported layout"
        ) from exc
    finally:
        ds.close()
        if grid_ds is not None:
            grid_ds.close()


def forecast_times(path: str | os.PathLike[str], *, variables: tuple[str, str] | None = None) -> ForecastTimes:
    """The time axis of a forecast file (seconds from its origin, as ``Forecast.time_s``), without reading currents.

    Reads the header and the 1-D time coordinate of the velocity variables only, so it is cheap
    for any file size: use it to turn a date into a time index before ``open_forecast(time_index=)``.
    It makes the checks that ``open_forecast`` makes before it reads the time axis, in the same
    order and with the same messages, so a broken file is refused here as it would be there.
    """
    return _scan(path, variables, times=True)


def ensemble_size(path: str | os.PathLike[str], *, variables: tuple[str, str] | None = None) -> int:
    """Number of ensemble members in a forecast file: the size of its member dimension, 1 when it has none.

    Member dimensions are recognised by name (member, realization, ensemble, number, ens, ...) or
    by the CF standard_name ``realization`` of their coordinate variable. Reads the header only;
    it refuses only what makes the count unknowable (no such file, not netCDF, two member
    dimensions), and leaves every other problem to ``open_forecast``. Without ``variables`` and
    with velocity variables it cannot find, it counts the file's one member-like dimension.
    """
    return _scan(path, variables, times=False).n_members


def _scan(path: str | os.PathLike[str], variables: tuple[str, str] | None, *, times: bool) -> ForecastTimes:
    label = os.fspath(path)
    if variables is not None and (
        not isinstance(variables, (tuple, list)) or len(variables) != 2 or not all(isinstance(n, str) and n for n in variables)
    ):
        raise ForecastError(f"{label}: variables: expected two variable names (U, V); got {variables!r}")
    ds, label, _ = open_dataset(path, "forecast file")
    try:
        with warnings.catch_warnings(), np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            if not times:
                return _count_members(ds, label, variables)
            # The checks of _load and the layouts' readers that come before the time axis is read.
            names = find_velocity_variables(ds, label, variables)
            u_name, v_name = names.u_name, names.v_name
            u_var, v_var = ds[u_name], ds[v_name]
            for name, var in ((u_name, u_var), (v_name, v_var)):
                check_packing(var, name, label)
                check_numeric(var, f"variable {name}", label)
            found = member_dim(ds, u_var, v_var, u_name, v_name, label)
            n_members = 1
            if found is not None:
                n_members = int(u_var.sizes[found])
                u_var, v_var = u_var.isel({found: 0}), v_var.isel({found: 0})
            for name, var in ((u_name, u_var), (v_name, v_var)):
                check_axes(var, name, label)
            if is_c_grid(ds, u_var, v_var):
                time_dim = c_grid_dims(ds, u_var, u_name, label).get("T")
                c_grid_dims(ds, v_var, v_name, label)
            else:
                if u_var.dims != v_var.dims or u_var.shape != v_var.shape:
                    raise ForecastError(
                        f"{label}: variables {u_name} {tuple(u_var.dims)} and {v_name} {tuple(v_var.dims)} are on "
                        "different grids; expected both on the same (time, depth, lat, lon) grid, or a ROMS/CROCO "
                        "C-grid with eta_/xi_ dims"
                    )
                time_dim = assign_roles(ds, u_var, u_name, label).get("T")
                for var, name in ((u_var, u_name), (v_var, v_name)):
                    velocity_factor(var, name, label, [])
            time_s, origin = read_time(ds, u_var, label, time_dim, [])
            check_time_range(time_s, label)
            return ForecastTimes(source=label, time_s=time_s, time_origin=origin, n_members=n_members,
                                 member_dim=found)
    except ForecastError:
        raise
    except LIBRARY_ERRORS as exc:
        raise ForecastError(
            f"{label}: could not read the forecast's header ({type(exc).__name__}: {exc}); the file may be "
            "damaged or of an unsupported layout"
        ) from exc
    finally:
        ds.close()


def _count_members(ds: xr.Dataset, label: str, variables: tuple[str, str] | None) -> ForecastTimes:
    try:
        names = find_velocity_variables(ds, label, variables)
    except ForecastError:
        if variables is not None:
            raise
        # Velocities not found by name: open_forecast will say so; count a member-like dimension.
        dims = [str(d) for d in ds.dims if str(d).lower() in MEMBER_NAMES or (
            str(d) in ds.variables and attr(ds.variables[str(d)], "standard_name").lower() in MEMBER_STANDARD_NAMES)]
        n = int(ds.sizes[dims[0]]) if len(dims) == 1 else 1
        return ForecastTimes(source=label, time_s=np.zeros(1), time_origin=None, n_members=n,
                             member_dim=dims[0] if len(dims) == 1 else None)
    u_name, v_name = names.u_name, names.v_name
    u_var, v_var = ds[u_name], ds[v_name]
    found = member_dim(ds, u_var, v_var, u_name, v_name, label)
    n = 1 if found is None else int(u_var.sizes[found])
    return ForecastTimes(source=label, time_s=np.zeros(1), time_origin=None, n_members=n, member_dim=found)


def _load(
    ctx: Context, identity: Callable[[], str], variables: tuple[str, str] | None, want: Want = Want()
) -> Forecast:
    ds, label = ctx.ds, ctx.label
    names = find_velocity_variables(ds, label, variables)
    u_name, v_name = names.u_name, names.v_name
    u_var, v_var = ds[u_name], ds[v_name]
    member_note = None
    member_info: tuple[str, int, int] | None = None  # (dimension, members, member held)
    for name, var in ((u_name, u_var), (v_name, v_var)):
        check_packing(var, name, label)
        check_numeric(var, f"variable {name}", label)
    found = member_dim(ds, u_var, v_var, u_name, v_name, label)
    if found is not None and want.member is None and int(u_var.sizes[found]) == 1:
        found = None  # one member and none asked for: read as before (a size-1 extra dimension is dropped)
    if found is not None:
        n_members = int(u_var.sizes[found])
        if want.member is None and n_members > 1:
            raise ForecastError(
                f"{label}: {u_name}/{v_name} have an ensemble member dimension {found!r} with {n_members} members; "
                f"expected one forecast: give member= (0..{n_members - 1}) to read one member, or plan the "
                "ensemble with the CLI's ensemble planning"
            )
        k = 0 if want.member is None else want.member
        if k >= n_members:
            raise ForecastError(
                f"{label}: member {k} out of range: the file has {n_members} ensemble member(s) along "
                f"dimension {found!r}; expected member= in 0..{n_members - 1}"
            )
        u_var, v_var = u_var.isel({found: k}), v_var.isel({found: k})
        ctx = replace(ctx, select={**ctx.select, found: k})
        member_info = (found, n_members, k)
        member_note = f"ensemble member {k} of {n_members} (dimension {found!r})"
    elif want.member is not None and want.member != 0:
        raise ForecastError(
            f"{label}: member {want.member} out of range: the file has no ensemble member dimension (expected one "
            f"named {', '.join(sorted(MEMBER_NAMES))} or with standard_name realization), so it is one "
            "forecast; only member=0 (or no member=) is valid"
        )
    if want.partial:
        for name, var in ((u_name, u_var), (v_name, v_var)):
            check_axes(var, name, label)
    else:
        for name, var in ((u_name, u_var), (v_name, v_var)):
            check_size(var, name, label)
    notes: list[str] = [f"variables: {u_name}, {v_name}" + describe_std_names(u_var, v_var)]
    if member_note is not None:
        notes.append(member_note)
    fields = _read_layout(ctx, u_var, v_var, names, notes, want)
    u, v = fields.u, fields.v
    finite = np.isfinite(u) & np.isfinite(v)
    part = fields.part
    if not np.any(finite) and fields.lon_index is None:
        if part:
            raise ForecastError(
                f"{label}: variables {u_name}/{v_name} hold no finite current values in the part read ({part}): "
                "all missing, fill or land; expected at least one water point there; check the bbox, time step "
                "and member, or pass --variables U,V to pick other variables"
            )
        raise ForecastError(
            f"{label}: variables {u_name}/{v_name} hold no finite current values (all missing, fill or land); "
            "expected at least one water point; check the file or pass --variables U,V to pick other variables"
        )
    if part:
        # A lon/lat window may lie wholly on land (the file has water elsewhere); planning on it then
        # says so, as it would on the whole file.
        notes.append(f"read part of the file: {part}" + ("" if np.any(finite) else " (all land)"))
    notes.append(f"land (NaN in u or v): {100.0 * (1.0 - finite.mean()):.1f} % of values")
    window = None
    if want.partial or member_info is not None:
        window = ForecastWindow(
            n_times=fields.file_n_times,
            time_index=want.time_index,
            n_members=1 if member_info is None else member_info[1],
            member=None if member_info is None else member_info[2],
            member_dim=None if member_info is None else member_info[0],
            lon_index=fields.lon_index,
            lat_index=fields.lat_index,
            file_lon_deg=fields.file_lon,
            file_lat_deg=fields.file_lat,
        )
    return Forecast(
        source=label,
        identity=identity(),
        time_s=fields.time_s,
        time_origin=fields.time_origin,
        lon_deg=fields.lon,
        lat_deg=fields.lat,
        depth_m=fields.depth,
        u_east_m_s=u,
        v_north_m_s=v,
        notes=tuple(notes),
        variables=(u_name, v_name),
        covers_surface=fields.covers_surface,
        window=window,
    )


def _read_layout(
    ctx: Context, u_var: xr.DataArray, v_var: xr.DataArray, names: Velocities, notes: list[str], want: Want
) -> Fields:
    """The velocities read by their layout's reader."""
    if is_c_grid(ctx.ds, u_var, v_var):
        return read_c_grid(ctx, u_var, v_var, names, notes, want)
    header = read_header(ctx, u_var, v_var, names, want)
    if header.layout is Layout.REGULAR:
        return read_regular(ctx, u_var, v_var, header, want, notes)
    return read_projected(ctx, u_var, v_var, header, want, notes)
