"""The executive's MCAP log: writing it, reading it back, and recovering one left by a killed process.

One file per run, JSON messages on a fixed set of topics (``executive.log_topics.Topic``),
some on Foxglove's well-known schemas so the Foxglove app draws the track (Map panel,
``foxglove.LocationFix``), the events (Log panel, ``foxglove.Log``) and the goals, geofence and
running plan (``foxglove.GeoJSON``) without configuration. Log times are UTC nanoseconds, from
the autopilot's SYSTEM_TIME (``executive.log_clock``: records before it are held, then dated;
the host clock stands in when none comes); each payload keeps its vehicle time since boot
(``time_boot_ms`` as ``executive.clock`` extrapolates it) in ``boot_time_s``. Foxglove
``timestamp`` fields are the log time. Publish times are the host's wall clock when written.

Crash safety: records go into small chunks and the loop calls ``maybe_flush`` every
iteration, so a SIGKILL loses at most ``flush_interval_s`` of data (and, in the
background, what the writer thread had not yet taken). The killed file has no footer and
the indexed reader refuses it; ``recover`` stream-reads every complete record and
writes a new, indexed file, like the ``mcap recover`` CLI does. A full or failing disk
never leaves half a record in the file (``executive.log_writer.PendingFile``).

Standard library and ``mcap`` only: the executive stays light.
"""

from __future__ import annotations

import json
import math
import os
import struct
import threading
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Self

from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import LIBRARY_IDENTIFIER

from executive.log_clock import ClockSource, LogClock
from executive.log_records import BoundedRecords, LogError
from executive.log_topics import (BOOT_TIME_KEY, NS_PER_S, LogLevel, LogLevelName, Topic, boot_time_of, encode,
                                  foxglove_time, level_code, time_ns)
from executive.log_writer import Background, Flush, PendingFile, reason_of
from executive.mcap_file import ChunkIndexSpool, Compression, McapFileWriter
from executive.state import Event
from planner.contract.atomic import atomic_target

__all__ = ["LogError", "LogLevel", "LogLevelName", "Recorder", "Recovery", "Topic", "check_head", "is_complete",
           "read_messages", "recover"]

