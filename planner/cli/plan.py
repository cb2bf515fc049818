"""``lrauv plan``: plan a feedback policy (``planner.pipeline``) and write the policy table.

A mission file gives everything; flags override it. The planning modules are imported
in ``run`` only: building the parser stays light (``lrauv exec`` builds it too).
"""

from __future__ import annotations

import argparse
import math
import re
import shlex
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from planner.cli.cluster_options import add_cluster_arguments
from planner.contract.arguments import Subcommands, floats
from planner.contract.columns import say
from planner.contract.errors import CoverageError, GoalError, LrauvError

COST_NAMES = ("drift", "forward", "rotate", "glide")


def costs(text: str) -> dict[str, float]:
    """``--costs NAME=VALUE,...``: an argparse type; integers stay integers."""
    out: dict[str, float] = {}
    for part in text.split(","):
        name, _, value = part.partition("=")
        if name not in COST_NAMES or not value:
            raise argparse.ArgumentTypeError(f"costs: expected NAME=VALUE with NAME in drift, forward, rotate, glide; got {part!r}")
        try:
            out[name] = float(value) if "." in value or "e" in value.lower() else int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"costs.{name}: expected a number; got {value!r}") from None
    return out


def add_parser(sub: Subcommands) -> None:
    plan = sub.add_parser("plan", help="plan a feedback policy and write the policy table")
    plan.add_argument("mission", nargs="?", type=Path, help="mission YAML file (flags below override it)")
    plan.add_argument("--forecast", nargs="+", metavar="FILE|URL",
                      help="forecast netCDF file or http(s) URL of one (downloaded to the cache); several (or a file "
                           "with a member dimension) are the members of an ensemble, the outcomes of the physical model "
                           "(a time-varying plan flies their mean)")
    plan.add_argument("--variables", type=lambda t: t.split(","), help="U,V variable names, when not found by CF standard names")
    plan.add_argument("--grid-file", type=Path, help="grid file (lon/lat/mask/angle) for a forecast without them")
    plan.add_argument("--bbox", type=lambda t: floats(t, 4, "bbox"), help="WEST,SOUTH,EAST,NORTH in degrees (cell centres on the edges)")
    plan.add_argument("--nx", type=int, help="columns, west to east")
    plan.add_argument("--ny", type=int, help="rows, south to north")
    plan.add_argument("--depths", type=lambda t: floats(t, None, "depths"), help="layer depths in metres, e.g. 0,5,10,15")
    plan.add_argument("--time-index", type=int, help="forecast time step by position (0 = first)")
    plan.add_argument("--time", help="forecast time (ISO 8601); the nearest step is used")
    plan.add_argument("--goal", type=lambda t: floats(t, 3, "goal"), help="LON,LAT,DEPTH of the goal")
    plan.add_argument("--goal-radius", type=int, help="goal radius in cells (default 1)")
    plan.add_argument("--model", choices=["paper", "physical"],
                      help="planning model: the paper's graph (default) or the physical one (docs/physical-model.md)")
    plan.add_argument("--criterion", choices=["robust", "optimistic", "expected"],
                      help="paper: robust (default) or optimistic; physical: robust (default) or expected")
    plan.add_argument("--uncertainty", choices=["lateral", "none"],
                      help="paper model: lateral (a move may also end in a cell beside the intended one) or none"
                           " (default: the mission's)")
    plan.add_argument("--costs", type=costs, help="e.g. drift=0,forward=4,rotate=10,glide=2")
    plan.add_argument("--calm-speed", type=float, help="calm threshold in m/s (default 0.01)")
    plan.add_argument("--time-varying", action="store_true", default=None,
                      help="physical model: a plan with time in the state, a slice per forecast step (docs/time-varying.md)")
    plan.add_argument("--horizon-h", type=float, help="time-varying plan: hours of forecast it spans (default 72)")
    plan.add_argument("--slice-h", type=float, help="time-varying plan: hours between slices, a multiple of the "
                                                     "forecast's step (default: every step)")
    plan.add_argument("--timing-correction", action=argparse.BooleanOptionalAction, default=None,
                      help="time-varying plan: carry each slice's mean current, so the vehicle fits the tide's timing "
                           "to the current it meets (default: the mission's planning.timing_correction)")
    plan.add_argument("--timing-block-cells", type=int, metavar="N",
                      help="with --timing-correction: the reference current is the mean per block of N x N cells in each"
                           " layer; as large as the grid, one mean per layer (default: the mission's"
                           " planning.timing_block_cells, or 4)")
    plan.add_argument("--current-error", metavar="M_S|measured",
                      help="physical model: forecast error per current component, m/s, or 'measured' from the data")
    plan.add_argument("--previous-forecast", metavar="FILE|URL",
                      help="an earlier issue of the forecast: with --current-error measured, the error is the issues' difference")
    plan.add_argument("--out", type=Path, help="policy table to write (default: <mission name>.lrpt)")
    plan.add_argument("--no-compress", action="store_true", help="store the table payload uncompressed")
    plan.add_argument("--export-values", type=Path, metavar="FILE.nc|FILE.npz",
                      help="also write the plan's values: CF-1.8 netCDF (.nc, docs/plan-values.md) or the arrays of "
                           "spec section 8 (.npz)")
    plan.add_argument("--cache-dir", type=Path, metavar="DIR",
                      help="cache for downloaded and synthetic forecasts (default: $LRAUV_CACHE_DIR, "
                           "$XDG_CACHE_HOME/lrauv or ~/.cache/lrauv)")
    plan.add_argument("--plot", type=Path, metavar="DIR", help="write PNG pictures of the flow, policy and nominal path here")
    plan.add_argument("--plot-heading", type=int, default=0, help="heading k (0 = E, counter-clockwise) for the policy picture")
    plan.add_argument("--plot-layer", type=int, help="layer for the policy picture (default: the goal's)")
    plan.add_argument("--start", type=lambda t: floats(t, 4, "start"), help="LON,LAT,DEPTH,HEADING_DEG for the nominal path")
    plan.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_cluster_arguments(plan)  # used when there is parallel work: several forecast members


