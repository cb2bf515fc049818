"""``lrauv upload MISSION.yaml --to ADDRESS``: send a mission's goals and tables to a running executive
(``planner.shore.upload``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from planner.contract.arguments import Subcommands, mavlink_id, seconds


def add_parser(sub: Subcommands) -> None:
    up = sub.add_parser("upload", help="upload a mission's goals and tables to a running executive over MAVLink")
    up.add_argument("mission", type=Path, help="mission YAML")
    up.add_argument("--to", required=True, metavar="ADDRESS",
                    help="pymavlink address of the executive's ground-station link, e.g. udpout:127.0.0.1:14551")
    up.add_argument("--table", type=Path, action="append", default=[],
                    help="a ready policy table for one of the goals (repeatable); other goals are planned here")
    up.add_argument("--forecast", type=Path, help="forecast to plan on (default: the mission's source)")
    up.add_argument("--target-system", type=mavlink_id, help="the executive's MAVLink system (default 1)")
    up.add_argument("--target-component", type=mavlink_id, help="the executive's MAVLink component (default 191)")
    up.add_argument("--timeout-s", type=seconds, default=5.0, help="MAVLink FTP: seconds to wait for each reply before resending (default 5)")
    up.add_argument("--signing-key-file", type=Path, metavar="KEY",
                    help="MAVLink 2 signing key (32 bytes, or 64 hex digits) to sign with"
                         " (default: the mission's signing section; docs/missions.md)")
    up.add_argument("--quiet", action="store_true", help="print nothing but errors")


def run(args: argparse.Namespace) -> int:
    from planner.contract.columns import fit, say as print_fitted
    from planner.shore.upload import upload_mission

    say = None if args.quiet else (lambda text: print(fit(text), file=sys.stderr, flush=True))
    report = None if args.quiet else print_fitted  # the summary of each goal planned on shore, as `lrauv plan` prints it
    upload_mission(args.mission, to=args.to, tables=args.table, forecast=args.forecast, target_system=args.target_system,
                   target_component=args.target_component, timeout_s=args.timeout_s,
                   signing_key_file=args.signing_key_file, say=say, report=report)
    return 0
