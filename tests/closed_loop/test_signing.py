"""MAVLink 2 signing of uploads and commands: keys, verdicts, the rule, and a live executive.

The pure parts (``executive.signing``) are checked against frames signed by pymavlink's
own ``sign_packet``, and ours against pymavlink's own check, so the two implementations
cross-check each other. The live tests reuse ``tests.support.live_rig.Live`` (a simulated
vehicle and an executive over real UDP on ephemeral ports) with a key generated here.
"""

from __future__ import annotations

import hashlib
import os
import socket
import time
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from executive import mavlink_bridge as bridge  # noqa: E402
from executive import goal_tables
from executive.ftp import Frame, Opcode  # noqa: E402
from executive.recorder import read_messages  # noqa: E402
from executive.signing import (  # noqa: E402
    GUARDED_MESSAGES,
    NEW_STREAM_MAX_AGE_TICKS,
    TICKS_PER_S,
    Link,
    RefusalLog,
    SigningError,
    SigningKey,
    Streams,
    Verdict,
    judge,
    load_key,
    must_be_signed,
    note_refusal,
    timestamp_at,
)
from executive.uploads import Uploads  # noqa: E402
from planner.cli import main as lrauv  # noqa: E402
from planner.contract.errors import MissionError  # noqa: E402
from planner.shore.ftp_client import put_file  # noqa: E402
from planner.contract.mission import load_mission  # noqa: E402
from planner.shore.mission_client import upload_goals  # noqa: E402
from planner.contract.mission import goals_to_items  # noqa: E402

from tests.support.helpers import DEMO_MISSION, plan_for, start_west_of_goal  # noqa: E402
from tests.support.live_rig import Live  # noqa: E402

KEY = SigningKey(bytes(range(1, 33)))
OTHER = SigningKey(bytes(range(101, 133)))
NOW_S = 1_750_000_000.0  # a Unix time for the pure tests (2025-06-15)


class _Sink:
    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.frames.append(bytes(data))


def _sender(key: SigningKey | None, *, link_id: int = 0, stamp: int = 0, system: int = 255,
            component: int = 190) -> mavlink.MAVLink:
    """A plain pymavlink MAVLink signing as a ground station does (mavutil's setup_signing, by hand)."""
    mav = mavlink.MAVLink(_Sink(), srcSystem=system, srcComponent=component)
    if key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing = key.secret, True
        mav.signing.link_id, mav.signing.timestamp = link_id, stamp
    return mav


def _frame(mav: mavlink.MAVLink, msg=None) -> bytes:  # type: ignore[no-untyped-def]
    mav.send(msg or mav.mission_count_encode(1, 191, 2, 0))
    return mav.file.frames[-1]


# -- keys --------------------------------------------------------------------------------------------


def test_key_files_hold_32_raw_bytes_or_64_hex_digits(tmp_path):
    raw, hexed = tmp_path / "raw.key", tmp_path / "hex.key"
    raw.write_bytes(KEY.secret)
    hexed.write_text(KEY.secret.hex() + "\n")
    assert load_key(key_file=raw) == load_key(key_file=hexed) == KEY
    assert KEY.secret.hex() not in repr(KEY) and str(KEY.secret) not in repr(KEY)  # never printed
    for content, message in [(KEY.secret[:31], "got 31 bytes"), (bytes(32), "all zeros"),
                             (b"z" * 64, "neither")]:
        raw.write_bytes(content)
        with pytest.raises(SigningError, match=message) as err:
            load_key(key_file=raw, where="m.yaml:40 signing.key_file")
        assert str(err.value).startswith(f"m.yaml:40 signing.key_file: {raw}: ")
    with pytest.raises(SigningError, match="cannot read"):
        load_key(key_file=tmp_path / "absent.key")


def test_a_passphrase_gives_mavproxys_key(monkeypatch):
    # MAVProxy's `signing key PASSPHRASE`: hashlib.sha256(passphrase.encode('ascii')).digest()
    monkeypatch.setenv("LRAUV_TEST_PASSPHRASE", "correct horse battery staple")
    key = load_key(passphrase_env="LRAUV_TEST_PASSPHRASE")
    assert key.secret == hashlib.sha256(b"correct horse battery staple").digest()
    monkeypatch.setenv("LRAUV_TEST_PASSPHRASE", "h\u00e9las")
    with pytest.raises(SigningError, match="ASCII"):
        load_key(passphrase_env="LRAUV_TEST_PASSPHRASE")
    monkeypatch.delenv("LRAUV_TEST_PASSPHRASE")
    with pytest.raises(SigningError, match="LRAUV_TEST_PASSPHRASE is not set"):
        load_key(passphrase_env="LRAUV_TEST_PASSPHRASE")


