"""``lrauv replay LOG --tlog OUT.tlog``: the dive's MAVLink frames as a telemetry log that MAVLink tools read.

The dive is the shared real closed-loop log (``dive_log`` in conftest.py). The .tlog is read back
with pymavlink's own log reader (``mavutil.mavlink_connection``) and with its ``mavlogdump.py``
script in a subprocess, and compared record for record with the MCAP log's decoded messages.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
import pytest
from pymavlink import mavutil

from executive.mavlink_bridge import describe, mavlink
from executive.recorder import Recorder, Topic
from planner.cli import main as lrauv
from planner.shore.replay.divelog import open_dive
from planner.shore.replay.tlog import write_tlog

from tests.planner.shore.mcap_logs import as_old_format, rewrite_log

_MAVLINK_TOPICS = (Topic.MAVLINK_RX.value, Topic.MAVLINK_TX.value)


def _records(log: Path) -> list[Any]:
    return list(open_dive(log).messages((Topic.MAVLINK_RX, Topic.MAVLINK_TX)))


def _read_back(tlog: Path) -> list[Any]:
    conn = mavutil.mavlink_connection(str(tlog), dialect="ardupilotmega")
    out = []
    while (msg := conn.recv_msg()) is not None:
        out.append(msg)
    conn.close()
    return out


def _same(logged: Any, read: Any) -> bool:
    """A logged field (JSON: NaN as null, text as str) and the value pymavlink decoded from the frame."""
    if isinstance(read, float) and math.isnan(read):
        return logged is None or (isinstance(logged, float) and math.isnan(logged))
    if isinstance(read, bytes):
        read = read.decode("ascii", "replace").rstrip("\x00")
    if isinstance(read, float) and isinstance(logged, float) and read != logged:
        # a float field the executive sent: logged as computed (float64), on the wire as float (MAVLink float32)
        return struct.unpack("<f", struct.pack("<f", logged))[0] == read
    if isinstance(read, list):
        return len(read) == len(logged) and all(_same(a, b) for a, b in zip(logged, read, strict=True))
    return logged == read


def _utc_offset_s(records: list[Any]) -> float:
    st = next(r.payload["fields"] for r in records
              if r.payload["name"] == "SYSTEM_TIME" and r.payload["fields"]["time_unix_usec"] > 0)
    return st["time_unix_usec"] / 1e6 - st["time_boot_ms"] / 1e3


@pytest.fixture(scope="module")
def tlog(dive_log, tmp_path_factory) -> tuple[Path, str]:
    """``lrauv replay --tlog`` on the dive (a wrong forecast file: no planning again), and what it printed."""
    folder = tmp_path_factory.mktemp("tlog")
    (folder / "other.nc").write_bytes(b"not the forecast")
    out = folder / "dive.tlog"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = lrauv(["replay", str(dive_log), "--no-audit", "--forecast", str(folder / "other.nc"), "--tlog", str(out)])
    assert code == 0, printed.getvalue()
    return out, printed.getvalue()


def test_the_tlog_holds_every_logged_frame_message_for_message_at_utc(dive_log, tlog):
    out, printed = tlog
    records = _records(dive_log)
    assert f"tlog       {len(records):,} MAVLink frames, time utc" in printed
    assert f"wrote      {out}" in printed
    read = _read_back(out)
    assert len(read) == len(records) > 100
    kinds = {r.payload["name"] for r in records}
    assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "SYSTEM_TIME", "SET_POSITION_TARGET_GLOBAL_INT"} <= kinds, kinds
    for rec, msg in zip(records, read, strict=True):
        p = rec.payload
        assert (msg.get_type(), msg.get_msgId(), msg.get_srcSystem(), msg.get_srcComponent()) == (
            p["name"], p["msg_id"], p["src_system"], p["src_component"])
        wrong = [f for f in msg.get_fieldnames() if not _same(p["fields"][f], getattr(msg, f))]
        assert not wrong, (p["name"], wrong, p["fields"], msg)
    # Each frame at the log's UTC (SYSTEM_TIME's offset on vehicle time), never stepping back.
    stamps = [m._timestamp for m in read]
    assert stamps == sorted(stamps)
    offset_s = _utc_offset_s(records)
    assert abs(stamps[0] - (records[0].log_time_s + offset_s)) < 1e-6
    assert abs(stamps[-1] - max(r.log_time_s for r in records) - offset_s) < 1e-6
    assert stamps[0] > 1e9  # a real date, not 1970


def test_mavlogdump_lists_the_messages(dive_log, tlog):
    out, _ = tlog
    records = _records(dive_log)
    script = Path(sys.executable).parent / "mavlogdump.py"
    done = subprocess.run([sys.executable, str(script), str(out)], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "TZ": "UTC", "MAVLINK20": "1"}, check=False)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == len(records), (len(lines), len(records), done.stdout[-2000:])
    offset_s = _utc_offset_s(records)
    for line, rec in zip(lines, records, strict=True):
        # mavlogdump: "YYYY-MM-DD HH:MM:SS.cc: NAME {field : value, ...}"
        assert line.split(": ", 1)[1].startswith(rec.payload["name"] + " {"), line
    first = records[0].log_time_s + offset_s
    assert lines[0].startswith(time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(first))), (lines[0], first)
    position = next(r.payload for r in records if r.payload["name"] == "GLOBAL_POSITION_INT")
    assert any(f"lat : {position['fields']['lat']}," in line for line in lines)


def _frames_log(path: Path, utc: bool, *, old: bool = True) -> Path:
    """A small log of real frames (``describe`` of packed messages): SYSTEM_TIME after a first heartbeat,
    a message behind the newest log time, a reboot (vehicle time back near zero) and a later SYSTEM_TIME.

    ``old``: in the format of logs whose log times were vehicle time (``as_old_format``); else as the
    executive writes them now, its clock set by each SYSTEM_TIME as the loop does."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)

    def packed(msg: Any) -> dict[str, Any]:
        msg.pack(mav)
        return describe(msg)

    def system_time(unix_s: float, boot_s: float) -> dict[str, Any]:
        return packed(mavlink.MAVLink_system_time_message(round(unix_s * 1e6) if utc else 0, round(boot_s * 1e3)))

    def position(boot_s: float) -> dict[str, Any]:
        return packed(mavlink.MAVLink_global_position_int_message(round(boot_s * 1e3), 336_000_000, -1_178_000_000,
                                                                  0, -5_000, 0, 0, 0, 9_000))

    heartbeat = packed(mavlink.MAVLink_heartbeat_message(12, 3, 0, 0, 4, 3))
    rx = Topic.MAVLINK_RX
    new = path.with_name(f"new-{path.name}") if old else path
    with Recorder(new, utc_offset_ns=0 if old else None) as rec:
        for t, payload in ((5.0, heartbeat), (10.0, system_time(UNIX_S + 10.0, 10.0)), (11.0, position(11.0)),
                           (10.5, position(10.5)), (1.0, position(1.0)), (2.0, system_time(UNIX_S + 100.0, 2.0)),
                           (3.0, position(3.0))):
            if payload["name"] == "SYSTEM_TIME" and not old:  # before its own record is written, as the loop does
                rec.system_time(payload["fields"]["time_unix_usec"], t)
            rec.write(rx, t, payload)
    return as_old_format(new, path) if old else path


