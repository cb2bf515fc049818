"""ROMS and CROCO native C-grid output: staggered u/v, land masks, ``angle`` rotation, s-level depths.

u/v are averaged from u/v points to rho points, land masks applied (land u/v are not NaN in
these files), grid xi/eta components rotated to east/north by ``angle``, and s-levels converted
to per-column depths with Vtransform 1 or 2 (spec section 1). What the output file lacks
(lon/lat, masks, h, angle) may come from a grid file.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.errors import ForecastError
from planner.forecast.cf import attr, dim_role, numbers, read_depth_axis, read_time, velocity_factor, velocity_values
from planner.forecast.layout import Components, Velocities
from planner.forecast.lazy import check_size, read_ready, time_step
from planner.forecast.projected import rotate
from planner.forecast.request import Context, Fields, Want
from planner.forecast.structured import to_tzyx


def read_c_grid(
    ctx: Context,
    u_var: xr.DataArray,
    v_var: xr.DataArray,
    names: Velocities,
    notes: list[str],
    want: Want,
) -> Fields:
    """u/v averaged to rho points, masked and rotated to east/north, with per-column depths of s-levels."""
    ds, label = ctx.ds, ctx.label
    u_name, v_name = names.u_name, names.v_name
    hint = ctx.grid_hint()

    lon_found = ctx.find(("lon_rho",)) or None
    lat_found = ctx.find(("lat_rho",)) or None
    if lon_found is None or lat_found is None:
        where = "the file" if ctx.grid_ds is None else f"the file or the grid file {ctx.grid_label}"
        raise ForecastError(
            f"{label}: ROMS/CROCO C-grid variables {u_name}/{v_name} but no lon_rho/lat_rho (rho-point longitude/"
            f"latitude) in {where}{hint}"
        )
    lon = numbers(lon_found[1], "lon_rho", lon_found[2])
    lat = numbers(lat_found[1], "lat_rho", lat_found[2])
    if lon.ndim != 2 or lon.shape != lat.shape:
        raise ForecastError(
            f"{label}: lon_rho/lat_rho: expected two 2-D arrays of equal shape; got {lon.shape}, {lat.shape}"
        )
    ny, nx = lon.shape
    rho_ydim, rho_xdim = (str(d) for d in lon_found[1].dims)
    for nm, arr in (("lon_rho", lon), ("lat_rho", lat)):
        finite = arr[np.isfinite(arr)]
        if finite.size == 0 or np.ptp(finite) == 0.0:
            raise ForecastError(
                f"{label}: {nm} in {lon_found[2]} is constant or missing (broken packing?); "
                f"expected varying degrees{hint}"
            )
    notes.append(f"ROMS/CROCO C-grid: rho grid {ny} x {nx} ({rho_ydim}, {rho_xdim}), lon/lat from {lon_found[2]}")

    u_roles = c_grid_dims(ds, u_var, u_name, label)
    v_roles = c_grid_dims(ds, v_var, v_name, label)
    if u_roles.get("S") != v_roles.get("S") or u_roles.get("T") != v_roles.get("T"):
        raise ForecastError(
            f"{label}: {u_name} {tuple(u_var.dims)} and {v_name} {tuple(v_var.dims)} have different time/level "
            "dimensions; expected the same"
        )
    # One time step (time_index=): the time axis is read first and the step selected before any value.
    early: tuple[NDArray[np.float64], str | None] | None = None
    time_notes: list[str] = []
    t = None
    part = ""
    if want.partial:
        for var, name in ((u_var, u_name), (v_var, v_name)):
            velocity_factor(var, name, label, [])  # unit errors first, as before
        early = read_time(ds, u_var, label, u_roles.get("T"), time_notes)
        t = time_step(early[0], want, label)
        if t is not None:
            part = f"time step {t} of {early[0].size}"
            if "T" in u_roles:
                step = {u_roles["T"]: slice(t, t + 1)}
                u_var, v_var = u_var.isel(step), v_var.isel(step)
                ctx = replace(ctx, select={**ctx.select, **step})
        for var, name in ((u_var, u_name), (v_var, v_name)):
            check_size(var, name, label, part=part or "the whole variable")
        u_var, v_var = read_ready(u_var), read_ready(v_var)
    u = velocity_values(_to_c_tsyx(u_var, u_roles), u_name, label, notes)
    v = velocity_values(_to_c_tsyx(v_var, v_roles), v_name, label, notes)
    (nyu, nxu), (nyv, nxv) = u.shape[-2:], v.shape[-2:]
    u_xdim, v_ydim = u_roles["X"], v_roles["Y"]
    if nyu != ny or nxu not in (nx - 1, nx):
        raise ForecastError(
            f"{label}: {u_name} horizontal shape ({nyu}, {nxu}) does not fit the rho grid ({ny}, {nx}); expected "
            f"({ny}, {nx - 1}) for u points or ({ny}, {nx}){hint}"
        )
    if nxv != nx or nyv not in (ny - 1, ny):
        raise ForecastError(
            f"{label}: {v_name} horizontal shape ({nyv}, {nxv}) does not fit the rho grid ({ny}, {nx}); expected "
            f"({ny - 1}, {nx}) for v points or ({ny}, {nx}){hint}"
        )
    u_stag = nxu == nx - 1 or u_xdim != rho_xdim
    v_stag = nyv == ny - 1 or v_ydim != rho_ydim
    if (u_stag and nxu == nx) or (v_stag and nyv == ny):
        notes.append(
            "u/v point dimensions have the rho sizes (subsetting artifact): u[i] taken between rho i and i+1, "
            "v[j] between rho j and j+1"
        )

    # Land masks (1 = water): land u/v are not NaN in these files (spec section 1 'land').
    mask_rho_f = ctx.find(("mask_rho",), (ny, nx))
    mask_rho = None if mask_rho_f is None else _mask01(mask_rho_f[1])
    mask_rho_from = "" if mask_rho_f is None else mask_rho_f[2]  # the file it was found in
    mask_u = _c_grid_mask(ctx, "mask_u", (nyu, nxu), mask_rho, "x", notes)
    mask_v = _c_grid_mask(ctx, "mask_v", (nyv, nxv), mask_rho, "y", notes)
    if mask_u is not None:
        u = np.where(mask_u, u, np.nan)
    if mask_v is not None:
        v = np.where(mask_v, v, np.nan)
    if u_stag or v_stag:
        u = _to_rho(u, nx, axis=-1) if u_stag else u
        v = _to_rho(v, ny, axis=-2) if v_stag else v
        notes.append(
            "u/v averaged from u/v points to rho points (a NaN neighbour makes the point land); rho points on the "
            "domain edge without two neighbours are land"
        )
    if mask_rho is not None:
        u = np.where(mask_rho, u, np.nan)
        v = np.where(mask_rho, v, np.nan)
        notes.append(f"mask_rho applied from {mask_rho_from}")
    if mask_rho is None and mask_u is None and mask_v is None:
        notes.append("no mask_rho/mask_u/mask_v found: land is only where the file's values are missing")

    if names.components is not Components.EAST_NORTH:
        angle_f = ctx.find(("angle",), (ny, nx))
        if angle_f is None:
            raise ForecastError(
                f"{label}: {u_name}/{v_name} are grid-relative (xi/eta) components but no 'angle' at rho points "
                f"({ny}, {nx}) was found to rotate them to east/north{hint}"
            )
        angle = np.asarray(angle_f[1].values, dtype=np.float64)
        if not np.all(np.isfinite(angle)):
            angle = np.where(np.isfinite(angle), angle, np.nan)
        u, v = rotate(u, v, angle)
        notes.append(
            f"rotated xi/eta components to east/north by 'angle' from {angle_f[2]} "
            f"({np.nanmin(angle):.4g}..{np.nanmax(angle):.4g} rad)"
        )

    if early is None:
        time_s, origin = read_time(ds, u_var, label, u_roles.get("T"), notes)
    else:
        time_s, origin = early
        notes.extend(time_notes)
    file_n_times = int(time_s.size)
    if t is not None:
        time_s = time_s[t : t + 1]
    depth = None
    covers_surface = True
    if "S" in u_roles and dim_role(ds, u_roles["S"]) != "S":
        # Fixed z-levels on a ROMS grid (e.g. rho-point output interpolated to depths).
        depth = read_depth_axis(ds, u_var, label, u_roles["S"], notes)
        if depth is not None and depth.size > 1 and depth[0] > depth[-1]:
            depth, u, v = depth[::-1], u[:, ::-1], v[:, ::-1]
        if depth is not None and depth.size > 1 and np.any(np.diff(depth) <= 0):
            raise ForecastError(f"{label}: depth levels of {u_name}: expected strictly monotonic depths")
    elif "S" in u_roles:
        depth, covers_surface = _s_level_depths(ctx, u_roles["S"], (ny, nx), time_s.size, u_roles.get("T"), notes)
        # Shallowest level first (spec section 1 orders layers by depth).
        depth, u, v = depth[:, ::-1], u[:, ::-1], v[:, ::-1]
    else:
        notes.append("no vertical axis on the velocities (surface field): the field applies to every layer")
    return Fields(
        u=np.ascontiguousarray(u),
        v=np.ascontiguousarray(v),
        lon=lon,
        lat=lat,
        depth=None if depth is None else np.ascontiguousarray(depth),
        time_s=time_s,
        time_origin=origin,
        covers_surface=covers_surface,
        file_n_times=file_n_times,
        part=part,
    )


def c_grid_dims(ds: xr.Dataset, var: xr.DataArray, name: str, label: str) -> dict[str, str]:
    """Map 'T', 'S' (s-levels), 'Y', 'X' to a C-grid velocity's dimensions."""
    dims = [str(d) for d in var.dims]
    if len(dims) < 2 or len(dims) > 4:
        raise ForecastError(
            f"{label}: {name} has dimensions {tuple(dims)}; expected (time, s_rho, eta, xi) or (time, eta, xi)"
        )
    roles = {"Y": dims[-2], "X": dims[-1]}
    for d in dims[:-2]:
        r = dim_role(ds, d)
        if r in ("S", "Z") and "S" not in roles:
            roles["S"] = d
        elif r == "T" and "T" not in roles:
            roles["T"] = d
        elif var.sizes[d] != 1:
            if "T" not in roles and d == dims[0]:
                roles["T"] = d
            else:
                raise ForecastError(
                    f"{label}: {name}: dimension {d!r} is neither time nor an s-level axis; expected "
                    f"(time, s_rho, eta, xi); got {tuple(dims)}"
                )
    return roles