def run(args: argparse.Namespace) -> int:
    from planner.contract.atomic import check_file_target, write_atomic
    from planner.contract.mission import load_mission
    from planner.cli.progress_bar import bars
    from planner.pipeline import plan_with_scheduler
    from planner.plan_summary import summary_lines, time_line
    from planner.plan_values import check_suffix, export_values

    progress = not args.quiet
    if args.export_values:
        check_suffix(args.export_values)  # before the plan's minutes, not after
        check_file_target(args.export_values)
    mission = None if args.mission is None else load_mission(args.mission)
    out = args.out or Path((mission.name if mission else "plan") + ".lrpt")
    check_file_target(out)  # the outputs before the forecast is fetched or made, and before the plan
    if args.plot:
        depths = args.depths or (mission.region.depths_m if mission is not None else None)
        check_plot_options(args, None if depths is None else len(depths))
    request = plan_request(args, mission)
    t0 = time.perf_counter()
    settings = request.settings
    if progress:
        how = f"physical, {settings.criterion}" if settings.model == "physical" else f"{settings.criterion}, {settings.uncertainty}"
        print(f"planning on {request.forecast_path} ({how})", file=sys.stderr)
    try:
        with bars(quiet=args.quiet) as meter:
            result = plan_with_scheduler(request, scheduler=args.scheduler, workers=args.workers, progress=progress,
                                         meter=meter)
    except GoalError as exc:  # a goal from the mission: name its file and line
        if mission is None or args.goal is not None:
            raise
        raise GoalError(f"{mission.goals[0].where}: {exc}") from None
    except CoverageError as exc:  # the mission's region: name its file and line
        if mission is None or args.bbox is not None or not mission.region.where:
            raise
        raise CoverageError(f"{mission.region.where}: {exc}") from None
    start = None if args.start is None else start_state(result, args.start)
    if start is not None:  # the vehicle shows it on its map (executive.map_layers)
        from planner.shore.plots.solutions import nominal_lon_lat

        path = nominal_lon_lat(result.solution, start, (args.start[0], args.start[1]))
        result = replace(result, table=replace(result.table, nominal_path=path))
    data = result.table.to_bytes(compress=not args.no_compress)
    # The table first: the options and paths of the values and pictures were checked before the plan, and a
    # failure writing them (a full disk) then costs the extras, never the plan.
    write_atomic(out, data)
    for line in summary_lines(result, out=out, size=len(data)):
        say(line)
    if start is not None:
        say(start_line(result, args.start, start))
    say(time_line(result, time.perf_counter() - t0))
    if args.export_values:
        history = shlex.join(["lrauv", *sys.argv[1:]]) if sys.argv[1:2] == ["plan"] else "lrauv plan"
        mission_file = None if mission is None else str(mission.path)
        say(f"values     {export_values(result, args.export_values, mission=mission_file, history=history)}")
    if args.plot:
        from planner.shore.plots import default_start, moment_of_plan, plot_all

        paths = plot_all(result.u_m_s, result.v_m_s, result.solution, args.plot,
                         start=default_start(result.solution) if start is None else start, heading=args.plot_heading,
                         layer=args.plot_layer, when=moment_of_plan(result),
                         start_lon_lat=None if args.start is None else (args.start[0], args.start[1]))
        for p in paths:
            say(f"picture    {p}")
    return 0


