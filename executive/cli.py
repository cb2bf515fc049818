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
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from executive.helm import HelmConfig
from planner.contract.arguments import Subcommands
from planner.contract.columns import say
from planner.contract.errors import ExecutiveError
from planner.contract.table import PolicyTable, read_table_file

if TYPE_CHECKING:  # at run time imported where used, as below
    from executive.goal_tables import MissionPlan
    from executive.uploads import UploadQuota
    from planner.contract.mission import Mission
    from planner.contract.settings import OnArrival


def add_parser(sub: Subcommands) -> None:
    """Register ``exec`` and ``log`` (one module runs both)."""
    ex = sub.add_parser("exec", help="run the onboard executive against a vehicle over MAVLink")
    ex.add_argument("--table", type=Path, action="append",
                    help="policy table (.lrpt) from `lrauv plan`; repeat for the goals of a multi-goal mission")
    ex.add_argument("--state-dir", type=Path, metavar="DIR",
                    help="keep the durable state here (goals, tables, active goal) for --resume"
                         " (default: the log's name + -state, beside the log)")
    ex.add_argument("--resume", type=Path, metavar="STATE_DIR",
                    help="go on after a crash: reload goals, tables and the active goal from this state directory,"
                         " recover the killed run's log, and write a new one (both beside --log when given)")
    ex.add_argument("--mission", type=Path,
                    help="mission YAML: goals, vehicle figures, safety limits; enables onboard replanning")
    ex.add_argument("--gcs", metavar="ADDRESS",
                    help="pymavlink address to hear a ground station on (e.g. udpin:0.0.0.0:14551): uploads, and the"
                         " autopilot's traffic both ways as through a MAVLink router (docs/ground-station.md)")
    ex.add_argument("--watch", type=Path, metavar="DIR",
                    help="replan when a new forecast (*.nc) appears here (default: the mission's forecast.directory)")
    ex.add_argument("--work-dir", type=Path, help="uploaded forecasts and onboard plans (default: beside the log)")
    ex.add_argument("--replan-period-h", type=float, help="also replan this often on the latest forecast")
    ex.add_argument("--link", default="udpout:127.0.0.1:14560",
                    help="pymavlink address of the autopilot (default udpout:127.0.0.1:14560; ArduSub SITL: tcp:127.0.0.1:5760)")
    ex.add_argument("--log", type=Path, help="MCAP log to write (default out/exec-<UTC time>.mcap)")
    ex.add_argument("--on-arrival", choices=["hold", "surface", "drift"], help="override the mission's on_arrival at its last goal")
    ex.add_argument("--exit-on-arrival", action="store_true", help="stop after the goal is reached (and --linger-s)")
    ex.add_argument("--linger-s", type=float, default=10.0, help="vehicle seconds of the arrival behaviour before exiting")
    ex.add_argument("--max-wall-s", type=float, help="stop after this much wall time")
    ex.add_argument("--max-vehicle-h", type=float, help="stop after this much vehicle time")
    ex.add_argument("--telemetry-hz", type=float, default=2.0,
                    help="rate asked for GLOBAL_POSITION_INT and ATTITUDE, in vehicle time (default 2)")
    ex.add_argument("--signing-key-file", type=Path, metavar="KEY",
                    help="MAVLink 2 signing key (32 bytes, or 64 hex digits): uploads and commands must be signed with it"
                         " (default: the mission's signing section; docs/missions.md)")
    ex.add_argument("--upload-max-files", type=int, default=16, metavar="N",
                    help="storage quota of uploads: files held at once (default 16); more are refused")
    ex.add_argument("--upload-max-mb", type=float, default=64.0, metavar="MB",
                    help="storage quota of uploads: megabytes (MiB) held at once (default 64); more are refused")
    ex.add_argument("--quiet", action="store_true", help="no start and end summary on stdout")

    log = sub.add_parser("log", help="MCAP log tools")
    lsub = log.add_subparsers(dest="log_command", required=True)
    rec = lsub.add_parser("recover", help="rebuild a readable log from one left by a killed executive")
    rec.add_argument("source", type=Path, help="the log a killed executive left")
    rec.add_argument("dest", type=Path, nargs="?", help="output (default SOURCE.recovered.mcap)")


