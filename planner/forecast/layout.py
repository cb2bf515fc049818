"""What a forecast file holds: which variables are the currents, what they point along, and the grid layout.

Three layouts (spec section 1), each with its reader: ``Layout.REGULAR`` (1-D lon/lat axes,
``planner.forecast.regular``), ``Layout.PROJECTED`` (projected or curvilinear structured grids
with 2-D lon/lat, ``planner.forecast.projected``) and ``Layout.C_GRID`` (ROMS/CROCO native
output, ``planner.forecast.cgrid``). Read from the header only.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import xarray as xr

from planner.contract.errors import ForecastError
from planner.forecast.cf import attr, axis_variable, dim_role, is_lat_like, is_lon_like


class Layout(Enum):
    """How the velocities sit on the file's grid."""

    REGULAR = "regular lon/lat grid"  # 1-D lon/lat coordinate variables on both horizontal dimensions
    PROJECTED = "projected or curvilinear grid"  # 2-D lon/lat, from the file or computed from X/Y
    C_GRID = "ROMS/CROCO C-grid"  # staggered u/v points, eta/xi dimensions or s-levels


class Components(Enum):
    """What the two velocity variables point along (spec section 1: rotated to east/north when read)."""

    EAST_NORTH = "east_north"  # CF eastward/northward standard names
    GRID_XY = "grid_xy"  # grid-relative x/y (xi/eta) components
    UNKNOWN = "unknown"  # named (--variables or a common name) without a standard_name that says


@dataclass(frozen=True, kw_only=True)
class Velocities:
    """The names of the file's two current variables and what they point along."""

    u_name: str
    v_name: str
    components: Components


# CF standard names of east/north components (spec section 1: velocities must be east/north).
_EAST_NORTH_STANDARD_NAMES = (
    ("eastward_sea_water_velocity", "northward_sea_water_velocity"),
    ("surface_eastward_sea_water_velocity", "surface_northward_sea_water_velocity"),
    ("eastward_sea_water_velocity_assuming_no_tide", "northward_sea_water_velocity_assuming_no_tide"),
    ("baroclinic_eastward_sea_water_velocity", "baroclinic_northward_sea_water_velocity"),
    ("barotropic_eastward_sea_water_velocity", "barotropic_northward_sea_water_velocity"),
)
# Grid-relative components (ROMS xi/eta, projection X/Y): rotated when read.
_GRID_XY_STANDARD_NAMES = (
    ("x_sea_water_velocity", "y_sea_water_velocity"),
    ("sea_water_x_velocity", "sea_water_y_velocity"),
    ("sea_water_x_velocity_at_u_location", "sea_water_y_velocity_at_v_location"),
    ("sea_water_surface_x_velocity", "sea_water_surface_y_velocity"),
    ("surface_sea_water_x_velocity", "surface_sea_water_y_velocity"),
)
# Common variable names, tried when no standard_name matches.
_COMMON_NAMES = (
    ("water_u", "water_v"),
    ("uo", "vo"),
    ("u_eastward", "v_northward"),
    ("ucur", "vcur"),
    ("u", "v"),
    ("U", "V"),
    ("u_sur", "v_sur"),
)

# Ensemble member dimensions: CF's standard_name "realization" (and its name), ECMWF/Copernicus
# "number", and the common "member"/"ensemble"/"ens" spellings.
MEMBER_NAMES = {
    "member", "members", "member_id", "ensemble_member", "realization", "realisation", "ensemble", "number", "ens",
}  # fmt: skip
MEMBER_STANDARD_NAMES = {"realization", "realisation", "ensemble_member"}


def member_dim(
    ds: xr.Dataset, u_var: xr.DataArray, v_var: xr.DataArray, u_name: str, v_name: str, label: str
) -> str | None:
    """The velocities' ensemble member dimension, or None (by name or CF standard_name realization)."""
    found = []
    for d in (str(d) for d in u_var.dims):
        by_name = d.lower() in MEMBER_NAMES
        by_std = d in ds.variables and attr(ds.variables[d], "standard_name").lower() in MEMBER_STANDARD_NAMES
        by_axis = d in ds.variables and attr(ds.variables[d], "_CoordinateAxisType").lower() == "ensemble"
        if by_name or by_std or by_axis:
            found.append(d)
    if not found:
        return None
    if len(found) > 1:
        raise ForecastError(
            f"{label}: {u_name} has several ensemble member dimensions {tuple(found)}; expected at most one"
        )
    d = found[0]
    if d not in v_var.dims or v_var.sizes[d] != u_var.sizes[d]:
        raise ForecastError(
            f"{label}: {u_name} has the ensemble member dimension {d!r} ({u_var.sizes[d]} members) but {v_name} "
            f"{tuple(str(x) for x in v_var.dims)} does not have it with the same size; expected both to have it"
        )
    return d


