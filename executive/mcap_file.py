"""Writing an MCAP file (https://mcap.dev/spec), with the chunk indexes kept out of memory.

``McapFileWriter`` writes what ``mcap.writer.Writer`` 1.6 writes for the same calls (all
indexes, statistics, summary offsets, chunk, attachment and summary CRCs), byte for byte. It is built from mcap's public record classes (``mcap.records``, each with
``write(builder)``) so the encoding of every record stays mcap's own. Two things differ, and
are why it exists:

- The chunk index of every finished chunk goes to a ``ChunkIndexStore`` given to the
  constructor, as its record's bytes: the executive flushes a chunk every second, so a dive of
  weeks has a million of them, and ``ChunkIndexSpool`` keeps them in an unlinked temporary file
  instead of in memory (mcap's Writer keeps a list of them until ``finish``).
- ``finish`` writes the summary in pieces, with a ``drain`` call between them, so the summary of
  a long dive never sits whole in memory either.

Layout (spec, "Overview"): magic, Header, then the data section: Chunks (Schema, Channel and
Message records, compressed) each followed by its MessageIndex records, and Attachment and
Metadata records between chunks; DataEnd; the summary section (the
Schemas and Channels again, Statistics, ChunkIndex, AttachmentIndex and MetadataIndex records,
then SummaryOffset records, one per group); Footer (summary CRC); magic.

Standard library, ``mcap``'s records and ``zstandard`` only: the executive stays light.
"""

from __future__ import annotations

import struct
import tempfile
import zlib
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, Literal, Protocol

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Attachment, AttachmentIndex, Channel, Chunk, ChunkIndex, DataEnd, Footer, Header,
                          McapRecord, MessageIndex, Metadata, MetadataIndex, Schema, Statistics, SummaryOffset)

__all__ = ["MAGIC", "ChunkIndexSpool", "ChunkIndexStore", "Compression", "McapFileWriter", "Stream"]

MAGIC = b"\x89MCAP0\r\n"  # spec, "Magic"
Compression = Literal["zstd", "none"]
# Message record (spec, "Message (op=0x05)"): opcode, record length, then channel_id uint16,
# sequence uint32, log_time uint64, publish_time uint64, and the data to the end of the record.
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_FIELDS = _MESSAGE_HEAD.size - 9
_RECORD_HEAD = struct.Struct("<BQ")  # every record: opcode, length of what follows
_FOOTER_FIELDS = struct.Struct("<BQQQ")  # the Footer up to its CRC, which the summary CRC covers
_ZSTD_LEVEL = 3  # zstandard.compress's default, as mcap's Writer uses
_DRAIN_BYTES = 1 << 20  # finish() hands the summary on after each MiB of it


class Stream(Protocol):
    """Where the file goes: ``executive.log_writer.PendingFile``, or an open binary file."""

    def write(self, data: bytes, /) -> Any: ...


class ChunkIndexStore(Protocol):
    """Where finished chunks' ChunkIndex records wait for the summary: a ``list`` or a ``ChunkIndexSpool``."""

    def append(self, record: bytes, /) -> None: ...
    def __iter__(self) -> Iterator[bytes]: ...


def _encoded(record: McapRecord) -> bytes:
    builder = RecordBuilder()
    record.write(builder)
    return bytes(builder.end())


