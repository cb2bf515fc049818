"""Structured grids (regular lon/lat, projected X/Y, curvilinear with 2-D lon/lat): the header and the values.

``read_header`` reads everything but the velocities' values first (units, time, depth, the time
step to keep), so that the part to read is known before any value is; ``read_velocities`` then
reads the selected values. The layout's reader (``planner.forecast.regular`` or
``planner.forecast.projected``) puts them on the Forecast's axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.errors import ForecastError
from planner.forecast.cf import dim_role, read_depth_axis, read_time, velocity_factor, velocity_values
from planner.forecast.layout import Layout, Velocities, structured_layout
from planner.forecast.lazy import check_size, read_ready, time_step
from planner.forecast.request import Context, Want


def assign_roles(ds: xr.Dataset, var: xr.DataArray, name: str, label: str) -> dict[str, str]:
    """Map 'T', 'Z', 'Y', 'X' to the variable's dimensions; size-1 extras are dropped later."""
    dims = [str(d) for d in var.dims]
    if len(dims) < 2:
        raise ForecastError(f"{label}: variable {name} has dimensions {dims}; expected at least (lat, lon) or (y, x)")
    roles: dict[str, str] = {}
    for d in dims:
        r = dim_role(ds, d)
        if r == "S":
            r = "Z"
        if r is not None and r not in roles:
            roles[r] = d
    if "Y" not in roles or "X" not in roles:
        rest = [d for d in dims if d not in roles.values()]
        if "Y" in roles or "X" in roles or len(rest) < 2:
            horizontal = dims[-2:]
        else:
            horizontal = rest[-2:]
        roles["Y"], roles["X"] = horizontal
        for key in ("T", "Z"):
            if key in roles and roles[key] in horizontal:
                del roles[key]
    leftovers = [d for d in dims if d not in roles.values()]
    for d in leftovers:
        if var.sizes[d] == 1:
            continue
        if "T" not in roles:
            roles["T"] = d
        else:
            raise ForecastError(
                f"{label}: variable {name} has a dimension {d!r} of size {var.sizes[d]} that is not time, depth, "
                f"latitude or longitude; expected dimensions like (time, depth, lat, lon); got {tuple(dims)}"
            )
    return roles


def to_tzyx(var: xr.DataArray, roles: dict[str, str]) -> xr.DataArray:
    """The variable as (T, Z, Y, X): size-1 extra dimensions dropped, missing T or Z added with size 1."""
    for d in [str(d) for d in var.dims if str(d) not in roles.values()]:
        var = var.isel({d: 0})
    if "T" not in roles:
        var = var.expand_dims("__t")
    if "Z" not in roles:
        var = var.expand_dims("__z")
    order = [roles.get("T", "__t"), roles.get("Z", "__z"), roles["Y"], roles["X"]]
    return var.transpose(*order)


@dataclass(frozen=True, eq=False, kw_only=True)
class StructuredHeader:
    """A structured grid's axes as read from the header, before any velocity value."""

    velocities: Velocities
    roles: dict[str, str]  # 'T', 'Z', 'Y', 'X' -> the velocities' dimension
    layout: Layout  # REGULAR or PROJECTED
    time_s: NDArray[np.float64]  # the steps kept (one with time_index=)
    time_origin: str | None
    file_n_times: int
    depth: NDArray[np.float64] | None  # shallowest first
    reverse_depth: bool  # the file's levels run deepest first
    select: dict[str, slice]  # the time step to read, by dimension
    part: tuple[str, ...]  # what part of the file is read, for notes and messages
    notes: tuple[str, ...]  # on time and depth; they follow the velocities' own notes


def read_header(
    ctx: Context, u_var: xr.DataArray, v_var: xr.DataArray, names: Velocities, want: Want
) -> StructuredHeader:
    """Check the velocities' grid and read its time and depth axes; refusals in the order of a whole read."""
    ds, label = ctx.ds, ctx.label
    u_name, v_name = names.u_name, names.v_name
    if u_var.dims != v_var.dims or u_var.shape != v_var.shape:
        raise ForecastError(
            f"{label}: variables {u_name} {tuple(u_var.dims)} and {v_name} {tuple(v_var.dims)} are on different "
            "grids; expected both on the same (time, depth, lat, lon) grid, or a ROMS/CROCO C-grid with eta_/xi_ dims"
        )
    roles = assign_roles(ds, u_var, u_name, label)
    ydim, xdim, tdim = roles["Y"], roles["X"], roles.get("T")
    # Everything but the velocities' values is read first (units, time, depth, the lon/lat axes), so
    # that the part to read is known before any value is; the notes keep the order of a whole read
    # (velocities, time, depth, axes).
    for var, name in ((u_var, u_name), (v_var, v_name)):
        velocity_factor(var, name, label, [])  # unit errors first, as before
    later: list[str] = []
    time_s, origin = read_time(ds, u_var, label, tdim, later)
    file_n_times = int(time_s.size)
    depth = read_depth_axis(ds, u_var, label, roles.get("Z"), later)
    reverse_depth = depth is not None and depth.size > 1 and depth[0] > depth[-1]
    if reverse_depth:
        assert depth is not None
        depth = depth[::-1]
        later.append("depth levels reversed to shallowest first")
    if depth is not None and depth.size > 1 and np.any(np.diff(depth) <= 0):
        raise ForecastError(
            f"{label}: depth levels of {u_name}: expected strictly monotonic depths; got {depth.tolist()[:12]}"
        )
    t = time_step(time_s, want, label)
    select: dict[str, slice] = {}
    part: list[str] = []
    if t is not None:
        if tdim is not None:
            select[tdim] = slice(t, t + 1)
        time_s = time_s[t : t + 1]
        part.append(f"time step {t} of {file_n_times}")
    return StructuredHeader(
        velocities=names,
        roles=roles,
        layout=structured_layout(ds, ydim, xdim),
        time_s=time_s,
        time_origin=origin,
        file_n_times=file_n_times,
        depth=depth,
        reverse_depth=bool(reverse_depth),
        select=select,
        part=tuple(part),
        notes=tuple(later),
    )


def read_velocities(
    ctx: Context,
    u_var: xr.DataArray,
    v_var: xr.DataArray,
    header: StructuredHeader,
    want: Want,
    notes: list[str],
    *,
    select: dict[str, slice],
    part: str,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The selected values of u and v, ``(T, Z, Y, X)`` in m/s in the file's horizontal order, shallowest level first."""
    label = ctx.label

    def values(var: xr.DataArray, name: str) -> NDArray[np.float64]:
        if want.partial:
            var = var.isel(select)  # lazy: nothing is read until .values
            check_size(var, name, label, part=part or "the whole variable")
            var = read_ready(var)
        elif select:
            var = var.isel(select)
        return velocity_values(to_tzyx(var, header.roles), name, label, notes)

    u = values(u_var, header.velocities.u_name)
    v = values(v_var, header.velocities.v_name)
    if header.reverse_depth:
        u, v = u[:, ::-1], v[:, ::-1]
    return u, v
