"""Tampered and damaged copies of a dive's MCAP log, written with the real ``mcap`` writer."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import Writer

from executive.log_records import BoundedRecords


def rewrite_log(src: Path, dst: Path, transform: Callable[[str, Message], bytes | None] = lambda t, m: m.data, *,
                extra_channel: str | None = None, attachments: Callable[[Attachment], bytes] | None = None,
                metadata: Callable[[str, dict[str, str]], Mapping[str, str]] | None = None,
                chunk_size: int = 1024 * 1024) -> Path:
    """Copy ``src`` record by record, each message's data through ``transform`` (None drops it).

    ``extra_channel`` adds a channel of another program's with a message every 100;
    ``attachments`` and ``metadata`` replace an attachment's bytes and a metadata record's map.
    ``chunk_size``: the writer's (the executive writes chunks of 64 KiB).
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
                    writer.add_message(channels[r.channel_id], r.log_time, data, r.publish_time, r.sequence)
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