def run(args: argparse.Namespace) -> int:
    if args.command == "log":
        from executive.recorder import recover

        r = recover(args.source, args.dest)
        state = "complete" if r.complete else f"truncated at byte {r.truncated_at_byte}"
        last = "none" if r.last_log_time_s is None else f"{r.last_log_time_s:.1f} s"
        say(f"recovered {r.messages:,} messages on {r.channels} channels from {r.source} ({state});"
            f" last log time {last}; wrote {r.output}")
        return 0
    return _exec(args)


def _safety_stop(resumed: Any) -> Any:
    """The safety stop a resumed run saved (it holds until an operator clears it), as the helm's Situation."""
    from executive.state import Situation

    if resumed is None or resumed.safety_stop is None:
        return None
    try:
        return Situation(resumed.safety_stop)
    except ValueError:
        raise ExecutiveError(f"--resume: the saved safety_stop {resumed.safety_stop!r} is not a known limit;"
                             f" expected one of {', '.join(s.value for s in Situation)}") from None


def _exec(args: argparse.Namespace) -> int:
    from executive.loop import ExecConfig, Executive
    from executive.signing import load_key

    from executive import durable, goal_tables

    resumed = None
    mission_loaded = None
    if args.resume is not None:
        resumed = durable.load(args.resume)
        args.mission = args.mission or resumed.mission_path
        args.state_dir = args.state_dir or args.resume
    elif not args.table:
        raise ExecutiveError("exec: no table: give --table TABLE.lrpt (or --resume STATE_DIR after a crash)")
    paths = args.table or []
    blobs = [read_table_file(p) for p in paths]
    tables = [PolicyTable.from_bytes(data, name=str(p)) for p, data in zip(paths, blobs)]
    helm = HelmConfig()
    watch, period_s, replan_on_new = args.watch, None, True
    key = None
    if args.signing_key_file is not None:
        key = load_key(key_file=args.signing_key_file, where="--signing-key-file")
    if resumed is not None:
        plan = resumed.plan  # the goals and tables in use when the state was saved, not the mission file's
        tables = [t for t in plan.tables if t is not None]
        blobs = [resumed.blobs[t.crc32] for t in tables]
        on_arrival = plan.goal.on_arrival if plan.goal is not None else helm.on_arrival
        helm = replace(helm, on_arrival=on_arrival)
        if args.mission is not None:
            m = mission_loaded = _load_mission(args.mission)
            helm = replace(_helm_figures(m), on_arrival=on_arrival)
            if watch is None and m.forecast.directory is not None:
                watch = m.forecast.directory
            period_s, replan_on_new = m.replanning.period_s, m.replanning.on_new_forecast
            if key is None and m.signing is not None:
                key = load_key(key_file=m.signing.key_file, passphrase_env=m.signing.passphrase_env,
                               where=m.signing.where)
    elif args.mission is not None:
        helm, plan, mission = _mission_setup(args.mission, paths, tables, args.on_arrival)
        mission_loaded = mission
        if watch is None and mission.forecast.directory is not None:
            watch = mission.forecast.directory
        period_s, replan_on_new = mission.replanning.period_s, mission.replanning.on_new_forecast
        if key is None and mission.signing is not None:
            sg = mission.signing
            key = load_key(key_file=sg.key_file, passphrase_env=sg.passphrase_env, where=sg.where)
    else:
        if len(tables) > 1:
            raise ExecutiveError("--table: several tables need a --mission to say the order of their goals")
        if args.on_arrival:
            helm = replace(helm, on_arrival=args.on_arrival)
        plan = goal_tables.single(tables[0], on_arrival=helm.on_arrival)
    if args.replan_period_h is not None:
        if not (math.isfinite(args.replan_period_h) and args.replan_period_h > 0):
            raise ExecutiveError(f"--replan-period-h: expected a positive number of hours; got {args.replan_period_h}")
        period_s = args.replan_period_h * 3600.0
    if watch is not None and not watch.is_dir():
        raise ExecutiveError(f"--watch {watch}: not a directory")
    if not (math.isfinite(args.telemetry_hz) and 0.1 <= args.telemetry_hz <= 50):
        raise ExecutiveError(f"--telemetry-hz: expected 0.1 to 50 Hz; got {args.telemetry_hz}")
    fast = {"GLOBAL_POSITION_INT", "ATTITUDE"}
    rates = tuple((name, 1.0 / args.telemetry_hz if name in fast else s) for name, s in helm.rates)
    helm = replace(helm, rates=rates)
    for name in ("linger_s", "max_wall_s", "max_vehicle_h"):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise ExecutiveError(f"--{name.replace('_', '-')}: expected a non-negative number; got {value}")
    quota = _upload_quota(args.upload_max_files, args.upload_max_mb)
    log_path = args.log or Path("out") / time.strftime("exec-%Y%m%dT%H%M%SZ.mcap", time.gmtime())
    recovered = None
    if resumed is not None:
        log_path, recovered = _resume_log(resumed.log_path, args.log)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    state_dir = args.state_dir or log_path.with_name(log_path.stem + "-state")
    config = ExecConfig(
        coverage=None if mission_loaded is None else mission_loaded.region.bbox,
        link=args.link, log_path=log_path, helm=helm, exit_on_arrival=args.exit_on_arrival, linger_s=args.linger_s,
        max_wall_s=args.max_wall_s, max_vehicle_s=None if args.max_vehicle_h is None else args.max_vehicle_h * 3600.0,
        gcs_link=args.gcs, mission_path=args.mission, watch_dir=watch, work_dir=args.work_dir,
        replan_on_new_forecast=replan_on_new, replan_period_s=period_s, signing=key, state_dir=state_dir,
        upload_quota=quota,
    )
    table = plan.table
    assert table is not None
    meta = {"executive": {"table": ",".join(str(p) for p in paths), "table_crc32": f"{table.crc32:08x}",
                          "link": args.link, "gcs": args.gcs or "", "mission": str(args.mission or ""),
                          "forecast_identity": table.forecast_identity, "forecast_time": table.forecast_time or "",
                          "signing": "off" if key is None else f"required, key {key.fingerprint}",
                          "state_dir": str(state_dir)}}
    if resumed is not None:
        meta["resumed"] = {"state_dir": str(args.resume), "saved_utc": resumed.saved_utc,
                           "goal_index": str(plan.index), "previous_log": str(resumed.log_path or ""),
                           "recovered": recovered or ""}
    try:
        executive = Executive(config, plan, table_bytes={t.crc32: b for t, b in zip(tables, blobs)}, metadata=meta,
                              safety_stop=_safety_stop(resumed), tide=None if resumed is None else resumed.tide)
    except OSError as exc:
        raise ExecutiveError(f"--link {args.link} or --gcs {args.gcs}: cannot open: {exc}") from None
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    if not args.quiet:
        gcs = f", ground station on {args.gcs}" if args.gcs else ""
        signed = "" if key is None else f", signing required (key {key.fingerprint})"
        if resumed is not None:
            say(f"resumed    from {args.resume} (saved {resumed.saved_utc}): goal {plan.index} of {len(plan.goals)};"
                f" previous log {recovered or 'absent'}", flush=True)
        say(f"lrauv exec: {len(plan.goals)} goal(s), table crc {table.crc32:08x}, link {args.link}{gcs}{signed},"
            f" log {log_path}", flush=True)
    s = executive.run(stop)
    if not args.quiet:
        energy = "unknown" if s.energy_used_wh is None else f"{s.energy_used_wh:.1f} Wh"
        took = "-" if s.mission_time_s is None else f"{s.mission_time_s / 3600:.2f} h vehicle time"
        say(f"goal       {'reached' if s.reached else 'not reached'} ({took}); stopped: {s.reason}; phase {s.final_phase}")
        say(f"energy     {energy}")
        say(f"run        {s.vehicle_time_s / 3600:.2f} h vehicle time in {s.wall_s:.1f} s wall;"
            f" {s.decisions:,} decisions, {s.messages_in:,} messages in ({s.messages_bad} bad), {s.commands_out:,} out")
        if s.messages_not_logged:
            say(f"raw log    {s.messages_not_logged:,} unused autopilot messages counted, not logged raw")
        if s.decision_median_us is not None:
            say(f"latency    decision median {s.decision_median_us:.0f} us, p99 {s.decision_p99_us:.0f} us"
                f" (with MCAP writes p99 {s.message_p99_us:.0f} us)")
        if executive.swaps:
            say(f"plans      {len(executive.swaps)} swapped in: "
                + "; ".join(f"{w.get('source')} -> goal {w['goal_index']} table {w['table_crc32']}" for w in executive.swaps))
        if executive.signature_refusals:
            say("signing    refused " + ", ".join(f"{n:,} {verdict.value}"
                                                   for verdict, n in executive.signature_refusals.items()))
        if executive.gcs is not None:
            print(executive.router.summary().replace("ground station: ", "gcs        ", 1))
        dropped = executive.recorder.records_dropped
        lost = f" ({dropped:,} records dropped: the disk failed or fell behind)" if dropped else ""
        say(f"log        {s.log_path}{lost}", flush=True)
    return 0 if s.reached or not args.exit_on_arrival else 1


