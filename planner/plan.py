"""The planning pipeline in one call: forecast -> grid -> transitions -> solve -> table."""

from __future__ import annotations

import io
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from planner.errors import ForecastError, GridError
from planner.forecast import Forecast, nearest_time_index, open_forecast
from planner.resample import resample
from planner.grid import BBox, Grid
from planner.settings import Goal, PlanSettings
from planner.solve import Solution, goal_cells_on, solve
from planner.atomic import write_atomic
from planner.table import PolicyTable
from planner.transitions import TransitionModel, build_transitions
from planner.physical import PhysicalModel, build_physical, fine_grid, refine_factor
from planner.physical_solve import PhysicalSolution, solve_physical


@dataclass(frozen=True, kw_only=True)
class PlanRequest:
    """Everything a plan depends on. ``bbox``/``nx``/``ny`` None: the forecast's own grid."""

    forecast_path: Path
    goal: Goal
    depths_m: tuple[float, ...]
    settings: PlanSettings = PlanSettings()
    bbox: BBox | None = None
    nx: int | None = None
    ny: int | None = None
    time_index: int | None = None
    time_iso: str | None = None
    variables: tuple[str, str] | None = None
    grid_file: Path | None = None


@dataclass(frozen=True, eq=False, kw_only=True)
class PlanResult:
    """The products of one plan, and how long each stage took (seconds)."""

    forecast: Forecast
    time_index: int
    grid: Grid
    u_m_s: NDArray[np.float64]
    v_m_s: NDArray[np.float64]
    model: TransitionModel | PhysicalModel
    solution: Solution | PhysicalSolution
    table: PolicyTable
    timings_s: dict[str, float]


def planning_grid(forecast: Forecast, request: PlanRequest) -> Grid:
    """The request's grid, or the forecast's own regular grid when no bbox is given (spec section 1)."""
    if request.bbox is not None:
        if request.nx is None or request.ny is None:
            raise GridError("grid: a bbox needs --nx and --ny")
        return Grid.from_bbox(request.bbox, nx=request.nx, ny=request.ny, depths_m=list(request.depths_m))
    lon, lat = forecast.lon_deg, forecast.lat_deg
    if lon.ndim != 1:
        raise GridError(
            f"{forecast.source}: the forecast grid is curvilinear; give --bbox WEST,SOUTH,EAST,NORTH with --nx and --ny"
        )
    bbox = BBox(west_deg=float(lon[0]), south_deg=float(lat[0]), east_deg=float(lon[-1]), north_deg=float(lat[-1]))
    return Grid.from_bbox(
        bbox, nx=request.nx or lon.size, ny=request.ny or lat.size, depths_m=list(request.depths_m)
    )


def native_spacing_deg(forecast: Forecast) -> float | None:
    """The forecast's own lon/lat spacing (the finer), or None for a curvilinear grid."""
    lon, lat = forecast.lon_deg, forecast.lat_deg
    if lon.ndim != 1 or lon.size < 2 or lat.size < 2:
        return None
    return float(min(np.abs(np.diff(lon)).min(), np.abs(np.diff(lat)).min()))


def check_coverage(forecast: Forecast, grid: Grid) -> None:
    """Refuse a bbox that lies wholly outside the forecast's longitude/latitude range."""
    lon, lat = forecast.lon_deg, forecast.lat_deg
    b = grid.bbox
    if b.east_deg < np.nanmin(lon) or b.west_deg > np.nanmax(lon) or b.north_deg < np.nanmin(lat) or b.south_deg > np.nanmax(lat):
        raise GridError(
            f"bbox {b.west_deg:g},{b.south_deg:g},{b.east_deg:g},{b.north_deg:g} lies outside the forecast "
            f"{forecast.source}, which covers lon {np.nanmin(lon):.4f}..{np.nanmax(lon):.4f}, "
            f"lat {np.nanmin(lat):.4f}..{np.nanmax(lat):.4f}"
        )


def choose_time_index(forecast: Forecast, request: PlanRequest) -> int:
    """``--time-index`` by position, or the step nearest to ``--time``; default the first step."""
    if request.time_iso is not None:
        try:
            when = np.datetime64(request.time_iso.rstrip("Z"), "s")
        except ValueError:
            raise ForecastError(f"time: expected an ISO 8601 time like 2026-01-15T06:00:00Z; got {request.time_iso!r}") from None
        return nearest_time_index(forecast, when)
    index = 0 if request.time_index is None else request.time_index
    if not 0 <= index < forecast.time_s.size:
        raise ForecastError(
            f"{forecast.source}: time index {index} is out of range; the file has {forecast.time_s.size} "
            f"steps (0..{forecast.time_s.size - 1})"
        )
    return index


