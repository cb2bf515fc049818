"""A plan's values on disk: CF-1.8 netCDF (``.nc``) for the field's tools, or the spec's ``.npz`` arrays.

The file's suffix chooses the format. ``.npz`` stays because spec section 8 and the independent
checks that read it fix its arrays (``ValueArrays``); ``.nc`` carries the same arrays with named
dimensions, units and CF attributes, so ncdump, Panoply, xarray and GIS tools read it without
this project (docs/plan-values.md).
"""

from __future__ import annotations

import io
import os
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, NotRequired, TypedDict

import netCDF4
import numpy as np
from numpy.typing import NDArray

from planner import __version__
from planner.contract.actions import Action
from planner.contract.atomic import atomic_target, write_atomic
from planner.contract.errors import PlannerError
from planner.contract.headings import bearings_deg, cell_size_m
from planner.physical.solve import PhysicalSolution

if TYPE_CHECKING:
    from planner.pipeline import PlanResult

SUFFIXES = (".nc", ".npz")
# netCDF's default fill for doubles: land and unreachable states hold it in cost_to_go and time_to_go.
FILL_F8 = float(netCDF4.default_fillvals["f8"])
STEPS_FILL = -1  # spec section 8: -1 where unreachable or land
# flow_dir codes (spec section 8): the grid directions 0..7, then calm and land.
FLOW_MEANINGS = {-2: "land", -1: "calm", 0: "east", 1: "northeast", 2: "north", 3: "northwest", 4: "west",
                 5: "southwest", 6: "south", 7: "southeast"}


class ValueArrays(TypedDict):
    """The arrays of an exported ``.npz`` by name (spec section 8)."""

    cost: NDArray[np.float64]
    steps: NDArray[np.int64]
    action: NDArray[np.uint8]
    lon: NDArray[np.float64]
    lat: NDArray[np.float64]
    depth: NDArray[np.float64]
    flow_dir: NDArray[np.int8]
    time_s: NotRequired[NDArray[np.float64]]  # physical plans only


def export_values(result: PlanResult, path: str | os.PathLike[str], *, mission: str | None = None,
                  history: str | None = None) -> Path:
    """Write the plan's values to ``path`` atomically: CF netCDF for ``.nc``, the spec's arrays for ``.npz``.

    ``mission`` (its file) and ``history`` (the command line) go into the netCDF's global attributes.
    """
    if check_suffix(path) == ".npz":
        return write_npz(result, path)
    return write_cf(result, path, mission=mission, history=history)


def check_suffix(path: str | os.PathLike[str]) -> str:
    """The export format of ``path`` ('.nc' or '.npz', any case); PlannerError for another suffix."""
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise PlannerError(f"--export-values {os.fspath(path)}: expected a file ending in .nc (CF-1.8 netCDF) or "
                           f".npz (the arrays of spec section 8); got suffix {suffix or 'none'!r}")
    return suffix


def value_arrays(result: PlanResult) -> ValueArrays:
    """The arrays of spec section 8 (shape ``(L, ny, nx, 8)``; a time-varying plan's first slice)."""
    sol = result.solution
    arrays: ValueArrays = {
        "cost": np.ascontiguousarray(sol.cost),
        "steps": np.ascontiguousarray(sol.steps).astype(np.int64),
        "action": np.ascontiguousarray(sol.action).astype(np.uint8),
        "lon": result.grid.lon_deg,
        "lat": result.grid.lat_deg,
        "depth": result.grid.depth_m,
        "flow_dir": np.asarray(result.model.flow_dir, dtype=np.int8),
    }
    if isinstance(sol, PhysicalSolution):  # cost in Wh and the time to go, s (docs/physical-model.md)
        arrays["time_s"] = np.ascontiguousarray(sol.time_s)
    return arrays