def _resume_log(previous: Path | None, given: Path | None) -> tuple[Path, str | None]:
    """The new log's path, and what became of the killed run's log (recovered up to its last record).

    With ``--log`` both go where it points: the killed run's disk may be the full one. The
    killed log is only read; a failure to recover it is noted, never a reason not to start.
    """
    from executive.recorder import LogError, is_complete, recover

    note = None
    if previous is not None and previous.exists():
        if given is not None and given.resolve() == previous.resolve():
            raise ExecutiveError(f"--log {given}: that is the killed run's log; give the resumed run another file")
        if is_complete(previous):
            note = f"{previous} (complete)"
        else:
            out = None
            if given is not None:  # beside the new log, not on the killed run's (maybe full) disk
                stem = given.parent / f"{previous.stem}.recovered"
                out = _unused(lambda n: stem.with_name(f"{stem.name}{'' if n == 1 else f'-{n}'}.mcap"))
            try:
                if out is not None:
                    out.parent.mkdir(parents=True, exist_ok=True)
                r = recover(previous, out)
            except (LogError, OSError) as exc:
                note = f"{previous}: not recovered ({exc}); recover it later with `lrauv log recover`"
            else:
                last = "none" if r.last_log_time_s is None else f"{r.last_log_time_s:.1f} s"
                note = (f"{previous}: {r.messages:,} messages up to vehicle time {last} recovered into {r.output}"
                        f" (cut at byte {r.truncated_at_byte:,})")
    if given is not None:
        return given, note
    base = previous if previous is not None else Path("out") / "exec.mcap"
    return _unused(lambda n: base.with_name(f"{base.stem}-resumed-{n}.mcap")), note


