"""The MCAP recorder: real files read back with the official mcap reader, crash safety, recovery."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from enum import Enum, IntEnum
from pathlib import Path

import pytest
from mcap.reader import make_reader

from executive.recorder import LogError, Recorder, Topic, read_messages, recover
from tests.support import REPO


STATE = {"time_s": 12.5, "lat_deg": 33.6, "lon_deg": -118.4, "depth_m": 20.0, "heading_deg": 91.0, "mode": 4,
         "armed": True, "position_ok": True, "battery_pct": 80.0, "energy_used_wh": 1.5, "heartbeat_s": 12.0}
# One payload per custom topic, shaped as executive/loop.py builds them.
PAYLOADS = {
    Topic.STATE: STATE,
    Topic.DECISION: {"time_s": 12.5, "lat_deg": 33.6, "lon_deg": -118.4, "depth_m": 20.0, "heading_deg": 91.0,
                     "cell": [0, 3, 4, 2], "situation": "following", "action": "FORWARD", "mode": "GUIDED",
                     "changed": True},
    Topic.COMMAND: {"time_s": 12.5, "kind": "DepthTarget", "depth_m": 20.0},
    Topic.POLICY: {"time_s": 0.0, "reason": "loaded", "table_crc32": "0badf00d",
                   "forecast": {"identity": "scb-2024", "time": None}, "grid": {"nx": 29}, "goal": {"lat_deg": 33.7},
                   "model": "paper", "criterion": "robust"},
    Topic.MAVLINK_RX: {"msg_id": 33, "name": "GLOBAL_POSITION_INT", "src_system": 1, "src_component": 1,
                       "fields": {"time_boot_ms": 12500, "lat": 336000000}},
    Topic.MAVLINK_TX: {"msg_id": 0, "name": "HEARTBEAT", "src_system": 1, "src_component": 191,
                       "fields": {"type": 18}},
}


def _messages(path: Path) -> list[tuple[str, int, int, int, bytes]]:
    """Every message as (topic, log_time, publish_time, sequence, data), read with the official reader."""
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.publish_time, m.sequence, m.data)
                for _, c, m in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False)]


UTC0_NS = 1_700_000_000_250_000_000  # UTC of vehicle time 0 in the sample (Unix ns)
GEOJSON = {Topic.MAP_GOALS: {"type": "Point", "coordinates": [-117.9, 33.7]},
           Topic.MAP_GEOFENCE: {"type": "Polygon", "coordinates": [[[-118.5, 33.5], [-117.5, 33.5], [-117.5, 34.0],
                                                                   [-118.5, 33.5]]]},
           Topic.MAP_PLAN: {"type": "FeatureCollection", "features": []}}


def _write_sample(path: Path) -> None:
    with Recorder(path, metadata={"executive": {"table": "demo.lrpt", "link": "udpout:127.0.0.1:14560"}},
                  utc_offset_ns=UTC0_NS) as rec:
        rec.metadata("mission", {"name": "demo"})
        rec.attach("policy-0badf00d.lrpt", b"LRPT\x00\x01policy bytes", log_time_s=0.0)
        rec.location_fix(10.0, lat_deg=33.6, lon_deg=-118.4, depth_m=20.0, heading_deg=-90.0,
                         velocity_enu_m_s=(0.5, -1.0, 0.25))
        for i, level in enumerate(("debug", "info", "warning", "error")):
            rec.log(11.0 + i, level, f"a {level} line")
        for i, (topic, payload) in enumerate(PAYLOADS.items()):
            rec.write(topic, 20.0 + i, payload, publish_time_s=1_700_000_100.0)
        for i, (topic, layer) in enumerate(GEOJSON.items()):
            rec.geojson(topic, 30.0 + i, layer)


# -- writing and reading back ------------------------------------------------------------


def test_a_log_reads_back_with_the_official_reader(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_header().profile == "lrauv"
        summary = reader.get_summary()
        assert summary is not None
        schemas = {s.name: s for s in summary.schemas.values()}
        assert {"foxglove.LocationFix", "foxglove.Log"} <= set(schemas)
        assert all(s.encoding == "jsonschema" for s in schemas.values())
        assert len(schemas) == 8  # the MAVLink channels share lrauv.MavlinkMessage, the map layers foxglove.GeoJSON
        assert all(c.message_encoding == "json" for c in summary.channels.values())
        assert summary.statistics.message_count == 1 + 4 + len(PAYLOADS) + len(GEOJSON)
        assert summary.statistics.channel_count == 2 + len(PAYLOADS) + len(GEOJSON)
        assert summary.statistics.attachment_count == 1 and summary.statistics.metadata_count == 3
        decoded = [(c.topic, s.name, m.log_time, json.loads(m.data)) for s, c, m in reader.iter_messages()]
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = list(reader.iter_attachments())

    topic, schema_name, log_time, fix = decoded[0]
    # Log time and timestamp: UTC (vehicle time + the clock's offset); the vehicle time in boot_time_s.
    assert (topic, schema_name, log_time) == ("/vehicle/fix", "foxglove.LocationFix", UTC0_NS + 10_000_000_000)
    assert fix["timestamp"] == {"sec": 1_700_000_010, "nsec": 250_000_000} and fix["boot_time_s"] == 10.0
    assert fix["latitude"] == 33.6 and fix["longitude"] == -118.4 and fix["altitude"] == -20.0
    assert fix["position_covariance"] == [0.0] * 9 and fix["position_covariance_type"] == 0
    assert fix["heading"] == pytest.approx(math.radians(270.0))  # radians clockwise from north, in [0, 2 pi)
    assert fix["velocity"] == {"x": 0.5, "y": -1.0, "z": 0.25}  # east, north, up
    assert set(fix) - {"boot_time_s"} <= set(json.loads(schemas["foxglove.LocationFix"].data)["properties"])
    logs = [p for t, _, _, p in decoded if t == "/log"]
    assert [(p["level"], p["message"]) for p in logs] == [
        (1, "a debug line"), (2, "a info line"), (3, "a warning line"), (4, "a error line")]
    assert all(p["name"] == "executive" and p["file"] == "" and p["line"] == 0 for p in logs)
    by_topic = {t: p for t, _, _, p in decoded}
    assert by_topic["/vehicle/state"] == {**STATE, "boot_time_s": 20.0}
    for i, (topic, layer) in enumerate(GEOJSON.items()):  # the GeoJSON as text, as foxglove.GeoJSON has it
        assert json.loads(by_topic[topic.value]["geojson"]) == layer
        assert by_topic[topic.value]["timestamp"] == {"sec": 1_700_000_030 + i, "nsec": 250_000_000}
    assert metadata == {"executive": {"table": "demo.lrpt", "link": "udpout:127.0.0.1:14560"},
                        "mission": {"name": "demo"},
                        "clock": {"log_time": metadata["clock"]["log_time"], "source": "given",
                                  "utc_offset_ns": str(UTC0_NS), "held_records": "0", "changes": "0"}}
    assert [(a.name, a.media_type, a.data, a.log_time) for a in attachments] == [
        ("policy-0badf00d.lrpt", "application/octet-stream", b"LRPT\x00\x01policy bytes", UTC0_NS)]


def test_custom_schemas_are_json_and_every_payload_has_the_required_keys(tmp_path):
    for topic in Topic:
        schema = json.loads(json.dumps(topic.schema))
        assert schema["type"] == "object" and schema["title"] == topic.schema_name
        assert set(topic.required) <= set(schema["properties"]), topic
    path = tmp_path / "run.mcap"
    _write_sample(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        written = {s.name: json.loads(s.data) for s in reader.get_summary().schemas.values()}
        for schema, channel, message in reader.iter_messages():
            payload = json.loads(message.data)
            required = written[schema.name].get("required", [])
            assert set(required) <= set(payload), (channel.topic, set(required) - set(payload))
    assert {t for t in PAYLOADS} | {Topic.FIX, Topic.LOG} | set(GEOJSON) == set(Topic)


class Color(Enum):
    RED = "red"


class Mode(IntEnum):
    GUIDED = 4


class Plain(Enum):
    ONE = 1


def test_nan_enum_and_tuple_payloads_serialise(tmp_path):
    path = tmp_path / "odd.mcap"
    with Recorder(path) as rec:
        rec.write(Topic.STATE, 1.0, {"time_s": math.nan, "depth_m": math.inf, "lat_deg": -math.inf,
                                     "mode": Mode.GUIDED, "color": Color.RED, "plain": Plain.ONE,
                                     "cell": (1, 2, 3, 4), "nested": {"x": [math.nan, (Color.RED, 2.5)]},
                                     Color.RED: 1, 7: "int key", "raw": b"\x00\xff"})
        rec.write(Topic.STATE, 2.0, {"fast": (1, 2), "mode": Mode.GUIDED, "plain": Plain.ONE})  # no NaN: fast path
    (_, _, odd), (_, _, fast) = list(read_messages(path))
    assert odd == {"time_s": None, "depth_m": None, "lat_deg": None, "mode": 4, "color": "red", "plain": 1,
                   "cell": [1, 2, 3, 4], "nested": {"x": [None, ["red", 2.5]]}, "red": 1, "7": "int key",
                   "raw": "AP8="}
    assert fast == {"fast": [1, 2], "mode": 4, "plain": 1}


def test_bad_input_fails_with_a_log_error(tmp_path):
    with Recorder(tmp_path / "bad.mcap") as rec:
        with pytest.raises(LogError, match="not JSON serialisable"):
            rec.write(Topic.STATE, 1.0, {"x": object()})
        with pytest.raises(LogError, match="finite log_time_s"):
            rec.write(Topic.STATE, math.nan, {})
        with pytest.raises(LogError, match="log level"):
            rec.log(1.0, "loud", "x")  # type: ignore[arg-type]
        with pytest.raises(LogError, match="strings"):
            rec.metadata("m", {"k": 1})  # type: ignore[dict-item]
    with pytest.raises(LogError, match="after close"):
        rec.write(Topic.STATE, 1.0, {})
    rec.close()  # idempotent
    with pytest.raises(LogError, match="chunk_size"):
        Recorder(tmp_path / "x.mcap", chunk_size=0)
    with pytest.raises(LogError, match="cannot open"):
        Recorder(tmp_path / "missing-dir" / "x.mcap")


def test_log_time_may_go_backwards(tmp_path):
    path = tmp_path / "reboot.mcap"
    with Recorder(path) as rec:
        for t in (100.0, 101.0, 3.0, -1.0, 4.0):  # an autopilot reboot, then a clock glitch below zero
            rec.write(Topic.STATE, t, {"time_s": t})
    assert rec.messages_written == 5
    # read_messages gives vehicle time (boot_time_s); ordered by log time, UTC (here the host's clock)
    assert [t for _, t, _ in read_messages(path)] == [-1.0, 3.0, 4.0, 100.0, 101.0]
    assert [s for _, _, _, s, _ in _messages(path)] == [0, 1, 2, 3, 4]  # per-channel sequence


def test_read_messages_filters_topics(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    assert [t for t, _, _ in read_messages(path, ["/log"])] == ["/log"] * 4
    assert {t for t, _, _ in read_messages(path)} == {t.value for t in Topic}


def test_maybe_flush_follows_the_wall_clock_interval(tmp_path):
    path = tmp_path / "flush.mcap"
    rec = Recorder(path, flush_interval_s=1.0, utc_offset_ns=UTC0_NS)
    t0 = time.monotonic()
    size0 = rec.bytes_written
    rec.write(Topic.STATE, 1.0, STATE)
    rec.maybe_flush(t0 - 10.0)  # earlier than the last flush: nothing to do
    assert rec.bytes_written == size0 == path.stat().st_size
    rec.maybe_flush(t0 + 2.0)
    assert rec.bytes_written > size0 and path.stat().st_size == rec.bytes_written
    rec.close()
    assert rec.bytes_written == path.stat().st_size


# -- crash safety and recovery --------------------------------------------------------------

WRITER = textwrap.dedent("""
    import sys
    from executive.recorder import Recorder, Topic
    rec = Recorder(sys.argv[1], chunk_size=2048, flush_interval_s=0, utc_offset_ns=1_700_000_000 * 10**9)
    print("ready", flush=True)
    i = 0
    while True:
        rec.write(Topic.STATE, i * 0.5, {"time_s": i * 0.5, "lat_deg": 33.0 + i * 1e-6, "note": "x" * (i % 50)})
        if i % 7 == 0:
            rec.log(i * 0.5, "info", f"line {i}")
        rec.maybe_flush()  # flush_interval_s=0: every call flushes
        i += 1
        if i % 25 == 0:
            print("flushed", rec.messages_written, flush=True)