def test_timestamps_count_10_us_since_2015():
    assert timestamp_at(1_420_070_400.0) == 0
    assert timestamp_at(1_420_070_401.5) == 150_000


# -- verdicts ----------------------------------------------------------------------------------------


def test_verdicts_on_frames_signed_by_pymavlink():
    now = timestamp_at(NOW_S)
    good = _frame(_sender(KEY, stamp=now))
    assert judge(good, KEY, last_ticks=None, now_ticks=now) is Verdict.SIGNED
    assert judge(good, KEY, last_ticks=now - 1, now_ticks=now) is Verdict.SIGNED
    assert judge(good, KEY, last_ticks=now, now_ticks=now) is Verdict.REPLAYED  # not after the stream's last
    assert judge(good, OTHER, last_ticks=None, now_ticks=now) is Verdict.BAD_SIGNATURE
    altered = bytearray(good)
    altered[10] ^= 0x01  # a payload byte (the CRC no longer matters: the signature covers it)
    assert judge(bytes(altered), KEY, last_ticks=None, now_ticks=now) is Verdict.BAD_SIGNATURE
    assert judge(_frame(_sender(None)), KEY, last_ticks=None, now_ticks=now) is Verdict.UNSIGNED
    # A new stream may start up to a minute behind our clock (the C library's rule), not more.
    edge = _frame(_sender(KEY, stamp=now - NEW_STREAM_MAX_AGE_TICKS))
    old = _frame(_sender(KEY, stamp=now - NEW_STREAM_MAX_AGE_TICKS - 1))
    assert judge(edge, KEY, last_ticks=None, now_ticks=now) is Verdict.SIGNED
    assert judge(old, KEY, last_ticks=None, now_ticks=now) is Verdict.TOO_OLD


def test_streams_are_link_system_component_and_a_forger_cannot_move_them():
    now = timestamp_at(NOW_S)
    streams = Streams(KEY)
    real = _sender(KEY, link_id=1, stamp=now)
    assert streams.admit(_frame(real), wall_ticks=now) is Verdict.SIGNED
    # Without the key, a frame claiming the same stream and a far-future timestamp changes nothing
    # (pymavlink's own check_signature records the timestamp before comparing signatures).
    forged = _frame(_sender(OTHER, link_id=1, stamp=now + 10**9))
    assert streams.admit(forged, wall_ticks=now) is Verdict.BAD_SIGNATURE
    assert streams.admit(_frame(real), wall_ticks=now) is Verdict.SIGNED
    # The same timestamps from another link id or component are other streams.
    assert streams.admit(_frame(_sender(KEY, link_id=2, stamp=now)), wall_ticks=now) is Verdict.SIGNED
    assert streams.admit(_frame(_sender(KEY, link_id=1, stamp=now, component=191)), wall_ticks=now) is Verdict.SIGNED
    assert set(streams.last_ticks) == {(1, 255, 190), (2, 255, 190), (1, 255, 191)}
    assert streams.clock_ticks == now + 1  # our clock follows what verified, never the forger