def find_velocity_variables(ds: xr.Dataset, label: str, variables: tuple[str, str] | None) -> Velocities:
    """The current variables: ``variables`` when given, else by CF standard name, else by common name."""
    if variables is not None:
        missing = [n for n in variables if n not in ds.data_vars]
        if missing:
            raise ForecastError(
                f"{label}: variables: {', '.join(repr(m) for m in missing)} not in the file; "
                f"expected two of its data variables, e.g. {_candidate_list(ds)}; "
                "pass --variables U,V with names from that list"
            )
        u_name, v_name = variables
        return Velocities(u_name=u_name, v_name=v_name, components=_components_of(ds[u_name], ds[v_name]))
    by_std: dict[str, str] = {}
    for name, var in ds.data_vars.items():
        std = attr(var, "standard_name").lower()
        if std and std not in by_std and var.ndim >= 2:
            by_std[std] = str(name)
    for pairs, components in (
        (_EAST_NORTH_STANDARD_NAMES, Components.EAST_NORTH),
        (_GRID_XY_STANDARD_NAMES, Components.GRID_XY),
    ):
        for su, sv in pairs:
            if su in by_std and sv in by_std:
                return Velocities(u_name=by_std[su], v_name=by_std[sv], components=components)
    for un, vn in _COMMON_NAMES:
        if un in ds.data_vars and vn in ds.data_vars and ds[un].ndim >= 2 and ds[vn].ndim >= 2:
            return Velocities(u_name=un, v_name=vn, components=_components_of(ds[un], ds[vn]))
    raise ForecastError(
        f"{label}: no ocean current variables found: expected variables with standard_name "
        "eastward_sea_water_velocity/northward_sea_water_velocity (or x_/y_sea_water_velocity with a grid "
        "angle or projection) or common names (water_u/water_v, uo/vo, u/v); the file has "
        f"{_candidate_list(ds)}; pass --variables U,V to name them"
    )


def _candidate_list(ds: xr.Dataset) -> str:
    names = [str(n) for n, var in ds.data_vars.items() if var.ndim >= 2]
    shown = ", ".join(names[:20]) + (", ..." if len(names) > 20 else "")
    return f"data variables [{shown}]" if names else "no data variables with 2 or more dimensions"


def _components_of(u_var: xr.DataArray, v_var: xr.DataArray) -> Components:
    stds = {attr(u_var, "standard_name").lower(), attr(v_var, "standard_name").lower()}
    if any(s for pair in _EAST_NORTH_STANDARD_NAMES for s in pair if s in stds):
        return Components.EAST_NORTH
    if any("_x_" in s or s.startswith("x_") or "_y_" in s or s.startswith("y_") for s in stds if s):
        return Components.GRID_XY
    return Components.UNKNOWN


def is_c_grid(ds: xr.Dataset, u_var: xr.DataArray, v_var: xr.DataArray) -> bool:
    """ROMS/CROCO native output: staggered u/v, eta/xi dimensions or s-coordinate levels."""
    if u_var.ndim < 2 or v_var.ndim < 2:
        return False
    hu, hv = tuple(u_var.dims[-2:]), tuple(v_var.dims[-2:])
    if hu != hv:
        return True
    if all(str(d).startswith(("eta_", "xi_")) for d in hu):
        return True
    return any(dim_role(ds, str(d)) == "S" for d in u_var.dims)


def structured_layout(ds: xr.Dataset, ydim: str, xdim: str) -> Layout:
    """``Layout.REGULAR`` when the horizontal dimensions have 1-D lon/lat coordinates, else ``Layout.PROJECTED``."""
    xcoord, ycoord = axis_variable(ds, xdim), axis_variable(ds, ydim)
    if xcoord is not None and ycoord is not None and is_lon_like(xdim, xcoord) and is_lat_like(ydim, ycoord):
        return Layout.REGULAR
    return Layout.PROJECTED
