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

import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from planner.contract.errors import LrauvError, ShoreError

if TYPE_CHECKING:
    from executive.signing import SigningKey
    from planner.contract.mission import Mission
    from planner.pipeline import SampleCache

GCS_SYSTEM, GCS_COMPONENT = 255, 190  # a ground station's usual MAVLink identity (MAVProxy, QGC)


def upload_mission(mission_path: Path, *, to: str, tables: Sequence[Path] = (), forecast: Path | None = None,
                   target_system: int | None = None, target_component: int | None = None, timeout_s: float = 5.0,
                   signing_key_file: Path | None = None, say: Callable[[str], None] | None = None,
                   report: Callable[[str], None] | None = None) -> None:
    """Send the mission's goals and a table for each goal to the executive at ``to``; refusals raise LrauvError.

    ``tables``: ready tables (each must serve a goal); the other goals are planned here on
    ``forecast`` (default: the mission's). ``say`` gets progress lines, ``report`` the summary of
    each plan made here (``lrauv plan``'s lines); None: silent.
    """
    from executive import goal_tables
    from planner.contract.mission import load_mission
    from planner.contract.table import PolicyTable, read_table_file
    from planner.shore.ftp_client import FtpTimeoutError
    from planner.shore.mission_client import MissionTransferError

    from executive.mavlink_bridge import check_address

    check_address(to, flag="--to")  # before the goals are planned on shore, not after
    say = say or _silent
    mission = load_mission(mission_path)
    key, link_id = _signing(signing_key_file, mission)
    files = {str(path): read_table_file(path) for path in tables}
    ready = {name: PolicyTable.from_bytes(data, name=name) for name, data in files.items()}
    plan = goal_tables.assign(mission.goals, ready.items(), str(mission_path))
    names = {id(table): name for name, table in ready.items()}
    blobs = {n: files[names[id(t)]] for n, t in enumerate(plan.tables) if t is not None}
    with tempfile.TemporaryDirectory(prefix="lrauv-upload-") as tmp:
        samples = None
        for n, goal in enumerate(mission.goals):
            if n not in blobs:
                say(f"planning goal {n} on shore")
                if samples is None:
                    from planner.pipeline import SampleCache

                    samples = SampleCache()  # the goals share one forecast: sampled once
                blobs[n] = _plan_goal(mission, n, forecast, Path(tmp) / f"goal-{n}.lrpt", report or _silent,
                                      samples)
        conn = _connect(to)
        try:
            if key is not None:
                _sign(conn, key, link_id)
                say(f"signing with key {key.fingerprint}, link id {link_id}")
            try:
                _send(conn, mission, blobs, target_system=target_system, target_component=target_component,
                      timeout_s=timeout_s, say=say)
            except (MissionTransferError, FtpTimeoutError) as exc:  # no answer: say what signing may have to do with it
                diagnosis = _signing_diagnosis(conn, signed=key is not None)
                if (isinstance(exc, MissionTransferError) and exc.result is not None) or not diagnosis:
                    raise
                raise type(exc)(f"{exc}; {diagnosis}") from None
        finally:
            conn.close()


def _silent(_text: str) -> None:
    pass


def _signing(signing_key_file: Path | None, mission: Mission) -> tuple[SigningKey | None, int]:
    """The key to sign with (``signing_key_file`` first, then the mission's) and the link id, or (None, 0)."""
    from executive.signing import load_key

    sg = mission.signing
    link_id = sg.link_id if sg is not None else 0
    if signing_key_file is not None:
        return load_key(key_file=signing_key_file, where="--signing-key-file"), link_id
    if sg is None:
        return None, 0
    return load_key(key_file=sg.key_file, passphrase_env=sg.passphrase_env, where=sg.where), link_id


def _sign(conn: Any, key: SigningKey, link_id: int) -> None:  # conn: a pymavlink connection (pymavlink has no types)
    """Sign every frame; read only frames signed with ``key`` (pymavlink counts the others)."""
    conn.setup_signing(key.secret, sign_outgoing=True, link_id=link_id,
                       allow_unsigned_callback=lambda _mav, _msg_id: False)  # counted in reject_count, then dropped


def _signing_diagnosis(conn: Any, *, signed: bool) -> str:  # conn: a pymavlink connection (no types)
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


def _plan_goal(mission: Mission, n: int, forecast: Path | None, out: Path, report: Callable[[str], None],
               samples: SampleCache) -> bytes:
    """Plan goal ``n`` as ``lrauv plan MISSION --goal ... --forecast ...`` would, write the table to ``out``."""
    from dataclasses import replace

    from planner.contract.atomic import write_atomic
    from planner.pipeline import PlanRequest, mission_forecast, plan_with_scheduler
    from planner.plan_summary import summary_lines, time_line

    goal = mission.goals[n]
    if forecast is None:  # a missing source is the mission's forecast line's error, not the goal's
        request = PlanRequest.for_mission(mission, mission_forecast(mission), goal_index=n)
    else:  # the given forecast replaces the mission's whole forecast section: its step and variables too
        request = replace(PlanRequest.for_mission(mission, forecast, goal_index=n),
                          time_index=None, time_iso=None, variables=None, grid_file=None)
    try:
        t0 = time.perf_counter()
        result = plan_with_scheduler(request, samples=samples)
    except LrauvError as exc:
        g = goal.goal
        raise ShoreError(f"{goal.where or mission.path}: planning goal ({g.lon_deg:g}, {g.lat_deg:g}) failed: {exc}") from None
    data = result.table.to_bytes()
    write_atomic(out, data)
    for line in summary_lines(result, out=out, size=len(data)):
        report(line)
    report(time_line(result, time.perf_counter() - t0))
    return data


def _connect(address: str) -> Any:  # a pymavlink connection: pymavlink has no types
    from executive.mavlink_bridge import open_link

    try:
        return open_link(address, source_system=GCS_SYSTEM, source_component=GCS_COMPONENT, flag="--to")
    except OSError as exc:
        raise ShoreError(f"--to {address}: cannot open: {exc}") from None


def _send(conn: Any, mission: Mission, blobs: dict[int, bytes], *, target_system: int | None,
          target_component: int | None, timeout_s: float, say: Callable[[str], None]) -> None:
    """Goals by the mission protocol, then each table by FTP; conn: a pymavlink connection (no types)."""
    from executive.mavlink_bridge import EXECUTIVE_COMPONENT, EXECUTIVE_SYSTEM
    from planner.contract.mission import goals_to_items
    from planner.shore.ftp_client import put_file
    from planner.shore.mission_client import upload_goals

    first = mission.goals[0].goal
    items = goals_to_items(mission.goals, home_lat_deg=first.lat_deg, home_lon_deg=first.lon_deg)
    system = target_system or EXECUTIVE_SYSTEM
    component = target_component or EXECUTIVE_COMPONENT
    upload_goals(conn, items, target_system=system, target_component=component)
    say(f"goals: {len(mission.goals)} accepted by system {system} component {component}")
    for n in sorted(blobs):
        remote = f"/tables/goal-{n}.lrpt"
        put_file(conn, blobs[n], remote, timeout_s=timeout_s, target_system=system, target_component=component)
        say(f"table for goal {n}: {len(blobs[n]):,} bytes accepted as {remote}")