_MAGIC = b"\x89MCAP0\r\n"  # MCAP spec, "Magic"
_FOOTER_BYTES = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset_start, summary_crc
_FOOTER_OPCODE = 0x02
_LIBRARY = f"lrauv executive.recorder; {LIBRARY_IDENTIFIER}"
# ZSTD (mcap's default, level 3) rather than LZ4: on a telemetry mix like the loop's (MAVLink,
# state, fix, decision; 100k messages, 64 KiB chunks) the file was 5.5 MB with ZSTD, 7.6 MB with
# LZ4 and 28.6 MB uncompressed, and neither costs a measurable share of write()'s ~11 us
# (compression runs once per chunk). Disk on a multi-day mission is the scarcer resource.
_COMPRESSION: Compression = "zstd"
# All indexes (executive.mcap_file; mcap's advice "if in doubt, choose ALL"). Message indexes are
# ~30% of the file (16 bytes a message, uncompressed) but let readers skip chunks without a wanted topic.


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
                 close_timeout_s: float = 5.0, utc_offset_ns: int | None = None, max_held_records: int = 5000) -> None:
        if not (isinstance(chunk_size, int) and chunk_size > 0):
            raise LogError(f"chunk_size: expected a positive number of bytes; got {chunk_size!r}")
        if not (math.isfinite(flush_interval_s) and flush_interval_s >= 0):
            raise LogError(f"flush_interval_s: expected a non-negative number of seconds; got {flush_interval_s!r}")
        self.path = Path(path)
        try:
            self._file = PendingFile(self.path)
        except OSError as exc:
            raise LogError(f"{self.path}: cannot open the log for writing: {exc.strerror or exc}") from None
        # A chunk a second for weeks: their indexes wait on disk for the summary, not in memory.
        self._chunk_indexes = ChunkIndexSpool(self.path.parent)
        self._writer = McapFileWriter(self._file, chunk_size=chunk_size, compression=_COMPRESSION,
                                      chunk_indexes=self._chunk_indexes)
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
        # Vehicle time -> UTC log time; ``utc_offset_ns`` known from the start, else held for SYSTEM_TIME.
        self._clock = LogClock(utc_offset_ns, max_records=max_held_records)
        self._described: dict[str, str] | None = None
        self._writer.start(profile, _LIBRARY)  # into memory: the file sees it at the first push
        self._background: Background | None = None
        try:
            if background:
                self._background = Background(self, max_records=max_queued_records, max_bytes=max_queued_bytes)
            for name, data in (metadata or {}).items():
                self.metadata(name, data)
            if self._clock.known:
                self._describe_clock()
            if self._background is not None:
                self._background.request(Flush(fsync=False))  # the header to the file: a killed run leaves a log
            else:
                self._disk("write", self.push)
        except BaseException:
            self._file.close()
            self._chunk_indexes.close()
            raise

    # -- messages ---------------------------------------------------------------------

    def write(self, topic: Topic, log_time_s: float, payload: Mapping[str, object], *,
              publish_time_s: float | None = None) -> None:
        """Log ``payload`` as JSON at vehicle time ``log_time_s`` (may go backwards: reboots).

        The payload gets ``boot_time_s`` (= ``log_time_s``) as its last key; the log time is UTC
        (``executive.log_clock``). NaN/inf are written as null, Enums as their value, tuples as
        arrays; ``publish_time_s`` (Unix seconds) defaults to the wall clock now.
        """
        self._write(topic, log_time_s, payload, _publish_ns(publish_time_s), stamp=False)

    def _write(self, topic: Topic, log_time_s: float, payload: Mapping[str, object], publish_ns: int, *,
               stamp: bool) -> None:
        if self._closed:
            raise LogError(f"{self.path}: write to {topic.value} after close()")
        try:
            vehicle_ns = round(log_time_s * NS_PER_S)
        except (ValueError, OverflowError, TypeError):
            raise LogError(f"{self.path}: {topic.value}: expected a finite log_time_s; got {log_time_s!r}") from None
        body = dict(payload)
        body.pop(BOOT_TIME_KEY, None)
        body[BOOT_TIME_KEY] = log_time_s  # last: readers take it off the end (log_topics.boot_time_of)
        try:
            data = encode(body)
        except (ValueError, TypeError) as exc:
            raise LogError(f"{self.path}: {topic.value}: payload is not JSON serialisable: {exc}") from None
        seq = self._sequence.get(topic, 0)
        self._sequence[topic] = (seq + 1) & 0xFFFFFFFF
        self._dirty = True
        op = ("message", topic, vehicle_ns, data, publish_ns, seq, stamp)
        if self._clock.offset_ns is None:
            if self._clock.hold(vehicle_ns, op, len(data)):
                self._clock.fall_back(vehicle_ns)
                self._clock_known()
            return
        self._submit(_dated(op, vehicle_ns + self._clock.offset_ns), len(data))

    def location_fix(self, log_time_s: float, *, lat_deg: float, lon_deg: float, depth_m: float,
                     heading_deg: float | None = None, velocity_enu_m_s: tuple[float, float, float] | None = None,
                     frame_id: str = "vehicle", publish_time_s: float | None = None) -> None:
        """A foxglove.LocationFix for the Map panel; altitude = -depth_m, covariance unknown.

        ``heading_deg`` (compass) is written as ``heading``, radians clockwise from north as the
        schema defines it; ``velocity_enu_m_s`` as ``velocity`` (east, north, up).
        """
        fix: dict[str, object] = {
            "frame_id": frame_id,
            "latitude": lat_deg,
            "longitude": lon_deg,
            "altitude": -depth_m,
            "position_covariance": _NO_COVARIANCE,
            "position_covariance_type": 0,  # UNKNOWN
        }
        if heading_deg is not None and math.isfinite(heading_deg):
            fix["heading"] = math.radians(heading_deg % 360.0)
        if velocity_enu_m_s is not None:
            fix["velocity"] = dict(zip("xyz", velocity_enu_m_s, strict=True))
        self._write(Topic.FIX, log_time_s, fix, _publish_ns(publish_time_s), stamp=True)

    def log(self, log_time_s: float, level: LogLevelName, text: str, *, name: str = "executive",
            publish_time_s: float | None = None) -> None:
        """A foxglove.Log line for the Log panel (no source file: ``file`` empty, ``line`` 0)."""
        self._write(Topic.LOG, log_time_s, {"level": level_code(level), "message": text, "name": name, "file": "",
                                            "line": 0}, _publish_ns(publish_time_s), stamp=True)

    def geojson(self, topic: Topic, log_time_s: float, layer: Mapping[str, Any], *,
                publish_time_s: float | None = None) -> None:
        """A foxglove.GeoJSON message: ``layer`` (a GeoJSON object) replaces the topic's last on the map."""
        if topic.schema_name != "foxglove.GeoJSON":
            raise LogError(f"{self.path}: {topic.value} is not a foxglove.GeoJSON topic")
        try:
            text = encode(layer).decode()
        except (ValueError, TypeError) as exc:
            raise LogError(f"{self.path}: {topic.value}: GeoJSON is not JSON serialisable: {exc}") from None
        self._write(topic, log_time_s, {"geojson": text}, _publish_ns(publish_time_s), stamp=True)

    # -- the clock --------------------------------------------------------------------------

    def system_time(self, time_unix_usec: int, boot_s: float | None) -> None:
        """The autopilot's SYSTEM_TIME (its UTC at vehicle time ``boot_s``); 0 means it has none yet."""
        if time_unix_usec > 0 and boot_s is not None and math.isfinite(boot_s):
            self.set_utc_offset(time_unix_usec * 1000 - round(boot_s * NS_PER_S), "autopilot SYSTEM_TIME")

    def set_utc_offset(self, offset_ns: int, source: ClockSource) -> None:
        """UTC = vehicle time + ``offset_ns`` from now on; held records are written with it."""
        self._check_open("set the clock")
        first = self._clock.source
        if self._clock.adopt(int(offset_ns), source):
            self._clock_known(first != self._clock.source)

    @property
    def clock_source(self) -> ClockSource | None:
        """Where the log times' UTC comes from; None while records wait for it."""
        return self._clock.source

    def _clock_known(self, describe: bool = True) -> None:
        assert self._clock.offset_ns is not None
        for log_ns, op in self._clock.release():
            self._submit(_dated(op, log_ns), len(op[3]) if op[0] == "message" else len(op[5]))
        if describe:
            self._describe_clock()

    def _describe_clock(self) -> None:
        described = self._clock.metadata()
        if described != self._described:
            self._described = described
            self.metadata("clock", described)

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
        try:
            vehicle_ns = round(log_time_s * NS_PER_S)
        except (ValueError, OverflowError, TypeError):
            raise LogError(f"attachment {name!r}: expected a finite log_time_s; got {log_time_s!r}") from None
        op = ("attachment", time.time_ns(), vehicle_ns, name, media_type, bytes(data))
        if self._clock.offset_ns is None:
            if self._clock.hold(vehicle_ns, op, len(data)):
                self._clock.fall_back()
                self._clock_known()
            return
        self._submit(_dated(op, vehicle_ns + self._clock.offset_ns), len(data))

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
        if self._clock.holding:  # no UTC came: the host's clock, said so in the metadata
            self._clock.fall_back()
            self._clock_known()
        elif self._clock.known:
            self._describe_clock()  # offsets adopted since it was first described
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
                self._writer.finish(drain=self._file.push)
            self._file.push()
            self._file.sync()
        finally:
            self._file.close()
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