def test_what_we_sign_pymavlink_verifies_and_the_timestamps_keep_up_with_the_clock():
    wall = [NOW_S]
    streams = Streams(KEY)
    sink = _Sink()
    mav = bridge.SigningMAVLink(sink, system=1, component=191, streams=streams, link_id=1,
                                wall_unix_s=lambda: wall[0])
    mav.send(mav.heartbeat_encode(18, 8, 0, 0, 4))
    wall[0] += 3600.0  # an hour without sending: our next timestamp is the clock's, not the last + 1
    mav.send(mav.heartbeat_encode(18, 8, 0, 0, 4))
    checker = mavlink.MAVLink(None)
    checker.robust_parsing = True  # a refused frame comes out as BAD_DATA instead of raising
    checker.signing.secret_key = KEY.secret  # pymavlink's own check, with the timestamp rules
    checker.signing.timestamp = timestamp_at(NOW_S + 3600.0)
    first, second = (checker.parse_buffer(frame)[0] for frame in sink.frames)
    assert (first.get_type(), first.reason) == ("BAD_DATA", "Invalid signature")  # an hour old on a new stream
    assert second.get_type() == "HEARTBEAT" and second.get_signed() and second.get_link_id() == 1
    assert int.from_bytes(sink.frames[1][-12:-6], "little") >= timestamp_at(NOW_S + 3600.0)
    # And the other way: what pymavlink signs, a SigningMAVLink admits once.
    gcs = _sender(KEY, link_id=3, stamp=timestamp_at(time.time()))
    frame = _frame(gcs)
    receiver = bridge.new_mav(_Sink(), streams=Streams(KEY))
    assert [bridge.signature(m) for m in receiver.parse_buffer(frame)] == [Verdict.SIGNED]
    assert [bridge.signature(m) for m in receiver.parse_buffer(frame)] == [Verdict.REPLAYED]
    assert bridge.signature(bridge.new_mav(_Sink()).parse_buffer(frame)[0]) is Verdict.UNSIGNED  # no key: no verdict


def test_the_rule_for_what_must_be_signed():
    gcs, ap = Link.GROUND_STATION, Link.AUTOPILOT
    assert must_be_signed("HEARTBEAT", link=gcs, from_autopilot=False, for_us=True)
    assert not must_be_signed("RADIO_STATUS", link=gcs, from_autopilot=False, for_us=True)  # a radio's own
    assert not must_be_signed("GLOBAL_POSITION_INT", link=ap, from_autopilot=True, for_us=True)  # telemetry
    assert not must_be_signed("HEARTBEAT", link=ap, from_autopilot=False, for_us=True)
    for kind in ("MISSION_COUNT", "FILE_TRANSFER_PROTOCOL", "COMMAND_LONG", "COMMAND_INT"):
        assert must_be_signed(kind, link=ap, from_autopilot=False, for_us=True)
        assert not must_be_signed(kind, link=ap, from_autopilot=False, for_us=False)  # for someone else
    assert Uploads.MESSAGES <= GUARDED_MESSAGES


def test_refusals_are_logged_at_most_once_a_period():
    log, lines = RefusalLog(period_s=10.0), []
    for wall_s in [0.0, 0.1, 0.2, 5.0, 10.5, 10.6, 30.0]:
        log, covers = note_refusal(log, wall_s)
        lines.append(covers)
    assert lines == [1, None, None, None, 4, None, 2]


# -- missions ------------------------------------------------------------------------------------------


def _mission(tmp_path: Path, signing: str) -> Path:
    path = tmp_path / "signed.yaml"
    path.write_text(DEMO_MISSION.read_text() + signing)
    return path


def test_the_mission_names_where_the_key_is_never_the_key(tmp_path, monkeypatch):
    (tmp_path / "keys").mkdir()
    (tmp_path / "keys" / "m.key").write_bytes(KEY.secret)
    m = load_mission(_mission(tmp_path, "signing: {key_file: keys/m.key, link_id: 7}\n"))
    assert m.signing is not None and m.signing.key_file == tmp_path / "keys" / "m.key" and m.signing.link_id == 7
    assert load_key(key_file=m.signing.key_file) == KEY
    m = load_mission(_mission(tmp_path, "signing:\n  passphrase_env: LRAUV_PASS\n"))
    assert m.signing is not None and m.signing.passphrase_env == "LRAUV_PASS" and m.signing.link_id == 0
    monkeypatch.delenv("LRAUV_PASS", raising=False)
    with pytest.raises(SigningError) as err:
        load_key(passphrase_env=m.signing.passphrase_env, where=m.signing.where)
    line = len(DEMO_MISSION.read_text().splitlines()) + 2
    where = f"{tmp_path / 'signed.yaml'}:{line} signing.passphrase_env"
    assert str(err.value) == f"{where}: environment variable LRAUV_PASS is not set"
    assert load_mission(DEMO_MISSION).signing is None


