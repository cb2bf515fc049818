"""Uploads a file to the vehicle by MAVLink FTP (https://mavlink.io/en/services/ftp.html).

``put_file`` runs "Uploading a File": CreateFile, WriteFile in 239-byte chunks with up
to ``WINDOW`` writes in flight, TerminateSession. Every request is resent with the
same sequence number when its reply is late ("Timeouts/Resending"), so lost packets
either way cost time, not data. No ResetSessions: it would close other clients'
sessions too (the spec's warning under "Uploading a File").

The receiver judges the file when the session is closed: a NAK to TerminateSession
means it refused the file (``executive.ftp``) and ``put_file`` raises. The wire format
is repeated here rather than imported, so the planner does not depend on the executive.
"""

from __future__ import annotations

import random
import struct
import time
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from planner.errors import PlannerError

PAYLOAD_LEN = 251
MAX_DATA = 239
WINDOW = 8  # WriteFile requests in flight
_HEADER = struct.Struct("<HBBBBBxI")  # seq, session, opcode, size, req_opcode, burst_complete, pad, offset
_ERRORS = {1: "Fail", 2: "FailErrno", 3: "InvalidDataSize", 4: "InvalidSession", 5: "NoSessionsAvailable",
           6: "EOF", 7: "UnknownCommand", 8: "FileExists", 9: "FileProtected", 10: "FileNotFound"}


class FtpUploadError(PlannerError):
    """An upload that failed: the message says which step, and the NAK code or the timeout."""


class _Op(IntEnum):
    TERMINATE_SESSION = 1
    CREATE_FILE = 6
    WRITE_FILE = 7
    ACK = 128
    NAK = 129


@dataclass(frozen=True)
class _Request:
    seq: int
    session: int
    opcode: _Op
    offset: int
    data: bytes

    def pack(self) -> bytes:
        header = _HEADER.pack(self.seq, self.session, self.opcode, len(self.data), 0, 0, self.offset)
        return (header + self.data).ljust(PAYLOAD_LEN, b"\0")

    @property
    def reply_seq(self) -> int:
        return (self.seq + 1) & 0xFFFF


@dataclass(frozen=True)
class _Reply:
    seq: int
    session: int
    opcode: int
    req_opcode: int
    offset: int
    data: bytes

    def nak_name(self) -> str:
        code = self.data[0] if self.data else 0
        name = _ERRORS.get(code, f"error {code}")
        return f"{name} (errno {self.data[1]})" if code == 2 and len(self.data) > 1 else name


@dataclass
class _Pending:
    request: _Request
    sent_s: float
    attempts: int = 1


class _Link:
    """Our side of one upload: sends requests, resends late ones, picks out their replies."""

    def __init__(self, conn: Any, target: tuple[int, int], timeout_s: float, retries: int) -> None:
        self.conn = conn
        self.target = target
        self.timeout_s = timeout_s
        self.retries = retries
        self._seq = random.randrange(0x10000)  # unlike a previous upload's, so no cached reply fits ours

    def request(self, session: int, opcode: _Op, offset: int = 0, data: bytes = b"") -> _Request:
        req = _Request(self._seq, session, opcode, offset, data)
        self._seq = (self._seq + 1) & 0xFFFF
        self.send(req)
        return req

    def send(self, req: _Request) -> None:
        self.conn.mav.file_transfer_protocol_send(0, self.target[0], self.target[1], req.pack())

    def receive(self, until_s: float) -> _Reply | None:
        """The next FTP reply addressed to us from the target, None at ``until_s``."""
        while (left := until_s - time.monotonic()) > 0:
            msg = self.conn.recv_match(type="FILE_TRANSFER_PROTOCOL", blocking=True, timeout=left)
            if msg is None:
                return None
            if (msg.get_srcSystem(), msg.get_srcComponent()) != self.target:
                continue
            if msg.target_system not in (0, self.conn.source_system) or \
                    msg.target_component not in (0, self.conn.source_component):
                continue
            raw = bytes(msg.payload).ljust(PAYLOAD_LEN, b"\0")
            seq, session, opcode, size, req_opcode, _burst, offset = _HEADER.unpack_from(raw)
            if opcode in (_Op.ACK, _Op.NAK):
                return _Reply(seq, session, opcode, req_opcode, offset, raw[12:12 + min(size, MAX_DATA)])
        return None

    def give_up(self, req: _Request, what: str) -> FtpUploadError:
        return FtpUploadError(f"{what}: no reply from system {self.target[0]} component {self.target[1]} to "
                              f"{req.opcode.name} after {self.retries + 1} tries of {self.timeout_s:g} s each")


