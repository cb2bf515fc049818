"""The planning pipeline in one call: forecast -> grid -> transitions -> solve -> table."""

from __future__ import annotations

import hashlib
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.cluster import InProcess, Runner, open_runner
from planner.contract.errors import CoverageError, ForecastError, GoalError, GridError, PlannerError
from planner.forecast import (
    Forecast,
    ForecastTimes,
    ensemble_size,
    file_identity,
    forecast_times,
    is_periodic_lon,
    lon_shifts,
    nearest_time_index,
    open_forecast,
)
from planner.forecast.ensemble import ensemble_mean
from planner.forecast.error import ErrorEstimate, measure_error
from planner.forecast.resample import axis_snap_tol, resample
from planner.grid import Grid, vehicle_longitudes
from planner.contract.columns import fit
from planner.contract.geodesy import BBox
from planner.compile_note import COMPILING, needs_compile
from planner.contract.progress import SILENT, Progress
from planner.contract.settings import Goal, PlanSettings
from planner.paper.solve import ENTRY_KERNEL as SEARCH_KERNEL
from planner.paper.solve import Solution, goal_cells_on, solve
from planner.contract.headings import N_HEADINGS
from planner.contract.table import MAX_STATES, PolicyTable
from planner.paper.transitions import TransitionModel, build_transitions
from planner.physical.model import (
    PhysicalModel,
    SampleStats,
    assemble,
    combine,
    enter_goal,
    fine_grid,
    refine_factor,
    sample_transitions,
)
from planner.physical.horizon import HorizonSolution, solve_horizon
from planner.physical.sampling import ENTRY_KERNEL as SAMPLING_KERNEL
from planner.physical.solve import PhysicalSolution, solve_physical

if TYPE_CHECKING:
    from planner.contract.mission import Mission


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
    grid_file: Path | str | None = None  # a path, or an http(s) URL
    ensemble: tuple[Path, ...] = ()  # further forecast files: members of an ensemble (physical model)
    members: tuple[MemberRef, ...] | None = None  # explicit members, instead of every member of the files
    previous_forecast: Path | None = None  # an earlier issue: measures the forecast error (planner.forecast.error)

    @classmethod
    def for_mission(cls, mission: Mission, forecast_path: Path, *, goal_index: int = 0) -> PlanRequest:
        """One goal of a mission: its region, settings, forecast step and variables (no flag overrides)."""
        m = mission
        return cls(forecast_path=forecast_path, goal=m.goals[goal_index].goal, depths_m=m.region.depths_m,
                   settings=m.settings, bbox=m.region.bbox, nx=m.region.nx, ny=m.region.ny,
                   time_index=m.forecast.time_index, time_iso=m.forecast.time_iso,
                   variables=m.forecast.variables, grid_file=m.forecast.grid_file)


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
    horizon: HorizonSolution | None = None  # a time-varying plan's slices; ``solution`` is its first
    error: ErrorEstimate | None = None  # the measured forecast error the physical model sampled with


class SampleCache:
    """The goal-free samples of the last forecast planned (planner.physical.sampling): a second goal on
    the same forecast step, grid and settings reuses them and samples only the cells near its goal.

    One entry: a mission's goals, or a batch worker's, are planned one forecast at a time.
    """

    def __init__(self) -> None:
        self._key: tuple | None = None
        self._stats: SampleStats | None = None
        self.hits = 0  # plans that reused the samples

    def get(self, key: tuple) -> SampleStats | None:
        if key != self._key:
            return None
        self.hits += 1
        return self._stats

    def put(self, key: tuple, stats: SampleStats) -> None:
        self._key, self._stats = key, stats


