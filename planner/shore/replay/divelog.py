"""A dive's MCAP log opened for replay: what it holds, and its messages in the order they were written.

The executive writes one log per run (``executive.recorder``). Replay reads it
record by record (``executive.log_records``, within a memory budget)
rather than through the index, so a log left by a killed writer replays up to its
last complete record, and ``DiveLog`` says where it ends. Each payload is checked
against its topic's schema as it is read (``planner.shore.replay.payloads``): a
wrong type or a missing key is a ``LogError`` naming the file, the message and
the key, never a crash further on. Messages come in file order, which is the order
the executive did things in. Each message's time is vehicle time since boot: its
payload's ``boot_time_s`` in a log whose log times are UTC (``executive.log_clock``),
the log time itself in an older log (vehicle time then); it may step back at a
reboot. Channels this version does not know are counted and skipped, never
guessed at.

Standard library, ``mcap`` and the executive's own modules, like the recorder.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from mcap.records import Attachment, Channel, Header, Message, Metadata

from executive.helm import HelmConfig
from executive.log_records import BoundedRecords
from executive.log_topics import BOOT_TIME_KEY, boot_time_of
from executive.recorder import LogError, Topic, check_head, is_complete
from planner.shore.replay.payloads import PayloadError, check_fields, check_payload
from planner.contract.progress import SILENT, Progress

__all__ = ["DiveLog", "LogMessage", "open_dive"]

_NS_PER_S = 1_000_000_000
_KNOWN = {t.value: t for t in Topic}
_TICK_EVERY = 1000  # messages of a topic between progress reports while reading a log through


@dataclass(frozen=True, slots=True)
class LogMessage:
    """One message of a known topic, decoded."""

    topic: Topic
    log_time_s: float  # vehicle time since boot (the payload's boot_time_s, or an old log's log time)
    publish_time_s: float  # wall clock (Unix seconds) when it was written
    payload: dict[str, Any]
    utc_s: float | None = None  # the log time as Unix seconds, in a log whose log times are UTC; else None


@dataclass(frozen=True, kw_only=True)
class DiveLog:
    """What one pass over a log found; ``messages()`` reads it again for the payloads."""

    path: Path
    size_bytes: int
    library: str
    profile: str
    complete: bool  # ended with a footer: the writer closed it
    end_byte: int  # end of the last complete record (== size_bytes when complete)
    damaged_chunks: tuple[int, ...]  # where each chunk starts whose CRC, compression or records were broken
    unreadable_inside: bool  # reading stopped at end_byte, yet the file ends with its footer: damage, not a cut
    counts: Mapping[Topic, int]  # messages per known topic
    unknown: Mapping[str, int]  # messages on topics (or encodings) this version does not read
    first_log_time_s: float | None  # vehicle time of the first message in the file
    last_log_time_s: float | None  # and of the last
    metadata: Mapping[str, Mapping[str, str]]
    attachments: Mapping[str, bytes]

    @property
    def n_messages(self) -> int:
        return sum(self.counts.values())

    @property
    def clock(self) -> str:
        """What the log times are: UTC and where it came from (metadata ``clock``), or vehicle time (older logs)."""
        source = self.metadata.get("clock", {}).get("source")
        return "vehicle time since boot" if source is None else f"UTC ({source})"

    def where_it_ends(self) -> str:
        """One line for the operator: complete, or where the cut is; and any damaged chunk."""
        if self.complete:
            text = f"complete ({self.size_bytes:,} bytes)"
        elif self.unreadable_inside:
            text = f"read up to byte {self.end_byte:,} of {self.size_bytes:,}"
        else:
            last = "no messages" if self.last_log_time_s is None else f"vehicle time {self.last_log_time_s:.1f} s"
            text = (f"TRUNCATED: the writer did not finish (killed?); read up to byte {self.end_byte:,} of"
                    f" {self.size_bytes:,}, the last complete message at {last}")
        damage = self.damage()
        return text + (f"; {damage}" if damage else "")

    def damage(self) -> str:
        """What of the file could not be read though it is there, for the operator (empty when nothing)."""
        parts = []
        if self.damaged_chunks:
            at = ", ".join(f"{b:,}" for b in self.damaged_chunks[:5]) + (", ..." if len(self.damaged_chunks) > 5 else "")
            parts.append(f"{len(self.damaged_chunks)} chunk(s) failed their CRC or decompression (at byte {at})")
        if self.unreadable_inside:
            parts.append(f"the record at byte {self.end_byte:,} is unreadable though the file goes on to its footer")
        return "" if not parts else f"DAMAGED: {'; '.join(parts)}; what could not be read is missing from this replay"

    def messages(self, topics: Iterable[Topic] | None = None, *,
                 containing: Mapping[Topic, bytes | tuple[bytes, ...]] | None = None,
                 keep_undecodable: bool = False) -> Iterator[LogMessage]:
        """The messages on ``topics`` (default all known ones), in file order, each checked (``payloads``).

        ``containing`` keeps, on the topics it names, only messages whose JSON holds
        those bytes (e.g. ``b'"name":"SYSTEM_TIME"'``), or any of a tuple of them: a cheap filter before decoding.
        ``keep_undecodable``: MAVLink records whose fields do not fit the dialect come as logged
        (for the re-stream, which skips them by name) instead of raising ``LogError``.
        """
        wanted = set(Topic) if topics is None else set(topics)
        filters = containing or {}
        for channel, message in _stream_messages(self.path):
            topic = _KNOWN.get(channel.topic)
            if topic is None or topic not in wanted or channel.message_encoding != "json":
                continue
            needle = filters.get(topic)
            if needle is not None and not any(n in message.data for n in ((needle,) if isinstance(needle, bytes)
                                                                          else needle)):
                continue
            t = message.log_time / _NS_PER_S
            where = f"{self.path}: {channel.topic} message {message.sequence} (log time {t:.3f} s)"
            try:
                payload = check_payload(topic, json.loads(message.data), keep_undecodable=keep_undecodable)
                boot_s = payload.pop(BOOT_TIME_KEY, None)  # lifted out: the payload is what the executive logged
            except RecursionError:
                raise LogError(f"{where}: JSON nested too deeply to read") from None
            except PayloadError as exc:
                raise LogError(f"{where}: {exc}") from None
            except ValueError as exc:
                raise LogError(f"{where}: not JSON ({exc})") from None
            if boot_s is None:  # a log from before UTC log times: the log time is vehicle time
                yield LogMessage(topic, t, message.publish_time / _NS_PER_S, payload)
            else:
                yield LogMessage(topic, boot_s, message.publish_time / _NS_PER_S, payload, t)


def open_dive(path: str | os.PathLike[str], *, meter: Progress = SILENT) -> DiveLog:
    """Read ``path`` once through: header, channels, counts, metadata, attachments, where it ends.
    ``meter`` hears the bytes read.

    Raises ``LogError`` for a file that is missing, not MCAP, has no lrauv channel, holds
    a chunk over the memory budget, or helm metadata that is not what the executive writes.
    """
    p = Path(path)
    counts: dict[Topic, int] = {}
    unknown: dict[str, int] = {}
    metadata: dict[str, dict[str, str]] = {}
    attachments: dict[str, bytes] = {}
    channels: dict[int, tuple[Topic | None, str]] = {}
    header: Header | None = None
    first: float | None = None
    last_ns: int | None = None
    last_data = b""
    with _open(p) as f:
        size = os.fstat(f.fileno()).st_size
        stream = BoundedRecords(f, size, p)
        for r in stream:
            if isinstance(r, Header):
                header = r
            elif isinstance(r, Channel):
                topic = _KNOWN.get(r.topic) if r.message_encoding == "json" else None
                channels[r.id] = (topic, r.topic if r.message_encoding == "json" else f"{r.topic} ({r.message_encoding})")
            elif isinstance(r, Message):
                topic, name = channels.get(r.channel_id, (None, f"channel {r.channel_id} (no Channel record)"))
                if topic is None:
                    unknown[name] = unknown.get(name, 0) + 1
                    continue
                counts[topic] = counts.get(topic, 0) + 1
                if counts[topic] % _TICK_EVERY == 0:
                    meter.update("reading the log", min(f.tell(), size), size, unit="B")
                if first is None:
                    first = _vehicle_time(r.log_time, r.data)
                last_ns, last_data = r.log_time, r.data
            elif isinstance(r, Metadata):
                metadata[r.name] = dict(r.metadata)
            elif isinstance(r, Attachment):
                attachments[r.name] = bytes(r.data)
    if header is None:
        raise LogError(f"{p}: truncated inside the MCAP header ({size} bytes); nothing to replay")
    if not counts and not stream.complete and not unknown:
        raise LogError(f"{p}: truncated at byte {stream.end_byte:,} of {size:,}, before the first message"
                       " (the writer was killed at once?); nothing to replay")
    if not counts:
        seen = ", ".join(f"{name} ({n})" for name, n in unknown.items()) or "none"
        raise LogError(f"{p}: no lrauv executive channel in this MCAP file (library {header.library!r});"
                       f" expected topics like {Topic.DECISION.value}; channels seen: {seen}")
    _check_helm(p, metadata.get("helm"))
    last = None if last_ns is None else _vehicle_time(last_ns, last_data)
    meter.update("reading the log", size, size, unit="B")
    return DiveLog(path=p, size_bytes=size, library=header.library, profile=header.profile, complete=stream.complete,
                   end_byte=size if stream.complete else stream.end_byte, damaged_chunks=tuple(stream.damaged_chunks),
                   unreadable_inside=not stream.complete and is_complete(p),
                   counts=counts, unknown=unknown, first_log_time_s=first, last_log_time_s=last, metadata=metadata,
                   attachments=attachments)


def _vehicle_time(log_ns: int, data: bytes) -> float:
    """A message's vehicle time, without decoding it all: ``boot_time_s``, or an old log's log time."""
    boot_s = boot_time_of(data)
    return log_ns / _NS_PER_S if boot_s is None else boot_s


def _open(p: Path) -> BinaryIO:
    """The log opened for reading, its magic checked."""
    try:
        f = open(p, "rb")  # noqa: SIM115 (the caller closes it)
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    try:
        check_head(p, f.read(8))
    except LogError:
        f.close()
        raise
    f.seek(0)
    return f


def _check_helm(p: Path, helm: Mapping[str, str] | None) -> None:
    """The ``helm`` metadata the audit runs with (``executive.loop``), when the log has it."""
    if helm is None:
        return  # a log from before the audit: the audit says so
    goal = helm.get("goal_index", "0")
    if not (goal.isascii() and goal.isdigit()):
        raise LogError(f"{p}: metadata helm.goal_index: expected a goal index (0, 1, ...); got {goal!r}")
    if "config" in helm:
        try:
            check_fields(HelmConfig.from_json(helm["config"]), "helm.config")
        except PayloadError as exc:
            raise LogError(f"{p}: metadata {exc}") from None
        except Exception as exc:  # noqa: BLE001 - untrusted text: whatever the parser raises, the key is named
            raise LogError(f"{p}: metadata helm.config: not a helm configuration the executive writes"
                           f" ({type(exc).__name__}: {exc})") from None


def _stream_messages(p: Path) -> Iterator[tuple[Channel, Message]]:
    channels: dict[int, Channel] = {}
    with _open(p) as f:
        for r in BoundedRecords(f, os.fstat(f.fileno()).st_size, p):
            if isinstance(r, Channel):
                channels[r.id] = r
            elif isinstance(r, Message):
                channel = channels.get(r.channel_id)
                if channel is not None:
                    yield channel, r