def forecast_time_iso(forecast: Forecast, index: int) -> str | None:
    """The step's time in ISO 8601 UTC, or None when the file gives no reference date."""
    if forecast.time_origin is None:
        return None
    origin = np.datetime64(forecast.time_origin.rstrip("Z"), "s")
    return str(origin + np.timedelta64(int(round(forecast.time_s[index])), "s")) + "Z"


def make_plan(request: PlanRequest, *, forecast: Forecast | None = None, progress: bool = False) -> PlanResult:
    """Run the whole pipeline. Raises a PlannerError subclass on bad input."""
    timings: dict[str, float] = {}
    t = time.perf_counter()
    if forecast is None:
        forecast = open_forecast(request.forecast_path, variables=request.variables, grid_file=request.grid_file)
    timings["load_s"] = time.perf_counter() - t
    grid = planning_grid(forecast, request)
    check_coverage(forecast, grid)
    index = choose_time_index(forecast, request)
    _note(progress, f"grid {grid.nx} x {grid.ny} x {grid.n_layers} layers x 8 headings = {grid.n_states:,} states")
    model: TransitionModel | PhysicalModel
    solution: Solution | PhysicalSolution
    if request.settings.model == "physical":
        t = time.perf_counter()
        refine = refine_factor(grid, native_spacing_deg(forecast))
        uf, vf = resample(forecast, fine_grid(grid, refine), time_index=index)
        u, v = uf[:, ::refine, ::refine], vf[:, ::refine, ::refine]
        timings["resample_s"] = time.perf_counter() - t
        t = time.perf_counter()
        water = np.isfinite(u) & np.isfinite(v)
        if not water.any():
            raise GridError(f"{forecast.source}: no water on the planning grid")
        goal_mask = goal_cells_on(grid, water, request.goal).mask
        model = build_physical(uf, vf, grid, request.settings, refine=refine, goal_mask=goal_mask)
        timings["transitions_s"] = time.perf_counter() - t
        _note(progress, f"physical model: {model.n_pairs:,} state-actions, {model.samples_per_action} samples each, "
                        f"currents {refine}x finer than the grid")
        solution = solve_physical(model, request.goal)
        timings["plan_s"] = time.perf_counter() - t
    else:
        t = time.perf_counter()
        u, v = resample(forecast, grid, time_index=index)
        timings["resample_s"] = time.perf_counter() - t
        t = time.perf_counter()
        model = build_transitions(u, v, grid, request.settings)
        solution = solve(model, request.goal, progress=progress)
        timings["plan_s"] = time.perf_counter() - t
    table = PolicyTable.from_solution(
        solution,
        forecast_source=forecast.source,
        forecast_identity=forecast.identity,
        forecast_time=forecast_time_iso(forecast, index),
    )
    return PlanResult(
        forecast=forecast, time_index=index, grid=grid, u_m_s=u, v_m_s=v, model=model,
        solution=solution, table=table, timings_s=timings,
    )


def export_values(result: PlanResult, path: str | os.PathLike[str]) -> Path:
    """Write the arrays of spec section 8 to an ``.npz``, atomically."""
    sol = result.solution
    buf = io.BytesIO()
    arrays = dict(
        cost=np.ascontiguousarray(sol.cost),
        steps=np.ascontiguousarray(sol.steps).astype(np.int64),
        action=np.ascontiguousarray(sol.action).astype(np.uint8),
        lon=result.grid.lon_deg,
        lat=result.grid.lat_deg,
        depth=result.grid.depth_m,
        flow_dir=np.asarray(result.model.flow_dir, dtype=np.int8),
    )
    if isinstance(sol, PhysicalSolution):  # cost in Wh and the time to go, s (docs/physical-model.md)
        arrays["time_s"] = np.ascontiguousarray(sol.time_s)
    np.savez_compressed(buf, **arrays)
    return write_atomic(path, buf.getvalue())


def _note(progress: bool, text: str) -> None:
    if progress:
        print(f"  {text}", file=sys.stderr, flush=True)
