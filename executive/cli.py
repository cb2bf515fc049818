"""``lrauv exec`` (run the executive) and ``lrauv log recover`` (repair a killed executive's log).

Argument parsing only; the work is in ``executive.loop`` and ``executive.recorder``.
Importing this module loads nothing heavy: the executive never imports xarray or scipy.
"""

from __future__ import annotations

import argparse
import math
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path

from executive.helm import HelmConfig
from planner.errors import PlannerError
from planner.table import PolicyTable


def add_parsers(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    ex = sub.add_parser("exec", help="run the onboard executive against a vehicle over MAVLink")
    ex.add_argument("--table", type=Path, required=True, help="policy table (.lrpt) from `lrauv plan`")
    ex.add_argument("--mission", type=Path, help="mission YAML: vehicle figures, on_arrival and safety limits")
    ex.add_argument("--link", default="udpout:127.0.0.1:14560",
                    help="pymavlink address of the autopilot (default udpout:127.0.0.1:14560; ArduSub SITL: tcp:127.0.0.1:5760)")
    ex.add_argument("--log", type=Path, help="MCAP log to write (default out/exec-<UTC time>.mcap)")
    ex.add_argument("--on-arrival", choices=["hold", "surface", "drift"], help="override the mission's on_arrival")
    ex.add_argument("--exit-on-arrival", action="store_true", help="stop after the goal is reached (and --linger-s)")
    ex.add_argument("--linger-s", type=float, default=10.0, help="vehicle seconds of the arrival behaviour before exiting")
    ex.add_argument("--max-wall-s", type=float, help="stop after this much wall time")
    ex.add_argument("--max-vehicle-h", type=float, help="stop after this much vehicle time")
    ex.add_argument("--telemetry-hz", type=float, default=2.0,
                    help="rate asked for GLOBAL_POSITION_INT and ATTITUDE, in vehicle time (default 2)")
    ex.add_argument("--quiet", action="store_true")

    log = sub.add_parser("log", help="MCAP log tools")
    lsub = log.add_subparsers(dest="log_command", required=True)
    rec = lsub.add_parser("recover", help="rebuild a readable log from one left by a killed executive")
    rec.add_argument("source", type=Path)
    rec.add_argument("dest", type=Path, nargs="?", help="output (default SOURCE.recovered.mcap)")


def run(args: argparse.Namespace) -> int:
    if args.command == "log":
        from executive.recorder import recover

        r = recover(args.source, args.dest)
        state = "complete" if r.complete else f"truncated at byte {r.truncated_at_byte}"
        last = "none" if r.last_log_time_s is None else f"{r.last_log_time_s:.1f} s"
        print(f"recovered {r.messages:,} messages on {r.channels} channels from {r.source} ({state});"
              f" last log time {last}; wrote {r.output}")
        return 0
    return _exec(args)


def _exec(args: argparse.Namespace) -> int:
    from executive.loop import ExecConfig, Executive

    data = _read(args.table)
    table = PolicyTable.from_bytes(data, name=str(args.table))
    helm = HelmConfig()
    if args.mission is not None:
        helm = _helm_config(args.mission, table)
    if args.on_arrival:
        helm = replace(helm, on_arrival=args.on_arrival)
    if not (math.isfinite(args.telemetry_hz) and 0.1 <= args.telemetry_hz <= 50):
        raise PlannerError(f"--telemetry-hz: expected 0.1 to 50 Hz; got {args.telemetry_hz}")
    fast = {"GLOBAL_POSITION_INT", "ATTITUDE"}
    rates = tuple((name, 1.0 / args.telemetry_hz if name in fast else s) for name, s in helm.rates)
    helm = replace(helm, rates=rates)
    for name in ("linger_s", "max_wall_s", "max_vehicle_h"):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise PlannerError(f"--{name.replace('_', '-')}: expected a non-negative number; got {value}")
    log_path = args.log or Path("out") / time.strftime("exec-%Y%m%dT%H%M%SZ.mcap", time.gmtime())
    log_path.parent.mkdir(parents=True, exist_ok=True)
    config = ExecConfig(
        link=args.link, log_path=log_path, helm=helm, exit_on_arrival=args.exit_on_arrival, linger_s=args.linger_s,
        max_wall_s=args.max_wall_s, max_vehicle_s=None if args.max_vehicle_h is None else args.max_vehicle_h * 3600.0,
    )
    meta = {"executive": {"table": str(args.table), "table_crc32": f"{table.crc32:08x}", "link": args.link,
                          "mission": str(args.mission or ""), "forecast_identity": table.forecast_identity,
                          "forecast_time": table.forecast_time or ""}}
    try:
        executive = Executive(config, table, table_bytes=data, metadata=meta)
    except OSError as exc:
        raise PlannerError(f"--link {args.link}: cannot open: {exc}") from None
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    if not args.quiet:
        print(f"lrauv exec: table {args.table} (crc {table.crc32:08x}), link {args.link}, log {log_path}", flush=True)
    s = executive.run(stop)
    if not args.quiet:
        energy = "unknown" if s.energy_used_wh is None else f"{s.energy_used_wh:.1f} Wh"
        took = "-" if s.mission_time_s is None else f"{s.mission_time_s / 3600:.2f} h vehicle time"
        print(f"goal       {'reached' if s.reached else 'not reached'} ({took}); stopped: {s.reason}; phase {s.final_phase}")
        print(f"energy     {energy}")
        print(f"run        {s.vehicle_time_s / 3600:.2f} h vehicle time in {s.wall_s:.1f} s wall;"
              f" {s.decisions:,} decisions, {s.messages_in:,} messages in ({s.messages_bad} bad), {s.commands_out:,} out")
        if s.decision_median_us is not None:
            print(f"latency    decision median {s.decision_median_us:.0f} us, p99 {s.decision_p99_us:.0f} us"
                  f" (with MCAP writes p99 {s.message_p99_us:.0f} us)")
        print(f"log        {s.log_path}", flush=True)
    return 0 if s.reached or not args.exit_on_arrival else 1


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise PlannerError(f"{path}: cannot read the policy table: {exc.strerror or exc}") from None


def _helm_config(mission_path: Path, table: PolicyTable) -> HelmConfig:
    """The helm's figures from a mission whose first goal is the table's goal."""
    from planner.mission import load_mission

    m = load_mission(mission_path)
    first = m.goals[0]
    goal = first.goal
    if (abs(goal.lat_deg - table.goal_lat_deg) > 1e-6 or abs(goal.lon_deg - table.goal_lon_deg) > 1e-6
            or abs(goal.depth_m - table.goal_depth_m) > 1e-6):
        raise PlannerError(
            f"{mission_path}: goals[0] ({goal.lon_deg:g}, {goal.lat_deg:g}, {goal.depth_m:g} m) does not match the table's goal"
            f" ({table.goal_lon_deg:g}, {table.goal_lat_deg:g}, {table.goal_depth_m:g} m): plan the table for this mission")
    v, s = m.vehicle, m.safety
    return HelmConfig(
        cruise_speed_m_s=v.cruise_speed_m_s, yaw_rate_deg_s=v.yaw_rate_deg_s, glide_rate_m_s=v.glide_rate_m_s,
        on_arrival=first.on_arrival, link_loss_timeout_s=s.link_loss_timeout_s, max_mission_time_s=s.max_mission_time_s,
        min_battery_pct=s.min_battery_pct, max_depth_m=s.max_depth_m,
    )