def _matches(reply: _Reply, req: _Request) -> bool:
    if reply.seq != req.reply_seq or reply.req_opcode != req.opcode:
        return False
    # CreateFile's ACK carries the new session; everything else echoes ours
    return reply.session == req.session or (req.opcode == _Op.CREATE_FILE and reply.opcode == _Op.ACK)


def _call(link: _Link, what: str, session: int, opcode: _Op, data: bytes = b"") -> _Reply:
    """One request and its reply, stop-and-wait with resends."""
    req = link.request(session, opcode, 0, data)
    for attempt in range(link.retries + 1):
        if attempt:
            link.send(req)
        deadline = time.monotonic() + link.timeout_s
        while (reply := link.receive(deadline)) is not None:
            if _matches(reply, req):
                return reply
    raise link.give_up(req, what)


def _write_all(link: _Link, what: str, session: int, data: bytes) -> None:
    """WriteFile for every chunk, ``WINDOW`` in flight, each resent until ACKed."""
    offsets = list(range(0, len(data), MAX_DATA))[::-1]  # popped from the end: ascending
    pending: dict[int, _Pending] = {}  # by reply seq
    while offsets or pending:
        while offsets and len(pending) < WINDOW:
            offset = offsets.pop()
            req = link.request(session, _Op.WRITE_FILE, offset, data[offset:offset + MAX_DATA])
            pending[req.reply_seq] = _Pending(req, time.monotonic())
        oldest = min(pending.values(), key=lambda p: p.sent_s)
        reply = link.receive(oldest.sent_s + link.timeout_s)
        if reply is not None:
            entry = pending.get(reply.seq)
            if entry is not None and _matches(reply, entry.request) and reply.offset == entry.request.offset:
                if reply.opcode == _Op.NAK:
                    raise FtpUploadError(f"{what}: WriteFile at offset {reply.offset} refused by the vehicle: "
                                         f"NAK {reply.nak_name()}")
                del pending[reply.seq]
            continue
        if oldest.attempts > link.retries:
            raise link.give_up(oldest.request, f"{what} (WriteFile at offset {oldest.request.offset})")
        link.send(oldest.request)
        oldest.sent_s = time.monotonic()
        oldest.attempts += 1


def put_file(conn: Any, data: bytes, remote_path: str, *, target_system: int = 1, target_component: int = 191,
             timeout_s: float = 5.0, retries: int = 5) -> None:
    """Uploads ``data`` to ``remote_path`` on the vehicle; raises FtpUploadError unless it was accepted.

    ``conn`` is a pymavlink connection (``mavutil.mavlink_connection``); FILE_TRANSFER_PROTOCOL
    replies are read from it, other messages read meanwhile are dropped. Each request
    is resent after ``timeout_s`` without its reply, at most ``retries`` times.
    """
    what = f"upload of {len(data)} bytes to {remote_path}"
    try:
        path = remote_path.encode("ascii")
    except UnicodeEncodeError:
        raise FtpUploadError(f"{what}: the path must be ASCII") from None
    if not 0 < len(path) <= MAX_DATA:
        raise FtpUploadError(f"{what}: the path must be 1 to {MAX_DATA} bytes, got {len(path)}")
    link = _Link(conn, (target_system, target_component), timeout_s, retries)
    created = _call(link, what, 0, _Op.CREATE_FILE, path)  # session 0, as PX4 expects
    if created.opcode == _Op.NAK:
        raise FtpUploadError(f"{what}: CreateFile refused by the vehicle: NAK {created.nak_name()}")
    _write_all(link, what, created.session, bytes(data))
    closed = _call(link, what, created.session, _Op.TERMINATE_SESSION)
    if closed.opcode == _Op.NAK:
        raise FtpUploadError(f"{what}: refused by the vehicle (TerminateSession NAK {closed.nak_name()})")
