"""The executive's MCAP logs read by an independent implementation: Foxglove's TypeScript ``@mcap/core`` under Node.

``tests/node/read_mcap.mjs`` reads a log with ``McapIndexedReader`` (footer,
summary, chunk and message indexes, every CRC checked) or, with ``--stream``,
with ``McapStreamReader`` fed the file in pieces, and prints what it saw as
JSON. These tests write real logs with ``Recorder`` and check that the other
implementation sees exactly what was written: every message's bytes, log and
publish time and sequence, the schemas, metadata and attachments; and that a
log cut off by a killed writer stream-reads up to the same message as
``recover``.

``make test`` installs the pinned packages (``npm ci --prefix tests/node``)
when ``node`` and ``npm`` are on PATH; otherwise these tests are skipped, with
the reason.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from executive.recorder import Recorder, Topic, read_messages, recover
from tests.support import REPO

NODE_DIR = REPO / "tests" / "node"
SCRIPT = NODE_DIR / "read_mcap.mjs"
PACKAGES = ("@mcap/core", "@foxglove/wasm-zstd")
NODE = shutil.which("node")
INSTALLED = all((NODE_DIR / "node_modules" / p / "package.json").is_file() for p in PACKAGES)

pytestmark = [
    pytest.mark.skipif(NODE is None, reason="node is not on PATH: the cross-check with the TypeScript MCAP reader"
                       " (@mcap/core) needs Node.js >= 18 and npm"),
    pytest.mark.skipif(NODE is not None and not INSTALLED, reason="tests/node/node_modules lacks @mcap/core or"
                       " @foxglove/wasm-zstd: run `make test` (it runs `npm ci --prefix tests/node` when node and npm"
                       " are on PATH)"),
]

NS = 1_000_000_000
T0 = 1_700_000_000  # Unix seconds of the first publish time, and the UTC of vehicle time 0 (the log times)
STEPS = 120  # one message per topic and step (policy every 25 steps, map layers every 40)
CHUNK_SIZE = 2048  # small chunks: the log has dozens of them
ATTACHMENT = ("policy-0badf00d.lrpt", bytes(range(256)) * 9 + b"LRPT tail", "application/x-lrauv-policy")
METADATA = {"executive": {"table": "demo.lrpt", "link": "udpout:127.0.0.1:14560"},
            "mission": {"name": "demo", "note": "ünïcode ✓, \"quotes\"\nand a newline"}}
LEVELS = ("debug", "info", "warning", "error")
ACTIONS = ("FORWARD", "DRIFT", "ROTATE_LEFT", "ROTATE_RIGHT", "UP", "DOWN", None)


def _pinned_core() -> str:
    return json.loads((NODE_DIR / "package.json").read_text())["dependencies"]["@mcap/core"]


def _node(*args: str | Path) -> subprocess.CompletedProcess[str]:
    assert NODE is not None
    return subprocess.run([NODE, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=120,
                          check=False, cwd=NODE_DIR)


def _read(path: Path, *options: str) -> dict[str, Any]:
    proc = _node(*options, path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    return json.loads(proc.stdout)


def _messages(report: dict[str, Any]) -> list[dict[str, Any]]:
    """Node's messages with times as ints, comparable with ``_write_log``'s expectations."""
    return [{"topic": m["topic"], "log_time": int(m["log_time"]), "publish_time": int(m["publish_time"]),
             "sequence": m["sequence"], "payload": m["payload"]} for m in report["messages"]]


def _python_messages(path: Path) -> list[tuple[str, int, int, int, str]]:
    """(topic, log_time, publish_time, sequence, JSON text) read with the Python mcap package, in file order."""
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.publish_time, m.sequence, m.data.decode())
                for _, c, m in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False)]


def _node_texts(report: dict[str, Any]) -> list[tuple[str, int, int, int, str]]:
    return [(m["topic"], int(m["log_time"]), int(m["publish_time"]), m["sequence"], m["text"])
            for m in report["messages"]]


# -- a log written with the Recorder --------------------------------------------------------


def _write_log(path: Path) -> list[dict[str, Any]]:
    """A log on every topic; returns the messages as written (payloads as JSON gives them back), in order.

    Each message has its own vehicle time (n * 0.125 s, exact in binary), so its own UTC log
    time (T0 + that) and publish time, and log-time order is write order.
    """
    expected: list[dict[str, Any]] = []
    sequence: dict[Topic, int] = {}
    n = 0

    def stamp() -> tuple[float, float]:
        nonlocal n
        n += 1
        return n * 0.125, T0 + n * 0.25

    def add(topic: Topic, payload: dict[str, Any]) -> None:  # the message written at the last stamp()
        seq = sequence.get(topic, 0)
        sequence[topic] = seq + 1
        # In integers: a Unix time in float nanoseconds would be off by up to 128 ns.
        expected.append({"topic": topic.value, "log_time": T0 * NS + n * NS // 8, "publish_time": T0 * NS + n * NS // 4,
                         "sequence": seq, "payload": {**payload, "boot_time_s": n * 0.125}})

    def timestamp() -> dict[str, int]:  # the Foxglove timestamp of the last stamp(): its log time
        return {"sec": T0 + n // 8, "nsec": n % 8 * NS // 8}

    with Recorder(path, chunk_size=CHUNK_SIZE, metadata={"executive": METADATA["executive"]},
                  utc_offset_ns=T0 * NS) as rec:
        rec.metadata("mission", METADATA["mission"])
        name, data, media_type = ATTACHMENT
        rec.attach(name, data, media_type=media_type, log_time_s=0.5)
        for i in range(STEPS):
            lat, lon, depth = 33.5 + i * 1e-4, -118.1 + i * 2.5e-4, float(i % 16)
            t, u = stamp()
            rec.location_fix(t, lat_deg=lat, lon_deg=lon, depth_m=depth, heading_deg=i * 3.0, publish_time_s=u)
            add(Topic.FIX, {"timestamp": timestamp(), "frame_id": "vehicle", "latitude": lat, "longitude": lon,
                            "altitude": -depth, "position_covariance": [0.0] * 9, "position_covariance_type": 0,
                            "heading": math.radians(i * 3.0)})
            t, u = stamp()
            level = LEVELS[i % len(LEVELS)]
            text = f'step {i}: "{level}" ünïcode ✓ \\ tab\there\nsecond line'
            rec.log(t, level, text, publish_time_s=u)
            add(Topic.LOG, {"timestamp": timestamp(), "level": 1 + i % len(LEVELS), "message": text,
                            "name": "executive", "file": "", "line": 0})
            if i % 40 == 0:
                for topic in (Topic.MAP_GOALS, Topic.MAP_GEOFENCE, Topic.MAP_PLAN):
                    t, u = stamp()
                    layer = {"type": "Point", "coordinates": [lon, lat]}
                    rec.geojson(topic, t, layer, publish_time_s=u)
                    add(topic, {"timestamp": timestamp(), "geojson": json.dumps(layer, separators=(",", ":"))})
            state = {"time_s": t, "lat_deg": lat, "lon_deg": lon, "depth_m": depth, "heading_deg": (i * 7.5) % 360,
                     "mode": 4 if i else None, "armed": i > 0, "position_ok": i % 5 != 0,
                     "battery_pct": 100.0 - i * 0.3, "energy_used_wh": i * 0.01, "heartbeat_s": t - 0.1}
            payloads: list[tuple[Topic, dict[str, Any], dict[str, Any]]] = []
            if i % 7 == 3:  # not JSON as such: the recorder writes null (bare NaN would not parse in Node)
                payloads.append((Topic.STATE, {**state, "battery_pct": float("nan"), "energy_used_wh": float("inf")},
                                 {**state, "battery_pct": None, "energy_used_wh": None}))
            else:
                payloads.append((Topic.STATE, state, state))
            decision = {"time_s": t, "lat_deg": lat, "lon_deg": lon, "depth_m": depth, "heading_deg": 90.0,
                        "cell": [i % 4, i % 21, i % 29, i % 8] if i % 9 else None, "situation": "following",
                        "action": ACTIONS[i % len(ACTIONS)], "mode": "GUIDED", "changed": i % 3 == 0}
            payloads.append((Topic.DECISION, decision, decision))
            command = {"time_s": t, "kind": "VelocityYaw", "vx_m_s": 1.0 + i / 1000, "yaw_deg": -45.5}
            payloads.append((Topic.COMMAND, command, command))
            if i % 25 == 0:
                policy = {"time_s": t, "reason": "loaded" if i == 0 else "swapped", "table_crc32": f"{i:08x}",
                          "forecast": {"identity": "scb-2024", "time": None}, "grid": {"nx": 29, "ny": 21},
                          "goal": {"lat_deg": 33.7, "lon_deg": -117.9}, "model": "paper", "criterion": "robust"}
                payloads.append((Topic.POLICY, policy, policy))
            rx = {"msg_id": 33, "name": "GLOBAL_POSITION_INT", "src_system": 1, "src_component": 1,
                  "fields": {"time_boot_ms": 1000 * i, "lat": round(lat * 1e7), "lon": round(lon * 1e7),
                             "time_usec": 1_700_000_000_000_000 + i, "vel": (1, -2, 3)}}
            payloads.append((Topic.MAVLINK_RX, rx, {**rx, "fields": {**rx["fields"], "vel": [1, -2, 3]}}))
            tx = {"msg_id": 0, "name": "HEARTBEAT", "src_system": 1, "src_component": 191,
                  "fields": {"type": 18, "custom_mode": i}, "direction": "tx"}
            payloads.append((Topic.MAVLINK_TX, tx, tx))
            for topic, written, as_read in payloads:
                t, u = stamp()
                rec.write(topic, t, written, publish_time_s=u)
                add(topic, as_read)
    return expected


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> tuple[Path, list[dict[str, Any]]]:
    path = tmp_path_factory.mktemp("node") / "run.mcap"
    return path, _write_log(path)


@pytest.fixture(scope="module")
def indexed(written) -> dict[str, Any]:
    return _read(written[0], "--messages")


# -- the indexed reader on a finished log -------------------------------------------------


def test_node_reads_the_pinned_library_and_the_header(written, indexed):
    assert indexed["reader"] == f"mcap-typescript/{_pinned_core()}"
    assert indexed["mode"] == "indexed"
    assert indexed["header"]["profile"] == "lrauv"
    assert indexed["header"]["library"].startswith("lrauv executive.recorder; mcap-python/")


def test_node_reads_every_message_as_written(written, indexed):
    path, expected = written
    # seven topics each step, policy every 25, the three map layers every 40
    assert len(expected) == 7 * STEPS + len(range(0, STEPS, 25)) + 3 * len(range(0, STEPS, 40))
    got = _messages(indexed)
    assert len(got) == len(expected)
    for i, (g, e) in enumerate(zip(got, expected, strict=True)):
        assert g == e, f"message {i}"
    # The JSON text itself, byte for byte, against the Python mcap reader.
    assert _node_texts(indexed) == _python_messages(path)
    counts: dict[str, int] = {}
    for e in expected:
        counts[e["topic"]] = counts.get(e["topic"], 0) + 1
    assert indexed["counts"] == counts
    assert set(counts) == {t.value for t in Topic}
    assert indexed["message_count"] == len(expected)
    assert int(indexed["first_log_time"]) == expected[0]["log_time"]
    assert int(indexed["last_log_time"]) == expected[-1]["log_time"]


def test_node_sees_the_schemas_and_channels(indexed):
    for topic in Topic:
        schema = indexed["schemas"][topic.value]
        assert schema["name"] == topic.schema_name
        assert schema["encoding"] == "jsonschema"
        assert schema["schema"] == json.loads(json.dumps(topic.schema))  # the JSON schema parses in Node, unchanged
        assert indexed["channels"][topic.value] == {"message_encoding": "json", "metadata": {}}
    assert indexed["schemas"]["/vehicle/fix"]["name"] == "foxglove.LocationFix"
    assert indexed["schemas"]["/log"]["name"] == "foxglove.Log"


def _metadata_written() -> list[tuple[str, dict[str, str]]]:
    """The metadata records in file order: the constructor's, the clock it was given, then the mission's."""
    clock = {"log_time": "UTC, nanoseconds since the Unix epoch; boot_time_s in each payload is vehicle time since"
                         " boot", "source": "given", "utc_offset_ns": str(T0 * NS), "held_records": "0", "changes": "0"}
    return [("executive", METADATA["executive"]), ("clock", clock), ("mission", METADATA["mission"])]


def test_node_sees_the_metadata_and_attachments(indexed):
    assert [(m["name"], m["metadata"]) for m in indexed["metadata"]] == _metadata_written()
    assert indexed["metadata_index_names"] == [name for name, _ in _metadata_written()]
    name, data, media_type = ATTACHMENT
    [attachment] = indexed["attachments"]  # read with its CRC checked
    assert attachment["name"] == name
    assert attachment["media_type"] == media_type
    assert attachment["size"] == len(data)
    assert attachment["sha256"] == hashlib.sha256(data).hexdigest()
    assert int(attachment["log_time"]) == T0 * NS + NS // 2  # UTC too
    assert indexed["attachment_index_names"] == [name]


def test_node_finds_the_indexes_and_statistics_consistent(written, indexed):
    _, expected = written
    stats = indexed["statistics"]
    assert int(stats["message_count"]) == len(expected)
    assert stats["channel_count"] == len(Topic)
    assert stats["schema_count"] == len({t.schema_name for t in Topic})  # MAVLink and map topics share theirs
    assert (stats["metadata_count"], stats["attachment_count"]) == (len(_metadata_written()), 1)
    assert {k: int(v) for k, v in stats["channel_message_counts"].items()} == indexed["counts"]
    assert int(stats["message_start_time"]) == expected[0]["log_time"]
    assert int(stats["message_end_time"]) == expected[-1]["log_time"]
    # Small chunks: many of them, all ZSTD, each indexed; a topic filter goes through the message indexes.
    assert stats["chunk_count"] == len(indexed["chunk_indexes"]) > 20
    assert {c["compression"] for c in indexed["chunk_indexes"]} == {"zstd"}
    assert all(int(c["compressed_size"]) < int(c["uncompressed_size"]) for c in indexed["chunk_indexes"])
    assert indexed["indexed_counts"] == indexed["counts"]


# -- the stream reader ----------------------------------------------------------------------


def test_node_stream_reads_a_finished_log_like_the_indexed_reader(written, indexed):
    path, expected = written
    stream = _read(path, "--stream", "--messages", "--piece", "1000")
    assert stream["done"] is True and stream["bytes_remaining"] == 0
    assert stream["file_bytes"] == path.stat().st_size
    assert _messages(stream) == expected
    for key in ("header", "schemas", "channels", "counts", "metadata", "attachments", "first_log_time",
                "last_log_time"):
        assert stream[key] == indexed[key], key
    assert stream["records"]["Footer"] == 1


@pytest.mark.parametrize("cut", [0.35, 0.7, "footer"])
def test_node_stream_reads_a_cut_log_up_to_where_recover_stops(written, tmp_path, cut):
    """A killed writer's file (no footer): the indexed reader refuses it; the stream reader reads every
    complete message before the cut, and they are ``recover``'s messages and the first ones written."""
    path, expected = written
    data = path.read_bytes()
    end = len(data) - 10 if cut == "footer" else int(len(data) * cut)
    killed = tmp_path / "killed.mcap"
    killed.write_bytes(data[:end])

    refused = _node(killed)
    assert refused.returncode == 1 and refused.stdout == ""
    assert refused.stderr.startswith(f"read_mcap: {killed}: ")

    stream = _read(killed, "--stream", "--messages", "--piece", "4096")
    assert stream["done"] is False
    assert stream["file_bytes"] == end
    assert 0 <= stream["bytes_remaining"] < end  # 0 when the cut falls exactly between two records
    got = _messages(stream)
    n = len(got)
    if cut == "footer":
        assert n == len(expected)  # every chunk is before the summary
    else:
        assert 0 < n < len(expected)
    assert got == expected[:n]
    assert [(m["name"], m["metadata"]) for m in stream["metadata"]] == _metadata_written()
    assert [a["sha256"] for a in stream["attachments"]] == [hashlib.sha256(ATTACHMENT[1]).hexdigest()]

    recovery = recover(killed, tmp_path / "recovered.mcap")
    assert recovery.complete is False
    assert recovery.messages == n
    # Both implementations agree where the last complete record ends.
    assert recovery.truncated_at_byte == stream["file_bytes"] - stream["bytes_remaining"]
    recovered = [(topic, t, payload) for topic, t, payload in read_messages(recovery.output)]
    assert recovered == [(m["topic"], m["payload"]["boot_time_s"],  # vehicle time, lifted out of the payload
                          {k: v for k, v in m["payload"].items() if k != "boot_time_s"}) for m in got]
    # And the recovered file, a finished log again, reads in Node with the indexed reader.
    again = _read(Path(recovery.output), "--messages")
    assert _messages(again) == got