@pytest.mark.parametrize(("text", "key", "message"), [
    ("signing: {key_file: a.key, passphrase_env: P}\n", "signing", "exactly one of key_file or passphrase_env"),
    ("signing: {link_id: 3}\n", "signing", "exactly one of key_file or passphrase_env"),
    ("signing: {key: 0011}\n", "signing.key", "unknown key; expected one of: key_file, link_id, passphrase_env"),
    ("signing: {key_file: a.key, link_id: 256}\n", "signing.link_id", "expected 0 to 255"),
    ("signing: {passphrase_env: 'not a name'}\n", "signing.passphrase_env", "name of an environment variable"),
])
def test_signing_section_errors_name_file_line_and_key(tmp_path, text, key, message):
    path = _mission(tmp_path, text)
    with pytest.raises(MissionError) as err:
        load_mission(path)
    line = len(DEMO_MISSION.read_text().splitlines()) + 1
    assert str(err.value).startswith(f"{path}:{line} {key}: ") and message in str(err.value), str(err.value)


def test_lrauv_upload_with_a_missing_key_file_exits_2_naming_the_mission_line(tmp_path, capsys):
    path = _mission(tmp_path, "signing: {key_file: nowhere.key}\n")
    assert lrauv(["upload", str(path), "--to", "udpout:127.0.0.1:9", "--quiet"]) == 2
    line = len(DEMO_MISSION.read_text().splitlines()) + 1
    err = capsys.readouterr().err
    assert f"{path}:{line} signing.key_file: cannot read {tmp_path / 'nowhere.key'}" in err, err


# -- a live executive with a key ---------------------------------------------------------------------


def _write_key(path: Path, key: SigningKey) -> Path:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(key.secret)
    return path


@pytest.fixture()
def signed(demo_plan, synthetic_forecast, tmp_path):
    """A running executive (the demo mission) that requires ``KEY``."""
    table = demo_plan.table
    plan = goal_tables.MissionPlan(goals=load_mission(DEMO_MISSION).goals, tables=(table,))
    rig = Live(synthetic_forecast, plan, tmp_path / "exec.mcap", start=start_west_of_goal(table), signing=KEY)
    try:
        assert rig.wait(rig.running), "the executive did not start following the plan"
        yield rig
    finally:
        rig.stop()


@pytest.fixture()
def signed_mission(tmp_path) -> Path:
    """The demo mission with a signing section naming a key file (mode 0600) that holds ``KEY``."""
    _write_key(tmp_path / "mission.key", KEY)
    return _mission(tmp_path, "signing: {key_file: mission.key, link_id: 2}\n")


@pytest.fixture(scope="module")
def optimistic_table(synthetic_forecast):
    """The demo goal planned another way: a table the executive accepts for the running goal."""
    return plan_for(synthetic_forecast, criterion="optimistic").table


def _gcs(rig: Live, key: SigningKey | None, *, link_id: int = 0,  # type: ignore[no-untyped-def]
         initial_timestamp: int | None = None):
    """A ground-station connection (mavutil), signing as ``lrauv upload`` does when given ``key``."""
    conn = rig.ground_station()
    if key is not None:
        conn.setup_signing(key.secret, sign_outgoing=True, link_id=link_id, initial_timestamp=initial_timestamp,
                           allow_unsigned_callback=lambda _mav, _msg_id: False)
    return conn


def _log(path: Path, topic: str) -> list[dict]:
    return [payload for _topic, _t, payload in read_messages(path, [topic])]


def _refusal_lines(path: Path) -> list[str]:
    return [p["message"] for p in _log(path, "/log")
            if p["message"].startswith("refused ") and "signing is required" in p["message"]]


def _upload(rig: Live, mission: Path, table_path: Path) -> int:
    return lrauv(["upload", str(mission), "--to", f"udpout:127.0.0.1:{rig.gcs_port}", "--table", str(table_path),
                  "--quiet"])


slow = pytest.mark.slow


@slow
def test_a_signed_lrauv_upload_is_accepted_and_swapped_in(signed, signed_mission, optimistic_table, tmp_path):
    path = optimistic_table.save(tmp_path / "optimistic.lrpt")
    assert _upload(signed, signed_mission, path) == 0  # the client reads only replies signed with KEY
    assert signed.wait(lambda: signed.executive.table.crc32 == optimistic_table.crc32, 10.0)
    assert [w["source"] for w in signed.executive.swaps] == ["upload /tables/goal-0.lrpt"]
    assert signed.executive.signature_refusals == {}
    signed.stop()
    crc = f"{optimistic_table.crc32:08x}"
    log = signed.executive.config.log_path
    records = _log(log, "/executive/policy")
    assert {r["reason"] for r in records if r.get("table_crc32") == crc} == {"received", "swapped"}
    assert _refusal_lines(log) == []