""")


def test_a_killed_writer_leaves_a_recoverable_log(tmp_path):
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], cwd=REPO, stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    flushed = 0
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            flushed = int(line.split()[1])
            if flushed >= 3000 and path.stat().st_size > 150_000:
                break
        os.kill(proc.pid, signal.SIGKILL)
        for line in proc.stdout:  # lines printed between our last read and the kill
            flushed = int(line.split()[1])
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert flushed >= 3000

    with pytest.raises(LogError, match="truncated.*lrauv log recover"):
        read_messages(path)
    result = recover(path)
    assert result.output == str(tmp_path / "killed.recovered.mcap")
    assert not result.complete and result.truncated_at_byte is not None
    assert result.truncated_at_byte <= path.stat().st_size
    assert result.messages >= flushed and result.channels == 2
    messages = _messages(Path(result.output))
    assert len(messages) == result.messages
    state_times = [t for topic, t, _, _, _ in messages if topic == "/vehicle/state"]
    assert state_times == sorted(state_times) and len(set(state_times)) == len(state_times)
    assert result.last_utc_s == state_times[-1] / 1e9  # the latest log time, UTC
    assert result.last_log_time_s == (state_times[-1] - 1_700_000_000 * 10**9) / 1e9  # its vehicle time
    with open(result.output, "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == result.messages
    assert len(list(read_messages(result.output))) == result.messages


def test_recovering_a_complete_log_is_a_faithful_copy(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    out = tmp_path / "copy.mcap"
    result = recover(path, out)
    assert result.complete and result.truncated_at_byte is None and result.chunks_dropped == 0
    assert result.messages == 1 + 4 + len(PAYLOADS) + len(GEOJSON)
    assert result.channels == 2 + len(PAYLOADS) + len(GEOJSON)
    assert _messages(out) == _messages(path)
    with open(path, "rb") as a, open(out, "rb") as b:
        ra, rb = make_reader(a), make_reader(b)
        assert ra.get_header().profile == rb.get_header().profile
        assert [(m.name, m.metadata) for m in ra.iter_metadata()] == [(m.name, m.metadata) for m in rb.iter_metadata()]
        assert [(x.name, x.data) for x in ra.iter_attachments()] == [(x.name, x.data) for x in rb.iter_attachments()]
        schemas = [sorted((s.name, s.data) for s in r.get_summary().schemas.values()) for r in (ra, rb)]
        assert schemas[0] == schemas[1]


def test_every_cut_of_a_log_recovers_a_prefix(tmp_path):
    """Truncating a finished log anywhere loses only the records after the cut (property over cut points)."""
    path = tmp_path / "run.mcap"
    with Recorder(path, chunk_size=512) as rec:
        for i in range(60):
            rec.write(Topic.STATE, float(i), {"time_s": float(i), "i": i})
    data = path.read_bytes()
    full = _messages(path)
    header_end = None
    previous = 0
    for cut in range(8, len(data), 7):
        cut_path = tmp_path / "cut.mcap"
        cut_path.write_bytes(data[:cut])
        try:
            result = recover(cut_path, tmp_path / "cut.out.mcap")
        except LogError as exc:
            assert header_end is None, f"cut at {cut}: {exc}"  # only a cut inside the header is unrecoverable
            assert "header" in str(exc)
            continue
        header_end = header_end or cut
        got = _messages(tmp_path / "cut.out.mcap")
        assert got == full[: len(got)] and len(got) >= previous
        assert result.truncated_at_byte is not None and result.truncated_at_byte <= cut
        previous = len(got)
    assert previous == len(full)  # a cut inside the summary keeps every message


def test_a_damaged_chunk_is_dropped_and_the_rest_kept(tmp_path):
    path = tmp_path / "run.mcap"
    with Recorder(path, chunk_size=512, utc_offset_ns=0) as rec:  # log time = vehicle time
        for i in range(60):
            rec.write(Topic.STATE, float(i), {"time_s": float(i), "i": i})
    with open(path, "rb") as f:
        second = make_reader(f).get_summary().chunk_indexes[1]
    data = bytearray(path.read_bytes())
    data[second.chunk_start_offset + second.chunk_length - 3] ^= 0xFF  # inside the compressed records
    path.write_bytes(bytes(data))
    result = recover(path)
    assert result.complete and result.chunks_dropped == 1
    lost = range(second.message_start_time // 10**9, second.message_end_time // 10**9 + 1)
    assert [p["i"] for _, _, p in read_messages(result.output)] == [i for i in range(60) if i not in lost]


def test_not_mcap_and_empty_files_are_refused_by_name(tmp_path):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    text = tmp_path / "notes.mcap"
    text.write_text("this is not a log\n")
    for func in (read_messages, recover):
        with pytest.raises(LogError, match=r"empty\.mcap: empty file"):
            func(empty)
        with pytest.raises(LogError, match=r"notes\.mcap: not an MCAP file \(bad magic"):
            func(text)
    stub = tmp_path / "stub.mcap"
    stub.write_bytes(b"\x89MCA")  # killed while writing the magic
    with pytest.raises(LogError, match=r"stub\.mcap: truncated inside the MCAP magic"):
        recover(stub)
    with pytest.raises(LogError, match="missing.mcap: cannot read"):
        recover(tmp_path / "missing.mcap")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.mcap", "notes.mcap", "stub.mcap"]  # no output, no temp


def test_recover_refuses_to_overwrite_its_source(tmp_path):
    path = tmp_path / "run.mcap"
    _write_sample(path)
    before = path.read_bytes()
    with pytest.raises(LogError, match="onto the source"):
        recover(path, tmp_path / "." / "run.mcap")
    assert path.read_bytes() == before
