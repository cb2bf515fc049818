"""``lrauv upload MISSION.yaml --to ADDRESS``: send a mission to a running executive, as a ground station would.

1. Tables: each ``--table`` must serve one of the mission's goals; a goal without one is
   planned here, on shore, with the mission's settings (``lrauv plan`` for that goal).
2. Goals: the MAVLink mission protocol (``planner.shore.mission_client``, items as in
   ``planner.contract.waypoints``), to system 1 component 191 by default.
3. Tables: MAVLink FTP to ``/tables/goal-N.lrpt`` (``planner.shore.ftp_client``).

The executive checks each part and refuses it with a reason (sent as STATUSTEXT and
logged); a refused part never replaces the running plan. Any refusal here exits 2.

With a signing key (the mission's ``signing`` section, or ``--signing-key-file``) every
frame is signed (pymavlink's ``setup_signing``, link id from the mission) and only replies
signed with the same key are read: an executive with another key, or none, looks silent,
and the error then says which of the two it saw (pymavlink's signing counters).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
from pathlib import Path

from planner.contract.errors import ShoreError

GCS_SYSTEM, GCS_COMPONENT = 255, 190  # a ground station's usual MAVLink identity (MAVProxy, QGC)


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    up = sub.add_parser("upload", help="upload a mission's goals and tables to a running executive over MAVLink")
    up.add_argument("mission", type=Path, help="mission YAML")
    up.add_argument("--to", required=True, metavar="ADDRESS",
                    help="pymavlink address of the executive's ground-station link, e.g. udpout:127.0.0.1:14551")
    up.add_argument("--table", type=Path, action="append", default=[],
                    help="a ready policy table for one of the goals (repeatable); other goals are planned here")
    up.add_argument("--forecast", type=Path, help="forecast to plan on (default: the mission's source)")
    up.add_argument("--target-system", type=int, help="the executive's MAVLink system (default 1)")
    up.add_argument("--target-component", type=int, help="the executive's MAVLink component (default 191)")
    up.add_argument("--timeout-s", type=float, default=5.0, help="MAVLink FTP: seconds to wait for each reply before resending (default 5)")
    up.add_argument("--signing-key-file", type=Path, metavar="KEY",
                    help="MAVLink 2 signing key (32 bytes, or 64 hex digits) to sign with"
                         " (default: the mission's signing section; docs/missions.md)")
    up.add_argument("--quiet", action="store_true")


def run(args: argparse.Namespace) -> int:
    from executive import goal_tables
    from planner.shore.ftp_client import FtpTimeoutError
    from planner.contract.mission import load_mission
    from planner.shore.mission_client import MissionTransferError
    from planner.contract.table import PolicyTable, read_table_file

    mission = load_mission(args.mission)
    key, link_id = _signing(args, mission)
    files = {str(path): read_table_file(path) for path in args.table}
    tables = {name: PolicyTable.from_bytes(data, name=name) for name, data in files.items()}
    plan = goal_tables.assign(mission.goals, tables.items(), str(args.mission))
    names = {id(table): name for name, table in tables.items()}
    blobs = {n: files[names[id(t)]] for n, t in enumerate(plan.tables) if t is not None}
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    with tempfile.TemporaryDirectory(prefix="lrauv-upload-") as tmp:
        for n, goal in enumerate(mission.goals):
            if n not in blobs:
                say(f"planning goal {n} on shore")
                with contextlib.redirect_stdout(io.StringIO()) if args.quiet else contextlib.nullcontext():
                    blobs[n] = _plan_goal(args.mission, goal.goal, args.forecast, Path(tmp) / f"goal-{n}.lrpt")
        conn = _connect(args.to)
        try:
            if key is not None:
                _sign(conn, key, link_id)
                say(f"signing with key {key.fingerprint}, link id {link_id}")
            try:
                _send(conn, mission, blobs, args, say)
            except (MissionTransferError, FtpTimeoutError) as exc:  # no answer: say what signing may have to do with it
                diagnosis = _signing_diagnosis(conn, signed=key is not None)
                if (isinstance(exc, MissionTransferError) and exc.result is not None) or not diagnosis:
                    raise
                raise type(exc)(f"{exc}; {diagnosis}") from None
        finally:
            conn.close()
    return 0


def _signing(args: argparse.Namespace, mission):  # type: ignore[no-untyped-def]
    """The key to sign with (``--signing-key-file`` first, then the mission's) and the link id, or (None, 0)."""
    from executive.signing import load_key

    sg = mission.signing
    link_id = sg.link_id if sg is not None else 0
    if args.signing_key_file is not None:
        return load_key(key_file=args.signing_key_file, where="--signing-key-file"), link_id
    if sg is None:
        return None, 0
    return load_key(key_file=sg.key_file, passphrase_env=sg.passphrase_env, where=sg.where), link_id


def _sign(conn, key, link_id: int) -> None:  # type: ignore[no-untyped-def]
    """Sign every frame; read only frames signed with ``key`` (pymavlink counts the others)."""
    conn.setup_signing(key.secret, sign_outgoing=True, link_id=link_id,
                       allow_unsigned_callback=lambda _mav, _msg_id: False)  # counted in reject_count, then dropped


def _signing_diagnosis(conn, *, signed: bool) -> str:  # type: ignore[no-untyped-def]
    """What a silent executive probably means, from pymavlink's signing counters ("" when nothing to say)."""
    s = conn.mav.signing
    if not signed:  # sig_count counts signed frames even without a key
        return ("the vehicle signs its messages, so it probably refuses unsigned uploads: give the mission a signing"
                " key (docs/missions.md, Signing)") if s.sig_count else ""
    unsigned = s.reject_count - s.badsig_count  # reject_count counts both kinds of refused frame
    if s.goodsig_count == 0 and s.badsig_count:
        return (f"signing: {s.badsig_count} frames from the vehicle failed the signature check: is the executive using"
                " the same key (compare the key fingerprints both print)?")
    if s.goodsig_count == 0 and unsigned:
        return f"signing: the vehicle answered {unsigned} times unsigned: is `lrauv exec` run with the signing key?"
    if s.goodsig_count == 0:
        return "signing: nothing came back at all"
    return ("signing: the vehicle's frames verify but it did not answer: is this computer's clock more than a minute"
            " behind the vehicle's? (see its log)")


def _plan_goal(mission_path: Path, goal, forecast: Path | None, out: Path) -> bytes:  # type: ignore[no-untyped-def]
    from planner.cli import main as lrauv

    argv = ["plan", str(mission_path), "--quiet", f"--out={out}", f"--goal={goal.lon_deg!r},{goal.lat_deg!r},{goal.depth_m!r}",
            f"--goal-radius={goal.radius_cells}"]
    if forecast is not None:
        argv.append(f"--forecast={forecast}")
    if lrauv(argv) != 0:
        raise ShoreError(f"{mission_path}: planning goal ({goal.lon_deg:g}, {goal.lat_deg:g}) failed (see above)")
    return out.read_bytes()


def _connect(address: str):  # type: ignore[no-untyped-def]
    from executive.mavlink_bridge import open_link

    try:
        return open_link(address, source_system=GCS_SYSTEM, source_component=GCS_COMPONENT)
    except OSError as exc:
        raise ShoreError(f"--to {address}: cannot open: {exc}") from None


def _send(conn, mission, blobs: dict[int, bytes], args: argparse.Namespace, say) -> None:  # type: ignore[no-untyped-def]
    from executive.mavlink_bridge import EXECUTIVE_COMPONENT, EXECUTIVE_SYSTEM
    from planner.shore.ftp_client import put_file
    from planner.shore.mission_client import upload_goals
    from planner.contract.mission import goals_to_items

    first = mission.goals[0].goal
    items = goals_to_items(mission.goals, home_lat_deg=first.lat_deg, home_lon_deg=first.lon_deg)
    target = {"target_system": args.target_system or EXECUTIVE_SYSTEM,
              "target_component": args.target_component or EXECUTIVE_COMPONENT}
    upload_goals(conn, items, **target)
    say(f"goals: {len(mission.goals)} accepted by system {target['target_system']} component {target['target_component']}")
    for n in sorted(blobs):
        remote = f"/tables/goal-{n}.lrpt"
        put_file(conn, blobs[n], remote, timeout_s=args.timeout_s, **target)
        say(f"table for goal {n}: {len(blobs[n]):,} bytes accepted as {remote}")
