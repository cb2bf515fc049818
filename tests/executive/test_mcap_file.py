"""executive.mcap_file: our MCAP writer writes mcap's bytes, and a long dive's chunk indexes wait on disk."""

from __future__ import annotations

import io
import random
import tracemalloc
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from executive.mcap_file import ChunkIndexSpool, Compression, McapFileWriter


def _script(w: Any) -> None:
    """The same calls to either writer: chunks closed by size and by flush, records between them."""
    rnd = random.Random(7)
    w.start("lrauv", "test")
    schema = w.register_schema("state", "jsonschema", b'{"type":"object"}')
    channels = [w.register_channel("/state", "json", schema, {"k": "v"})]
    w.add_metadata("clock", {"source": "autopilot SYSTEM_TIME"})
    w.flush()  # no message yet: writes nothing, the schema and channel wait in the chunk
    for i in range(3000):
        if i == 100:
            channels.append(w.register_channel("/raw", "json", 0, {}))  # no schema
        if i % 700 == 5:
            w.add_attachment(i, i * 10, f"table-{i}.lrpt", "application/octet-stream", rnd.randbytes(300))
        if i % 333 == 0:
            w.flush()
        t = rnd.randrange(10**15)  # log times out of order, as after a clock step
        w.add_message(rnd.choice(channels), t, b'{"i":%d}' % i * rnd.randrange(1, 6), t + 5, i)
    w.add_metadata("end", {})
    w.finish()


@pytest.mark.parametrize(("ours", "theirs"), [("zstd", CompressionType.ZSTD), ("none", CompressionType.NONE)])
def test_the_file_is_byte_for_byte_what_mcaps_writer_writes(ours: Compression, theirs: CompressionType):
    expected, got = io.BytesIO(), io.BytesIO()
    _script(Writer(expected, chunk_size=4096, compression=theirs))
    _script(McapFileWriter(got, chunk_size=4096, compression=ours))
    assert got.getvalue() == expected.getvalue()
    summary = make_reader(io.BytesIO(got.getvalue()), validate_crcs=True).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 3000 and summary.statistics.attachment_count == 5
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 9


def test_every_record_reads_back_with_every_crc_checked(tmp_path: Path):
    path = tmp_path / "a.mcap"
    with open(path, "wb") as f:
        _script(McapFileWriter(f, chunk_size=4096))
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        messages = [(c.topic, m.sequence, m.data) for _, c, m in reader.iter_messages(log_time_order=False)]
        attachments = [(a.name, len(a.data)) for a in reader.iter_attachments()]
        metadata = [(m.name, m.metadata) for m in reader.iter_metadata()]
    assert [s for _, s, _ in messages] == list(range(3000))
    assert {t for t, _, _ in messages} == {"/state", "/raw"}
    assert attachments == [(f"table-{i}.lrpt", 300) for i in (5, 705, 1405, 2105, 2805)]
    assert metadata == [("clock", {"source": "autopilot SYSTEM_TIME"}), ("end", {})]
    with open(path, "rb") as f:  # the stream reader: record by record, chunk CRCs, no index
        kinds = [type(r).__name__ for r in StreamReader(f, validate_crcs=True).records]
    assert kinds.count("Message") == 3000 and kinds.count("Footer") == 1


class _Buffered:
    """A stream that only buffers, like PendingFile; ``drain`` empties it into a file."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, "wb")  # noqa: SIM115 (closed by the test)
        self.pending = bytearray()
        self.most_pending = 0

    def write(self, data: bytes) -> int:
        self.pending += data
        self.most_pending = max(self.most_pending, len(self.pending))
        return len(data)

    def drain(self) -> None:
        self._file.write(self.pending)
        self.pending.clear()

    def close(self) -> None:
        self.drain()
        self._file.close()


def _traced_growth_over_chunks(writer: McapFileWriter, stream: _Buffered, first: int, last: int) -> int:
    """Bytes still allocated after writing chunks ``first`` to ``last`` (one message each) that were not before."""
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for i in range(first, last):
            writer.add_message(1, i, b"{}", i, i)
            writer.flush()
            stream.drain()
        return tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()


def test_twenty_thousand_chunks_keep_no_chunk_index_in_memory(tmp_path: Path):
    path = tmp_path / "long.mcap"
    stream = _Buffered(path)
    spool = ChunkIndexSpool(tmp_path)
    writer = McapFileWriter(stream, chunk_size=64 * 1024, compression="none", chunk_indexes=spool)
    writer.start("lrauv", "test")
    writer.register_channel("/state", "json", 0)
    for i in range(15_000):
        writer.add_message(1, i, b"{}", i, i)
        writer.flush()
    stream.drain()
    grown = _traced_growth_over_chunks(writer, stream, 15_000, 20_000)
    # Held in memory, 5,000 chunk indexes of ~90 bytes are over 400 kB; spooled, nothing grows with them.
    assert grown < 64 * 1024 and spool.held == [] and len(spool) == 20_000
    writer.finish(drain=stream.drain)
    assert stream.most_pending < 2 * 1024 * 1024  # the summary (1.8 MB of indexes) went out a MiB at a time
    stream.close()
    spool.close()
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert len(summary.chunk_indexes) == summary.statistics.chunk_count == 20_000
        starts = [c.chunk_start_offset for c in summary.chunk_indexes]
        assert starts == sorted(set(starts))
        # The indexes lead to the right chunks: the reader seeks by them for a time window.
        assert [m.sequence for _, _, m in reader.iter_messages(starting_at=19_990)] == list(range(19_990, 20_000))


def test_the_same_chunk_indexes_held_in_memory_do_grow(tmp_path: Path):
    """The control for the test above: its measurement sees indexes kept in a list."""
    stream = _Buffered(tmp_path / "list.mcap")
    held: list[bytes] = []
    writer = McapFileWriter(stream, compression="none", chunk_indexes=held)
    writer.start("lrauv", "test")
    writer.register_channel("/state", "json", 0)
    assert _traced_growth_over_chunks(writer, stream, 0, 5000) > 5000 * 64
    assert len(held) == 5000
    stream.close()
