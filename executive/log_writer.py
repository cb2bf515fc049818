"""Writing the MCAP log off the control loop, and surviving a full, slow or failing disk.

``PendingFile`` is the stream ``executive.mcap_file.McapFileWriter`` writes into: bytes wait in memory and go
to the file in ``push``. A write the disk refuses (``ENOSPC``, ``EIO``) raises there and
keeps the bytes not yet written, so the file stays a clean prefix of the log and the
next ``push`` goes on from exactly where the last one stopped: the log stays readable
(``executive.recorder.recover``) however often the disk fails.

``Background`` runs the writer in a thread fed by a queue bounded in records and bytes.
The loop only encodes a record and appends it; it never waits for a write or an fsync.
When the disk fails, or is so slow that the queue fills, the log *degrades*: records are
buffered up to the bound, then dropped and counted, and a notice (an ``Event``) says so
once; when writing works again a second notice gives the number dropped. The loop sends
both as STATUSTEXT. ``close`` waits a bounded time: a dead disk leaves the log without its
footer (recoverable), never a hung process.

Standard library only (``threading``, ``collections``): the executive stays light.
"""

from __future__ import annotations

import errno
import logging
import os
import threading
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from executive.state import Event

__all__ = ["Background", "Flush", "PendingFile", "Sink", "reason_of"]

log = logging.getLogger(__name__)

RETRY_S = 1.0  # wall seconds between attempts to write to a failing disk
# fsync on a special file (a pipe, /dev/full) says EINVAL: nothing to make durable there.
_FSYNC_UNSUPPORTED = (errno.EINVAL, errno.ENOTSUP, errno.EROFS)


def reason_of(exc: OSError) -> str:
    """The OS's words for a failed write: "No space left on device"."""
    return exc.strerror or str(exc) or type(exc).__name__