class McapFileWriter:
    """One MCAP file, written from ``start`` to ``finish``; chunked, compressed, fully indexed.

    Schemas, channels and messages go into the open chunk, which is written out when it
    exceeds ``chunk_size`` bytes (uncompressed) or at ``flush``; attachments and metadata are
    written at once, between chunks. Nothing here touches a disk but through ``stream``.
    """

    def __init__(self, stream: Stream, *, chunk_size: int = 1024 * 1024, compression: Compression = "zstd",
                 chunk_indexes: ChunkIndexStore | None = None) -> None:
        self._stream = stream
        self._chunk_size = chunk_size
        self._compressor = zstandard.ZstdCompressor(level=_ZSTD_LEVEL) if compression == "zstd" else None
        self._compression = "zstd" if compression == "zstd" else ""  # spec: "" is uncompressed
        self._chunk_indexes: ChunkIndexStore = [] if chunk_indexes is None else chunk_indexes
        self._position = 0  # bytes handed to the stream
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._message_counts: dict[int, int] = {}  # per channel, in the order of their first message
        self._messages = 0
        self._start_ns = 0
        self._end_ns = 0
        self._chunks = 0
        self._attachments = 0
        self._metadata = 0
        # The open chunk: its records uncompressed, and per channel (log_time, offset in the chunk).
        self._chunk = bytearray()
        self._chunk_messages = 0
        self._chunk_start_ns = 0
        self._chunk_end_ns = 0
        self._chunk_offsets: dict[int, list[tuple[int, int]]] = {}

    # -- the data section ---------------------------------------------------------------------------

    def start(self, profile: str, library: str) -> None:
        self._write(MAGIC + _encoded(Header(profile=profile, library=library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A new schema (into the open chunk, and the summary); its id, from 1."""
        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas.append(schema)
        self._into_chunk(_encoded(schema))
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        """A new channel (into the open chunk, and the summary); its id, from 1. Schema id 0: none."""
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata or {}))
        self._channels.append(channel)
        self._into_chunk(_encoded(channel))
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        """A message into the open chunk (the hot path: one struct.pack, no record object)."""
        if self._messages == 0 or log_time < self._start_ns:
            self._start_ns = log_time
        if log_time > self._end_ns:
            self._end_ns = log_time
        self._messages += 1
        self._message_counts[channel_id] = self._message_counts.get(channel_id, 0) + 1
        if self._chunk_messages == 0 or log_time < self._chunk_start_ns:
            self._chunk_start_ns = log_time
        if self._chunk_messages == 0 or log_time > self._chunk_end_ns:
            self._chunk_end_ns = log_time
        self._chunk_messages += 1
        offsets = self._chunk_offsets.get(channel_id)
        if offsets is None:
            offsets = self._chunk_offsets[channel_id] = []
        offsets.append((log_time, len(self._chunk)))
        self._chunk += _MESSAGE_HEAD.pack(Opcode.MESSAGE, _MESSAGE_FIELDS + len(data), channel_id, sequence,
                                          log_time, publish_time)
        self._chunk += data
        if len(self._chunk) > self._chunk_size:
            self.flush()

    def add_attachment(self, create_time: int, log_time: int, name: str, media_type: str, data: bytes) -> None:
        """An attachment, written now (between chunks; the open chunk stays open), and indexed."""
        record = _encoded(Attachment(create_time=create_time, log_time=log_time, name=name, media_type=media_type,
                                     data=data))
        self._attachment_indexes.append(AttachmentIndex(
            offset=self._position, length=len(record), create_time=create_time, log_time=log_time,
            data_size=len(data), name=name, media_type=media_type))
        self._attachments += 1
        self._write(record)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A metadata record, written now (between chunks), and indexed."""
        record = _encoded(Metadata(name=name, metadata=dict(data)))
        self._metadata_indexes.append(MetadataIndex(offset=self._position, length=len(record), name=name))
        self._metadata += 1
        self._write(record)

    def flush(self) -> None:
        """Close the open chunk: the chunk, then its message indexes; nothing while it has no message."""
        if self._chunk_messages == 0:
            return  # schemas and channels registered since wait in the chunk for a message
        records = bytes(self._chunk)
        data = records if self._compressor is None else self._compressor.compress(records)
        chunk = _encoded(Chunk(compression=self._compression, data=data, message_start_time=self._chunk_start_ns,
                               message_end_time=self._chunk_end_ns, uncompressed_crc=zlib.crc32(records),
                               uncompressed_size=len(records)))
        chunk_start = self._position
        self._write(chunk)
        index_start = self._position
        index_offsets: dict[int, int] = {}
        indexes = bytearray()
        for channel_id, entries in self._chunk_offsets.items():
            index_offsets[channel_id] = index_start + len(indexes)
            indexes += _encoded(MessageIndex(channel_id=channel_id, records=entries))
        self._write(bytes(indexes))
        self._chunk_indexes.append(_encoded(ChunkIndex(
            message_start_time=self._chunk_start_ns, message_end_time=self._chunk_end_ns,
            chunk_start_offset=chunk_start, chunk_length=len(chunk), message_index_offsets=index_offsets,
            message_index_length=len(indexes), compression=self._compression, compressed_size=len(data),
            uncompressed_size=len(records))))
        self._chunks += 1
        self._chunk.clear()
        self._chunk_messages = 0
        self._chunk_offsets = {}

    # -- the summary --------------------------------------------------------------------------------

    def finish(self, drain: Callable[[], None] | None = None) -> None:
        """The open chunk, DataEnd, the summary section, the Footer and the closing magic.

        ``drain`` (e.g. ``PendingFile.push``) is called after each MiB of the summary, so a
        stream that buffers need not hold it whole. The stream is not closed.
        """
        self.flush()
        # No data-section CRC (0: "not available", spec "Data End"), as mcap's Writer by default:
        # chunks and attachments carry their own, and with one a reader that checks it refuses the
        # whole data section for one damaged chunk, which recovery drops and goes on past.
        self._write(_encoded(DataEnd(data_section_crc=0)))
        summary_start = self._position  # never an empty summary: it has the statistics at least
        summary = _Summary(self._stream, summary_start, drain)
        groups = (
            (Opcode.SCHEMA, (_encoded(s) for s in self._schemas)),
            (Opcode.CHANNEL, (_encoded(c) for c in self._channels)),
            (Opcode.STATISTICS, iter([_encoded(self._statistics())])),
            (Opcode.CHUNK_INDEX, iter(self._chunk_indexes)),
            (Opcode.ATTACHMENT_INDEX, (_encoded(a) for a in self._attachment_indexes)),
            (Opcode.METADATA_INDEX, (_encoded(m) for m in self._metadata_indexes)),
        )
        offsets = [summary.group(opcode, records) for opcode, records in groups]
        offsets_start = summary.end
        for offset in offsets:
            summary.add(_encoded(offset))
        crc = zlib.crc32(_FOOTER_FIELDS.pack(Opcode.FOOTER, 8 + 8 + 4, summary_start, offsets_start), summary.crc)
        summary.close()
        self._position = summary.end
        self._write(_encoded(Footer(summary_start=summary_start, summary_offset_start=offsets_start,
                                    summary_crc=crc)) + MAGIC)

    def _statistics(self) -> Statistics:
        return Statistics(message_count=self._messages, schema_count=len(self._schemas),
                          channel_count=len(self._channels), attachment_count=self._attachments,
                          metadata_count=self._metadata, chunk_count=self._chunks,
                          message_start_time=self._start_ns, message_end_time=self._end_ns,
                          channel_message_counts=dict(self._message_counts))

    # -- internals ---------------------------------------------------------------------------------

    def _into_chunk(self, record: bytes) -> None:
        self._chunk += record
        if len(self._chunk) > self._chunk_size:
            self.flush()

    def _write(self, data: bytes) -> None:
        if data:
            self._stream.write(data)
            self._position += len(data)


class _Summary:
    """The summary section as it is written: its position, its CRC so far, drained every MiB."""

    def __init__(self, stream: Stream, position: int, drain: Callable[[], None] | None) -> None:
        self._stream = stream
        self._written_to = position  # the stream's end: the pending bytes go after it
        self._drain = drain
        self._pending = bytearray()
        self.crc = 0

    @property
    def end(self) -> int:
        """The file position after the summary written so far."""
        return self._written_to + len(self._pending)

    def add(self, record: bytes) -> None:
        self._pending += record
        self.crc = zlib.crc32(record, self.crc)
        if len(self._pending) >= _DRAIN_BYTES:
            self._hand_on()

    def group(self, opcode: Opcode, records: Iterable[bytes]) -> SummaryOffset:
        """One group of records; its SummaryOffset (mcap writes one for every group, even an empty one)."""
        start = self.end
        for record in records:
            self.add(record)
        return SummaryOffset(group_opcode=opcode, group_start=start, group_length=self.end - start)

    def close(self) -> None:
        self._hand_on(drain=False)

    def _hand_on(self, *, drain: bool = True) -> None:
        if self._pending:
            self._stream.write(bytes(self._pending))
            self._written_to += len(self._pending)
            self._pending.clear()
        if drain and self._drain is not None:
            self._drain()


class ChunkIndexSpool:
    """Chunk index records kept in an unlinked temporary file instead of in memory.

    The loop flushes a chunk every second of wall time, so at sea (1x) that is 86,400
    indexes a vehicle day: the soak (bench/bench_soak.py) saw the executive grow 5 MB a day
    at 1000x while they stayed in memory. Here each index is its record's bytes on disk,
    read back once, a MiB at a time, at ``finish``; memory stays flat however long the
    mission. When the disk refuses a write (full), the records from then on are held in
    memory instead (a few hundred bytes a chunk), so the log can still be finished when the
    disk comes back.
    """

    def __init__(self, directory: Path) -> None:
        self._file: Any = None
        try:
            self._file = tempfile.TemporaryFile(dir=directory, buffering=0)  # noqa: SIM115 (closed in close()); unlinked
        except OSError:
            pass
        self._size = 0  # bytes of whole records in the file
        self.held: list[bytes] = []  # records in memory: those after the file failed
        self.count = 0

    def append(self, record: bytes, /) -> None:
        self.count += 1
        if self._file is None or self.held:
            self.held.append(record)
            return
        data = memoryview(record)
        done = 0
        try:
            while done < len(data):
                done += self._file.write(data[done:]) or 0
        except OSError:
            self.held.append(record)  # the disk is full: from now on in memory
            try:
                self._file.truncate(self._size)
                self._file.seek(self._size)
            except OSError:
                pass  # reads stop at _size anyway
            return
        self._size += done

    def __len__(self) -> int:
        return self.count

    def __iter__(self) -> Iterator[bytes]:
        if self._file is not None and self._size:
            self._file.seek(0)
            rest = b""
            left = self._size
            while left > 0:
                block = self._file.read(min(left, _DRAIN_BYTES))
                if not block:
                    break
                left -= len(block)
                rest += block
                at = 0
                while at + _RECORD_HEAD.size <= len(rest):
                    end = at + _RECORD_HEAD.size + _RECORD_HEAD.unpack_from(rest, at)[1]
                    if end > len(rest):
                        break
                    yield rest[at:end]
                    at = end
                rest = rest[at:]
            self._file.seek(self._size)
        yield from self.held

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