def _publish_ns(publish_time_s: float | None) -> int:
    """A publish time (Unix s) in ns; None: the wall clock now."""
    return time.time_ns() if publish_time_s is None else time_ns(publish_time_s, "publish_time_s")


def _dated(op: tuple[Any, ...], log_ns: int) -> tuple[Any, ...]:
    """A held or new record with its UTC log time; a Foxglove payload gets it as its ``timestamp`` too."""
    if op[0] == "attachment":
        return (*op[:2], max(log_ns, 0), *op[3:])
    _, topic, _, data, publish_ns, seq, stamp = op
    log_ns = max(log_ns, 0)  # MCAP times are unsigned
    if stamp:  # the payload's JSON always has boot_time_s, so a key follows
        data = b'{"timestamp":' + encode(foxglove_time(log_ns)) + b"," + data[1:]
    return ("message", topic, log_ns, data, publish_ns, seq)


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

    ``log_time_s`` is vehicle time since boot, as it was given to ``Recorder.write``: the
    payload's ``boot_time_s``, which is taken out of the payload, or the log time itself in a
    log from before log times were UTC.

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
                payload = json.loads(message.data)
                boot_s = payload.pop(BOOT_TIME_KEY, None)
                yield channel.topic, message.log_time / NS_PER_S if boot_s is None else boot_s, payload
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
    last_log_time_s: float | None  # vehicle time (boot_time_s) of the message with the latest log time recovered
    complete: bool  # the source already ended with a valid footer
    truncated_at_byte: int | None  # end of the last complete record, when the source was cut
    chunks_dropped: int = 0  # complete chunk records whose contents failed CRC or decompression, or over the budget
    last_utc_s: float | None = None  # that message's log time as Unix seconds, in a log with UTC log times


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
    writer: McapFileWriter | None = None
    schema_ids: dict[int, int] = {0: 0}
    channel_ids: dict[int, int] = {}
    messages, last_ns, last_data = 0, None, b""
    for r in stream:
        if isinstance(r, Header):
            # Chunks of 1 MiB: few enough that their indexes stay in memory for this short run.
            writer = McapFileWriter(out, chunk_size=1024 * 1024, compression=_COMPRESSION)
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
            if last_ns is None or r.log_time >= last_ns:
                last_ns, last_data = r.log_time, r.data
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
    boot_s = None if last_ns is None else boot_time_of(last_data)
    return {
        "messages": messages,
        "channels": len(channel_ids),
        "last_log_time_s": None if last_ns is None else last_ns / NS_PER_S if boot_s is None else boot_s,
        "last_utc_s": None if last_ns is None or boot_s is None else last_ns / NS_PER_S,
        "complete": stream.complete,
        "truncated_at_byte": None if stream.complete else stream.end_byte,
        "chunks_dropped": len(stream.damaged_chunks),
    }
