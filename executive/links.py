"""The autopilot link's guard: locked to the autopilot's address, duplicates dropped (docs/executive.md, "Links").

Between pymavlink's UDP link (``mavlink_bridge.UdpLink``) and the loop: the loop hands each
datagram here before parsing it. Once a datagram has carried a frame from the autopilot, the
link is locked to that datagram's address, and datagrams from any other address are counted
and dropped unparsed; a warning about them is due at most once per ``signing.RefusalLog``
period (10 s of wall time), with the count since the last one. A datagram identical to one of
the last few from the autopilot is a duplicate (every MAVLink frame carries a sequence number,
so a new datagram never repeats a recent one): a lockstep simulator's resent step, or the
network's. Other links (TCP, serial) are streams: read in whole buffers (``read``), never locked or
filtered; the peer closing one (``closed``) is a lost link at once.
"""

from __future__ import annotations

import select
from collections import deque
from typing import Any

from executive import mavlink_bridge as bridge
from executive.signing import RefusalLog, note_refusal

RECENT_DATAGRAMS = 16


class LinkGuard:
    """Lock, foreign-datagram count and duplicate filter of one autopilot link."""

    def __init__(self, conn: Any, autopilot_system: int) -> None:
        self.conn = conn
        self.autopilot_system = autopilot_system
        self.udp = hasattr(conn, "lock")  # a bridge.UdpLink
        self.foreign = 0  # datagrams from another address than the locked autopilot's
        self.duplicates = 0
        self._recent: deque[bytes] = deque(maxlen=RECENT_DATAGRAMS)
        self._warnings = RefusalLog()
        self._unreported = 0  # foreign datagrams not yet in a warning

    @property
    def locked(self) -> tuple[str, int] | None:
        return self.conn.locked if self.udp else None

    @property
    def closed(self) -> bool:
        """The peer closed the stream (TCP end of stream or reset, a serial device gone): a lost link at once."""
        return bool(getattr(self.conn, "closed", False))

    @property
    def fd(self) -> int | None:
        """What to wait on for input: None once a connection is closed for good (its end of stream reads
        ready for ever); a listening link waits for its next client."""
        return None if self.closed and not hasattr(self.conn, "listen") else self.conn.fd

    def read(self) -> bytes:
        """What waits on the link: one datagram (UDP), or all that waits of a stream, up to
        ``mavlink_bridge.STREAM_READ_BYTES`` (b"" when nothing does)."""
        if self.udp:
            return self.conn.recv()
        try:
            return self.conn.recv(bridge.STREAM_READ_BYTES) or b""
        except OSError:  # a serial device gone (pyserial's SerialException is an OSError)
            self.conn.closed = True
            return b""

    def admit(self, data: bytes) -> bool:
        """Whether the datagram just read goes on to the parser (False: from elsewhere, or a repeat)."""
        if not self.udp:
            return True
        locked, source = self.conn.locked, self.conn.source
        if locked is not None and source != locked:
            self.foreign += 1
            self._unreported += 1
            return False
        blob = bytes(data)
        if blob in self._recent:
            self.duplicates += 1
            return False
        self._recent.append(blob)
        return True

    def lock_on(self, msgs: list[Any]) -> tuple[str, int] | None:
        """Lock to the source of this datagram if it carries a frame from the autopilot; the address newly locked."""
        if not self.udp or self.conn.locked is not None or self.conn.source is None:
            return None
        if any(m.get_msgId() >= 0 and bridge.from_autopilot(m, self.autopilot_system) for m in msgs):
            self.conn.lock(self.conn.source)
            return self.conn.source
        return None

    def warning(self, wall_s: float) -> str | None:
        """The warning about datagrams from elsewhere, when one is due (rate-limited)."""
        if not self._unreported:
            return None
        log, line = self._warnings, None
        for _ in range(self._unreported):
            log, covers = note_refusal(log, wall_s)
            line = covers if covers is not None else line
        self._warnings, self._unreported = log, 0
        if line is None:
            return None
        source, locked = self.conn.source, self.conn.locked
        return (f"ignored {line} datagram(s) from {source[0]}:{source[1]} on the autopilot link:"
                f" the autopilot is at {locked[0]}:{locked[1]}")

    def input_waiting(self) -> bool:
        """Datagrams from the autopilot wait unread (those from elsewhere are read and counted here)."""
        if self.fd is None:
            return False
        while True:
            ready, _, _ = select.select([self.conn.fd], [], [], 0)
            if not ready or self.locked is None:
                return bool(ready)
            if self.conn.peek_source() in (self.conn.locked, None):
                return True
            self.admit(self.conn.recv())  # from elsewhere: counted, dropped