def write_npz(result: PlanResult, path: str | os.PathLike[str]) -> Path:
    """The arrays of spec section 8 as a compressed ``.npz``, atomically."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **value_arrays(result))
    return write_atomic(path, buf.getvalue())


def write_cf(result: PlanResult, path: str | os.PathLike[str], *, mission: str | None = None,
             history: str | None = None) -> Path:
    """The plan's values as CF-1.8 netCDF-4, atomically: dimensions (time,) depth, lat, lon, heading."""
    arrays = value_arrays(result)
    grid, table = result.grid, result.table
    sol, horizon = result.solution, result.horizon
    with atomic_target(path) as tmp, netCDF4.Dataset(tmp, "w", format="NETCDF4") as nc:
        _global_attributes(nc, result, mission=mission, history=history)
        for name, size in (("depth", grid.n_layers), ("lat", grid.ny), ("lon", grid.nx), ("heading", 8)):
            nc.createDimension(name, size)
        _coordinate(nc, "lon", arrays["lon"], units="degrees_east", standard_name="longitude", axis="X",
                    long_name="longitude of the cell centre")
        _coordinate(nc, "lat", arrays["lat"], units="degrees_north", standard_name="latitude", axis="Y",
                    long_name="latitude of the cell centre")
        _coordinate(nc, "depth", arrays["depth"], units="m", standard_name="depth", axis="Z", positive="down",
                    long_name="depth of the planning layer")
        _coordinate(nc, "heading", np.arange(8, dtype=np.float64) * 45.0, units="degree",
                    long_name="grid direction k of the vehicle's heading sector, k * 45 degrees counter-clockwise "
                              "from east (its true bearing per row is heading_bearing)")
        dx_m, dy_m = cell_size_m(grid.lat_deg, grid.dlon_deg, grid.dlat_deg)
        bearing = nc.createVariable("heading_bearing", "f8", ("lat", "heading"))
        bearing.setncatts({"units": "degree", "standard_name": "platform_orientation",
                           "long_name": "true compass bearing of grid direction k at each row, clockwise from north"})
        bearing[:] = bearings_deg(dx_m, dy_m)
        state: tuple[str, ...] = ("depth", "lat", "lon", "heading")
        coords = "heading_bearing"
        if horizon is not None:  # a time-varying plan: a slice per forecast step
            nc.createDimension("time", horizon.n_slices)
            units = ("s" if table.forecast_time is None
                     else f"seconds since {table.forecast_time.rstrip('Z').replace('T', ' ')}")
            _coordinate(nc, "time", horizon.times_s, units=units, standard_name="time", axis="T",
                        calendar="proleptic_gregorian", long_name="forecast time of the plan's slice")
            state = ("time", *state)
            cost, action = horizon.value_wh, horizon.action
        else:
            cost, action = arrays["cost"], arrays["action"]
            if table.forecast_time is not None:  # the forecast time planned on, a CF scalar coordinate
                t = nc.createVariable("time", "f8", ())
                t.setncatts({"units": "seconds since 1970-01-01 00:00:00", "standard_name": "time", "axis": "T",
                             "calendar": "proleptic_gregorian", "long_name": "forecast time planned on"})
                t.assignValue(_unix_s(table.forecast_time))
                coords += " time"
        if isinstance(sol, PhysicalSolution):
            _values(nc, "cost_to_go", cost, state, coords, units="W h",
                    long_name=f"energy to the goal under the {result.model.settings.criterion} criterion "
                              "(physical model)")
            _values(nc, "time_to_go", sol.time_s if horizon is None else horizon.time_s, state, coords, units="s",
                    long_name="time to the goal under the same criterion and policy")
        else:
            _values(nc, "cost_to_go", cost, state, coords, units="1",
                    long_name=f"cost-to-go: sum of the action costs to the goal under the "
                              f"{result.model.settings.criterion} criterion (spec section 8)")
            steps = nc.createVariable("steps", "i4", state, zlib=True, fill_value=STEPS_FILL)
            steps.setncatts({"units": "1", "coordinates": coords, "long_name": "actions to the goal along the branch "
                                                                        "the criterion follows (robust: the worst)"})
            steps[:] = arrays["steps"].astype(np.int32)
        codes = sorted(Action)
        act = nc.createVariable("action", "u1", state, zlib=True, fill_value=False)
        act.setncatts({"long_name": "the plan's action in each state", "coordinates": coords,
                       "flag_values": np.array([a.value for a in codes], dtype=np.uint8),
                       "flag_meanings": " ".join(a.name.lower() for a in codes)})
        act[:] = action
        flow = nc.createVariable("flow_dir", "i1", ("depth", "lat", "lon"), zlib=True, fill_value=False)
        flow.setncatts({"long_name": "grid direction of the forecast current in each cell (spec section 3)",
                        "flag_values": np.array(list(FLOW_MEANINGS), dtype=np.int8),
                        "flag_meanings": " ".join(FLOW_MEANINGS.values())})
        flow[:] = arrays["flow_dir"]
        water = nc.createVariable("water", "u1", ("depth", "lat", "lon"), zlib=True, fill_value=False)
        water.setncatts({"long_name": "cell holds water in the forecast (0: land, no state)",
                         "flag_values": np.array([0, 1], dtype=np.uint8), "flag_meanings": "land water"})
        water[:] = np.asarray(result.model.water, dtype=np.uint8)
    return Path(path)