def check_plot_options(args: argparse.Namespace, n_layers: int | None) -> None:
    """``--plot`` and its options, checked before the plan's minutes: a bad one would stop the command after them
    (``n_layers``: None when no depths are given yet, which the request refuses)."""
    from planner.contract.atomic import check_folder_target

    try:
        check_folder_target(args.plot)
    except NotADirectoryError as exc:  # the folder, or one above it, is a file
        raise LrauvError(f"--plot: {exc.filename} is a file: expected a folder for the pictures") from None
    if args.plot_layer is not None and n_layers is not None and not 0 <= args.plot_layer < n_layers:
        raise LrauvError(f"--plot-layer: expected 0..{n_layers - 1}; got {args.plot_layer}")
    if not 0 <= args.plot_heading < 8:
        raise LrauvError(f"--plot-heading: expected 0..7 (0 = east, counter-clockwise); got {args.plot_heading}")


def plan_request(args: argparse.Namespace, mission: Any) -> Any:
    """The ``PlanRequest`` of the flags over the mission (None: flags only); bad or missing input raises LrauvError."""
    from planner.contract.geodesy import BBox
    from planner.contract.settings import CRITERIA, Costs, Goal, PlanSettings
    from planner.pipeline import PlanRequest, mission_forecast

    # Forecast: the flag (files or URLs, downloaded to the cache), else the mission's source.
    region = BBox(west_deg=args.bbox[0], south_deg=args.bbox[1], east_deg=args.bbox[2], north_deg=args.bbox[3]) \
        if args.bbox else None if mission is None else mission.region.bbox
    sources = [local_forecast(s, args.cache_dir, region) for s in args.forecast or ()]
    forecast_path = sources[0] if sources else None
    ensemble = tuple(sources[1:])
    time_index, time_iso = args.time_index, args.time
    variables = tuple(args.variables) if args.variables else None
    grid_file = args.grid_file
    if forecast_path is None and mission is not None:
        forecast_path = mission_forecast(mission, cache_dir=args.cache_dir)
        if mission.forecast.synthetic_seed is not None:  # say where the generated file is: never beside the mission
            say(f"cache      synthetic forecast (seed {mission.forecast.synthetic_seed}, "
                f"{mission.forecast.synthetic_hours} h) {forecast_path}")
        if time_index is None and time_iso is None:  # the mission's step is of its own forecast, not of another file
            time_index, time_iso = mission.forecast.time_index, mission.forecast.time_iso
        variables = variables or mission.forecast.variables
        grid_file = grid_file or mission.forecast.grid_file
    if forecast_path is None:
        raise LrauvError("plan: no forecast: give --forecast FILE.nc or a mission file")
    if variables is not None and len(variables) != 2:
        raise LrauvError(f"--variables: expected two names U,V; got {','.join(variables)}")
    # Grid.
    bbox = BBox(west_deg=args.bbox[0], south_deg=args.bbox[1], east_deg=args.bbox[2], north_deg=args.bbox[3]) if args.bbox else None
    nx, ny = args.nx, args.ny
    depths = tuple(args.depths) if args.depths else None
    if mission is not None:
        bbox = bbox or mission.region.bbox
        nx = mission.region.nx if nx is None else nx
        ny = mission.region.ny if ny is None else ny
        depths = depths or mission.region.depths_m
    if depths is None:
        raise LrauvError("plan: no depth layers: give --depths D0,D1,... or a mission file")
    # Goal.
    if args.goal is not None:
        goal = Goal(lon_deg=args.goal[0], lat_deg=args.goal[1], depth_m=args.goal[2],
                    radius_cells=args.goal_radius if args.goal_radius is not None else 1)
    elif mission is not None:
        goal = mission.goals[0].goal
        if args.goal_radius is not None:
            goal = Goal(lon_deg=goal.lon_deg, lat_deg=goal.lat_deg, depth_m=goal.depth_m, radius_cells=args.goal_radius)
    else:
        raise LrauvError("plan: no goal: give --goal LON,LAT,DEPTH or a mission file")
    # Settings: the mission's (its vehicle figures and physical sampling included), flags override.
    base = mission.settings if mission is not None else PlanSettings()
    cost = base.costs
    if args.costs:
        fields = {"drift": cost.drift, "forward": cost.forward, "rotate": cost.rotate, "glide": cost.glide}
        fields.update(args.costs)
        cost = Costs(**fields)
    model = args.model or base.model
    criterion = args.criterion or base.criterion
    if criterion not in CRITERIA[model]:
        source = "" if args.criterion else f" (from {mission.path if mission is not None else 'the default'}; give --criterion)"
        raise LrauvError(f"--criterion: the {model} model has {' and '.join(CRITERIA[model])}; got {criterion!r}{source}")
    for flag, value in (("--slice-h", args.slice_h), ("--horizon-h", args.horizon_h)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise LrauvError(f"{flag}: expected a number of hours > 0; got {value:g}")
    measured = base.error_measured
    physical = base.physical
    timing_correction = base.timing_correction if args.timing_correction is None else args.timing_correction
    if args.timing_correction and not (args.time_varying or base.time_varying):
        raise LrauvError("--timing-correction: a stationary plan has no slices to look up earlier or later; give "
                         "--time-varying (or planning.time_varying: true in the mission)")
    if args.timing_block_cells is not None and args.timing_block_cells < 1:
        raise LrauvError(f"--timing-block-cells: expected a whole number of cells >= 1; got {args.timing_block_cells}")
    if args.timing_block_cells is not None and not timing_correction:
        raise LrauvError("--timing-block-cells: a reference current per block is for the tide's timing; give "
                         "--timing-correction (or planning.timing_correction: true in the mission)")
    if args.current_error is not None and model != "physical":
        raise LrauvError(f"--current-error: the {model} model has no forecast error to set (its uncertainty is "
                         "--uncertainty); give --model physical")
    if args.current_error is not None:
        measured = args.current_error == "measured"
        if not measured:
            try:
                value = float(args.current_error)
            except ValueError:
                raise LrauvError(f"--current-error: expected a speed in m/s >= 0 or 'measured'; got {args.current_error!r}") from None
            if not (math.isfinite(value) and value >= 0):
                raise LrauvError(f"--current-error: expected a speed in m/s >= 0 or 'measured'; got {args.current_error!r}")
            physical = replace(physical, current_error_m_s=value)
    settings = replace(
        base,
        physical=physical,
        error_measured=measured,
        model=model,
        criterion=criterion,
        uncertainty=args.uncertainty or base.uncertainty,
        costs=cost,
        calm_speed_m_s=base.calm_speed_m_s if args.calm_speed is None else args.calm_speed,
        time_varying=bool(args.time_varying) or base.time_varying,
        timing_correction=timing_correction,
        timing_block_cells=base.timing_block_cells if args.timing_block_cells is None else args.timing_block_cells,
        horizon_h=base.horizon_h if args.horizon_h is None else args.horizon_h,
        slice_h=base.slice_h if args.slice_h is None else args.slice_h,
    )
    return PlanRequest(
        forecast_path=forecast_path, goal=goal, depths_m=tuple(float(d) for d in depths), settings=settings,
        bbox=bbox, nx=nx, ny=ny, time_index=time_index, time_iso=time_iso, variables=variables,
        grid_file=grid_file, ensemble=ensemble,
        previous_forecast=None if args.previous_forecast is None else local_forecast(args.previous_forecast,
                                                                                       args.cache_dir),
    )


def local_forecast(source: str, cache_dir: Path | None, bbox: Any = None) -> Path:
    """A forecast argument as a file: an http(s) URL is downloaded to the cache (and said so), a path kept as given.

    An OPeNDAP dataset URL: only the part that planning inside ``bbox`` reads (``planner.forecast.opendap``)."""
    from planner.forecast.opendap import fetch_source
    from planner.forecast.remote import is_url

    if not is_url(source):
        if re.match(r"^[a-z][a-z0-9+.-]+://", source, re.IGNORECASE):  # a URL, but not one fetched from
            raise LrauvError(f"--forecast {source}: expected a file, or an http:// or https:// URL")
        return Path(source)
    fetched = fetch_source(source, cache_dir, bbox=bbox)
    say(f"cache      {fetched.describe()}")
    return fetched.path


def start_line(result: Any, given: list[float], start: tuple[int, int, int, int]) -> str:
    """The predicted cost (and, for the physical model, time) to go from ``--start``."""
    lon, lat, depth, heading = given
    where = f"start      ({lon:g}, {lat:g}, {depth:g} m, {heading:g} deg), state (l, j, i, k) = {start}:"
    sol = result.solution
    cost, steps = sol.value(*start)
    if not math.isfinite(cost):
        return f"{where} cannot reach the goal"
    if result.model.settings.model == "physical":
        hours = float(sol.time_s[start]) / 3600.0
        return f"{where} {cost:.1f} Wh, {hours:.2f} h to go ({result.model.settings.criterion})"
    return f"{where} cost {cost:g}, {steps} steps ({result.model.settings.criterion})"


def start_state(result: Any, start: list[float]) -> tuple[int, int, int, int]:
    """The state (l, j, i, k) of ``--start LON,LAT,DEPTH,HEADING_DEG``; off the grid or on land raises LrauvError."""
    from planner.contract.geodesy import swap_hint

    lon, lat, depth, heading = start
    cell = result.table.locate(lat, lon, depth)
    if cell is None:
        swapped = swap_hint(lon, lat, fits=lambda x, y: result.table.locate(y, x, depth) is not None)
        raise LrauvError(f"--start: ({lon:g}, {lat:g}, {depth:g} m) is outside the planning grid{swapped}")
    l, j, i = cell
    if not result.model.water[l, j, i]:
        raise LrauvError(f"--start: ({lon:g}, {lat:g}, {depth:g} m) is on land")
    return (l, j, i, result.table.heading_index(j, heading))