@slow
@pytest.mark.parametrize("sender", ["unsigned", "another key"])
def test_an_unsigned_or_wrongly_signed_upload_is_refused_and_the_plan_goes_on(signed, optimistic_table, tmp_path,
                                                                               capsys, sender):
    path = optimistic_table.save(tmp_path / "optimistic.lrpt")
    if sender == "unsigned":
        mission, verdict, hint = DEMO_MISSION, Verdict.UNSIGNED, "the vehicle signs its messages"
    else:
        _write_key(tmp_path / "other.key", OTHER)
        (tmp_path / "elsewhere").mkdir()  # a relative key_file is found from the mission's own folder
        mission = _mission(tmp_path / "elsewhere", "signing: {key_file: ../other.key}\n")
        verdict, hint = Verdict.BAD_SIGNATURE, "failed the signature check"
    running = signed.executive.table
    before = signed.executive._counts["decisions"]
    assert _upload(signed, mission, path) == 2  # no answer within the mission protocol's retries (about 9 s)
    err = capsys.readouterr().err
    assert "timed out" in err and hint in err, err
    assert signed.executive.signature_refusals.get(verdict, 0) >= 2  # MISSION_COUNT and its resends
    assert set(signed.executive.signature_refusals) == {verdict}
    assert signed.wait(lambda: signed.executive._counts["decisions"] > before + 10, 10.0)  # the plan went on
    assert signed.executive.table is running and signed.executive.swaps == []
    signed.stop()
    log = signed.executive.config.log_path
    lines = _refusal_lines(log)
    first = f"refused {verdict.value} MISSION_COUNT from 255/190 on the ground-station link"
    assert lines and lines[0].startswith(first), lines
    assert len(lines) <= 2  # rate-limited: one line per 10 s of wall time
    crc = f"{optimistic_table.crc32:08x}"
    assert not [r for r in _log(log, "/executive/policy") if r.get("table_crc32") == crc]


@slow
def test_replayed_frames_and_an_old_new_stream_are_refused(signed, optimistic_table, demo_plan):
    ex = signed.executive
    # A valid upload, recorded as it goes out...
    conn = _gcs(signed, KEY, link_id=4)
    sent: list[bytes] = []
    write = conn.write
    conn.write = lambda data: (sent.append(bytes(data)), write(data))[1]
    try:
        put_file(conn, optimistic_table.to_bytes(), "/tables/goal-0.lrpt", timeout_s=2.0)
    finally:
        conn.close()
    assert signed.wait(lambda: ex.table.crc32 == optimistic_table.crc32, 10.0)
    # ...then the first table again, so that a replay that got through would show.
    conn = _gcs(signed, KEY, link_id=4)
    try:
        put_file(conn, demo_plan.table.to_bytes(), "/tables/goal-0.lrpt", timeout_s=2.0)
    finally:
        conn.close()
    assert signed.wait(lambda: ex.table.crc32 == demo_plan.table.crc32, 10.0) and len(ex.swaps) == 2
    # The recorded bytes, sent again: every frame is older than its stream's last.
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for frame in sent:
            sock.sendto(frame, ("127.0.0.1", signed.gcs_port))
            time.sleep(0.002)
    assert signed.wait(lambda: ex.signature_refusals.get(Verdict.REPLAYED, 0) == len(sent), 10.0), ex.signature_refusals
    time.sleep(0.5)
    assert ex.table.crc32 == demo_plan.table.crc32 and len(ex.swaps) == 2
    # A frame signed two minutes ago on a stream never seen (recorded in another session): too old.
    two_minutes_ago = timestamp_at(time.time()) - 120 * TICKS_PER_S
    old = _sender(KEY, link_id=9, stamp=two_minutes_ago)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.sendto(_frame(old, old.mission_clear_all_encode(1, 191, 0)), ("127.0.0.1", signed.gcs_port))
    assert signed.wait(lambda: ex.signature_refusals.get(Verdict.TOO_OLD, 0) == 1, 10.0), ex.signature_refusals
    # A ground station whose clock lags as much is refused only until it hears the executive: pymavlink then
    # moves its timestamp up to the newest it verified (mavlink.io "Timestamp handling"), and a resend gets in.
    items = goals_to_items(load_mission(DEMO_MISSION).goals, home_lat_deg=33.4, home_lon_deg=-117.8)
    lagging = _gcs(signed, KEY, link_id=10, initial_timestamp=two_minutes_ago)
    try:
        upload_goals(lagging, items)  # the running goals again: accepted and kept
    finally:
        lagging.close()
    assert ex.signature_refusals[Verdict.TOO_OLD] >= 2  # its first MISSION_COUNT went out before it heard anything
    assert set(ex.signature_refusals) == {Verdict.REPLAYED, Verdict.TOO_OLD}
    signed.stop()
    lines = _refusal_lines(ex.config.log_path)
    assert lines[0].startswith("refused replayed FILE_TRANSFER_PROTOCOL from 255/190 on the ground-station link")
    assert any(line.startswith("refused too old MISSION_CLEAR_ALL from 255/190") for line in lines), lines
    sources = [r.get("source") for r in _log(ex.config.log_path, "/executive/policy") if r["reason"] == "swapped"]
    assert sources == ["upload /tables/goal-0.lrpt"] * 2