def _coordinate(nc: netCDF4.Dataset, name: str, values: NDArray[np.float64], **attrs: str) -> None:
    var = nc.createVariable(name, "f8", (name,))
    var.setncatts(attrs)
    var[:] = values


def _values(nc: netCDF4.Dataset, name: str, values: NDArray[np.float64], dims: tuple[str, ...], coords: str,
            **attrs: str) -> None:
    """A float variable of the states: land and unreachable states (inf) hold the fill value."""
    var = nc.createVariable(name, "f8", dims, zlib=True, fill_value=FILL_F8)
    var.setncatts({**attrs, "coordinates": coords})
    data = np.asarray(values, dtype=np.float64)
    var[:] = np.ma.masked_array(data, mask=~np.isfinite(data))


def _unix_s(iso_utc: str) -> float:
    return float((np.datetime64(iso_utc.rstrip("Z"), "ms") - np.datetime64(0, "ms")) / np.timedelta64(1, "s"))


def _global_attributes(nc: netCDF4.Dataset, result: PlanResult, *, mission: str | None, history: str | None) -> None:
    table, grid, settings = result.table, result.grid, result.model.settings
    now = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    goal = result.solution.goal
    attrs: dict[str, object] = {
        "Conventions": "CF-1.8",
        "title": "LRAUV feedback plan: the value and action of every state (cell, depth layer, heading)",
        "source": f"lrauv-feedback {__version__} planner, {settings.model} model, {settings.criterion} criterion",
        "history": f"{now} {history or 'planner.plan_values.write_cf'}",
        "references": "Orioke, Alam et al., Feedback Motion Planning for Long-Range Autonomous Underwater "
                      "Vehicles; the project's spec, section 8 (exported values)",
        "forecast_source": table.forecast_source,
        "forecast_identity": table.forecast_identity,
        "forecast_time": table.forecast_time or "none (the forecast has no reference date)",
        "forecast_time_index": int(result.time_index),
        "goal_lon_deg": float(goal.lon_deg), "goal_lat_deg": float(goal.lat_deg),
        "goal_depth_m": float(goal.depth_m), "goal_radius_cells": int(goal.radius_cells),
        "geospatial_lon_min": float(grid.lon_deg[0]), "geospatial_lon_max": float(grid.lon_deg[-1]),
        "geospatial_lat_min": float(grid.lat_deg[0]), "geospatial_lat_max": float(grid.lat_deg[-1]),
    }
    if mission is not None:
        attrs["mission"] = mission
    if settings.model == "paper":
        c = settings.costs
        attrs["uncertainty"] = settings.uncertainty
        attrs["action_costs"] = f"drift={c.drift:g} forward={c.forward:g} rotate={c.rotate:g} glide={c.glide:g}"
    nc.setncatts(attrs)