class PendingFile:
    """A file written through a memory buffer: ``write`` never touches the disk, ``push`` does."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, "wb", buffering=0)  # noqa: SIM115 (closed in close())
        self._pending = bytearray()
        self.written = 0  # bytes in the file: always a prefix of what was written here

    # -- the stream the MCAP writer uses ---------------------------------------------------------

    def write(self, data: bytes | bytearray | memoryview) -> int:
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self.written + len(self._pending)

    # -- to the disk ------------------------------------------------------------------------------

    @property
    def pending(self) -> int:
        return len(self._pending)

    def push(self) -> None:
        """Write the buffered bytes; an ``OSError`` keeps those the OS did not take, for the next push."""
        done = 0
        view = memoryview(self._pending)
        try:
            while done < len(view):
                n = self._file.write(view[done:])
                if not n:  # a non-blocking file that takes nothing now: try again later
                    raise BlockingIOError(errno.EAGAIN, "the file takes no more bytes now")
                done += n
                self.written += n
        finally:
            view.release()
            del self._pending[:done]

    def sync(self) -> None:
        try:
            os.fsync(self._file.fileno())
        except OSError as exc:
            if exc.errno not in _FSYNC_UNSUPPORTED:
                raise

    def close(self) -> None:
        self._file.close()


class Sink(Protocol):
    """What the writer thread drives (``executive.recorder.Recorder``)."""

    path: Path

    def apply(self, op: tuple[Any, ...]) -> None: ...  # into the MCAP writer: memory only
    def push(self) -> None: ...  # the buffered bytes to the file; OSError when the disk refuses
    def flush_chunk(self, *, fsync: bool) -> None: ...  # close the open chunk, push, fsync
    def finish(self) -> None: ...  # summary and footer, push, fsync, close


@dataclass(frozen=True, slots=True)
class Flush:
    """A request to the writer thread: close the chunk, write and (``fsync``) sync; ``done`` is set after."""

    fsync: bool
    done: threading.Event | None = None


_CLOSE = object()
_BEHIND = "the disk is not keeping up; the log buffer is full"


class Background:
    """The writer thread and its bounded queue; ``put`` from the loop's thread only."""

    def __init__(self, sink: Sink, *, max_records: int, max_bytes: int) -> None:
        self._sink = sink
        self.path = sink.path
        self.max_records = max_records
        self.max_bytes = max_bytes
        self._cond = threading.Condition()
        self._ops: deque[tuple[Any, int]] = deque()
        self._bytes = 0
        self.dropped = 0  # records dropped since the start
        self._dropped_then = 0  # ... when the current degradation began
        self._degraded: str | None = None  # why, while degraded
        self._notices: list[Event] = []
        self._closing = False
        self._thread = threading.Thread(target=self._run, name=f"log writer {self.path.name}", daemon=True)
        self._thread.start()

    # -- the loop's side ---------------------------------------------------------------------------

    def put(self, op: tuple[Any, ...], nbytes: int) -> bool:
        """Queue a record; False (dropped, counted) when the queue is at its bound."""
        with self._cond:
            if len(self._ops) >= self.max_records or self._bytes + nbytes > self.max_bytes:
                if self._degraded is None:
                    self._degrade(_BEHIND)
                self.dropped += 1
                return False
            self._ops.append((op, nbytes))
            self._bytes += nbytes
            if len(self._ops) == 1:
                self._cond.notify()
            return True

    def request(self, op: Flush) -> None:
        """A flush request: never dropped."""
        with self._cond:
            self._ops.append((op, 0))
            self._cond.notify()

    def notices(self) -> list[Event]:
        """What happened to the log since the last call: degraded, writing again."""
        if not self._notices:
            return []
        with self._cond:
            out, self._notices = self._notices, []
        return out

    @property
    def degraded(self) -> str | None:
        return self._degraded

    def close(self, timeout_s: float) -> bool:
        """Write what is queued, finish the file; False when the thread did not end within ``timeout_s``."""
        with self._cond:
            self._closing = True
            self._ops.append((_CLOSE, 0))
            self._cond.notify()
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.warning("%s: the log writer did not finish within %.0f s (the disk does not answer); the log is"
                        " left without its footer: `lrauv log recover %s`", self.path, timeout_s, self.path)
            return False
        if self.dropped:
            log.warning("%s: %d records were dropped while the disk failed", self.path, self.dropped)
        return True

    # -- the writer thread ---------------------------------------------------------------------------

    def _degrade(self, reason: str) -> None:
        """Called with the lock held; once per episode, and once more if a disk error explains a full buffer."""
        if self._degraded is None:
            self._dropped_then = self.dropped
        self._degraded = reason
        text = f"log degraded ({reason}): {self.path}; buffering, then dropping records"
        log.warning("%s", text)
        self._notices.append(Event("warning", text))

    def _failed(self, exc: OSError) -> None:
        with self._cond:
            if self._degraded in (None, _BEHIND):
                self._degrade(reason_of(exc))

    def _maybe_recovered(self) -> None:
        """After a good write: writing again once the queue has drained to half its bound."""
        with self._cond:
            if self._degraded is None or len(self._ops) > self.max_records // 2 or self._bytes > self.max_bytes // 2:
                return
            self._degraded = None
            n = self.dropped - self._dropped_then
            text = f"log writing again: {self.path}; {n} records dropped"
            log.warning("%s", text)
            self._notices.append(Event("warning" if n else "info", text))

    def _attempt(self, fn: Any, **kwargs: Any) -> bool:
        try:
            fn(**kwargs)
        except OSError as exc:
            self._failed(exc)
            return False
        return True

    def _run(self) -> None:
        failing = False
        while True:
            if failing:  # the queue is the buffer meanwhile; close() cuts the wait short
                with self._cond:
                    if not self._closing:
                        self._cond.wait(RETRY_S)
                    closing = self._closing
                failing = not self._attempt(self._sink.push)
                if failing:
                    if closing:
                        self._give_up()
                        return
                    continue
                self._maybe_recovered()
            with self._cond:
                while not self._ops:
                    self._cond.wait()
                batch, self._ops, self._bytes = self._ops, deque(), 0
            failing, closed = self._handle(batch)
            if closed:
                return

    def _handle(self, batch: deque[tuple[Any, int]]) -> tuple[bool, bool]:
        """Apply a batch in order; (the disk failed, the file is closed)."""
        for op, _nbytes in batch:
            if op is _CLOSE:
                self._finish()
                return False, True
            if isinstance(op, Flush):
                ok = self._attempt(self._sink.flush_chunk, fsync=op.fsync)
                if op.done is not None:
                    op.done.set()
                if not ok:
                    self._requeue(batch, op)
                    return True, False
                continue
            try:
                self._sink.apply(op)
            except Exception:  # one bad record must not stop the log
                with self._cond:
                    self.dropped += 1
                log.exception("%s: a record could not be logged", self.path)
        ok = self._attempt(self._sink.push)
        if ok:
            self._maybe_recovered()
        return not ok, False

    def _requeue(self, batch: deque[tuple[Any, int]], after: Any) -> None:
        """Put what followed ``after`` in ``batch`` back at the head of the queue (a failed flush)."""
        rest: list[tuple[Any, int]] = []
        seen = False
        for item in batch:
            if seen:
                rest.append(item)
            seen = seen or item[0] is after
        with self._cond:
            self._ops.extendleft(reversed(rest))
            self._bytes += sum(n for _op, n in rest)

    def _give_up(self) -> None:
        """Closing on a disk that still fails: drop what is queued; the file keeps its good prefix."""
        with self._cond:
            self.dropped += sum(1 for op, _n in self._ops if op is not _CLOSE and not isinstance(op, Flush))
            self._ops.clear()
        self._finish()

    def _finish(self) -> None:
        """One attempt at the summary and footer; the file is closed either way."""
        try:
            self._sink.finish()
        except OSError as exc:
            log.warning("%s: cannot finish the log (%s); it ends at its last complete record:"
                        " `lrauv log recover %s`", self.path, reason_of(exc), self.path)
