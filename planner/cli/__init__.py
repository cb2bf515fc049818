"""``lrauv``: the one console command. Parses, calls one library function, maps errors to exit codes.

Bad input prints one line ``lrauv: error: ...`` to stderr and exits with status 2.
Subcommands of other packages are imported only when used, so ``lrauv exec``
never loads the planner's heavy dependencies.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from planner.contract.arguments import CommandParser, floats
from planner.contract.errors import LrauvError

EXIT_BAD_INPUT = 2


def _costs(text: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for part in text.split(","):
        name, _, value = part.partition("=")
        if name not in ("drift", "forward", "rotate", "glide") or not value:
            raise argparse.ArgumentTypeError(f"costs: expected NAME=VALUE with NAME in drift, forward, rotate, glide; got {part!r}")
        try:
            out[name] = float(value) if "." in value or "e" in value.lower() else int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"costs.{name}: expected a number; got {value!r}") from None
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = CommandParser(prog="lrauv", description="Feedback motion planning and onboard execution for long-range AUVs.")
    sub = parser.add_subparsers(dest="command", required=True)

    plan = sub.add_parser("plan", help="plan a feedback policy and write the policy table")
    plan.add_argument("mission", nargs="?", type=Path, help="mission YAML file (flags below override it)")
    plan.add_argument("--forecast", type=Path, nargs="+", metavar="FILE",
                      help="forecast netCDF file; several files (or a file with a member dimension) are the members "
                           "of an ensemble, the outcomes of the physical model")
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
    plan.add_argument("--uncertainty", choices=["lateral", "none"])
    plan.add_argument("--costs", type=_costs, help="e.g. drift=0,forward=4,rotate=10,glide=2")
    plan.add_argument("--calm-speed", type=float, help="calm threshold in m/s (default 0.01)")
    plan.add_argument("--out", type=Path, help="policy table to write (default: <mission name>.lrpt)")
    plan.add_argument("--no-compress", action="store_true", help="store the table payload uncompressed")
    plan.add_argument("--export-values", type=Path, help="also write the arrays of spec section 8 to this .npz")
    plan.add_argument("--plot", type=Path, metavar="DIR", help="write PNG pictures of the flow, policy and nominal path here")
    plan.add_argument("--plot-heading", type=int, default=0, help="heading k (0 = E, counter-clockwise) for the policy picture")
    plan.add_argument("--plot-layer", type=int, help="layer for the policy picture (default: the goal's)")
    plan.add_argument("--start", type=lambda t: floats(t, 4, "start"), help="LON,LAT,DEPTH,HEADING_DEG for the nominal path")
    plan.add_argument("--quiet", action="store_true", help="no progress on stderr")
    from planner.cluster import add_arguments as add_cluster_arguments

    add_cluster_arguments(plan)  # used when there is parallel work: several forecast members

    fc = sub.add_parser("forecast", help="inspect or generate forecasts")
    fsub = fc.add_subparsers(dest="forecast_command", required=True)
    info = fsub.add_parser("info", help="describe a forecast file as the loader understands it")
    info.add_argument("file", type=Path)
    info.add_argument("--variables", type=lambda t: t.split(","))
    info.add_argument("--grid-file", type=Path)
    synth = fsub.add_parser("synth", help="write the built-in synthetic Southern California Bight forecast")
    synth.add_argument("out", type=Path)
    synth.add_argument("--seed", type=int, default=0)
    synth.add_argument("--hours", type=int, default=72)
    synth.add_argument("--issue", type=int, help="forecast issue number (error shrinks with each issue); default: the truth")

    # Options of planner.forecast.synthetic.double_gyre.DoubleGyreSettings, here so that building the parser imports no xarray.
    gyre = fsub.add_parser("gyre", help="write the analytic double gyre (Shadden et al. 2005) as a forecast")
    gyre.add_argument("out", type=Path)
    gyre.add_argument("--peak-speed-m-s", type=float, help="peak speed of the steady gyre, m/s (default 0.5)")
    gyre.add_argument("--eps", type=float, help="oscillation amplitude of the dividing line, 0..0.5 (default 0.1; 0 = steady)")
    gyre.add_argument("--period-h", type=float, help="oscillation period in hours (default 12)")
    gyre.add_argument("--phase-rad", type=float, help="oscillation phase at the issue time, radians (default 0)")
    gyre.add_argument("--hours", type=float, help="forecast length in hours (default 48)")
    gyre.add_argument("--step-h", type=float, help="time step in hours (default 1)")
    gyre.add_argument("--spacing-deg", type=float, help="grid spacing in degrees (default 0.005)")
    gyre.add_argument("--bbox", help="WEST,SOUTH,EAST,NORTH in degrees, points on the edges (default -118.2,33.3,-117.8,33.467)")
    gyre.add_argument("--depths", help="layer depths in metres (default 0,5,10,15)")
    gyre.add_argument("--issue-time", help="ISO 8601 issue time, t = 0 (default 2026-01-15T00:00:00Z)")
    # Options of planner.forecast.synthetic.ensemble (the gyre's as above), here so that building the parser imports no xarray.
    ens = fsub.add_parser("ensemble", help="write a synthetic forecast ensemble: one file, u/v with a leading member dimension")
    ens.add_argument("out", type=Path)
    ens.add_argument("--kind", choices=["gyre", "scb"], required=True,
                     help="gyre: double gyres with drawn eps, phase and peak speed; scb: one SCB forecast issue, independent error draws")
    ens.add_argument("--members", type=int, required=True, help="number of members, 1..1000")
    ens.add_argument("--seed", type=int, default=0,
                     help="gyre: seed of the members' draws; scb: the scenario's seed, as `lrauv forecast synth --seed` (default 0)")
    ens.add_argument("--hours", type=float, help="forecast length in hours (gyre: default 48; scb: whole hours, default 72)")
    ens.add_argument("--peak-speed-m-s", type=float, help="gyre: base peak speed, m/s; members x U[1 - spread, 1 + spread] (default 0.5)")
    ens.add_argument("--eps", type=float, help="gyre: base eps; members draw eps from U[0, min(2 eps, 0.5)] (default 0.1)")
    ens.add_argument("--spread", type=float, help="gyre: relative spread of the members' peak speed, 0 <= spread < 1 (default 0.2)")
    ens.add_argument("--period-h", type=float, help="gyre: oscillation period in hours (default 12)")
    ens.add_argument("--step-h", type=float, help="gyre: time step in hours (default 1)")
    ens.add_argument("--spacing-deg", type=float, help="gyre: grid spacing in degrees (default 0.005)")
    ens.add_argument("--bbox", help="gyre: WEST,SOUTH,EAST,NORTH in degrees (default -118.2,33.3,-117.8,33.467)")
    ens.add_argument("--depths", help="gyre: layer depths in metres (default 0,5,10,15)")
    ens.add_argument("--issue-time", help="gyre: ISO 8601 issue time, t = 0 (default 2026-01-15T00:00:00Z)")
    ens.add_argument("--issue", type=int, help="scb: forecast issue of every member, its issue time and error size (default 0)")

    from planner.shore.batch import add_parser as add_batch
    from planner.cli.evaluate import add_parser as add_evaluate
    from planner.shore.evaluation.holdout import add_parser as add_holdout

    add_evaluate(sub)
    add_batch(sub)
    add_holdout(sub)

    # The vehicle side registers its own subcommands; their modules import nothing heavy.
    from executive.cli import add_parsers as add_executive
    from vehicle_sim.cli import add_parser as add_sim
    from planner.shore.demo import add_parser as add_demo

    from planner.cli.replay import add_parser as add_replay
    from planner.shore.upload import add_parser as add_upload
    from planner.cli.waypoints import add_parser as add_waypoints

    add_executive(sub)
    add_sim(sub)
    add_demo(sub)
    add_upload(sub)
    add_waypoints(sub)
    add_replay(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``lrauv``; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "plan":
            return _plan(args)
        if args.command == "forecast":
            return _forecast(args)
        if args.command in ("exec", "log"):
            from executive.cli import run as run_executive

            return run_executive(args)
        if args.command == "sim":
            from vehicle_sim.cli import run as run_sim

            return run_sim(args)
        if args.command == "demo":
            from planner.shore.demo import run as run_demo

            return run_demo(args)
        if args.command == "upload":
            from planner.shore.upload import run as run_upload

            return run_upload(args)
        if args.command == "waypoints":
            from planner.cli.waypoints import run as run_waypoints

            return run_waypoints(args)
        if args.command == "holdout":
            from planner.shore.evaluation.holdout import run as run_holdout

            return run_holdout(args)
        if args.command == "batch":
            from planner.shore.batch import run as run_batch

            return run_batch(args)
        if args.command == "evaluate":
            from planner.cli.evaluate import run as run_evaluate

            return run_evaluate(args)
        if args.command == "replay":
            from planner.cli.replay import run as run_replay

            return run_replay(args)
    except LrauvError as exc:
        print(f"lrauv: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:  # a file we were told to read or write
        where = exc.filename or "file"
        print(f"lrauv: error: {where}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("lrauv: interrupted", file=sys.stderr)
        return 130
    return 0


def _forecast(args: argparse.Namespace) -> int:
    if args.forecast_command == "info":
        from planner.forecast import describe, open_forecast

        variables = tuple(args.variables) if args.variables else None
        if variables is not None and len(variables) != 2:
            raise LrauvError(f"--variables: expected two names U,V; got {args.variables}")
        print(describe(open_forecast(args.file, variables=variables, grid_file=args.grid_file)))  # type: ignore[arg-type]
        return 0
    if args.forecast_command == "ensemble":
        from planner.forecast.synthetic.ensemble import write_ensemble_from_args

        print(f"wrote {write_ensemble_from_args(args)}")
        return 0
    if args.forecast_command == "gyre":
        from planner.forecast.synthetic.double_gyre import settings_from_args, write_gyre

        print(f"wrote {write_gyre(args.out, settings_from_args(args))}")
        return 0
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    path = write_synthetic(args.out, SyntheticSettings(seed=args.seed, hours=args.hours), issue_number=args.issue)
    print(f"wrote {path}")
    return 0


def _plan(args: argparse.Namespace) -> int:
    from planner.contract.geodesy import BBox
    from planner.pipeline import PlanRequest, export_values, make_plan
    from planner.contract.settings import CRITERIA, Costs, Goal, PlanSettings

    progress = not args.quiet
    mission = None
    if args.mission is not None:
        from planner.contract.mission import load_mission

        mission = load_mission(args.mission)
    # Forecast: the flag, else the mission's source.
    forecast_path = args.forecast[0] if args.forecast else None
    ensemble = tuple(args.forecast[1:]) if args.forecast else ()
    time_index, time_iso = args.time_index, args.time
    variables = tuple(args.variables) if args.variables else None
    grid_file = args.grid_file
    if forecast_path is None and mission is not None:
        forecast_path = _mission_forecast(mission, out_dir=(args.out or Path(mission.name + ".lrpt")).parent)
        if time_index is None and time_iso is None:
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
        nx, ny = nx or mission.region.nx, ny or mission.region.ny
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
    costs = base.costs
    if args.costs:
        fields = {"drift": costs.drift, "forward": costs.forward, "rotate": costs.rotate, "glide": costs.glide}
        fields.update(args.costs)
        costs = Costs(**fields)
    model = args.model or base.model
    criterion = args.criterion or base.criterion
    if criterion not in CRITERIA[model]:
        source = "" if args.criterion else f" (from {mission.path if mission is not None else 'the default'}; give --criterion)"
        raise LrauvError(f"--criterion: the {model} model has {' and '.join(CRITERIA[model])}; got {criterion!r}{source}")
    settings = replace(
        base,
        model=model,
        criterion=criterion,
        uncertainty=args.uncertainty or base.uncertainty,
        costs=costs,
        calm_speed_m_s=base.calm_speed_m_s if args.calm_speed is None else args.calm_speed,
    )
    request = PlanRequest(
        forecast_path=forecast_path, goal=goal, depths_m=tuple(float(d) for d in depths), settings=settings,
        bbox=bbox, nx=nx, ny=ny, time_index=time_index, time_iso=time_iso, variables=variables,  # type: ignore[arg-type]
        grid_file=grid_file, ensemble=ensemble,
    )
    out = args.out or Path((mission.name if mission else "plan") + ".lrpt")
    t0 = time.perf_counter()
    physical = settings.model == "physical"
    if progress:
        how = f"physical, {settings.criterion}" if physical else f"{settings.criterion}, {settings.uncertainty}"
        print(f"planning on {forecast_path} ({how})", file=sys.stderr)
    from planner.pipeline import members_of

    refs = members_of(request)  # the file headers are read once, here
    request = replace(request, members=tuple(refs))
    if len(refs) > 1:
        from planner.cluster import open_runner

        with open_runner(args.scheduler, workers=args.workers) as runner:
            if progress:
                print(f"  {len(refs)} forecast members, sampled: {runner.describe()}", file=sys.stderr)
            result = make_plan(request, progress=progress, runner=runner)
    else:
        result = make_plan(request, progress=progress)
    data = result.table.to_bytes(compress=not args.no_compress)
    from planner.contract.atomic import write_atomic

    write_atomic(out, data)
    sol = result.solution
    water_states = int(result.model.water.sum()) * 8
    reachable = int(sol.reachable.sum())
    raw = len(result.table.to_bytes(compress=False))
    print(f"table      {out}  ({len(data):,} bytes; {raw:,} uncompressed; {result.grid.n_states:,} states)")
    print(f"forecast   {result.table.forecast_source} [{result.table.forecast_identity}] step {result.time_index}"
          f" ({result.table.forecast_time or 'no reference date'})")
    print(f"grid       {result.grid.nx} x {result.grid.ny} cells x {result.grid.n_layers} layers"
          f" ({', '.join(f'{d:g}' for d in result.grid.depth_m)} m) x 8 headings")
    for line in _model_lines(result):
        print(line)
    print(f"reachable  {reachable:,} of {water_states:,} water states ({reachable / max(water_states, 1):.1%})")
    start = None if args.start is None else _start_state(result, args.start)
    if start is not None:
        print(_start_line(result, args.start, start))
    t = result.timings_s
    stages = f"load {t['load_s']:.2f} s, resample {t['resample_s']:.2f} s, plan {t['plan_s']:.3f} s"
    if "transitions_s" in t:  # the physical model's plan time: sampling the transitions, then solving
        stages += f" (transitions {t['transitions_s']:.2f} s, solve {t['plan_s'] - t['transitions_s']:.3f} s)"
    print(f"time       {stages}, total {time.perf_counter() - t0:.2f} s")
    if args.export_values:
        print(f"values     {export_values(result, args.export_values)}")
    if args.plot:
        from planner.shore.plots import default_start, plot_all

        start = default_start(sol) if start is None else start
        layer = args.plot_layer
        if layer is not None and not 0 <= layer < result.grid.n_layers:
            raise LrauvError(f"--plot-layer: expected 0..{result.grid.n_layers - 1}; got {layer}")
        if not 0 <= args.plot_heading < 8:
            raise LrauvError(f"--plot-heading: expected 0..7 (0 = east, counter-clockwise); got {args.plot_heading}")
        paths = plot_all(result.u_m_s, result.v_m_s, sol, args.plot, start=start, heading=args.plot_heading, layer=layer)
        for p in paths:
            print(f"picture    {p}")
    return 0


def _model_lines(result) -> list[str]:  # type: ignore[no-untyped-def]
    """What was planned, for the summary: the paper model's settings, or the physical model's figures."""
    s = result.model.settings
    if s.model != "physical":
        c = s.costs
        return [f"model      paper, {s.criterion}, {s.uncertainty} uncertainty; costs drift {c.drift}, forward"
                f" {c.forward}, rotate {c.rotate}, glide {c.glide}"]
    m, sol, v = result.model, result.solution, s.vehicle
    lines = [f"model      physical, {s.criterion}; costs in Wh (hotel {v.hotel_w:g} W, propulsion {v.propulsion_w:g} W"
             f" at {v.cruise_speed_m_s:g} m/s, buoyancy {v.buoyancy_w:g} W)",
             f"samples    {m.n_pairs:,} state-actions, {m.samples_per_action} samples per action"
             f" ({s.physical.start_points}x{s.physical.start_points} start points x {s.physical.error_members + 1}"
             f" currents{f' x {m.members} forecast members' if m.members > 1 else ''}),"
             f" currents {m.refine}x finer than the grid"]
    if s.criterion == "expected":
        lines.append(f"solve      policy iteration: {sol.iterations} iterations, residual {sol.residual_wh:.2g} Wh")
    return lines


def _start_line(result, given: list[float], start: tuple[int, int, int, int]) -> str:  # type: ignore[no-untyped-def]
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


def _start_state(result, start: list[float]) -> tuple[int, int, int, int]:  # type: ignore[no-untyped-def]
    lon, lat, depth, heading = start
    cell = result.table.locate(lat, lon, depth)
    if cell is None:
        raise LrauvError(f"--start: ({lon:g}, {lat:g}, {depth:g} m) is outside the planning grid")
    l, j, i = cell
    if not result.model.water[l, j, i]:
        raise LrauvError(f"--start: ({lon:g}, {lat:g}, {depth:g} m) is on land")
    return (l, j, i, result.table.heading_index(j, heading))


def _mission_forecast(mission, *, out_dir: Path) -> Path:  # type: ignore[no-untyped-def]
    """The forecast file a mission names: its file, the newest file in its directory, or a generated one."""
    src = mission.forecast
    if src.file is not None:
        return src.file
    if src.directory is not None:
        files = sorted(src.directory.glob("*.nc"), key=lambda p: (p.stat().st_mtime, p.name))
        if not files:
            raise LrauvError(f"{mission.path}: forecast.directory {src.directory} holds no .nc files")
        return files[-1]
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    path = out_dir / f"synthetic_seed{src.synthetic_seed}_{src.synthetic_hours}h.nc"
    if not path.exists():
        write_synthetic(path, SyntheticSettings(seed=src.synthetic_seed, hours=src.synthetic_hours))
    return path


if __name__ == "__main__":
    sys.exit(main())
