"""An MCAP file's records one at a time, its chunks opened within a memory budget.

Replay (``planner.shore.replay``) and ``lrauv log recover`` (``executive.recorder.recover``)
read files that may be cut, damaged or hostile. Records are read one by one (the index is
not trusted), reading stops at the first record that is cut off or unreadable, and the
summary section is skipped. Nothing is decompressed that was not budgeted for: a chunk
declares its uncompressed size (MCAP spec, "Chunk"), and one that declares more than
``CHUNK_BUDGET_BYTES`` is refused (replay: the file is refused; recovery: the chunk is
dropped) before a byte of it is decompressed. Within the
budget, decompression stops at the declared size, so a chunk that holds more than
it declares (a decompression bomb: 3 GB of zeros zstd-compress to about 100 kB)
costs at most the budget. The records inside a chunk are yielded one by one, never
gathered in a list.

A chunk that fails its CRC, does not decompress to its declared size, or holds a
record that runs past its end is damaged: what came before the damage is kept, the
rest of that chunk skipped, and ``damaged_chunks`` lists where each one starts.
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Generator, Iterator
from pathlib import Path
from typing import Any, BinaryIO, Literal

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader

from planner.contract.errors import ExecutiveError

__all__ = ["CHUNK_BUDGET_BYTES", "BoundedRecords", "LogError", "Oversized"]


class LogError(ExecutiveError):
    """An MCAP log that cannot be written, read or recovered; the message names the file."""


# What to do with a chunk that declares more than the budget: refuse the file, or drop the chunk.
Oversized = Literal["refuse", "drop"]

# The executive writes chunks of 64 KiB and `lrauv log recover` of 1 MiB (executive.recorder); mcap's
# Python writer defaults to 1 MiB. 32 MiB leaves room for other writers and bounds what one chunk costs.
CHUNK_BUDGET_BYTES = 32 * 1024 * 1024
_MAGIC_BYTES = 8
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length (MCAP spec, "Records")
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel_id, sequence, log_time, publish_time


class BoundedRecords:
    """Iterate for Header, Schema, Channel, Message, Attachment and Metadata records, in file order.

    Afterwards ``complete`` says whether the file ended with its footer and closing
    magic, ``end_byte`` where the last complete record ended, ``damaged_chunks`` the
    byte offsets of the chunks that were damaged or dropped. A chunk that declares more
    than the budget raises ``LogError`` (naming the file, the chunk and the budget) with
    ``oversized="refuse"``, and is dropped unopened with ``oversized="drop"``.
    """

    def __init__(self, f: BinaryIO, size: int, path: Path, *, chunk_budget_bytes: int = CHUNK_BUDGET_BYTES,
                 oversized: Oversized = "refuse") -> None:
        self._f = f
        self._size = size
        self._path = path
        self._budget = chunk_budget_bytes
        self._oversized = oversized
        self.complete = False
        self.end_byte = _MAGIC_BYTES
        self.damaged_chunks: list[int] = []

    def __iter__(self) -> Iterator[Any]:
        # A record cannot be longer than the file: this bounds what a garbage length can
        # make the reader allocate (foxglove/mcap #1220, MemoryError on truncated files).
        records = StreamReader(self._f, emit_chunks=True, validate_crcs=True, record_size_limit=self._size).records
        data_ended = False
        while True:
            start = self.end_byte
            try:
                record = next(records)
            except StopIteration:  # the closing magic was read after the footer
                self.complete = True
                return
            except (McapError, ValueError, struct.error):
                return  # cut off (EndOfFile), a garbage length, or a bad CRC: keep what came before
            self.end_byte = self._f.tell()
            if isinstance(record, DataEnd | Footer):
                data_ended = True
            elif data_ended:
                continue  # the summary section repeats schemas and channels
            elif isinstance(record, Chunk):
                yield from self._chunk(record, start)
            else:
                yield record

    def _chunk(self, chunk: Chunk, start: int) -> Iterator[Schema | Channel | Message]:
        declared = chunk.uncompressed_size
        if declared > self._budget and self._oversized == "drop":
            self.damaged_chunks.append(start)
            return
        if declared > self._budget:
            raise LogError(f"{self._path}: the chunk at byte {start:,} declares {declared:,} bytes uncompressed, over"
                           f" the reader's budget of {self._budget:,} bytes a chunk; refused without decompressing it"
                           " (a damaged or hostile file: the executive writes chunks of 64 KiB)")
        data = _decompress(chunk, declared)
        if data is None or (chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc):
            self.damaged_chunks.append(start)
            return
        if not (yield from _chunk_records(data)):
            self.damaged_chunks.append(start)


def _decompress(chunk: Chunk, declared: int) -> bytes | None:
    """The chunk's records, at most ``declared`` + 1 bytes decompressed; None unless exactly ``declared``."""
    try:
        if chunk.compression == "":
            data = chunk.data
        elif chunk.compression == "zstd":
            import zstandard

            reader = zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True)
            parts, got = [], 0
            while got <= declared:
                part = reader.read(declared + 1 - got)
                if not part:
                    break
                parts.append(part)
                got += len(part)
            data = b"".join(parts)
        elif chunk.compression == "lz4":
            import lz4.frame  # type: ignore[import-untyped]

            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=declared + 1)
        else:
            return None  # a compression this reader does not know
    except Exception:  # noqa: BLE001 - untrusted bytes: any decompressor error (or a missing one) damages the chunk
        return None
    return data if len(data) == declared else None


def _chunk_records(data: bytes) -> Generator[Schema | Channel | Message, None, bool]:
    """The Schema, Channel and Message records of a chunk's bytes; returns whether they all parsed."""
    view = memoryview(data)
    pos, end = 0, len(data)
    while pos < end:
        if end - pos < _RECORD_HEAD.size:
            return False
        opcode, length = _RECORD_HEAD.unpack_from(view, pos)
        body = pos + _RECORD_HEAD.size
        pos = body + length
        # Runs past the chunk, or opcode 0x00, which names no record (the spec's opcodes start at 0x01):
        # a chunk of zeros is what a decompression bomb holds.
        if pos > end or opcode == 0 or (opcode == Opcode.MESSAGE and length < _MESSAGE_HEAD.size):
            return False
        try:
            if opcode == Opcode.MESSAGE:
                channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(view, body)
                yield Message(channel_id=channel_id, sequence=sequence, log_time=log_time,
                              publish_time=publish_time, data=bytes(view[body + _MESSAGE_HEAD.size:pos]))
            elif opcode == Opcode.CHANNEL:
                yield Channel.read(ReadDataStream(io.BytesIO(view[body:pos])))
            elif opcode == Opcode.SCHEMA:
                yield Schema.read(ReadDataStream(io.BytesIO(view[body:pos])))
            # any other record in a chunk is skipped, as the spec asks of readers
        except (McapError, ValueError, struct.error):
            return False
    return True
