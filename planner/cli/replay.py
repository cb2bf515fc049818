"""``lrauv replay LOG.mcap``: post-dive analysis of an executive's log (docs/replay.md).

Prints the dive summary (``planner.shore.replay.summary``) and runs the decision audit
(``planner.shore.replay.audit``); on request writes a report (``planner.shore.replay.report``), CSV,
GeoJSON and GPX (``planner.shore.replay.export``), and re-streams the telemetry as MAVLink
(``planner.shore.replay.restream``). The planning forecast, found by its identity, gives
the nominal path and the predicted cost-to-go (``planner.shore.replay.nominal``); without
it those parts say so and the rest goes on.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from planner.contract.errors import LrauvError
from planner.contract.columns import say

_MAX_LISTED = 20  # audit differences printed in full
EXIT_AUDIT_DIFFERS = 1


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser("replay", help="summarise, audit, report, export or re-stream a dive's MCAP log",
                       description="Post-dive analysis of an `lrauv exec` log (docs/replay.md).")
    p.add_argument("log", type=Path, help="MCAP log written by `lrauv exec` (a truncated one replays up to the cut)")
    p.add_argument("--forecast", type=Path,
                   help="the planning forecast, for the nominal path and cost-to-go (default: looked for by its"
                        " identity beside the log and where the table says)")
    p.add_argument("--report", type=Path, metavar="DIR", help="write PNG pictures and index.html here")
    p.add_argument("--csv", type=Path, help="write the state and action time series as CSV")
    p.add_argument("--geojson", type=Path, help="write the track as GeoJSON (RFC 7946), filtered and simplified")
    p.add_argument("--simplify-m", type=float, default=2.0, metavar="M",
                   help="the GeoJSON track keeps every filtered position within M metres of its line (default 2)")
    p.add_argument("--gpx", type=Path, help="write the track as GPX 1.1")
    p.add_argument("--tlog", type=Path, metavar="OUT.tlog",
                   help="write the logged MAVLink frames as a telemetry log (.tlog: mavlogdump.py, MAVExplorer, QGC)")
    p.add_argument("--layout", type=Path, metavar="OUT.json",
                   help="write a Foxglove layout for the log (map, log, depth and battery plot, states, raw messages)")
    p.add_argument("--no-audit", action="store_true", help="skip running the decisions again")
    p.add_argument("--mavlink", metavar="ADDRESS",
                   help="re-send the recorded telemetry as MAVLink to this pymavlink address (e.g. udpout:127.0.0.1:14550)")
    p.add_argument("--speed", type=float, default=10.0, help="re-stream speed, times real (vehicle) time (default 10)")
    p.add_argument("--quiet", action="store_true", help="no progress bars (they are drawn only on a terminal)")
    return p


def run(args: argparse.Namespace) -> int:
    """Exit status 0; 1 when the audit found a difference; a log that cannot be replayed raises ``LrauvError`` (2).

    Whatever a broken log makes go wrong ends as one line naming it, never a traceback:
    status 1 means only that the decisions differ.
    """
    try:
        return _replay(args)
    except (LrauvError, OSError, KeyboardInterrupt):  # ``planner.cli.main`` gives each its line and status
        raise
    except MemoryError:
        raise LrauvError(f"{args.log}: ran out of memory replaying it") from None
    except Exception as exc:  # noqa: BLE001 - a log this version cannot make sense of, however it fails
        raise LrauvError(f"{args.log}: cannot replay it: {type(exc).__name__}: {exc} (a damaged log, or one"
                         " written by another version)") from None


def _replay(args: argparse.Namespace) -> int:
    from executive.recorder import LogError
    from planner.contract.atomic import check_file_target, check_folder_target
    from planner.shore.replay.audit import audit, logged_tables, summary_line
    from planner.shore.replay.dive import load_dive
    from planner.shore.replay.divelog import open_dive
    from planner.cli.progress_bar import bars
    from planner.shore.replay.summary import format_summary, summarise

    if args.mavlink is not None and not (math.isfinite(args.speed) and args.speed > 0):
        raise LrauvError(f"--speed: expected a positive factor; got {args.speed}")
    if not (math.isfinite(args.simplify_m) and args.simplify_m >= 0):
        raise LrauvError(f"--simplify-m: expected metres >= 0; got {args.simplify_m}")
    for path in (args.csv, args.geojson, args.gpx, args.tlog, args.layout):  # before the work, not after it
        if path is not None:
            check_file_target(path)
    if args.report is not None:
        check_folder_target(args.report)
    if args.forecast is not None and not args.forecast.is_file():  # given: it must be there, not looked for
        raise LrauvError(f"--forecast {args.forecast}: no such file")
    t0 = time.perf_counter()
    with bars(quiet=args.quiet) as meter:  # closed before the summary prints on stdout
        log = open_dive(args.log, meter=meter)
        dive = load_dive(log, meter=meter)
    if len(dive.track) == 0:
        say(f"log        {log.path}: {log.where_it_ends()}")
        raise LrauvError(f"{log.path}: the log holds no decision: the executive never had a position to act on")
    tables = logged_tables(log)
    plans, nominal, note = _plans(dive, tables, args.forecast)
    summary = summarise(dive, nominal=nominal, nominal_note=note)
    text = format_summary(summary)
    say(text, flush=True)
    status = 0
    verdict = None
    if not args.no_audit:
        try:
            with bars(quiet=args.quiet) as meter:
                result = audit(log, meter=meter)
        except LogError as exc:  # some of the audit's say what is wrong, not in which file
            raise exc if str(log.path) in str(exc) else LogError(f"{log.path}: {exc}") from None
        verdict = summary_line(result)
        say(verdict)
        for m in result.mismatches[:_MAX_LISTED]:
            say(f"  {m.describe()}")
        if len(result.mismatches) > _MAX_LISTED:
            say(f"  ... and {len(result.mismatches) - _MAX_LISTED:,} more")
        status = 0 if result.clean else EXIT_AUDIT_DIFFERS
    written = _exports(args, dive)
    if args.tlog is not None:
        from planner.shore.replay.tlog import write_tlog

        tlog = write_tlog(log, args.tlog, first_offset_s=dive.unix_offset_s)
        say(f"tlog       {tlog.describe()}")
        written.append(tlog.path)
    if args.layout is not None:
        from planner.shore.replay.layout import write_layout

        written.append(write_layout(args.layout))
    if args.report is not None:
        from planner.shore.replay.report import write_report

        first = next(iter(plans.values()), None)
        written.append(write_report(dive, args.report, tables=tables, plan=first, summary_text=text,
                                    audit_text=verdict, exports=list(written)))
    for path in written:
        say(f"wrote      {path}")
    say(f"replay     {time.perf_counter() - t0:.1f} s", flush=True)
    if args.mavlink is not None:
        _restream(log, args.mavlink, args.speed)
    if log.damage():  # what could be read was; the gap makes it a broken log, not an audit verdict
        raise LrauvError(f"{log.path}: {log.damage()}")
    return status


def _plans(dive: Any, tables: dict[str, Any], forecast: Path | None) -> tuple[dict[str, Any], dict[int, Any], str | None]:
    """Plans again for the segments' tables, and each segment's nominal path; or why not."""
    from planner.shore.replay.nominal import find_forecast, nominal_from, plan_again

    plans: dict[str, Any] = {}
    nominal: dict[int, Any] = {}
    notes: list[str] = []
    near = (dive.log.path.parent,)
    for index, seg in enumerate(dive.track.segments()):
        table = tables.get(seg.table_crc32) if seg.table_crc32 is not None else None
        cells = dive.track.cell[seg.start:seg.stop]
        valid = cells[:, 0] >= 0
        if table is None or not valid.any():
            continue
        if seg.table_crc32 not in plans:
            try:
                plans[seg.table_crc32] = plan_again(table, find_forecast(table, given=forecast, near=near))
            except LrauvError as exc:
                notes.append(str(exc))
                plans[seg.table_crc32] = None
        plan = plans[seg.table_crc32]
        layer, row, col, heading = (int(x) for x in cells[valid][0])  # the track's cells are (n, 4)
        shape = (table.n_layers, table.ny, table.nx, table.actions.shape[-1])
        if not all(0 <= c < n for c, n in zip((layer, row, col, heading), shape, strict=True)):
            notes.append(f"the logged cell {(layer, row, col, heading)} is outside table {seg.table_crc32} {shape}")
        elif plan is not None:
            nominal[index] = nominal_from(plan, (layer, row, col, heading))
    note = "; ".join(dict.fromkeys(notes)) or None
    return {k: v for k, v in plans.items() if v is not None}, nominal, note


def _exports(args: argparse.Namespace, dive: Any) -> list[Path]:
    if args.csv is None and args.geojson is None and args.gpx is None:
        return []
    from planner.shore.replay.export import write_csv, write_geojson, write_gpx

    out = []
    for path, write in ((args.csv, write_csv), (args.geojson, write_geojson), (args.gpx, write_gpx)):
        if path is not None:
            out.append(write(dive, path, tolerance_m=args.simplify_m) if write is write_geojson else write(dive, path))
    return out


def _restream(log: Any, address: str, speed: float) -> None:
    import signal
    import threading

    from planner.shore.replay.restream import restream

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    say(f"restream   to {address} at {speed:g}x (Ctrl-C stops)", flush=True)
    r = restream(log, address, speed=speed, stop=stop)
    skipped = ", ".join(f"{k} ({v})" for k, v in r.skipped.items()) if r.skipped else "none"
    say(f"restream   {r.messages_sent:,} messages, {r.vehicle_s / 3600:.2f} h of vehicle time in {r.wall_s:.1f} s;"
        f" skipped {skipped}", flush=True)
