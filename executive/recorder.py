"""The executive's MCAP log: writing it, reading it back, and recovering one left by a killed process.

One file per run, JSON messages on a fixed set of topics (``Topic``), two of
them Foxglove well-known schemas so the Foxglove app draws the track (Map
panel, ``foxglove.LocationFix``) and the events (Log panel, ``foxglove.Log``)
without configuration. Log times are vehicle time since boot (``time_boot_ms``,
as ``executive.clock`` extrapolates it); publish times are the wall clock.

Crash safety: records go into small chunks and the loop calls ``maybe_flush`` every
iteration, so a SIGKILL loses at most ``flush_interval_s`` of data (and, in the
background, what the writer thread had not yet taken). The killed file has no footer and
the indexed reader refuses it; ``recover`` stream-reads every complete record and
writes a new, indexed file, like the ``mcap recover`` CLI does. A full or failing disk
never leaves half a record in the file (``executive.log_writer.PendingFile``).

Standard library and ``mcap`` only: the executive stays light.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
import os
import struct
import threading
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from enum import Enum, IntEnum
from pathlib import Path
from typing import IO, Any, BinaryIO, Literal, Self, cast, get_args

from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, IndexType, Writer

from executive.log_records import BoundedRecords, LogError
from executive.log_writer import Background, Flush, PendingFile, reason_of, spool_chunk_indexes
from executive.state import Event
from planner.contract.atomic import atomic_target

__all__ = ["LogError", "LogLevel", "Recorder", "Recovery", "Topic", "check_head", "is_complete", "read_messages", "recover"]

_MAGIC = b"\x89MCAP0\r\n"  # MCAP spec, "Magic"
_FOOTER_BYTES = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset_start, summary_crc
_FOOTER_OPCODE = 0x02
_LIBRARY = f"lrauv executive.recorder; {LIBRARY_IDENTIFIER}"
# ZSTD (mcap's default, level 3) rather than LZ4: on a telemetry mix like the loop's (MAVLink,
# state, fix, decision; 100k messages, 64 KiB chunks) the file was 5.5 MB with ZSTD, 7.6 MB with
# LZ4 and 28.6 MB uncompressed, and neither costs a measurable share of write()'s ~11 us
# (compression runs once per chunk). Disk on a multi-day mission is the scarcer resource.
_COMPRESSION = CompressionType.ZSTD
# All indexes (mcap's advice "if in doubt, choose ALL"). Message indexes are ~30% of the file
# (16 bytes a message, uncompressed) but let readers skip chunks without a wanted topic.
_INDEXES = IndexType.ALL
_NS_PER_S = 1_000_000_000


# -- topics and schemas ------------------------------------------------------------------

# Foxglove's published JSON schemas (foxglove/schemas, schemas/jsonschema/*.json), written
# out by hand; only the standard fields. Timestamps are {sec, nsec}.
_FOXGLOVE_TIME: dict[str, Any] = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}


def _enum(description: str, names: Iterable[str]) -> dict[str, Any]:
    return {"description": description, "oneOf": [{"title": n, "const": i} for i, n in enumerate(names)]}


_LOCATION_FIX: dict[str, Any] = {
    "title": "foxglove.LocationFix",
    "description": "A navigation satellite fix for any Global Navigation Satellite System",
    "type": "object",
    "properties": {
        "timestamp": {**_FOXGLOVE_TIME, "description": "Timestamp of the message"},
        "frame_id": {"type": "string", "description": "Frame for the sensor"},
        "latitude": {"type": "number", "description": "Latitude in degrees"},
        "longitude": {"type": "number", "description": "Longitude in degrees"},
        # Foxglove: metres above the WGS84 ellipsoid; we write -depth_m (sea level ~ ellipsoid).
        "altitude": {"type": "number", "description": "Altitude in meters"},
        "position_covariance": {
            "type": "array", "items": {"type": "number"}, "minItems": 9, "maxItems": 9,
            "description": "Position covariance (m^2), ENU, row-major",
        },
        "position_covariance_type": _enum(
            "Type of position_covariance", ("UNKNOWN", "APPROXIMATED", "DIAGONAL_KNOWN", "KNOWN")),
    },
}

_LOG: dict[str, Any] = {
    "title": "foxglove.Log",
    "description": "A log message",
    "type": "object",
    "properties": {
        "timestamp": {**_FOXGLOVE_TIME, "description": "Timestamp of log message"},
        "level": _enum("Log level", ("UNKNOWN", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL")),
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
}

_NUM = {"type": "number"}
_NUM_OR_NULL = {"type": ["number", "null"]}
_INT = {"type": "integer"}
_STR = {"type": "string"}
_STR_OR_NULL = {"type": ["string", "null"]}
_BOOL = {"type": "boolean"}
_OBJ = {"type": "object"}


def _lrauv(name: str, description: str, required: Mapping[str, Any], optional: Mapping[str, Any] | None = None
           ) -> dict[str, Any]:
    """A JSON schema for one of our own topics: ``required`` keys are in every payload.

    Objects stay open (no ``additionalProperties: false``), so a field added to a value
    object later does not make older readers reject the log.
    """
    return {
        "title": name,
        "description": description,
        "type": "object",
        "properties": {**required, **(optional or {})},
        "required": list(required),
    }


_VEHICLE_STATE = _lrauv("lrauv.VehicleState", "The executive's picture of the vehicle; null = not yet known", {
    "time_s": _NUM,  # vehicle time since boot
    "lat_deg": _NUM_OR_NULL,
    "lon_deg": _NUM_OR_NULL,
    "depth_m": _NUM_OR_NULL,  # positive down
    "heading_deg": _NUM_OR_NULL,  # compass, clockwise from north
    "mode": {"type": ["integer", "null"]},  # HEARTBEAT.custom_mode
    "armed": _BOOL,
    "position_ok": _BOOL,
    "battery_pct": _NUM_OR_NULL,
    "energy_used_wh": _NUM_OR_NULL,
}, {"heartbeat_s": _NUM_OR_NULL})

_DECISION = _lrauv("lrauv.Decision", "One helm decision: where the vehicle was and what the policy said", {
    "time_s": _NUM,
    "lat_deg": _NUM_OR_NULL,
    "lon_deg": _NUM_OR_NULL,
    "depth_m": _NUM_OR_NULL,
    "heading_deg": _NUM_OR_NULL,
    # policy-table state index, axis order [l, j, i, k] (docs/policy-table.md)
    "cell": {"type": ["array", "null"], "items": _INT, "minItems": 4, "maxItems": 4},
    "situation": _STR,
    "action": _STR_OR_NULL,
    "mode": _STR,
    "changed": _BOOL,
}, {
    # time-varying plans only (executive.timeline): the slice decided with, and why that slice
    "slice": _INT,
    "slice_status": {"type": "string", "enum": ["in_horizon", "before_start", "past_horizon", "time_unknown"]},
})

_COMMAND = _lrauv("lrauv.Command", "A command the helm sent; the remaining keys are the command's fields", {
    "time_s": _NUM,
    "kind": _STR,  # SetMode, Arm, VelocityYaw, DepthTarget, ...
})

_POLICY = _lrauv("lrauv.Policy", "A policy table the executive loaded, swapped in or refused", {
    "time_s": _NUM,
    "reason": {"type": "string", "enum": ["loaded", "received", "swapped", "refused"]},
}, {
    "table_crc32": {"type": "string", "pattern": "^[0-9a-f]{8}$"},  # absent only when a refused file is no table
    "source": _STR,  # what brought the table: upload PATH, onboard plan (REASON), next goal
    "goal_index": _INT,
    "previous": _OBJ,  # the replaced table's table_crc32, forecast_identity, forecast_time
    "forecast_identity": _STR_OR_NULL,
    "forecast_time": _STR_OR_NULL,
    "latency_s": _NUM,  # onboard plans: from the trigger (a new forecast seen) to the table ready
    "plan_s": _NUM,  # onboard plans: the planner process alone
    "refusal": _STR,
    "forecast": {"type": "object", "properties": {"identity": _STR, "time": _STR_OR_NULL}},
    "grid": _OBJ,
    "goal": _OBJ,
    "model": _STR_OR_NULL,
    "criterion": _STR_OR_NULL,
    # time-varying tables only: how many slices, the first's and the last's UTC time
    "slices": {"type": "object", "properties": {"count": _INT, "first_utc": _STR, "last_utc": _STR}},
})

_MAVLINK = _lrauv("lrauv.MavlinkMessage", "One MAVLink message as received or sent", {
    "msg_id": _INT,
    "name": _STR,
    "src_system": _INT,
    "src_component": _INT,
    "fields": _OBJ,  # field name -> value, MAVLink units (common.xml)
}, {
    "time_s": _NUM,
    "direction": {"type": "string", "enum": ["rx", "tx"]},  # also implied by the topic
    "frame": {"type": "string", "contentEncoding": "base64"},  # the exact wire bytes (lrauv replay --tlog)
})


class Topic(Enum):
    """The log's topics; ``value`` is the MCAP topic name."""

    FIX = "/vehicle/fix"
    LOG = "/log"
    STATE = "/vehicle/state"
    DECISION = "/executive/decision"
    COMMAND = "/executive/command"
    POLICY = "/executive/policy"
    MAVLINK_RX = "/mavlink/rx"
    MAVLINK_TX = "/mavlink/tx"

    @property
    def schema_name(self) -> str:
        """``foxglove.*`` for Foxglove's well-known schemas, ``lrauv.*`` for ours (the schema's title)."""
        return str(self.schema["title"])

    @property
    def schema(self) -> Mapping[str, Any]:
        """The JSON schema (a shared dict; do not mutate)."""
        return _SCHEMAS[self]

    @property
    def required(self) -> tuple[str, ...]:
        """Keys every payload on this topic has (the schema's ``required``)."""
        return tuple(self.schema.get("required", ()))


