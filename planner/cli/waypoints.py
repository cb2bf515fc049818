"""``lrauv waypoints``: exchange a mission's goals with QGC WPL 110 files (``planner.shore.waypoints``).

``export MISSION.yaml OUT.waypoints [--home LON,LAT]`` writes home and the goals;
``import FILE.waypoints --mission BASE.yaml --out NEW.yaml`` writes BASE's YAML with
its ``goals:`` list replaced by the file's goals.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from planner.contract.arguments import floats
from planner.contract.columns import say


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Register ``waypoints`` (with ``export`` and ``import``) on an ``add_subparsers`` object."""
    parser = sub.add_parser("waypoints", help="export or import goals as QGC WPL 110 waypoint files",
                            description="Goals as MAVLink mission items in QGC WPL 110 files (docs/missions.md).")
    wsub = parser.add_subparsers(dest="waypoints_command", required=True)
    ex = wsub.add_parser("export", help="write a mission's goals as a waypoint file (item 0 is home)")
    ex.add_argument("mission", type=Path, help="mission YAML file")
    ex.add_argument("out", type=Path, help="waypoint file to write (QGC WPL 110)")
    ex.add_argument("--home", type=lambda t: tuple(floats(t, 2, "home")), metavar="LON,LAT", help="home position (default: the first goal's)")
    im = wsub.add_parser("import", help="write a mission with its goals replaced by a waypoint file's")
    im.add_argument("file", type=Path, help="waypoint file (QGC WPL 110)")
    im.add_argument("--mission", type=Path, required=True, help="base mission YAML: everything but the goals")
    im.add_argument("--out", type=Path, required=True, help="mission YAML to write")
    return parser


def run(args: argparse.Namespace) -> int:
    """Run ``lrauv waypoints``; LrauvError on bad input (the CLI exits with status 2)."""
    from planner.shore.waypoints import export_waypoints, import_waypoints

    if args.waypoints_command == "export":
        path, n_goals = export_waypoints(args.mission, args.out, home=args.home)
        say(f"wrote {path} (home and {n_goals} goal{'s' if n_goals != 1 else ''})")
        return 0
    path, n_goals = import_waypoints(args.file, args.mission, args.out)
    say(f"wrote {path} ({n_goals} goal{'s' if n_goals != 1 else ''} from {args.file})")
    return 0
