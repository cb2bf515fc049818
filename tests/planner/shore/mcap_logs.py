"""Tampered and damaged copies of a dive's MCAP log, written with the real ``mcap`` writer."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import Writer

from executive.log_records import BoundedRecords


def rewrite_log(src: Path, dst: Path, transform: Callable[[str, Message], bytes | None] = lambda t, m: m.data, *,
                extra_channel: str | None = None, attachments: Callable[[Attachment], bytes] | None = None,
                metadata: Callable[[str, dict[str, str]], Mapping[str, str]] | None = None,
                chunk_size: int = 1024 * 1024, log_time: Callable[[str, Message], int] | None = None) -> Path:
    """Copy ``src`` record by record, each message's data through ``transform`` (None drops it).

    ``extra_channel`` adds a channel of another program's with a message every 100;
    ``attachments`` and ``metadata`` replace an attachment's bytes and a metadata record's map.
    ``chunk_size``: the writer's (the executive writes chunks of 64 KiB). ``log_time`` gives each message's new log time.
    """
    with open(src, "rb") as f, open(dst, "wb") as out:
        writer: Writer | None = None
        topics: dict[int, str] = {}
        schemas: dict[int, int] = {0: 0}
        channels: dict[int, int] = {}
        extra_id = None
        for r in BoundedRecords(f, src.stat().st_size, src):
            if isinstance(r, Header):
                writer = Writer(out, chunk_size=chunk_size)
                writer.start(r.profile, r.library)
                if extra_channel is not None:
                    schema = writer.register_schema("other.Thing", "jsonschema", b"{}")
                    extra_id = writer.register_channel(extra_channel, "json", schema)
            elif isinstance(r, Schema):
                assert writer is not None
                schemas[r.id] = writer.register_schema(r.name, r.encoding, r.data)
            elif isinstance(r, Channel):
                assert writer is not None
                channels[r.id] = writer.register_channel(r.topic, r.message_encoding, schemas[r.schema_id],
                                                         dict(r.metadata))
                topics[r.id] = r.topic
            elif isinstance(r, Message):
                assert writer is not None
                data = transform(topics[r.channel_id], r)
                if data is not None:
                    when = r.log_time if log_time is None else log_time(topics[r.channel_id], r)
                    writer.add_message(channels[r.channel_id], when, data, r.publish_time, r.sequence)
                if extra_id is not None and r.sequence % 100 == 0:
                    writer.add_message(extra_id, r.log_time, b'{"x":1}', r.publish_time, r.sequence)
            elif isinstance(r, Attachment):
                assert writer is not None
                data = r.data if attachments is None else attachments(r)
                writer.add_attachment(r.create_time, r.log_time, r.name, r.media_type, data)
            elif isinstance(r, Metadata):
                assert writer is not None
                writer.add_metadata(r.name, dict(r.metadata) if metadata is None else dict(metadata(r.name, dict(r.metadata))))
        assert writer is not None
        writer.finish()
    return dst


def as_old_format(src: Path, dst: Path) -> Path:
    """``src`` as the executive wrote logs before their log times were UTC: log time = vehicle time
    (each payload's ``boot_time_s``, which is taken out), no ``clock`` metadata (kept as an empty map,
    which old readers ignore), foxglove.Log without ``file`` and ``line``, LocationFix without heading and velocity,
    no map layers."""
    from executive.log_topics import BOOT_TIME_KEY, NS_PER_S

    def payload(topic: str, m: Message) -> bytes | None:
        if topic.startswith("/map/"):
            return None  # no GeoJSON layers then
        p = json.loads(m.data)
        p.pop(BOOT_TIME_KEY, None)
        for key in {"/log": ("file", "line"), "/vehicle/fix": ("heading", "velocity")}.get(topic, ()):
            p.pop(key, None)
        return json.dumps(p, separators=(",", ":")).encode()

    def log_time(topic: str, m: Message) -> int:
        return round(json.loads(m.data)[BOOT_TIME_KEY] * NS_PER_S)

    return rewrite_log(src, dst, payload, log_time=log_time,
                       metadata=lambda name, data: {} if name == "clock" else data)