UNIX_S = 1_780_000_000.0  # 2026-05-28


def test_frames_are_at_their_utc_log_time_and_never_step_back(tmp_path):
    result = write_tlog(open_dive(_frames_log(tmp_path / "utc.mcap", utc=True, old=False)), tmp_path / "utc.tlog")
    assert (result.frames, result.without_frame, result.clock) == (7, 0, "utc")
    stamps = [m._timestamp for m in _read_back(result.path)]
    # The log's own times: the heartbeat held until the first SYSTEM_TIME, then dated with its offset; 10.5 s
    # and the reboot's 1 s (the last offset goes on until the next SYSTEM_TIME) held at 11 s; the second
    # SYSTEM_TIME's offset (98 s later in UTC than vehicle time says) from there on.
    expected = [UNIX_S + t for t in (5.0, 10.0, 11.0, 11.0, 11.0, 100.0, 101.0)]
    assert stamps == pytest.approx(expected, abs=1e-6)


def test_without_the_autopilots_utc_the_tlog_is_at_the_host_clock(tmp_path):
    before = time.time()
    result = write_tlog(open_dive(_frames_log(tmp_path / "host.mcap", utc=False, old=False)), tmp_path / "host.tlog")
    assert result.clock == "utc (host clock)"
    stamps = [m._timestamp for m in _read_back(result.path)]
    # the host's clock at the log's close stood for its newest vehicle time, 11 s: the first frame was 6 s before
    assert before - 6.0 - 1e-6 <= stamps[0] <= time.time() - 6.0 + 1e-6
    assert stamps == sorted(stamps)


def test_an_old_logs_frames_are_at_utc_from_each_system_time(tmp_path):
    result = write_tlog(open_dive(_frames_log(tmp_path / "utc.mcap", utc=True)), tmp_path / "utc.tlog")
    assert (result.frames, result.without_frame, result.clock) == (7, 0, "utc")
    stamps = [m._timestamp for m in _read_back(result.path)]
    # first offset for the frames before SYSTEM_TIME; 10.5 s and the reboot's 1 s held at 11 s; the second
    # SYSTEM_TIME's offset (98 s later in UTC than vehicle time says) from there on.
    expected = [UNIX_S + t for t in (5.0, 10.0, 11.0, 11.0, 11.0, 100.0, 101.0)]
    assert stamps == pytest.approx(expected, abs=1e-6)


def test_without_the_autopilots_utc_an_old_logs_tlog_is_in_vehicle_time(tmp_path):
    result = write_tlog(open_dive(_frames_log(tmp_path / "boot.mcap", utc=False)), tmp_path / "boot.tlog")
    assert result.clock == "vehicle time since boot"
    assert "7 MAVLink frames, time vehicle time since boot" == result.describe()
    stamps = [m._timestamp for m in _read_back(result.path)]
    assert stamps == pytest.approx([5.0, 10.0, 11.0, 11.0, 11.0, 11.0, 11.0], abs=1e-6)


def test_a_log_without_frames_says_so_in_one_line(dive_log, tmp_path, capsys):
    def decoded_only(topic: str, m: Any) -> bytes:
        if topic not in _MAVLINK_TOPICS:
            return m.data
        return json.dumps({k: v for k, v in json.loads(m.data).items() if k != "frame"}).encode()

    old = rewrite_log(dive_log, tmp_path / "old.mcap", decoded_only)
    out = tmp_path / "old.tlog"
    (tmp_path / "other.nc").write_bytes(b"not the forecast")
    assert lrauv(["replay", str(old), "--no-audit", "--forecast", str(tmp_path / "other.nc"), "--tlog", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no MAVLink frames in this log" in err and str(old) in err, err
    assert not out.exists() and list(tmp_path.glob(".old.tlog*")) == []