_SCHEMAS: dict[Topic, dict[str, Any]] = {
    Topic.FIX: _LOCATION_FIX,
    Topic.LOG: _LOG,
    Topic.STATE: _VEHICLE_STATE,
    Topic.DECISION: _DECISION,
    Topic.COMMAND: _COMMAND,
    Topic.POLICY: _POLICY,
    Topic.MAVLINK_RX: _MAVLINK,  # both directions share one schema
    Topic.MAVLINK_TX: _MAVLINK,
}


class LogLevel(IntEnum):
    """foxglove.LogLevel (Log.json)."""

    UNKNOWN = 0
    DEBUG = 1
    INFO = 2
    WARNING = 3
    ERROR = 4
    FATAL = 5


LogLevelName = Literal["debug", "info", "warning", "error"]
_LEVELS: dict[str, int] = {name: int(LogLevel[name.upper()]) for name in get_args(LogLevelName)}


# -- JSON encoding (pure) ------------------------------------------------------------------


def _json_default(obj: Any) -> Any:
    """What the C encoder cannot do itself; called only for such objects, so it costs nothing otherwise."""
    if isinstance(obj, Enum):
        return obj.value
    if isinstance(obj, bytes | bytearray | memoryview):
        return base64.b64encode(obj).decode("ascii")  # Foxglove's JSON convention for bytes
    if isinstance(obj, set | frozenset):
        return list(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if hasattr(obj, "dtype") and hasattr(obj, "item"):  # a numpy scalar, without importing numpy
        return obj.item()
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serialisable")


def _sanitise(obj: Any) -> Any:
    """A copy with non-finite floats as null and every key a string; the slow path only."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, str | int | bool) or obj is None:
        return obj
    if isinstance(obj, Mapping):
        return {_key(k): _sanitise(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_sanitise(v) for v in obj]
    return _sanitise(_json_default(obj))


def _key(key: Any) -> str:
    key = key.value if isinstance(key, Enum) else key
    if isinstance(key, str):
        return key
    return json.dumps(key) if isinstance(key, bool | int | float) else str(key)  # as json spells such keys


# Compact and strict: allow_nan=False makes NaN/inf raise, and the slow path writes null
# (bare NaN is not JSON; Foxglove and json.loads in other languages reject it).
_ENCODE = json.JSONEncoder(separators=(",", ":"), allow_nan=False, default=_json_default).encode


def _time_ns(t_s: float, what: str) -> int:
    """Seconds -> int ns, exact to the float: a Unix time times 1e9 would lose ~100 ns to rounding."""
    try:
        sec = math.floor(t_s)
        ns = sec * _NS_PER_S + round((t_s - sec) * _NS_PER_S)
    except (ValueError, OverflowError, TypeError):
        raise LogError(f"{what}: expected a finite time in seconds; got {t_s!r}") from None
    return max(ns, 0)  # MCAP times are unsigned


def _foxglove_time(ns: int) -> dict[str, int]:
    sec, nsec = divmod(max(ns, 0), _NS_PER_S)
    return {"sec": sec, "nsec": nsec}


# -- writing -----------------------------------------------------------------------------


class Recorder:
    """Writes the executive's MCAP log; one instance per file.

    The file is the final path from the start, so a killed process leaves a log
    that is readable up to its last flushed chunk (``recover``).

    By default it writes in the caller's thread and a disk error is a ``LogError`` naming
    the file. With ``background=True`` (the executive's loop) the caller only encodes and
    queues; a writer thread writes and fsyncs, and a full, slow or failing disk degrades the
    log instead (``executive.log_writer``: bounded queue, then records dropped and counted).
    """

    def __init__(self, path: str | os.PathLike[str], *, chunk_size: int = 64 * 1024, flush_interval_s: float = 1.0,
                 profile: str = "lrauv", metadata: Mapping[str, Mapping[str, str]] | None = None,
                 background: bool = False, max_queued_records: int = 50_000, max_queued_bytes: int = 16 * 1024 * 1024,
                 close_timeout_s: float = 5.0) -> None:
        if not (isinstance(chunk_size, int) and chunk_size > 0):
            raise LogError(f"chunk_size: expected a positive number of bytes; got {chunk_size!r}")
        if not (math.isfinite(flush_interval_s) and flush_interval_s >= 0):
            raise LogError(f"flush_interval_s: expected a non-negative number of seconds; got {flush_interval_s!r}")
        self.path = Path(path)
        try:
            self._file = PendingFile(self.path)
        except OSError as exc:
            raise LogError(f"{self.path}: cannot open the log for writing: {exc.strerror or exc}") from None
        self._writer = Writer(cast(IO[Any], self._file), chunk_size=chunk_size, compression=_COMPRESSION, index_types=_INDEXES,
                              use_statistics=True, use_summary_offsets=True, enable_crcs=True)
        self._chunk_indexes = spool_chunk_indexes(self._writer, self.path.parent)
        self._flush_interval_s = float(flush_interval_s)
        self._close_timeout_s = float(close_timeout_s)
        self._channel_ids: dict[Topic, int] = {}
        self._schema_ids: dict[str, int] = {}
        self._sequence: dict[Topic, int] = {}  # the caller's: a dropped record leaves a gap, as MCAP means it
        self._messages = 0
        self._dirty = False
        self._closed = False
        self._finished = False
        self._last_flush_wall_s = time.monotonic()
        self._writer.start(profile, _LIBRARY)  # into memory: the file sees it at the first push
        self._background: Background | None = None
        try:
            if background:
                self._background = Background(self, max_records=max_queued_records, max_bytes=max_queued_bytes)
            for name, data in (metadata or {}).items():
                self.metadata(name, data)
            if self._background is not None:
                self._background.request(Flush(fsync=False))  # the header to the file: a killed run leaves a log
            else:
                self._disk("write", self.push)
        except BaseException:
            self._file.close()
            raise

    # -- messages ---------------------------------------------------------------------

    def write(self, topic: Topic, log_time_s: float, payload: Mapping[str, object], *,
              publish_time_s: float | None = None) -> None:
        """Log ``payload`` as JSON at vehicle time ``log_time_s`` (may go backwards: reboots).

        NaN/inf are written as null, Enums as their value, tuples as arrays;
        ``publish_time_s`` (Unix seconds) defaults to the wall clock now.
        """
        publish_ns = time.time_ns() if publish_time_s is None else _time_ns(publish_time_s, "publish_time_s")
        self._write(topic, log_time_s, payload, publish_ns)

    def _write(self, topic: Topic, log_time_s: float, payload: Mapping[str, object], publish_ns: int) -> None:
        if self._closed:
            raise LogError(f"{self.path}: write to {topic.value} after close()")
        try:
            data = _ENCODE(payload).encode()
        except (ValueError, TypeError):  # NaN/inf, or keys/values the fast path cannot take
            try:
                data = _ENCODE(_sanitise(payload)).encode()
            except (ValueError, TypeError, RecursionError) as exc:  # RecursionError: a cycle
                raise LogError(f"{self.path}: {topic.value}: payload is not JSON serialisable: {exc}") from None
        try:
            log_ns = round(log_time_s * _NS_PER_S)
        except (ValueError, OverflowError, TypeError):
            raise LogError(f"{self.path}: {topic.value}: expected a finite log_time_s; got {log_time_s!r}") from None
        seq = self._sequence.get(topic, 0)
        self._sequence[topic] = (seq + 1) & 0xFFFFFFFF
        self._dirty = True
        self._submit(("message", topic, max(log_ns, 0), data, publish_ns, seq), len(data))  # MCAP times are unsigned

    def location_fix(self, log_time_s: float, *, lat_deg: float, lon_deg: float, depth_m: float,
                     unix_time_s: float | None = None, frame_id: str = "vehicle") -> None:
        """A foxglove.LocationFix for the Map panel; altitude = -depth_m, covariance unknown."""
        unix_ns = time.time_ns() if unix_time_s is None else _time_ns(unix_time_s, "unix_time_s")
        self._write(Topic.FIX, log_time_s, {
            "timestamp": _foxglove_time(unix_ns),
            "frame_id": frame_id,
            "latitude": lat_deg,
            "longitude": lon_deg,
            "altitude": -depth_m,
            "position_covariance": _NO_COVARIANCE,
            "position_covariance_type": 0,  # UNKNOWN
        }, unix_ns)

    def log(self, log_time_s: float, level: LogLevelName, text: str, *, name: str = "executive",
            unix_time_s: float | None = None) -> None:
        """A foxglove.Log line for the Log panel."""
        code = _LEVELS.get(level)
        if code is None:
            raise LogError(f"log level: expected one of {list(_LEVELS)}; got {level!r}")
        unix_ns = time.time_ns() if unix_time_s is None else _time_ns(unix_time_s, "unix_time_s")
        self._write(Topic.LOG, log_time_s, {
            "timestamp": _foxglove_time(unix_ns), "level": code, "message": text, "name": name,
        }, unix_ns)

    # -- metadata and attachments ------------------------------------------------------------

    def metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A metadata record (string -> string), e.g. the resolved settings of the run."""
        self._check_open(f"metadata {name!r}")
        bad = [k for k, v in data.items() if not (isinstance(k, str) and isinstance(v, str))]
        if bad:
            raise LogError(f"metadata {name!r}: keys and values must be strings; not so for {bad}")
        self._submit(("metadata", name, dict(data)), sum(len(k) + len(v) for k, v in data.items()))

    def attach(self, name: str, data: bytes, *, media_type: str = "application/octet-stream",
               log_time_s: float = 0.0) -> None:
        """An attachment (exact bytes), e.g. the uploaded policy table."""
        self._check_open(f"attachment {name!r}")
        self._submit(("attachment", time.time_ns(), _time_ns(log_time_s, "log_time_s"), name, media_type,
                      bytes(data)), len(data))

    # -- durability ---------------------------------------------------------------------------

    def flush(self, *, fsync: bool = False) -> None:
        """Close the open chunk and hand everything to the OS (survives SIGKILL); fsync survives power loss.

        In the background, waits for the writer at most ``close_timeout_s`` (not on a failing disk).
        """
        self._check_open("flush")
        self._dirty = False
        self._last_flush_wall_s = time.monotonic()
        if self._background is None:
            self._disk("flush", self.flush_chunk, fsync=fsync)
            return
        done = threading.Event()
        self._background.request(Flush(fsync, done))
        done.wait(self._close_timeout_s)

    def maybe_flush(self, now_wall_s: float | None = None) -> list[Event]:
        """``flush()`` when ``flush_interval_s`` of wall time (``time.monotonic``) has passed; cheap otherwise.

        In the background only asked for; returns the log's notices since the last call (degraded, writing again).
        """
        now = time.monotonic() if now_wall_s is None else now_wall_s
        if self._closed:
            return []
        if now - self._last_flush_wall_s >= self._flush_interval_s:
            if self._dirty and self._background is not None:
                self._background.request(Flush(fsync=False))
                self._dirty = False
            elif self._dirty:
                self.flush()
            self._last_flush_wall_s = now
        return [] if self._background is None else self._background.notices()

    def close(self) -> None:
        """Write the summary and footer, fsync and close; a second call does nothing.

        In the background, waits at most ``close_timeout_s``: a dead disk leaves the log without its footer.
        """
        if self._closed:
            return
        self._closed = True
        if self._background is not None:
            self._background.close(self._close_timeout_s)
        else:
            self._disk("finish the log", self.finish)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def messages_written(self) -> int:
        return self._messages  # handed to the MCAP writer (in the background: by the writer thread)

    @property
    def records_dropped(self) -> int:
        """Records the background writer dropped because the disk failed or fell behind."""
        return 0 if self._background is None else self._background.dropped

    @property
    def degraded(self) -> str | None:
        """Why the log is degraded now (a full disk, say); None while it is written."""
        return None if self._background is None else self._background.degraded

    @property
    def bytes_written(self) -> int:
        """Log size so far (flushed chunks and buffered records; not the open chunk)."""
        return self._file.tell()

    # -- the writer's side (the caller's thread, or the background writer's) -----------------------

    def apply(self, op: tuple[Any, ...]) -> None:
        """One queued record into the MCAP writer (memory; ``push`` writes it out)."""
        kind = op[0]
        if kind == "message":
            _, topic, log_ns, data, publish_ns, seq = op
            channel_id = self._channel_ids.get(topic)
            if channel_id is None:
                channel_id = self._register(topic)
            self._writer.add_message(channel_id, log_ns, data, publish_ns, seq)
            self._messages += 1
        elif kind == "metadata":
            self._writer.add_metadata(op[1], op[2])
        else:
            self._writer.add_attachment(*op[1:])

    def push(self) -> None:
        self._file.push()

    def flush_chunk(self, *, fsync: bool) -> None:
        self._writer.flush()
        self._file.push()
        if fsync:
            self._file.sync()

    def finish(self) -> None:
        try:
            if not self._finished:
                self._finished = True
                self._writer.finish()
            self._file.push()
            self._file.sync()
        finally:
            self._file.close()
            if self._chunk_indexes is not None:
                self._chunk_indexes.close()

    # -- internals ------------------------------------------------------------------------------

    def _submit(self, op: tuple[Any, ...], nbytes: int) -> None:
        if self._background is not None:
            self._background.put(op, nbytes)
            return
        self.apply(op)
        self._disk("write", self.push)

    def _disk(self, what: str, fn: Any, **kwargs: Any) -> None:
        """``fn`` in the caller's thread; a disk error is a ``LogError`` that names the file."""
        try:
            fn(**kwargs)
        except OSError as exc:
            raise LogError(f"{self.path}: cannot {what}: {reason_of(exc)}") from None

    def _check_open(self, what: str) -> None:
        if self._closed:
            raise LogError(f"{self.path}: {what} after close()")

    def _register(self, topic: Topic) -> int:
        """Schema (once per name) and channel of ``topic``, on first use; they go into the open chunk."""
        name = topic.schema_name
        schema_id = self._schema_ids.get(name)
        if schema_id is None:
            data = json.dumps(topic.schema, separators=(",", ":")).encode()
            schema_id = self._writer.register_schema(name, "jsonschema", data)
            self._schema_ids[name] = schema_id
        channel_id = self._writer.register_channel(topic.value, "json", schema_id, {})
        self._channel_ids[topic] = channel_id
        return channel_id


_NO_COVARIANCE = (0.0,) * 9


# -- reading -----------------------------------------------------------------------------


def check_head(path: Path, head: bytes) -> None:
    if not head:
        raise LogError(f"{path}: empty file (0 bytes); not an MCAP log")
    if len(head) < len(_MAGIC) and _MAGIC.startswith(head):
        raise LogError(f"{path}: truncated inside the MCAP magic ({len(head)} bytes); nothing to read")
    if head[: len(_MAGIC)] != _MAGIC:
        raise LogError(f"{path}: not an MCAP file (bad magic {head[:len(_MAGIC)]!r}; expected {_MAGIC!r})")


def _has_footer(f: BinaryIO, size: int) -> bool:
    """Whether the file ends with a Footer record and the closing magic (MCAP spec, "Footer")."""
    if size < 2 * len(_MAGIC) + _FOOTER_BYTES:
        return False
    f.seek(size - len(_MAGIC) - _FOOTER_BYTES)
    tail = f.read(_FOOTER_BYTES + len(_MAGIC))
    opcode, length = struct.unpack_from("<BQ", tail)
    return tail[-len(_MAGIC):] == _MAGIC and opcode == _FOOTER_OPCODE and length == _FOOTER_BYTES - 9


def is_complete(path: str | os.PathLike[str]) -> bool:
    """Whether the log ends with its footer (the writer closed it); False for a cut or unreadable file."""
    try:
        with open(path, "rb") as f:
            return f.read(len(_MAGIC)) == _MAGIC and _has_footer(f, os.fstat(f.fileno()).st_size)
    except OSError:
        return False


def read_messages(path: str | os.PathLike[str], topics: Iterable[str] | None = None
                  ) -> Iterator[tuple[str, float, dict[str, Any]]]:
    """``(topic, log_time_s, payload)`` of a finished log, in log-time order.

    Raises ``LogError`` at once for a file that is not MCAP or has no footer
    (a killed writer: run ``lrauv log recover``).
    """
    p = Path(path)
    try:
        with open(p, "rb") as f:
            check_head(p, f.read(len(_MAGIC)))
            complete = _has_footer(f, os.fstat(f.fileno()).st_size)
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    if not complete:
        raise LogError(f"{p}: truncated; the writer did not finish (killed?): run `lrauv log recover {p}`")
    return _iter_messages(p, None if topics is None else list(topics))


def _iter_messages(path: Path, topics: list[str] | None) -> Iterator[tuple[str, float, dict[str, Any]]]:
    with open(path, "rb") as f:
        try:
            for _, channel, message in make_reader(f, validate_crcs=True).iter_messages(topics=topics):
                if channel.message_encoding != "json":
                    raise LogError(f"{path}: {channel.topic}: message encoding {channel.message_encoding!r};"
                                   " only json is decoded here")
                yield channel.topic, message.log_time / _NS_PER_S, json.loads(message.data)
        except LogError:
            raise
        except Exception as exc:  # noqa: BLE001 - any failure inside a damaged file (mcap, zstd, json) names the file
            raise LogError(f"{path}: damaged MCAP log ({type(exc).__name__}: {exc});"
                           f" run `lrauv log recover {path}`") from None


# -- recovery ----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class Recovery:
    """What ``recover`` found and wrote."""

    source: str
    output: str
    messages: int
    channels: int
    last_log_time_s: float | None  # the latest (largest) log time recovered
    complete: bool  # the source already ended with a valid footer
    truncated_at_byte: int | None  # end of the last complete record, when the source was cut
    chunks_dropped: int = 0  # complete chunk records whose contents failed CRC or decompression, or over the budget


def _default_output(src: Path) -> Path:
    return src.with_suffix(".recovered.mcap") if src.suffix == ".mcap" else src.with_name(src.name + ".recovered.mcap")


def recover(src: str | os.PathLike[str], dst: str | os.PathLike[str] | None = None) -> Recovery:
    """Copy every complete record of a (possibly killed) log into a new, indexed MCAP file.

    Reads ``src`` record by record (``executive.log_records``: chunks within a memory budget)
    and stops at the first record that is cut off or unreadable; writes ``dst`` (default ``SRC.recovered.mcap``) atomically.
    """
    source = Path(src)
    output = _default_output(source) if dst is None else Path(dst)
    if output.resolve() == source.resolve():
        raise LogError(f"{source}: recovering onto the source itself is refused; give another output path")
    try:
        f = open(source, "rb")  # noqa: SIM115 (closed below)
    except OSError as exc:
        raise LogError(f"{source}: cannot read: {exc.strerror or exc}") from None
    with f:
        size = os.fstat(f.fileno()).st_size
        check_head(source, f.read(len(_MAGIC)))
        f.seek(0)
        try:
            with atomic_target(output) as tmp, open(tmp, "wb") as out:
                result = _copy_records(f, size, source, out)
        except OSError as exc:
            raise LogError(f"{output}: cannot write the recovered log: {exc.strerror or exc}") from None
    return Recovery(source=str(source), output=str(output), **result)


def _copy_records(f: BinaryIO, size: int, source: Path, out: BinaryIO) -> dict[str, Any]:
    stream = BoundedRecords(f, size, source, oversized="drop")
    writer: Writer | None = None
    schema_ids: dict[int, int] = {0: 0}
    channel_ids: dict[int, int] = {}
    messages, last_ns = 0, None
    for r in stream:
        if isinstance(r, Header):
            writer = Writer(out, chunk_size=1024 * 1024, compression=_COMPRESSION, enable_crcs=True)
            writer.start(r.profile, f"{r.library} (recovered by {_LIBRARY})")
            continue
        if writer is None:
            raise LogError(f"{source}: the first record is a {type(r).__name__}, not a Header; cannot recover")
        if isinstance(r, Message):
            channel_id = channel_ids.get(r.channel_id)
            if channel_id is None:
                continue  # its Channel record was lost with a dropped chunk
            writer.add_message(channel_id, r.log_time, r.data, r.publish_time, r.sequence)
            messages += 1
            last_ns = r.log_time if last_ns is None else max(last_ns, r.log_time)
        elif isinstance(r, Schema) and r.id not in schema_ids:
            schema_ids[r.id] = writer.register_schema(r.name, r.encoding, r.data)
        elif isinstance(r, Channel) and r.id not in channel_ids and r.schema_id in schema_ids:
            channel_ids[r.id] = writer.register_channel(r.topic, r.message_encoding, schema_ids[r.schema_id],
                                                        dict(r.metadata))
        elif isinstance(r, Attachment):
            writer.add_attachment(r.create_time, r.log_time, r.name, r.media_type, r.data)
        elif isinstance(r, Metadata):
            writer.add_metadata(r.name, dict(r.metadata))
    if writer is None:
        raise LogError(f"{source}: truncated before the end of the MCAP header ({size} bytes); nothing to recover")
    writer.finish()
    return {
        "messages": messages,
        "channels": len(channel_ids),
        "last_log_time_s": None if last_ns is None else last_ns / _NS_PER_S,
        "complete": stream.complete,
        "truncated_at_byte": None if stream.complete else stream.end_byte,
        "chunks_dropped": len(stream.damaged_chunks),
    }
