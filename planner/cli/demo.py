"""``lrauv demo``: the simulated vehicle and the executive as two processes over UDP, to the goal
(``planner.shore.demo``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from planner.contract.arguments import Subcommands
from planner.contract.columns import say


def add_parser(sub: Subcommands) -> None:
    p = sub.add_parser("demo", help="run the simulated vehicle and the executive over UDP to the goal")
    p.add_argument("--table", type=Path, required=True, help="policy table from `lrauv plan`")
    p.add_argument("--mission", type=Path, required=True, help="mission YAML (vehicle, safety, goal)")
    p.add_argument("--truth", type=Path, required=True, help="forecast the simulator uses as the true currents")
    p.add_argument("--start", required=True, help="LON,LAT of the vehicle at the start")
    p.add_argument("--depth-m", type=float, default=0.0, help="depth of the vehicle at the start, m (default 0)")
    p.add_argument("--heading-deg", type=float, default=0.0,
                   help="heading at the start, degrees clockwise from north (default 0)")
    p.add_argument("--speedup", type=float, default=1000.0, help="simulator speedup over real time (default 1000)")
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="directory for the log, track and pictures")
    p.add_argument("--timeout-s", type=float, default=170.0, help="wall-time limit for the run")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulator's sensor noise (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr (drawn only on a terminal)")


def run(args: argparse.Namespace) -> int:
    from planner.cli import EXIT_BAD_INPUT
    from planner.cli.progress_bar import announcer, bars
    from planner.shore.demo import check_inputs, draw_track, run_closed_loop

    check_inputs(table=args.table, mission=args.mission, truth=args.truth, timeout_s=args.timeout_s,
                 speedup=args.speedup)
    args.out.mkdir(parents=True, exist_ok=True)
    with bars(quiet=args.quiet) as meter:
        announcer(meter, quiet=args.quiet)(f"closed loop: simulator and executive at {args.speedup:g}x, up to"
                                           f" {args.timeout_s:g} s of wall time")
        result = run_closed_loop(
            table=args.table, mission=args.mission, truth=args.truth, start=args.start, depth_m=args.depth_m,
            heading_deg=args.heading_deg, speedup=args.speedup, out=args.out, timeout_s=args.timeout_s,
            seed=args.seed, meter=meter,
        )
    if result.exec_status == EXIT_BAD_INPUT:  # the executive refused its input: its error, and no pictures of no run
        sys.stderr.write(result.exec_output)
        return result.exec_status
    sys.stdout.write(result.exec_output)
    picture = draw_track(args.table, result.track_csv, args.out / "pictures" / "track.png", truth=args.truth)
    say(f"track      {result.track_csv}")
    say(f"picture    {picture}")
    say(f"layout     {result.layout_path} (Foxglove: Layouts, Import from file; then open {result.log_path})")
    say(f"demo       {result.wall_s:.1f} s wall in all")
    return result.exec_status
