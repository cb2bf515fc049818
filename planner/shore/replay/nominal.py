"""A logged table's plan again, from its forecast: cost-to-go and the nominal path for post-dive analysis.

The table the vehicle carried holds actions only (docs/policy-table.md). Replay
wants what the planner knew besides: the cost-to-go of each state (spec section
8) and the nominal path (spec section 5, each action's nominal outcome). Both
come from planning again with the settings in the table's header on the same
forecast, found by its identity (the SHA-256 prefix in ``forecast.identity``).
The plan is accepted only if it gives the table's actions, state for state.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import ShoreError
from planner.forecast import file_identity
from planner.contract.geodesy import BBox
from planner.physical.solve import PhysicalSolution, PhysicalStep
from planner.pipeline import PlanRequest, PlanResult, make_plan
from planner.contract.settings import Costs, Criterion, Goal, Model, PhysicalSettings, PlanSettings, Uncertainty
from planner.paper.solve import PathStep, nominal_path
from planner.contract.table import PolicyTable
from planner.contract.vehicle import VehicleParams

__all__ = ["NominalPath", "find_forecast", "nominal_from", "plan_again", "table_settings"]


def find_forecast(table: PolicyTable, *, given: Path | None = None, near: tuple[Path, ...] = ()) -> Path:
    """The forecast file ``table`` was planned on: ``given``, or its source beside any of ``near``.

    A candidate counts only if its identity matches the table's; raises
    ``ShoreError`` saying where it looked otherwise.
    """
    name = Path(table.forecast_source).name
    candidates = [given] if given is not None else [Path(table.forecast_source), *(d / name for d in near)]
    looked = []
    for path in candidates:
        if path is None or not path.is_file():
            looked.append(f"{path} (absent)")
            continue
        found = file_identity(path)
        if found == table.forecast_identity:
            return path
        looked.append(f"{path} ({found})")
    raise ShoreError(f"the planning forecast {table.forecast_identity} ({name}) was not found: looked at "
                       + "; ".join(looked) + "; give it with --forecast")


def table_settings(table: PolicyTable) -> PlanSettings:
    """The ``PlanSettings`` a table's header records (docs/policy-table.md); ShoreError when they are not valid.

    Paper tables carry their costs; physical tables their vehicle figures and sampling (``physical``;
    a physical table without it, from before the key existed, gets the defaults without course
    offsets, which did not exist then either, and ``plan_again``'s action check then tells whether
    they were the ones used).
    """
    name = f"table {table.crc32:08x}"
    costs = Costs()
    if table.model != "physical" or table.costs:
        c = table.costs
        missing = [k for k in ("drift", "forward", "rotate", "glide") if k not in c]
        if missing:
            raise ShoreError(f"{name}: header costs lack {', '.join(missing)}")
        costs = Costs(drift=c["drift"], forward=c["forward"], rotate=c["rotate"], glide=c["glide"])
    # A physical table from before the header key (or course offsets) existed: planned without offsets.
    physical, vehicle = PhysicalSettings(course_offsets=False), VehicleParams()
    if table.physical is not None:
        try:
            # A table from before course offsets existed planned with the eight bearings only.
            # Header values as read: the constructors check each key and value.
            sampling: dict[str, Any] = {"course_offsets": False, **table.physical.get("sampling", {})}
            figures: dict[str, Any] = table.physical.get("vehicle", {})
            physical = PhysicalSettings(**sampling)
            vehicle = VehicleParams(**figures)
        except TypeError as exc:  # a key this version does not know
            raise ShoreError(f"{name}: header physical: {exc}; planned by a newer planner?") from None
        except ValueError as exc:
            raise ShoreError(f"{name}: header physical: {exc}") from None
    # A time-varying plan: its slices span the horizon, evenly spaced or at the forecast's own steps.
    time_varying, horizon_h, slice_h = False, 72.0, None
    if table.time_varying:
        times = np.asarray(table.slice_unix_s)
        gaps = np.diff(times)
        time_varying, horizon_h = True, float(times[-1] - times[0]) / 3600.0
        slice_h = float(gaps[0]) / 3600.0 if np.all(np.abs(gaps - gaps[0]) < 1.0) else None
    # The header's words as read: PlanSettings checks them, with its own messages.
    return PlanSettings(model=cast(Model, table.model), criterion=cast(Criterion, table.criterion),
                        uncertainty=cast(Uncertainty, table.uncertainty),
                        costs=costs, physical=physical, vehicle=vehicle, time_varying=time_varying,
                        horizon_h=horizon_h, slice_h=slice_h)


def plan_again(table: PolicyTable, forecast: str | os.PathLike[str]) -> PlanResult:
    """Plan ``table``'s goal on ``forecast`` with the header's settings; refuse if any action differs."""
    grid_east = table.lon0_deg + (table.nx - 1) * table.dlon_deg
    grid_north = table.lat0_deg + (table.ny - 1) * table.dlat_deg
    request = PlanRequest(
        forecast_path=Path(forecast),
        goal=Goal(lon_deg=table.goal_lon_deg, lat_deg=table.goal_lat_deg, depth_m=table.goal_depth_m,
                  radius_cells=table.goal_radius_cells),
        depths_m=tuple(table.depth_m),
        settings=table_settings(table),
        bbox=BBox(west_deg=table.lon0_deg, south_deg=table.lat0_deg, east_deg=grid_east, north_deg=grid_north),
        nx=table.nx, ny=table.ny, time_iso=table.forecast_time,
    )
    result = make_plan(request)
    again = result.table
    if again.slice_times != table.slice_times:
        raise ShoreError(f"{forecast}: planning table {table.crc32:08x} again gives {again.n_slices} time slice(s) from "
                         f"{again.forecast_time}; the table has {table.n_slices} from {table.forecast_time}")
    differ = int(np.count_nonzero(again.actions != table.actions) if again.slices is None
                 else np.count_nonzero(again.slices != table.slices))
    if differ:
        raise ShoreError(f"{forecast}: planning table {table.crc32:08x} again gives {differ:,} of {table.n_states * table.n_slices:,}"
                           " actions that differ from the table; it was not planned on this forecast and step"
                           " with these settings")
    # The same table again: the nominal path it carries was drawn on shore from its start, not planned.
    return replace(result, table=replace(again, nominal_path=table.nominal_path))


@dataclass(frozen=True, eq=False, kw_only=True)
class NominalPath:
    """Cell centres along the nominal path from a start state, with the action taken at each."""

    lon_deg: NDArray[np.float64]
    lat_deg: NDArray[np.float64]
    depth_m: NDArray[np.float64]
    actions: tuple[str, ...]
    cost: float  # predicted cost-to-go at the start (inf: unreachable), in ``cost_unit``
    cost_unit: str = "cost units"  # the paper model's action costs, or "Wh" for the physical model
    time_s: float | None = None  # physical model: predicted time to go at the start, s (inf: unreachable)


def nominal_from(result: PlanResult, start: tuple[int, int, int, int]) -> NominalPath:
    """The nominal path of ``result``'s policy from table state ``start`` ``(l, j, i, k)``.

    Paper plans: ``planner.paper.solve.nominal_path`` (each action's nominal outcome); physical plans:
    ``PhysicalSolution.nominal`` (each action's most likely outcome), with the cost in Wh.
    """
    grid = result.grid
    sol = result.solution
    physical = isinstance(sol, PhysicalSolution)
    steps: Sequence[PathStep | PhysicalStep]
    if isinstance(sol, PhysicalSolution):
        steps, time_s = sol.nominal(start), float(sol.time_s[tuple(start)])
    else:
        steps, time_s = nominal_path(sol, start), None
    return NominalPath(
        lon_deg=np.array([grid.lon_deg[s.i] for s in steps]), lat_deg=np.array([grid.lat_deg[s.j] for s in steps]),
        depth_m=np.array([grid.depth_m[s.l] for s in steps]), actions=tuple(s.action.name for s in steps),
        cost=sol.value(*start)[0], cost_unit="Wh" if physical else "cost units", time_s=time_s,
    )