def planning_grid(forecast: Forecast, request: PlanRequest) -> Grid:
    """The request's grid, or the forecast's own regular grid when no bbox is given (spec section 1).

    Either way in the vehicle's longitudes (``vehicle_longitudes``): a table is looked up with
    the positions MAVLink reports, -180..180.
    """
    if request.bbox is not None:
        if request.nx is None or request.ny is None:
            raise GridError("grid: a bbox needs --nx and --ny")
        _check_states(request.nx, request.ny, len(request.depths_m))
        return Grid.from_bbox(vehicle_longitudes(request.bbox), nx=request.nx, ny=request.ny,
                              depths_m=list(request.depths_m))
    lon, lat = forecast.lon_deg, forecast.lat_deg
    if lon.ndim != 1:
        raise GridError(
            f"{forecast.source}: the forecast grid is curvilinear; give --bbox WEST,SOUTH,EAST,NORTH with --nx and --ny"
        )
    bbox = vehicle_longitudes(
        BBox(west_deg=float(lon[0]), south_deg=float(lat[0]), east_deg=float(lon[-1]), north_deg=float(lat[-1])))
    nx = lon.size if request.nx is None else request.nx
    ny = lat.size if request.ny is None else request.ny
    _check_states(nx, ny, len(request.depths_m))
    return Grid.from_bbox(bbox, nx=nx, ny=ny, depths_m=list(request.depths_m))


def _check_states(nx: int, ny: int, n_layers: int) -> None:
    """Refuse a planning grid the table cannot hold, before the currents are resampled onto it."""
    n_states = n_layers * ny * nx * N_HEADINGS
    if nx >= 2 and ny >= 2 and n_states >= MAX_STATES:
        raise GridError(f"grid: {n_layers} layers x {ny} x {nx} cells x {N_HEADINGS} headings = {n_states:,} states; "
                        f"a plan holds at most {MAX_STATES - 1:,}")


def native_spacing_deg(forecast: Forecast) -> float | None:
    """The forecast's own lon/lat spacing (the finer), or None for a curvilinear grid."""
    lon, lat = forecast.file_lon_lat  # the whole file's axes, also for a window (open_forecast(bbox=))
    if lon.ndim != 1 or lon.size < 2 or lat.size < 2:
        return None
    return float(min(np.abs(np.diff(lon)).min(), np.abs(np.diff(lat)).min()))


def check_coverage(forecast: Forecast, grid: Grid, goal: Goal | None = None) -> None:
    """Refuse a bbox that lies wholly outside the forecast's longitude/latitude range, or a goal outside it
    (it would read as land: no current there).

    Longitudes compare modulo 360 deg, as resampling reads them (``planner.forecast.resample``): a
    box in -180..180 covers a file on 0..360 (HYCOM's regional files) where it does after a whole turn.
    """
    lon, lat = forecast.lon_deg, forecast.lat_deg
    if goal is not None:
        # The goal's cell centre, not the point: a goal up to half a cell beyond the outermost centres plans
        # (spec section 6); one further out is refused later, with its own hint.
        i, j, outside = grid.nearest_cell(goal.lon_deg, goal.lat_deg)
        if outside <= 0.5 and not _covered(forecast, grid.lon_deg[i:i + 1], grid.lat_deg[j:j + 1])[0]:
            raise GoalError(f"goal ({goal.lon_deg:g}, {goal.lat_deg:g}) lies outside the forecast {forecast.source}, "
                            f"which covers lon {np.nanmin(lon):.4f}..{np.nanmax(lon):.4f}, lat {np.nanmin(lat):.4f}.."
                            f"{np.nanmax(lat):.4f}")
    b = grid.bbox
    lon_lo, lon_hi = float(np.nanmin(lon)), float(np.nanmax(lon))
    if (not lon_shifts(b.west_deg, b.east_deg, lon_lo, lon_hi)
            or b.north_deg < np.nanmin(lat) or b.south_deg > np.nanmax(lat)):
        raise CoverageError(
            f"bbox {b.west_deg:g},{b.south_deg:g},{b.east_deg:g},{b.north_deg:g} lies outside the forecast "
            f"{forecast.source}, which covers lon {np.nanmin(lon):.4f}..{np.nanmax(lon):.4f}, "
            f"lat {np.nanmin(lat):.4f}..{np.nanmax(lat):.4f}"
        )


# A curvilinear grid's range is of its 2-D coordinates: a few float32 units of a longitude near 180 deg.
_CURVILINEAR_TOL_DEG = 1e-4


