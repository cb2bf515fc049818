"""The log on a full, failing or stalled disk: faults injected at the OS boundary, never by mocks.

``/dev/full`` fails every write with ENOSPC ("No space left on device"), as a full disk
does; a named pipe nobody reads blocks every write once its buffer is full, as a hung disk
does, and writes again when it is read.
"""

from __future__ import annotations

import fcntl
import os
import threading
from pathlib import Path

import pytest

from executive.recorder import LogError, Recorder, Topic, read_messages
from tests.support.helpers import wait_until

pytestmark = pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs Linux /dev/full")


def _full(tmp_path: Path) -> Path:
    path = tmp_path / "full.mcap"
    path.symlink_to("/dev/full")
    return path


def test_a_full_disk_is_a_log_error_that_names_the_file(tmp_path):
    with pytest.raises(LogError, match=r"full\.mcap: cannot write: No space left on device"):
        Recorder(_full(tmp_path))


def test_in_the_background_a_full_disk_degrades_the_log_once_and_never_raises(tmp_path):
    path = _full(tmp_path)
    rec = Recorder(path, background=True, max_queued_records=100, utc_offset_ns=0)  # no UTC to wait for
    assert wait_until(lambda: rec.degraded is not None, 10)  # the header's write failed
    for i in range(1000):  # none raises or waits: beyond the bound they are dropped and counted
        rec.write(Topic.STATE, float(i), {"time_s": float(i), "i": i})
    notices = []
    assert wait_until(lambda: bool(notices.extend(rec.maybe_flush()) or notices), 10)
    assert [(n.level, n.text) for n in notices] == [
        ("warning", f"log degraded (No space left on device): {path}; buffering, then dropping records")]
    assert rec.degraded == "No space left on device" and rec.records_dropped >= 900
    rec.close()  # gives up on the dead disk instead of waiting for it
    assert rec.maybe_flush() == [] and rec.records_dropped >= 900


def test_a_stalled_disk_drops_what_does_not_fit_and_says_so_when_it_writes_again(tmp_path):
    path = tmp_path / "slow.mcap"
    os.mkfifo(path)
    reader = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    fcntl.fcntl(reader, fcntl.F_SETPIPE_SZ, 4096)
    rec = Recorder(path, background=True, max_queued_records=50, chunk_size=1024, utc_offset_ns=0)
    try:
        for i in range(2000):
            rec.write(Topic.STATE, float(i), {"time_s": float(i), "noise": os.urandom(64).hex()})
        notices = rec.maybe_flush(float("inf"))  # asks for a flush too: the writer is stuck in write()
        assert rec.records_dropped > 0
        assert [n.text for n in notices] == [(f"log degraded (the disk is not keeping up; the log buffer is full):"
                                              f" {path}; buffering, then dropping records")]
        drained = bytearray()
        drainer = threading.Thread(target=_drain, args=(reader, drained), daemon=True)
        drainer.start()  # the disk answers again
        assert wait_until(lambda: bool(notices.extend(rec.maybe_flush()) or len(notices) > 1), 10)
        dropped = rec.records_dropped
        assert notices[1].text == f"log writing again: {path}; {dropped} records dropped"
        rec.close()
        drainer.join(timeout=10)
    finally:
        os.close(reader)
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(bytes(drained))
    kept = [p["time_s"] for _, _, p in read_messages(copy)]  # a whole log: the dropped records are just missing
    assert len(kept) == 2000 - dropped == rec.messages_written
    assert kept == sorted(kept)


def _drain(fd: int, into: bytearray) -> None:
    os.set_blocking(fd, True)
    while block := os.read(fd, 65536):
        into += block
