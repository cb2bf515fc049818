"""``lrauv replay`` on broken logs: one line naming the file and exit status 2, never a traceback.

Status 1 stays "the decision audit found a difference". The broken logs are copies of
the real dive log (``dive_log`` in conftest.py, cut short here to keep each copy quick)
changed record by record with the ``mcap`` writer, or small logs of the executive's
own ``Recorder`` with a hostile chunk spliced in with mcap's record builder.
"""

from __future__ import annotations

import json
import socket
import struct
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from mcap.data_stream import RecordBuilder
from mcap.records import Attachment, Chunk, Message

from executive.helm import HelmConfig
from executive.recorder import Recorder, Topic, read_messages, recover
from planner.cli import main as lrauv
from planner.shore.replay.payloads import check_payload
from executive.log_records import CHUNK_BUDGET_BYTES, BoundedRecords
from tests.planner.shore.mcap_logs import rewrite_log

_SHORT = 3000  # messages kept of the dive: past the first decisions, a fraction of the dive


@pytest.fixture(scope="module")
def short_log(dive_log: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The first messages of the real dive, closed with a footer like any finished log."""
    kept = [0]

    def first(topic: str, m: Message) -> bytes | None:
        kept[0] += 1
        return m.data if kept[0] <= _SHORT else None

    return rewrite_log(dive_log, tmp_path_factory.mktemp("short") / "short.mcap", first, chunk_size=16 * 1024)


def _one_error(capsys: pytest.CaptureFixture[str], path: Path) -> str:
    """The one line on stderr; it names the file."""
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"lrauv: error: {path}"), err
    assert "Traceback" not in err
    return lines[0]


def _first(topic: str, edit: Callable[[Any], Any], name: str | None = None) -> Callable[[str, Message], bytes]:
    """A transform that changes the first message on ``topic`` (of MAVLink message ``name``) with ``edit``."""
    done = [False]

    def transform(t: str, m: Message) -> bytes:
        if done[0] or t != topic:
            return m.data
        payload = json.loads(m.data)
        if name is not None and payload.get("name") != name:
            return m.data
        done[0] = True
        out = edit(payload)
        return out if isinstance(out, bytes) else json.dumps(out).encode()
    return transform


def _fields(change: Callable[[dict], None]) -> Callable[[dict], dict]:
    def edit(p: dict) -> dict:
        change(p["fields"])
        return p
    return edit


# Each fault class of a record's JSON, and what the line must say.
FAULTS = {
    "NaN heading as text": (Topic.DECISION, None, lambda p: {**p, "heading_deg": "NaN"},
                            "heading_deg: expected number or null; got str 'NaN'"),
    "a list for the payload": (Topic.DECISION, None, lambda p: [p], "the payload: expected object; got list"),
    "a string in the table cell": (Topic.DECISION, None, lambda p: {**p, "cell": ["a", 1, 2, 3]},
                                   "cell[0]: expected integer; got str 'a'"),
    "a missing key": (Topic.POLICY, None, lambda p: {k: v for k, v in p.items() if k != "reason"}, "reason: missing"),
    "text for a MAVLink number": (Topic.MAVLINK_RX, "GLOBAL_POSITION_INT", _fields(lambda f: f.update(lat="33.4")),
                                  "GLOBAL_POSITION_INT.lat: expected int32_t"),
    "a missing MAVLink field": (Topic.MAVLINK_RX, "GLOBAL_POSITION_INT", _fields(lambda f: f.pop("lat")),
                                "GLOBAL_POSITION_INT: field 'lat' is missing"),
    "a list for the MAVLink fields": (Topic.MAVLINK_RX, "HEARTBEAT", lambda p: {**p, "fields": [1, 2]},
                                      "fields: expected object; got list"),
    "a number past its type": (Topic.MAVLINK_RX, "SYSTEM_TIME", _fields(lambda f: f.update(time_unix_usec=10 ** 400)),
                               "SYSTEM_TIME.time_unix_usec: expected uint64_t"),
    "text for the energy": (Topic.STATE, None, lambda p: {**p, "energy_used_wh": "lots"},
                            "energy_used_wh: expected number or null; got str 'lots'"),
    "JSON nested too deeply": (Topic.LOG, None, lambda p: b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_a_record_of_the_wrong_shape_is_named_with_status_2(short_log, tmp_path, capsys, fault):
    topic, name, edit, words = FAULTS[fault]
    bad = rewrite_log(short_log, tmp_path / "bad.mcap", _first(topic.value, edit, name))
    assert lrauv(["replay", str(bad)]) == 2
    line = _one_error(capsys, bad)
    assert f"{topic.value} message " in line and words in line, line


def _udp_port() -> tuple[socket.socket, int]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    return sock, sock.getsockname()[1]


@pytest.mark.parametrize("mode", ["--no-audit", "--csv", "--geojson", "--gpx", "--report", "--mavlink"])
def test_every_mode_gives_one_line_and_status_2(short_log, tmp_path, capsys, mode):
    """The exports, the report and the re-stream read the log through the same checks."""
    if mode == "--mavlink":  # only the re-stream reads what the executive sent
        bad = rewrite_log(short_log, tmp_path / "bad.mcap", _first(Topic.MAVLINK_TX.value, lambda p: {**p, "name": [1]}))
        sock, port = _udp_port()
        with sock:
            code = lrauv(["replay", str(bad), "--no-audit", "--mavlink", f"udpout:127.0.0.1:{port}", "--speed", "1e6"])
        words = "/mavlink/tx message 0"
    else:
        bad = rewrite_log(short_log, tmp_path / "bad.mcap", _first(Topic.DECISION.value, lambda p: {**p, "time_s": "x"}))
        extra = [] if mode == "--no-audit" else [mode, str(tmp_path / "out")]
        code = lrauv(["replay", str(bad), "--no-audit", *extra])
        words = "time_s: expected number"
    assert code == 2
    assert words in _one_error(capsys, bad)
    assert not (tmp_path / "out").exists()


def test_a_nan_heading_from_the_autopilot_is_replayed_as_nan(short_log, tmp_path, capsys):
    """The recorder writes NaN as null; the audit gives the helm NaN again, as the executive had it."""
    nan_yaw = rewrite_log(short_log, tmp_path / "nan.mcap",
                          _first(Topic.MAVLINK_RX.value, _fields(lambda f: f.update(yaw=None)), "ATTITUDE"))
    code = lrauv(["replay", str(nan_yaw)])
    captured = capsys.readouterr()
    assert code in (0, 1), captured.err
    assert "audit      " in captured.out and "Traceback" not in captured.err


def test_payloads_decode_as_pymavlink_gives_them():
    record = {"msg_id": 147, "name": "BATTERY_STATUS", "src_system": 1, "src_component": 1,
              "fields": {"id": 0, "battery_function": 1, "type": 3, "temperature": None, "voltages": [16000] * 10,
                         "current_battery": 50, "current_consumed": 62, "energy_consumed": 10, "battery_remaining": 90}}
    with pytest.raises(ValueError, match=r"BATTERY_STATUS.temperature: expected int16_t"):
        check_payload(Topic.MAVLINK_RX, record)  # null is NaN, and only a float can be NaN
    record["fields"]["temperature"] = 32767
    fields = check_payload(Topic.MAVLINK_RX, record)["fields"]
    assert fields["time_remaining"] == 0 and fields["voltages_ext"] == [0, 0, 0, 0]  # extensions the record lacks
    attitude = {"msg_id": 30, "name": "ATTITUDE", "src_system": 1, "src_component": 1,
                "fields": {"time_boot_ms": 1, "roll": 0, "pitch": 0.0, "yaw": None, "rollspeed": 0.0,
                           "pitchspeed": 0.0, "yawspeed": 0.0}}
    fields = check_payload(Topic.MAVLINK_RX, attitude)["fields"]
    assert fields["yaw"] != fields["yaw"] and isinstance(fields["roll"], float)  # NaN; 0 read as 0.0
    with pytest.raises(ValueError, match="msg_id 30 is ATTITUDE, not HEARTBEAT"):
        check_payload(Topic.MAVLINK_RX, {**attitude, "name": "HEARTBEAT"})


@pytest.mark.parametrize("name, change, words", [
    ("helm", lambda m: {**m, "config": json.dumps({"on_arrival": 5})},
     "metadata helm.config.on_arrival: expected one of 'hold'"),
    ("helm", lambda m: {**m, "config": "[1, 2]"}, "metadata helm.config: not a helm configuration"),
    ("helm", lambda m: {**m, "goal_index": "first"}, "metadata helm.goal_index: expected a goal index"),
])
def test_broken_helm_metadata_is_named_with_status_2(short_log, tmp_path, capsys, name, change, words):
    bad = rewrite_log(short_log, tmp_path / "bad.mcap", metadata=lambda n, m: change(m) if n == name else m)
    assert lrauv(["replay", str(bad)]) == 2
    assert words in _one_error(capsys, bad)


def test_a_policy_attachment_that_is_no_table_is_named_with_status_2(short_log, tmp_path, capsys):
    def junk(a: Attachment) -> bytes:
        return b"a text file, not a policy table" if a.name.startswith("policy-") else a.data

    bad = rewrite_log(short_log, tmp_path / "bad.mcap", attachments=junk)
    assert lrauv(["replay", str(bad)]) == 2
    assert "attachment policy-" in _one_error(capsys, bad)


# -- damaged files ---------------------------------------------------------------------------


def _records(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of the top-level records up to the footer."""
    out, pos = [], 8
    while pos < len(data) - 8:
        opcode, length = struct.unpack_from("<BQ", data, pos)
        out.append((pos, opcode, length))
        pos += 9 + length
        if opcode == 0x02:
            break
    return out


def test_a_chunk_that_fails_its_crc_replays_the_rest_then_exits_2(short_log, tmp_path, capsys):
    data = bytearray(short_log.read_bytes())
    chunks = [r for r in _records(bytes(data)) if r[1] == 0x06]
    at = chunks[len(chunks) // 2][0]
    compressed = at + 9 + 8 + 8 + 8 + 4 + 4  # start, end, uncompressed size, crc, compression "" or "zstd"
    compressed += struct.unpack_from("<I", data, at + 9 + 28)[0]  # the compression name's length
    for i in range(compressed + 8 + 20, compressed + 8 + 60):  # past the records' length, inside the records
        data[i] ^= 0xFF
    bad = tmp_path / "crc.mcap"
    bad.write_bytes(bytes(data))
    assert lrauv(["replay", str(bad), "--no-audit"]) == 2
    out = capsys.readouterr()
    assert "decisions  " in out.out  # what could be read was replayed
    assert f"DAMAGED: 1 chunk(s) failed their CRC or decompression (at byte {at:,})" in out.err
    assert len(out.err.strip().splitlines()) == 1 and out.err.startswith(f"lrauv: error: {bad}")


def test_an_unreadable_record_before_the_footer_is_damage_not_a_cut(short_log, tmp_path, capsys):
    data = bytearray(short_log.read_bytes())
    chunks = [r for r in _records(bytes(data)) if r[1] == 0x06]
    at = chunks[len(chunks) // 2][0]
    struct.pack_into("<Q", data, at + 1, 2 ** 40)  # a garbage length; the footer is still there
    bad = tmp_path / "garbage.mcap"
    bad.write_bytes(bytes(data))
    assert lrauv(["replay", str(bad), "--no-audit"]) == 2
    line = _one_error(capsys, bad)
    assert f"the record at byte {at:,} is unreadable though the file goes on to its footer" in line


def _zeros_zstd(n_bytes: int) -> bytes:
    """A zstd frame of ``n_bytes`` zeros, 4 bytes per 128 KiB (RFC 8878: RLE blocks, no content size)."""
    block = 128 * 1024
    rle = ((1 << 1) | (block << 3)).to_bytes(3, "little") + b"\x00"
    last = (1 | (1 << 1) | (block << 3)).to_bytes(3, "little") + b"\x00"
    # magic, a frame header without content size, window 128 KiB (exponent 7)
    return (0xFD2FB528).to_bytes(4, "little") + bytes([0x00, 7 << 3]) + rle * (n_bytes // block - 1) + last


def _bombed_log(path: Path, *, declared: int, holds: int) -> Path:
    """A small executive log with, right after its header, a zstd chunk of ``holds`` zeros declaring ``declared``."""
    plain = path.with_suffix(".plain.mcap")
    with Recorder(plain) as rec:
        rec.write(Topic.DECISION, 1.0, {"time_s": 1.0, "lat_deg": 33.4, "lon_deg": -117.8, "depth_m": 0.0,
                                        "heading_deg": 90.0, "cell": [0, 1, 1, 2], "situation": "following",
                                        "action": "FORWARD", "mode": "GUIDED", "changed": True})
    data = plain.read_bytes()
    header_end = 8 + 9 + struct.unpack_from("<Q", data, 9)[0]
    builder = RecordBuilder()
    Chunk(message_start_time=0, message_end_time=0, uncompressed_size=declared, uncompressed_crc=0,
          compression="zstd", data=_zeros_zstd(holds)).write(builder)
    path.write_bytes(data[:header_end] + builder.end() + data[header_end:])
    return path


def _peak_bytes(run: Callable[[], int]) -> tuple[int, int]:
    tracemalloc.start()
    try:
        code = run()
        return code, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_decompression_bomb_is_refused_before_it_is_decompressed(tmp_path, capsys):
    """98 kB that say and hold 3 GiB (the zeros a 133 kB log took 117 s and 3.2 GB to read)."""
    bomb = _bombed_log(tmp_path / "bomb.mcap", declared=3 * 2 ** 30, holds=3 * 2 ** 30)
    assert bomb.stat().st_size < 200_000
    code, peak = _peak_bytes(lambda: lrauv(["replay", str(bomb)]))
    assert code == 2
    line = _one_error(capsys, bomb)
    assert (f"declares {3 * 2 ** 30:,} bytes uncompressed, over the reader's budget of {CHUNK_BUDGET_BYTES:,} bytes a chunk"
            in line)
    assert peak < CHUNK_BUDGET_BYTES  # nothing of it was decompressed


def test_a_chunk_holding_more_than_it_declares_is_cut_at_what_it_declares(tmp_path, capsys):
    bomb = _bombed_log(tmp_path / "liar.mcap", declared=64 * 1024, holds=3 * 2 ** 30)
    code, peak = _peak_bytes(lambda: lrauv(["replay", str(bomb), "--no-audit"]))
    assert code == 2
    out = capsys.readouterr()
    assert "decisions  1" in out.out  # the log's own chunk is read on past it
    assert "DAMAGED: 1 chunk(s) failed their CRC or decompression" in out.err
    assert len(out.err.strip().splitlines()) == 1 and out.err.startswith(f"lrauv: error: {bomb}")
    assert peak < CHUNK_BUDGET_BYTES  # decompression stopped one byte past the 64 KiB declared


def test_the_bounded_reader_reads_what_the_indexed_reader_reads(dive_log):
    with open(dive_log, "rb") as f:
        ours = BoundedRecords(f, dive_log.stat().st_size, dive_log)
        messages = [r.data for r in ours if isinstance(r, Message)]
        assert ours.complete and not ours.damaged_chunks
    indexed = list(read_messages(dive_log))
    assert len(messages) == len(indexed) > 1000
    assert sorted(json.loads(m)["time_s"] for m in messages if b'"situation"' in m) == sorted(
        p["time_s"] for t, _, p in indexed if t == Topic.DECISION.value)


def test_recovery_drops_a_bomb_unopened_and_keeps_the_rest(tmp_path):
    """``lrauv log recover`` reads like replay: the 3 GiB chunk is dropped without decompressing it."""
    bomb = _bombed_log(tmp_path / "bomb.mcap", declared=3 * 2 ** 30, holds=3 * 2 ** 30)
    out = tmp_path / "fixed.mcap"
    code, peak = _peak_bytes(lambda: lrauv(["log", "recover", str(bomb), str(out)]))
    assert code == 0
    assert peak < CHUNK_BUDGET_BYTES
    assert [t for t, _, _ in read_messages(out)] == [Topic.DECISION.value]
    assert recover(bomb, tmp_path / "again.mcap").chunks_dropped == 1