def coverage_fraction(forecast: Forecast, grid: Grid) -> float:
    """The fraction of the grid's cells whose centres lie within the forecast's longitude/latitude range:
    the others have no current and are land to the plan."""
    lon_ok = _covered(forecast, grid.lon_deg, np.full(grid.nx, float(np.nanmin(forecast.lat_deg))))
    lat_ok = _covered(forecast, np.full(grid.ny, float(np.nanmin(forecast.lon_deg))), grid.lat_deg)
    return float(lon_ok.mean() * lat_ok.mean())


def _covered(forecast: Forecast, lon_deg: NDArray[np.float64], lat_deg: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Points within the forecast's longitude (modulo 360 deg; all of them on a periodic axis) and latitude ranges,
    to the resampler's tolerance: an axis stored in float32 ends a few of its units off the decimal value."""
    lon, lat = forecast.lon_deg, forecast.lat_deg
    lon_tol_deg = axis_snap_tol(lon) if lon.ndim == 1 else _CURVILINEAR_TOL_DEG
    lat_tol_deg = axis_snap_tol(lat) if lat.ndim == 1 else _CURVILINEAR_TOL_DEG
    lo, hi = float(np.nanmin(lon)), float(np.nanmax(lon))
    lon_ok = np.ones(lon_deg.shape, dtype=bool) if lon.ndim == 1 and is_periodic_lon(lon) else \
        np.mod(lon_deg - lo + lon_tol_deg, 360.0) <= hi - lo + 2 * lon_tol_deg
    return lon_ok & (lat_deg >= np.nanmin(lat) - lat_tol_deg) & (lat_deg <= np.nanmax(lat) + lat_tol_deg)


def choose_time_index(forecast: Forecast | ForecastTimes, request: PlanRequest) -> int:
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


@dataclass(frozen=True, kw_only=True)
class MemberRef:
    """One forecast member: a file, and the index along its member dimension (None: the file has none)."""

    path: Path
    member: int | None = None

    @property
    def label(self) -> str:
        return f"{self.path}" if self.member is None else f"{self.path}[member {self.member}]"


@dataclass(frozen=True, eq=False, kw_only=True)
class MemberTask:
    """What a worker needs to sample one member (docs/scale-out.md): small, picklable, no arrays of currents."""

    ref: MemberRef
    time_index: int
    grid: Grid
    refine: int
    settings: PlanSettings
    goal_mask: NDArray[np.bool_]
    variables: tuple[str, str] | None = None
    grid_file: Path | str | None = None  # a path, or an http(s) URL


def members_of(request: PlanRequest) -> list[MemberRef]:
    """The request's forecast members: every file, and every member of a file with a member dimension."""
    if request.members is not None:
        return list(request.members)
    refs: list[MemberRef] = []
    for path in (request.forecast_path, *request.ensemble):
        n = ensemble_size(path, variables=request.variables)
        refs.extend([MemberRef(path=Path(path))] if n == 1 else [MemberRef(path=Path(path), member=k) for k in range(n)])
    return refs


def sample_member(task: MemberTask) -> SampleStats:
    """One task: open one member (only the step and the region needed), resample it, sample its transitions."""
    fine = fine_grid(task.grid, task.refine)
    forecast = open_forecast(task.ref.path, variables=task.variables, grid_file=task.grid_file, member=task.ref.member,
                             bbox=fine.bbox, time_index=task.time_index)
    uf, vf = resample(forecast, fine, time_index=forecast.step_index(task.time_index))
    return sample_transitions(uf, vf, task.grid, task.settings, refine=task.refine, goal_mask=task.goal_mask)


def open_step(request: PlanRequest, ref: MemberRef) -> tuple[Forecast, int]:
    """A member's forecast opened at the request's step only, and that step's index in the file.

    The time axis alone first (cheap for any file size), then only that step, the member and,
    with a bbox, the region around it (docs/forecasts-large.md).
    """
    index = choose_time_index(forecast_times(ref.path, variables=request.variables), request)
    forecast = open_forecast(ref.path, variables=request.variables, grid_file=request.grid_file,
                             member=ref.member, bbox=request.bbox, time_index=index)
    return forecast, index


def member_tasks(request: PlanRequest, *, first: Forecast | None = None) -> list[MemberTask]:
    """The sampling tasks of a physical plan over the request's members (the first member sets grid and step)."""
    refs = members_of(request)
    if first is None:
        first, index = open_step(request, refs[0])
    elif first.window is not None and first.window.time_index is not None:
        index = first.window.time_index  # a one-step window (open_forecast(time_index=)): its step
    else:
        index = choose_time_index(first, request)
    grid = planning_grid(first, request)
    check_coverage(first, grid, request.goal)
    refine = refine_factor(grid, native_spacing_deg(first))
    u, v = resample(first, grid, time_index=first.step_index(index))
    goal_mask = _goal_mask(grid, u, v, request.goal, first.source)
    return [MemberTask(ref=r, time_index=index, grid=grid, refine=refine, settings=request.settings, goal_mask=goal_mask,
                       variables=request.variables, grid_file=request.grid_file) for r in refs]


def _goal_mask(grid: Grid, u: NDArray[np.float64], v: NDArray[np.float64], goal: Goal, source: str) -> NDArray[np.bool_]:
    """The goal cells on the planning grid's water (the physical model ends samples on entering them)."""
    water = np.isfinite(u) & np.isfinite(v)
    if not water.any():
        raise GridError(f"{source}: no water on the planning grid")
    return goal_cells_on(grid, water, goal).mask


def make_plan(request: PlanRequest, *, forecast: Forecast | None = None, progress: bool = False,
              runner: Runner | None = None, samples: SampleCache | None = None, meter: Progress = SILENT) -> PlanResult:
    """Run the whole pipeline. Raises a PlannerError subclass on bad input.

    Several forecast members (``request.ensemble``, a member dimension, ``request.members``)
    are outcomes of the physical model: each member is sampled as a task of ``runner``
    (default: here), and their samples together make the transitions (docs/scale-out.md).
    ``samples`` keeps one forecast's goal-free samples for the next goal planned on it.
    ``meter`` hears sampling and solving (``planner.contract.progress``) and a first run's compile.
    """
    timings: dict[str, float] = {}
    t = time.perf_counter()
    if request.goal.lon_deg > 180.0:  # given on 0..360: the grid is on -180..180 (planning_grid)
        request = replace(request, goal=replace(request.goal, lon_deg=request.goal.lon_deg - 360.0))
    refs = members_of(request) if forecast is None else [MemberRef(path=Path(request.forecast_path))]
    if len(refs) > 1 and request.settings.time_varying:
        members = [open_forecast(r.path, variables=request.variables, grid_file=request.grid_file, member=r.member,
                                 bbox=request.bbox) for r in refs]
        mean = ensemble_mean(members)
        _note(progress, f"time-varying plan on the mean of {len(refs)} forecast members")
        return _plan_horizon(request, mean, choose_time_index(mean, request), timings, t, progress, meter,
                             members=members)
    if len(refs) > 1:
        return _plan_ensemble(request, refs, runner=runner or InProcess(), progress=progress, meter=meter)
    steps_needed = request.settings.time_varying or (request.settings.error_measured and request.settings.model == "physical")
    if forecast is None and steps_needed:  # every step: the slices, or the change to measure
        forecast = open_forecast(refs[0].path, variables=request.variables, grid_file=request.grid_file,
                                 member=refs[0].member, bbox=request.bbox)
    if request.settings.time_varying:
        assert forecast is not None
        return _plan_horizon(request, forecast, choose_time_index(forecast, request), timings, t, progress, meter)
    if forecast is None:
        forecast, index = open_step(request, refs[0])
    else:
        index = choose_time_index(forecast, request)
    step = forecast.step_index(index)  # index into forecast.time_s: 0 for a one-step window
    timings["load_s"] = time.perf_counter() - t
    grid = planning_grid(forecast, request)
    check_coverage(forecast, grid, request.goal)
    _note(progress, f"grid {grid.nx} x {grid.ny} x {grid.n_layers} layers x 8 headings = {grid.n_states:,} states")
    model: TransitionModel | PhysicalModel
    solution: Solution | PhysicalSolution
    error = None
    if request.settings.model == "physical":
        request, error = _with_error(request, forecast, grid, index, progress)
        t = time.perf_counter()
        refine = refine_factor(grid, native_spacing_deg(forecast))
        uf, vf = resample(forecast, fine_grid(grid, refine), time_index=step)
        u, v = uf[:, ::refine, ::refine], vf[:, ::refine, ::refine]
        timings["resample_s"] = time.perf_counter() - t
        t = time.perf_counter()
        goal_mask = _goal_mask(grid, u, v, request.goal, forecast.source)
        box = grid.bbox
        key = (forecast.identity, index, (box.west_deg, box.south_deg, box.east_deg, box.north_deg), grid.nx, grid.ny,
               tuple(grid.depth_m), refine, refs[0].member, request.variables, request.grid_file,
               request.settings.physical, request.settings.vehicle)
        stats = samples.get(key) if samples is not None else None
        if stats is None:
            _announce_compile(meter, SAMPLING_KERNEL)
            stats = sample_transitions(uf, vf, grid, request.settings, refine=refine, meter=meter)
            if samples is not None:
                samples.put(key, stats)
        timings["sampling_s"] = time.perf_counter() - t
        stats = enter_goal(stats, uf, vf, grid, request.settings, refine=refine, goal_mask=goal_mask)
        model = assemble(stats, grid, request.settings, refine=refine)
        timings["transitions_s"] = time.perf_counter() - t
        _note(progress, f"physical model: {model.n_pairs:,} state-actions, {model.samples_per_action} samples each, "
                        f"currents {refine}x finer than the grid")
        solution = solve_physical(model, request.goal, meter=meter)
        timings["plan_s"] = time.perf_counter() - t
    else:
        t = time.perf_counter()
        u, v = resample(forecast, grid, time_index=step)
        timings["resample_s"] = time.perf_counter() - t
        t = time.perf_counter()
        model = build_transitions(u, v, grid, request.settings)
        _announce_compile(meter, SEARCH_KERNEL)
        solution = solve(model, request.goal, progress=progress, meter=meter)
        timings["plan_s"] = time.perf_counter() - t
    table = PolicyTable.from_solution(
        solution,
        forecast_source=forecast.source,
        forecast_identity=forecast.identity,
        forecast_time=forecast_time_iso(forecast, step),
    )
    return PlanResult(
        forecast=forecast, time_index=index, grid=grid, u_m_s=u, v_m_s=v, model=model,
        solution=solution, table=table, timings_s=timings, error=error,
    )


def _with_error(request: PlanRequest, forecast: Forecast, grid: Grid, index: int, progress: bool,
                members: Sequence[Forecast] = ()) -> tuple[PlanRequest, ErrorEstimate | None]:
    """The request with ``current_error_m_s`` measured from the data, when its settings ask for that
    (``members``: the ensemble whose mean ``forecast`` is)."""
    settings = request.settings
    if not settings.error_measured:
        return request, None
    previous = None
    if request.previous_forecast is not None:
        previous = open_forecast(request.previous_forecast, variables=request.variables, grid_file=request.grid_file,
                                 bbox=request.bbox)
    error = measure_error(forecast, grid, index, settings.horizon_h, time_varying=settings.time_varying,
                          previous=previous, members=members, default_m_s=settings.physical.current_error_m_s)
    _note(progress, f"forecast error {error.describe()}")
    physical = replace(settings.physical, current_error_m_s=round(error.current_error_m_s, 4))
    return replace(request, settings=replace(settings, physical=physical)), error


def slice_steps(forecast: Forecast, index: int, horizon_h: float, slice_h: float | None = None) -> list[int]:
    """The forecast steps of a time-varying plan: from ``index`` to ``horizon_h`` hours after it, every
    ``slice_h`` hours (a multiple of the forecast's step) or every step."""
    t0 = float(forecast.time_s[index])
    steps = [n for n in range(index, forecast.time_s.size) if forecast.time_s[n] - t0 <= horizon_h * 3600.0 + 1e-6]
    if slice_h is not None:
        on = [n for n in steps if abs((forecast.time_s[n] - t0) / 3600.0 / slice_h
                                      - round((forecast.time_s[n] - t0) / 3600.0 / slice_h)) * slice_h * 3600.0 < 1.0]
        gaps = np.diff(forecast.time_s[on]) / 3600.0
        if len(on) < 2 or np.any(np.abs(gaps - slice_h) > 1.0 / 3600.0):
            raise ForecastError(f"{forecast.source}: planning.slice_h = {slice_h:g} h is not a whole number of the "
                                f"forecast's steps from step {index} (its steps are "
                                f"{', '.join(f'{(t - t0) / 3600:g}' for t in forecast.time_s[steps[:6]])} ... h)")
        steps = on
    if len(steps) < 2:
        raise ForecastError(f"{forecast.source}: a time-varying plan needs two or more forecast steps within "
                            f"planning.horizon_h = {horizon_h:g} h of step {index}; the file has {forecast.time_s.size} "
                            f"step(s){'' if forecast.time_s.size < 2 else f', {(forecast.time_s[1] - forecast.time_s[0]) / 3600:g} h apart'}")
    return steps


def _plan_horizon(request: PlanRequest, forecast: Forecast, index: int, timings: dict[str, float], t: float,
                  progress: bool, meter: Progress, *, members: Sequence[Forecast] = ()) -> PlanResult:
    """A time-varying physical plan (``planner.physical.horizon``): a slice per forecast step
    (``members``: the ensemble whose mean ``forecast`` is, for the measured error)."""
    if forecast.time_origin is None:
        raise ForecastError(f"{forecast.source}: a time-varying plan needs dated forecast steps (its table is looked up "
                            "by UTC time); the file's time axis has no reference date")
    steps = slice_steps(forecast, index, request.settings.horizon_h, request.settings.slice_h)
    timings["load_s"] = time.perf_counter() - t
    grid = planning_grid(forecast, request)
    check_coverage(forecast, grid, request.goal)
    request, error = _with_error(request, forecast, grid, index, progress, members)
    settings = request.settings
    refine = refine_factor(grid, native_spacing_deg(forecast))
    fine = fine_grid(grid, refine)
    t = time.perf_counter()
    uf0, vf0 = resample(forecast, fine, time_index=forecast.step_index(steps[0]))
    u, v = uf0[:, ::refine, ::refine], vf0[:, ::refine, ::refine]
    goal_mask = _goal_mask(grid, u, v, request.goal, forecast.source)
    timings["resample_s"] = time.perf_counter() - t
    _note(progress, f"grid {grid.nx} x {grid.ny} x {grid.n_layers} layers x 8 headings = {grid.n_states:,} states, "
                    f"{len(steps)} time slices over {(forecast.time_s[steps[-1]] - forecast.time_s[steps[0]]) / 3600:g} h")

    sampled = [0]  # slices sampled so far, whatever order the solver asks for them in
    block = settings.timing_block_cells
    current: list[NDArray[np.float64]] = [np.zeros(0)] * len(steps)  # each slice's mean current per region, for the tide's timing

    def model_at(n: int) -> PhysicalModel:
        uf, vf = (uf0, vf0) if n == 0 else resample(forecast, fine, time_index=forecast.step_index(steps[n]))
        current[n] = region_mean_current(uf[:, ::refine, ::refine], vf[:, ::refine, ::refine], block)
        stats = sample_transitions(uf, vf, grid, settings, refine=refine)
        stats = enter_goal(stats, uf, vf, grid, settings, refine=refine, goal_mask=goal_mask)
        sampled[0] = min(sampled[0] + 1, len(steps))
        meter.update("time slices", sampled[0], len(steps), unit="slices")
        return assemble(stats, grid, settings, refine=refine)

    _announce_compile(meter, SAMPLING_KERNEL)
    meter.update("time slices", 0, len(steps), unit="slices")

    t = time.perf_counter()
    times = np.array([forecast.time_s[n] - forecast.time_s[steps[0]] for n in steps], dtype=np.float64)
    horizon = solve_horizon(model_at, times, request.goal, progress=lambda text: _note(progress, text))
    timings["transitions_s"] = horizon.timings_s["transitions_s"]
    timings["plan_s"] = time.perf_counter() - t
    solution = horizon.first
    _note(progress, f"physical model: {solution.model.n_pairs:,} state-actions in the first slice, "
                    f"{solution.model.samples_per_action} samples each; {sum(horizon.sweeps)} sweeps over the slices")
    slice_times = tuple(str(forecast_time_iso(forecast, forecast.step_index(n))) for n in steps)
    table = PolicyTable.from_solution(
        solution, forecast_source=forecast.source, forecast_identity=forecast.identity,
        forecast_time=slice_times[0],
    ).with_slices(slice_times, horizon.action, np.stack(current) if settings.timing_correction else None,
                  block_cells=block)
    return PlanResult(forecast=forecast, time_index=index, grid=grid, u_m_s=u, v_m_s=v, model=solution.model,
                      solution=solution, table=table, timings_s=timings, horizon=horizon, error=error)


def region_mean_current(u_m_s: NDArray[np.float64], v_m_s: NDArray[np.float64],
                        block_cells: int | None = None) -> NDArray[np.float64]:
    """(R, 2): the mean east and north current over each region's water (finite) nodes, 0 for a region of land.
    A region is a layer, or with ``block_cells`` a block of that many cells a side, in the order of
    ``PolicyTable.current_region``: layer, then block row, then block column."""
    L, ny, nx = u_m_s.shape
    k = max(ny, nx) if block_cells is None else block_cells
    out = []
    for l in range(L):
        for j0 in range(0, ny, k):
            for i0 in range(0, nx, k):
                u, v = u_m_s[l, j0:j0 + k, i0:i0 + k], v_m_s[l, j0:j0 + k, i0:i0 + k]
                wet = np.isfinite(u) & np.isfinite(v)
                out.append((float(np.mean(u[wet])), float(np.mean(v[wet]))) if np.any(wet) else (0.0, 0.0))
    return np.array(out).reshape(-1, 2)


def plan_with_scheduler(request: PlanRequest, *, scheduler: str | None = None, workers: int | None = None,
                        progress: bool = False, samples: SampleCache | None = None,
                        meter: Progress = SILENT) -> PlanResult:
    """``make_plan``, several forecast members sampled where ``scheduler`` says (``planner.cluster.open_runner``).

    One member plans here without a runner; the file headers are read once, here.
    """
    refs = members_of(request)
    request = replace(request, members=tuple(refs))
    if len(refs) == 1 or request.settings.time_varying:  # a time-varying plan flies the members' mean, here
        return make_plan(request, progress=progress, samples=samples, meter=meter)
    with open_runner(scheduler, workers=workers) as runner:
        _note(progress, f"{len(refs)} forecast members, sampled: {runner.describe()}")
        return make_plan(request, progress=progress, runner=runner, meter=meter)


def _plan_ensemble(request: PlanRequest, refs: list[MemberRef], *, runner: Runner, progress: bool,
                   meter: Progress) -> PlanResult:
    if request.settings.model != "physical":
        raise PlannerError(f"an ensemble of {len(refs)} forecast members needs the physical model (members are its "
                           f"outcomes; the paper model has none): give --model physical or one forecast")
    timings: dict[str, float] = {}
    t = time.perf_counter()
    first, index = open_step(request, refs[0])
    tasks = member_tasks(request, first=first)
    timings["load_s"] = time.perf_counter() - t
    timings["resample_s"] = 0.0  # in the member tasks
    grid, index = tasks[0].grid, tasks[0].time_index
    error = None
    if request.settings.error_measured:  # the members are the spread: measuring it again would count it twice
        error = ErrorEstimate(current_error_m_s=request.settings.physical.current_error_m_s, source="default",
                              detail=f"a stationary plan takes its {len(refs)} members as outcomes, so their spread "
                                     "is in the plan already; each member keeps the setting's own perturbation")
        _note(progress, f"forecast error {error.describe()}")
    _note(progress, f"grid {grid.nx} x {grid.ny} x {grid.n_layers} layers x 8 headings = {grid.n_states:,} states; "
                    f"{len(refs)} forecast members")
    t = time.perf_counter()
    _announce_compile(meter, SAMPLING_KERNEL)
    meter.update("sampling members", 0, len(tasks), unit="members")
    stats = runner.map(sample_member, tasks)
    meter.update("sampling members", len(tasks), len(tasks), unit="members")
    timings["transitions_s"] = time.perf_counter() - t
    model = assemble(combine(stats), grid, request.settings, refine=tasks[0].refine)
    _note(progress, f"physical model: {model.n_pairs:,} state-actions, {model.samples_per_action} samples each "
                    f"from {model.members} members")
    solution = solve_physical(model, request.goal, meter=meter)
    timings["plan_s"] = time.perf_counter() - t
    files = {refs[0].path: first.identity}  # each file hashed once, however many members it holds
    for r in refs:
        if r.path not in files:
            files[r.path] = file_identity(r.path)
    identity = "ensemble:" + hashlib.sha256(
        "|".join(f"{r.member}@{files[r.path]}" for r in refs).encode()).hexdigest()[:16]
    table = PolicyTable.from_solution(
        solution, forecast_source=" + ".join(r.label for r in refs)[:2000], forecast_identity=identity,
        forecast_time=forecast_time_iso(first, first.step_index(index)),
    )
    u, v = resample(first, grid, time_index=first.step_index(index))  # the first member's, for pictures
    return PlanResult(forecast=first, time_index=index, grid=grid, u_m_s=u, v_m_s=v,
                      model=model, solution=solution, table=table, timings_s=timings, error=error)


def mission_forecast(mission: Mission, *, cache_dir: Path | None = None) -> Path:
    """The forecast file a mission names: its file, the newest file in its directory, or a generated one.

    A generated (synthetic) forecast is written once into the per-user cache (``planner.forecast.cache``:
    ``cache_dir``, else ``$LRAUV_CACHE_DIR``, ``$XDG_CACHE_HOME/lrauv`` or ``~/.cache/lrauv``) and reused
    after; never beside the mission or the table.
    """
    src = mission.forecast
    if src.url is not None:  # downloaded into the cache; an OPeNDAP dataset, the part the mission's region needs
        from planner.forecast.opendap import fetch_source

        try:
            return fetch_source(src.url, cache_dir, bbox=mission.region.bbox).path
        except ForecastError as exc:
            raise ForecastError(f"{src.where}: {exc}") from None
    if src.file is not None:
        if not src.file.exists():  # said here, where the mission's line is known
            raise ForecastError(f"{src.where}: {src.file}: forecast file not found; check the path")
        return src.file
    if src.directory is not None:
        files = sorted(src.directory.glob("*.nc"), key=lambda p: (p.stat().st_mtime, p.name))
        if not files:
            raise ForecastError(f"{src.where}: {src.directory} holds no .nc files")
        return files[-1]
    from planner import __version__
    from planner.forecast.cache import forecasts_dir
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    if src.synthetic_seed is None:  # load_mission gives a file, a directory or a synthetic seed
        raise PlannerError(f"{mission.path}: forecast: expected a file, a directory or a synthetic seed")
    # The generator's version in the name: a newer generator does not reuse an older one's file.
    path = forecasts_dir(cache_dir) / f"synthetic_v{__version__}_seed{src.synthetic_seed}_{src.synthetic_hours}h.nc"
    if not path.exists():
        write_synthetic(path, SyntheticSettings(seed=src.synthetic_seed, hours=src.synthetic_hours))
    return path


def _announce_compile(meter: Progress, kernel: object) -> None:
    if needs_compile(kernel):
        meter.note(COMPILING)


def _note(progress: bool, text: str) -> None:
    if progress:
        print(fit(f"  {text}"), file=sys.stderr, flush=True)