def _unused(name: Callable[[int], Path]) -> Path:
    """``name(n)`` for the first n = 1, 2, ... that does not exist yet."""
    n = 1
    while (path := name(n)).exists():
        n += 1
    return path


def _upload_quota(max_files: int, max_mb: float) -> UploadQuota:
    from executive.uploads import UploadQuota

    if not (max_files > 0 and math.isfinite(max_mb) and max_mb > 0):
        raise ExecutiveError(f"--upload-max-files {max_files} --upload-max-mb {max_mb}: expected a positive number"
                             " of files and of megabytes")
    return UploadQuota(max_files=max_files, max_bytes=max(1, round(max_mb * 1024 * 1024)))


def _load_mission(mission_path: Path) -> Mission:
    from planner.contract.mission import load_mission

    return load_mission(mission_path)


def _helm_figures(m: Mission) -> HelmConfig:
    """The helm's vehicle figures and safety limits from a mission."""
    v, s = m.vehicle, m.safety
    return HelmConfig(
        cruise_speed_m_s=v.cruise_speed_m_s, yaw_rate_deg_s=v.yaw_rate_deg_s, glide_rate_m_s=v.glide_rate_m_s,
        link_loss_timeout_s=s.link_loss_timeout_s, max_mission_time_s=s.max_mission_time_s,
        min_battery_pct=s.min_battery_pct, max_depth_m=s.max_depth_m, geofence=s.geofence, on_breach=s.on_breach,
    )


def _mission_setup(mission_path: Path, paths: list[Path], tables: list[PolicyTable],
                   on_arrival: OnArrival | None) -> tuple[HelmConfig, MissionPlan, Mission]:
    """The helm's figures and the goal list from the mission; each table must serve one of its goals."""
    from executive import goal_tables

    m = _load_mission(mission_path)
    goals = m.goals
    if on_arrival:  # the mission's end; goals before it keep theirs (``next``)
        goals = (*goals[:-1], replace(goals[-1], on_arrival=on_arrival))
    plan = goal_tables.assign(goals, zip(map(str, paths), tables), str(mission_path))
    if plan.table is None:
        first = goals[0].goal
        raise ExecutiveError(f"--table: none is for goals[0] of {mission_path} ({first.lon_deg:g}, {first.lat_deg:g},"
                           f" {first.depth_m:g} m): plan it with `lrauv plan {mission_path}`")
    return replace(_helm_figures(m), on_arrival=goals[0].on_arrival), plan, m