def _to_c_tsyx(var: xr.DataArray, roles: dict[str, str]) -> xr.DataArray:
    mapped = {"T": roles.get("T"), "Z": roles.get("S"), "Y": roles["Y"], "X": roles["X"]}
    return to_tzyx(var, {k: d for k, d in mapped.items() if d is not None})


def _mask01(var: xr.DataArray) -> NDArray[np.bool_]:
    """Water where the (possibly packed, 0.99998) mask is above one half; NaN masks are land."""
    values = np.asarray(var.values, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return values > 0.5


def _c_grid_mask(
    ctx: Context,
    name: str,
    shape: tuple[int, int],
    mask_rho: NDArray[np.bool_] | None,
    axis: str,
    notes: list[str],
) -> NDArray[np.bool_] | None:
    found = ctx.find((name,), shape)
    if found is not None:
        notes.append(f"{name} applied from {found[2]}")
        return _mask01(found[1])
    if mask_rho is None:
        return None
    ny, nx = mask_rho.shape
    if axis == "x":
        right = np.minimum(np.arange(shape[1]) + 1, nx - 1)
        mask = mask_rho[:, : shape[1]] & mask_rho[:, right]
    else:
        up = np.minimum(np.arange(shape[0]) + 1, ny - 1)
        mask = mask_rho[: shape[0], :] & mask_rho[up, :]
    notes.append(f"{name} not in the file: derived from mask_rho (water where both rho neighbours are water)")
    return mask


def _to_rho(a: NDArray[np.float64], n_rho: int, *, axis: int) -> NDArray[np.float64]:
    """Average staggered values to rho points: value k sits between rho k and k+1 (C-grid)."""
    a = np.moveaxis(a, axis, -1)
    out = np.full(a.shape[:-1] + (n_rho,), np.nan)
    m = min(a.shape[-1] - 1, n_rho - 1)
    out[..., 1 : 1 + m] = 0.5 * (a[..., :m] + a[..., 1 : m + 1])
    return np.moveaxis(out, -1, axis)


def _s_level_depths(
    ctx: Context,
    s_dim: str,
    rho_shape: tuple[int, int],
    n_times: int,
    time_dim: str | None,
    notes: list[str],
) -> tuple[NDArray[np.float64], bool]:
    """Depth (positive down) of every s-level, (T, N, Y, X) in file order (bottom first), and covers_surface."""
    ds, label = ctx.ds, ctx.label
    hint = ctx.grid_hint()
    n = int(ds.sizes[s_dim])
    s_name = s_dim if s_dim in ds.variables else None
    if s_name is None:
        raise ForecastError(f"{label}: s-level dimension {s_dim!r} has no coordinate variable with s values")
    s_var = ds[s_name]
    s = np.asarray(s_var.values, dtype=np.float64)
    cs_found = ctx.find(("Cs_r", "Cs_rho"), (n,))
    hc_found = ctx.find(("hc",))
    h_found = ctx.find(("h",), rho_shape)
    missing = [nm for nm, f in (("Cs_r (or Cs_rho)", cs_found), ("hc", hc_found), ("h", h_found)) if f is None]
    if missing:
        raise ForecastError(
            f"{label}: s-level velocities need {', '.join(missing)} to compute depths; not found in the file"
            f"{' or the grid file' if ctx.grid_ds is not None else ''}{hint}"
        )
    assert cs_found is not None and hc_found is not None and h_found is not None
    cs = np.asarray(cs_found[1].values, dtype=np.float64)
    hc = float(np.asarray(hc_found[1].values, dtype=np.float64).ravel()[0])
    h = np.asarray(h_found[1].values, dtype=np.float64)
    vt_found = ctx.find(("Vtransform",))
    if vt_found is not None:
        vtransform = int(round(float(np.asarray(vt_found[1].values).ravel()[0])))
    elif str(s_var.attrs.get("Vtransform", "")).strip():
        vtransform = int(str(s_var.attrs["Vtransform"]).strip())
    elif attr(s_var, "standard_name").endswith("g2"):
        vtransform = 2
    elif attr(s_var, "standard_name").endswith("g1"):
        vtransform = 1
    else:
        raise ForecastError(
            f"{label}: s-level depths need Vtransform (1 or 2); no 'Vtransform' variable or attribute and no "
            "standard_name ocean_s_coordinate_g1/g2 on the s variable"
        )
    if vtransform not in (1, 2):
        raise ForecastError(f"{label}: Vtransform = {vtransform} not supported; expected 1 or 2")
    zeta_found = ctx.find(("zeta",))
    if zeta_found is not None and zeta_found[1].shape[-2:] == rho_shape:
        zvar = zeta_found[1]
        if time_dim is not None and time_dim in zvar.dims:
            zvar = zvar.transpose(time_dim, *[d for d in zvar.dims if d != time_dim])
            zeta = np.asarray(zvar.values, dtype=np.float64).reshape(n_times, *rho_shape)
        else:
            zeta = np.broadcast_to(np.asarray(zvar.values, dtype=np.float64).reshape(rho_shape), (n_times, *rho_shape))
        zeta = np.where(np.isfinite(zeta), zeta, 0.0)  # land fill: the velocities there are NaN anyway
    else:
        zeta = np.zeros((n_times, *rho_shape))
        notes.append("no zeta in the file: free surface taken as 0 for s-level depths")
    s4 = s[None, :, None, None]
    c4 = cs[None, :, None, None]
    h4 = h[None, None, :, :]
    z4 = zeta[:, None, :, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        if vtransform == 2:
            z0 = (hc * s4 + h4 * c4) / (hc + h4)
            z = z4 + (z4 + h4) * z0
        else:
            z0 = hc * s4 + (h4 - hc) * c4
            z = z0 + z4 * (1.0 + z0 / h4)
    depth = -z
    notes.append(
        f"{n} s-levels ({s_name}) converted to depths per column with Vtransform={vtransform}, hc={hc:g}, "
        f"{cs_found[0]}, h from {h_found[2]}, zeta"
    )
    covers_surface = True
    if "s_w" in ds.variables:
        s_w = np.sort(np.asarray(ds["s_w"].values, dtype=np.float64))
        if s_w.size > n + 1 and s_w.size >= 2 and np.max(s) < s_w[-2]:
            covers_surface = False
            notes.append(
                f"only {n} of {s_w.size - 1} s-levels kept and the top kept level (s = {np.max(s):.4g}) is not the "
                "model's top level: depths above it at each column are not covered and count as land (interpretation "
                "of spec section 1's 'shallower than the first level' rule, which is meant for z-level products)"
            )
    return depth, covers_surface
