"""``lrauv sim`` / ``python -m vehicle_sim``: run the simulated vehicle on a truth forecast.

Parses the flags once into a ``SimConfig`` and a ``World`` (or, with several ``--forecast``
files or a directory, a ``TruthSequence``: each forecast is the truth from its own first
time until the next one's), prints one ready line to stdout
(``lrauv sim: listening on udp HOST:PORT``, the port really bound), then runs until
``--duration-s`` simulated seconds have passed or SIGTERM/SIGINT arrives (exit 0 either way,
the track flushed). Bad input raises ``SimError`` (a ``SimulatorError``); ``main`` prints it as
one line, ``lrauv sim: error: ...``, and exits with status 2.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from planner.contract.arguments import CommandParser, Subcommands
from planner.contract.columns import fit
from planner.contract.errors import LrauvError, SimulatorError

if TYPE_CHECKING:  # at run time imported where used, as below: registering the parser loads neither
    from vehicle_sim.endpoint import SimConfig
    from vehicle_sim.world import Truth

EXIT_BAD_INPUT = 2
READY_PREFIX = "lrauv sim: listening on udp "
FAILSAFE_CHOICES = ("surface", "alt_hold", "disarm", "warn")
PROFILE_CHOICES = ("lrauv", "ardusub")
# ArduSub's autotest start location (ArduPilot Tools/autotest/locations.txt), used with --calm.
_CALM_START = "-118.393867,33.810313"


class SimError(SimulatorError):
    """Bad simulator input; the message names the flag, the value and what was expected."""


def add_parser(subparsers: Subcommands) -> argparse.ArgumentParser:
    """Register the ``sim`` subcommand (for ``lrauv``)."""
    p = subparsers.add_parser("sim", help="run the simulated ArduSub-like vehicle (MAVLink 2 over UDP)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_arguments(p)
    return p


def _add_arguments(p: argparse.ArgumentParser) -> None:
    # Values are parsed in `run`, so that every bad value gets the same one-line error.
    p.add_argument("--forecast", type=Path, action="append", metavar="FILE_OR_DIR",
                   help="netCDF forecast used as the true currents; repeat the flag (or give a directory: every "
                        "*.nc in it) for a sequence of dated forecasts, each the truth from its own first time "
                        "until the next one's (e.g. a later issue taking over)")
    p.add_argument("--calm", action="store_true", help="no forecast: still water everywhere")
    p.add_argument("--start", help="LON,LAT of the vehicle at boot (with --calm: ArduSub's autotest site)")
    p.add_argument("--depth-m", default="0", help="depth at boot, m (default 0)")
    p.add_argument("--heading-deg", default="0", help="heading at boot, compass degrees (default 0)")
    p.add_argument("--start-time", help="UTC time of boot, ISO 8601 (default: the forecast's first time)")
    p.add_argument("--speedup", default="1", help="simulated seconds per wall second, like SITL (default 1)")
    p.add_argument("--lockstep", action=argparse.BooleanOptionalAction, default=None,
                   help="never step the physics past what the executive has reported handled (TIMESYNC), plus "
                        "--lockstep-slack-s: the same dive on a quiet or a busy machine (default: on when "
                        "--speedup > 1; before the first report the vehicle waits up to 30 s of wall time)")
    p.add_argument("--lockstep-slack-s", default="0",
                   help="with --lockstep: simulated seconds the physics may run beyond the executive's report; "
                        "0 (default) makes a dive repeat exactly, a few seconds ride out a lossy link")
    p.add_argument("--listen", default="127.0.0.1:14560", help="HOST:PORT to bind; port 0 = any free port")
    p.add_argument("--seed", default="0", help="seed of the sensor noise (default 0)")
    p.add_argument("--profile", default="lrauv",
                   help="ardusub: every ArduSub-faithful choice at once (its other default streams, the GCS failsafe "
                        "disarms, an idle vehicle floats up), for a parity test with ArduSub SITL; lrauv (default): "
                        "the simulator's defaults. Flags given explicitly win over the profile")
    p.add_argument("--position-delay-s", default="41", help="seconds until the EKF has a position (default 41)")
    p.add_argument("--gps-delay-s", default="9",
                   help="seconds until the GPS is found; before, positions read lat = lon = 0 (default 9)")
    p.add_argument("--heartbeat-timeout-s", default="5",
                   help="GCS heartbeat failsafe timeout, simulated s; 0 disables (default 5)")
    p.add_argument("--gcs-sysid", default="255",
                   help="MAV_GCS_SYSID: the only system whose heartbeats feed the failsafe; it never fires before "
                        "one was heard (default 255, a ground station; 1 makes the executive's count)")
    p.add_argument("--failsafe", help=f"heartbeat failsafe action: {'|'.join(FAILSAFE_CHOICES)} "
                                      "(default surface; disarm with --profile ardusub)")
    p.add_argument("--ardusub-streams", action=argparse.BooleanOptionalAction, default=None,
                   help="also stream ArduSub's 19 other default messages (AHRS2, SIMSTATE, NAMED_VALUE_FLOAT, ...: "
                        "110 messages per vehicle second instead of 35; off by default, on with --profile ardusub)")
    p.add_argument("--duration-s", help="stop after this many simulated seconds (default: run until stopped)")
    p.add_argument("--track", type=Path, help="CSV of the true track, one row per simulated second")
    p.add_argument("--mission", type=Path,
                   help="mission YAML whose vehicle figures (speeds, rates, power) the simulated vehicle takes")
    p.add_argument("--quiet", action="store_true", help="no summary on stderr at the end")


def run(args: argparse.Namespace) -> int:
    """Run the simulator from parsed flags; raises ``SimError`` on bad input."""
    from vehicle_sim.endpoint import Simulator

    world, config, duration_s = _configure(args)
    try:
        sim = Simulator(world, config)
    except OSError as exc:
        if config.track_path is not None and exc.filename is not None:
            raise SimError(f"--track {config.track_path}: cannot write ({exc.strerror or exc})") from exc
        raise SimError(f"--listen {args.listen}: cannot bind a UDP socket ({exc.strerror or exc}); "
                       "expected a free local HOST:PORT") from exc
    print(f"{READY_PREFIX}{sim.host}:{sim.port}", flush=True)
    stop = threading.Event()
    restore = _install_stop_handlers(stop)
    wall0 = time.monotonic()
    try:
        sim.run(duration_s, stop_event=stop)
    finally:
        sim.close()
        restore()
    if not args.quiet:
        wall = max(time.monotonic() - wall0, 1e-9)
        state = "armed" if sim.armed else "disarmed"
        print(fit(f"lrauv sim: stopped at {sim.time_s:.1f} s simulated after {wall:.1f} s wall "
                  f"({sim.time_s / wall:.0f}x); {sim.mode.name} {state}, {sim.energy_used_wh:.1f} Wh used, "
                  f"{sim.stats.parse_errors} undecodable input(s)"
                  + (f"; lockstep: waited {sim.stats.lockstep_waits} times, ran free {sim.stats.lockstep_expired},"
                     f" resent {sim.stats.lockstep_resends}" if config.lockstep_slack_s is not None else "")),
              file=sys.stderr)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m vehicle_sim [sim] ...``; returns the exit status."""
    parser = CommandParser(prog="python -m vehicle_sim", description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    _add_arguments(parser)
    args_list = list(sys.argv[1:] if argv is None else argv)
    if args_list[:1] == ["sim"]:
        args_list = args_list[1:]
    args = parser.parse_args(args_list)
    try:
        return run(args)
    except LrauvError as exc:
        print(f"lrauv sim: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


def wait_ready(sim: subprocess.Popen[str], *, timeout_s: float = 60.0) -> int:
    """The UDP port of a started ``lrauv sim`` child, read from its ready line."""
    assert sim.stdout is not None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = sim.stdout.readline()
        if line.startswith(READY_PREFIX):
            return int(line[len(READY_PREFIX):].strip().rsplit(":", 1)[1])
        if not line and sim.poll() is not None:
            err = sim.stderr.read() if sim.stderr else ""
            raise SimError(f"the simulator exited with status {sim.returncode}: {err.strip()}")
    raise SimError(f"the simulator did not report its port within {timeout_s:g} s")


# -- parsing ----------------------------------------------------------------------------------


def _configure(args: argparse.Namespace) -> tuple[Truth, SimConfig, float | None]:
    """(World or TruthSequence, SimConfig, duration_s or None) from the flags."""
    from dataclasses import replace

    from vehicle_sim.autopilot import AutopilotSettings, FailsafeAction
    from vehicle_sim.endpoint import SimConfig
    from vehicle_sim.profile import Profile, with_profile
    from vehicle_sim.world import World, load_truth

    speedup = _number(args.speedup, "--speedup", "a number > 0", lambda x: x > 0)
    host, port = _listen(args.listen)
    seed = _integer(args.seed, "--seed")
    depth_m = _number(args.depth_m, "--depth-m", "a depth in metres >= 0", lambda x: x >= 0)
    heading = _number(args.heading_deg, "--heading-deg", "a compass heading in degrees", lambda x: True)
    delay = _number(args.position_delay_s, "--position-delay-s", "seconds >= 0", lambda x: x >= 0)
    gps_delay = _number(args.gps_delay_s, "--gps-delay-s", "seconds >= 0", lambda x: x >= 0)
    gcs_sysid = _integer(args.gcs_sysid, "--gcs-sysid")
    if not 1 <= gcs_sysid <= 255:
        raise SimError(f"--gcs-sysid {args.gcs_sysid!r}: expected a MAVLink system id 1..255")
    if args.profile not in PROFILE_CHOICES:
        raise SimError(f"--profile {args.profile!r}: expected one of {', '.join(PROFILE_CHOICES)}")
    hb_timeout = _number(args.heartbeat_timeout_s, "--heartbeat-timeout-s", "seconds >= 0 (0 disables)",
                         lambda x: x >= 0)
    slack = _number(args.lockstep_slack_s, "--lockstep-slack-s", "simulated seconds >= 0", lambda x: x >= 0)
    lockstep = speedup > 1 if args.lockstep is None else args.lockstep
    duration = None
    if args.duration_s is not None:
        duration = _number(args.duration_s, "--duration-s", "simulated seconds > 0", lambda x: x > 0)
    if args.failsafe is not None and args.failsafe not in FAILSAFE_CHOICES:
        raise SimError(f"--failsafe {args.failsafe!r}: expected one of {', '.join(FAILSAFE_CHOICES)}")

    world: Truth
    if args.calm:
        if args.forecast is not None:
            raise SimError("--calm and --forecast: expected one of them, not both")
        world = World.calm()
        start = args.start or _CALM_START
    else:
        if args.forecast is None:
            raise SimError("--forecast: expected a netCDF forecast file (or --calm for still water)")
        if args.start is None:
            raise SimError("--start: expected LON,LAT of the vehicle at boot, e.g. --start -118.10,33.45")
        world = load_truth(args.forecast)  # --forecast is repeatable: a list
        start = args.start
    lon, lat = _lon_lat(start)
    offset_s = _start_offset(args.start_time, world)
    _check_start(world, lon, lat, depth_m, offset_s, start)

    config = SimConfig(
        start_lat_deg=lat, start_lon_deg=lon, start_depth_m=depth_m, start_heading_deg=heading % 360.0,
        start_offset_s=offset_s, speedup=speedup, host=host, port=port, seed=seed,
        autopilot=AutopilotSettings(position_delay_s=delay, gps_delay_s=gps_delay, heartbeat_timeout_s=hb_timeout,
                                    gcs_system=gcs_sysid),
        track_path=args.track, lockstep_slack_s=slack if lockstep else None,
    )
    if getattr(args, "mission", None) is not None:  # one set of vehicle figures for planner and simulator
        from planner.contract.mission import load_mission

        config = replace(config, params=load_mission(args.mission).settings.vehicle)
    config = with_profile(config, Profile(args.profile))
    if args.failsafe is not None:  # explicit flags win over the profile
        config = replace(config, autopilot=replace(config.autopilot, failsafe=FailsafeAction(args.failsafe)))
    if args.ardusub_streams is not None:
        config = replace(config, ardusub_streams=args.ardusub_streams)
    return world, config, duration


def _number(text: str, flag: str, expected: str, ok: Callable[[float], bool]) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and ok(value)):
        raise SimError(f"{flag} {text!r}: expected {expected}")
    return value


def _integer(text: str, flag: str) -> int:
    try:
        return int(text)
    except (TypeError, ValueError):
        raise SimError(f"{flag} {text!r}: expected an integer") from None


def _listen(text: str) -> tuple[str, int]:
    host, sep, port_text = text.rpartition(":")
    try:
        port = int(port_text)
    except ValueError:
        port = -1
    if not sep or not host or not 0 <= port <= 65535:
        raise SimError(f"--listen {text!r}: expected HOST:PORT with a port 0..65535, e.g. 127.0.0.1:14560")
    return host, port


def _lon_lat(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        lon, lat = (float(p) for p in parts)
    except ValueError:
        lon = lat = math.nan
    if not (math.isfinite(lon) and math.isfinite(lat) and -180 <= lon <= 360 and -90 <= lat <= 90):
        raise SimError(f"--start {text!r}: expected LON,LAT in degrees, e.g. -118.10,33.45")
    return lon, lat


def _start_offset(text: str | None, world: Truth) -> float:
    """Seconds from the forecast's first time to ``--start-time`` (0 without the flag)."""
    if text is None:
        return 0.0
    if not world.dated:
        raise SimError(f"--start-time {text!r}: {world.source} has no reference date; leave --start-time out")
    try:
        when = dt.datetime.fromisoformat(text.strip())
    except ValueError:
        raise SimError(f"--start-time {text!r}: expected an ISO 8601 time such as 2026-01-15T06:00:00Z") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=dt.UTC)
    offset = when.timestamp() - world.start_unix_s
    if not 0.0 <= offset <= world.duration_s:
        first = dt.datetime.fromtimestamp(world.start_unix_s, dt.UTC)
        last = first + dt.timedelta(seconds=world.duration_s)
        raise SimError(f"--start-time {text!r}: outside the forecast ({first:%Y-%m-%dT%H:%M:%SZ} .. "
                       f"{last:%Y-%m-%dT%H:%M:%SZ}); expected a time within it")
    return offset


def _check_start(world: Truth, lon: float, lat: float, depth_m: float, offset_s: float, text: str) -> None:
    box = world.bbox
    if not (box.west_deg <= lon <= box.east_deg and box.south_deg <= lat <= box.north_deg):
        raise SimError(f"--start {text}: outside the forecast (lon {box.west_deg:.4f}..{box.east_deg:.4f}, "
                       f"lat {box.south_deg:.4f}..{box.north_deg:.4f}); expected a point inside it")
    if depth_m > world.max_depth_m:
        raise SimError(f"--depth-m {depth_m:g}: deeper than the forecast's deepest level ({world.max_depth_m:g} m)")
    if not world.is_water(lat, lon, depth_m, offset_s):
        raise SimError(f"--start {text}: on land at {depth_m:g} m in {world.source_at(offset_s)}; "
                       "expected a water point")


def _install_stop_handlers(stop: threading.Event) -> Callable[[], None]:
    """SIGTERM and SIGINT set ``stop`` (clean exit, track flushed); returns a function restoring the old ones."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    old = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    for sig in old:
        signal.signal(sig, lambda *_: stop.set())

    def restore() -> None:
        for sig, handler in old.items():
            signal.signal(sig, handler)

    return restore