@slow
def test_uploads_and_commands_through_the_autopilot_link_must_be_signed_and_a_flood_is_not_logged(signed):
    ex = signed.executive
    create = Frame(1, 0, Opcode.CREATE_FILE, 12, 0, 0, 0, b"/tables/x.lrpt").pack()
    unsigned, signer = _sender(None), _sender(KEY, link_id=5, stamp=timestamp_at(time.time()))
    decisions = ex._counts["decisions"]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        def route(frame: bytes) -> None:  # from the vehicle's address: the executive takes no other on that link
            signed.sim.route(frame)

        route(_frame(unsigned, unsigned.file_transfer_protocol_encode(0, 1, 191, create)))
        route(_frame(unsigned, unsigned.command_long_encode(1, 191, 400, 0, 1, 0, 0, 0, 0, 0, 0)))
        route(_frame(unsigned, unsigned.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)))  # not for us
        assert signed.wait(lambda: ex.signature_refusals.get(Verdict.UNSIGNED, 0) == 2, 10.0), ex.signature_refusals
        route(_frame(signer, signer.file_transfer_protocol_encode(0, 1, 191, create)))  # answered
        # A flood on the ground-station link: every frame counted, the log told once.
        for _ in range(300):
            sock.sendto(_frame(unsigned, unsigned.heartbeat_encode(6, 8, 0, 0, 4)), ("127.0.0.1", signed.gcs_port))
            time.sleep(0.001)  # paced: a full socket buffer would drop datagrams before they could be counted
    assert signed.wait(lambda: ex.signature_refusals.get(Verdict.UNSIGNED, 0) == 302, 10.0), ex.signature_refusals
    assert signed.wait(lambda: ex._counts["decisions"] > decisions + 10, 10.0)  # unsigned telemetry still drives it
    signed.stop()
    log = ex.config.log_path
    lines = _refusal_lines(log)
    # One line per verdict and link in 10 s: the routed command and the 300 heartbeats were only counted.
    # In either order: the two links' refusals are milliseconds apart, and the log orders messages by
    # their vehicle-time stamps, which the executive extrapolates between telemetry (seen swapped once).
    assert sorted(line.split(":")[0] for line in lines) == [
        "refused unsigned FILE_TRANSFER_PROTOCOL from 255/190 on the autopilot link",
        "refused unsigned HEARTBEAT from 255/190 on the ground-station link"], lines
    replies = [r for r in _log(log, "/mavlink/tx") if r["name"] == "FILE_TRANSFER_PROTOCOL"]
    assert len(replies) == 1 and replies[0]["fields"]["target_system"] == 255  # only the signed CreateFile
    received = [r for r in _log(log, "/mavlink/rx") if r["src_system"] == 255]
    assert [r["name"] for r in received] == ["COMMAND_LONG", "FILE_TRANSFER_PROTOCOL"]  # not for us; the signed one