def test_node_reader_refuses_a_file_that_is_not_mcap(tmp_path):
    bogus = tmp_path / "not.mcap"
    bogus.write_bytes(b"PK\x03\x04 not an MCAP file at all" * 4)
    for options in ((), ("--stream",)):
        proc = _node(*options, bogus)
        assert proc.returncode == 1, options
        assert proc.stdout == ""
        assert "magic" in proc.stderr.lower()


# -- a real closed-loop run ------------------------------------------------------------------


def test_node_reads_the_log_of_a_closed_loop_run(dive_log, demo_plan):
    """The shared dive (``lrauv sim`` and ``lrauv exec`` over UDP to the goal): Node reads the executive's log as
    Python does, and its times are the dive's UTC, as Foxglove will show them."""
    log = Path(dive_log)
    report = _read(log, "--messages")

    # Every message, byte for byte; log times repeat, so compare in one total order.
    assert sorted(_node_texts(report)) == sorted(_python_messages(log))
    with open(log, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
        attachments = {a.name: a.data for a in reader.iter_attachments()}
    assert report["message_count"] == summary.statistics.message_count > 100
    assert {"/vehicle/fix", "/log", "/executive/decision", "/mavlink/rx", "/mavlink/tx", "/map/goals",
            "/map/geofence", "/map/plan"} <= set(report["counts"])
    assert report["indexed_counts"] == report["counts"]
    assert [(m["name"], m["metadata"]) for m in report["metadata"]] == metadata
    policy = f"policy-{demo_plan.table.crc32:08x}.lrpt"
    assert policy in attachments
    assert {a["name"]: (a["size"], a["sha256"]) for a in report["attachments"]} == {
        name: (len(data), hashlib.sha256(data).hexdigest()) for name, data in attachments.items()}
    assert attachments[policy] == (log.parent / "demo.lrpt").read_bytes()
    decisions = [m["payload"] for m in report["messages"] if m["topic"] == "/executive/decision"]
    assert {d["action"] for d in decisions} >= {"FORWARD", "AT_GOAL"}
    # Foxglove's view: log times in UTC (after 2020), and each Foxglove timestamp equal to its log time.
    assert int(report["first_log_time"]) > 1_577_836_800 * NS
    for m in report["messages"]:
        if "timestamp" in m["payload"]:
            stamp = m["payload"]["timestamp"]
            assert int(m["log_time"]) == stamp["sec"] * NS + stamp["nsec"], m["topic"]
