"""Uploads a file to the vehicle by MAVLink FTP (https://mavlink.io/en/services/ftp.html).

``put_file`` runs "Uploading a File": CreateFile, WriteFile in 239-byte chunks with up
to ``WINDOW`` writes in flight, TerminateSession. Every request is resent with the
same sequence number when its reply is late ("Timeouts/Resending"), so lost packets
either way cost time, not data. No ResetSessions: it would close other clients'
sessions too (the spec's warning under "Uploading a File").

The receiver judges the file when the session is closed: a NAK to TerminateSession
means it refused the file (``executive.ftp``) and ``put_file`` raises, with the reason
the executive sent as STATUSTEXT just before the NAK (FTP has no field for it; a long
reason comes in MAVLink 2 chunks, joined here). The wire format (``Frame``, ``Opcode``,
``ErrorCode``) is ``executive.ftp``'s.
"""

from __future__ import annotations

import random
import time
from dataclasses import dataclass
from typing import Any

from executive.ftp import MAX_DATA, ErrorCode, Frame, Opcode
from executive.mavlink_bridge import EXECUTIVE_COMPONENT, EXECUTIVE_SYSTEM
from executive.mission_protocol import addressed_to
from planner.contract.errors import ShoreError
from planner.shore.mission_client import StatusTexts, linger

WINDOW = 8  # WriteFile requests in flight
_REFUSED = "refused "  # how the executive's STATUSTEXT for a refused upload begins (executive.plan_changes)


class FtpUploadError(ShoreError):
    """An upload that failed: the message says which step, and the NAK code or the timeout."""


class FtpTimeoutError(FtpUploadError):
    """No reply after every resend: the vehicle is silent, unreachable, or refused our frames unread (signing)."""


def _reply_seq(req: Frame) -> int:
    return (req.seq + 1) & 0xFFFF  # "Payload Format": a reply carries the request's seq + 1


def _nak_name(reply: Frame) -> str:
    code = reply.data[0] if reply.data else 0
    try:
        name = ErrorCode(code).spec_name
    except ValueError:
        name = f"error {code}"
    return f"{name} (errno {reply.data[1]})" if code == ErrorCode.FAIL_ERRNO and len(reply.data) > 1 else name


@dataclass
class _Pending:
    request: Frame
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
        self.texts = StatusTexts()  # what the target says meanwhile: a refusal's reason

    def request(self, session: int, opcode: Opcode, offset: int = 0, data: bytes = b"") -> Frame:
        req = Frame(self._seq, session, opcode, len(data), 0, 0, offset, data)
        self._seq = (self._seq + 1) & 0xFFFF
        self.send(req)
        return req

    def send(self, req: Frame) -> None:
        self.conn.mav.file_transfer_protocol_send(0, self.target[0], self.target[1], req.pack())

    def receive(self, until_s: float) -> Frame | None:
        """The next FTP reply addressed to us from the target, None at ``until_s``."""
        while (left := until_s - time.monotonic()) > 0:
            msg = self.conn.recv_match(type=["FILE_TRANSFER_PROTOCOL", "STATUSTEXT"], blocking=True, timeout=left)
            if msg is None:
                return None
            if (msg.get_srcSystem(), msg.get_srcComponent()) != self.target or \
                    not addressed_to(msg, self.conn.source_system, self.conn.source_component):
                continue
            if msg.get_type() == "STATUSTEXT":
                self.texts.add(msg)
                continue
            reply = Frame.parse(bytes(msg.payload))
            if reply.opcode in (Opcode.ACK, Opcode.NAK):
                return reply
        return None

    def give_up(self, req: Frame, what: str) -> FtpUploadError:
        return FtpTimeoutError(f"{what}: no reply from system {self.target[0]} component {self.target[1]} to "
                              f"{Opcode(req.opcode).name} after {self.retries + 1} tries of {self.timeout_s:g} s each")


def _matches(reply: Frame, req: Frame) -> bool:
    if reply.seq != _reply_seq(req) or reply.req_opcode != req.opcode:
        return False
    # CreateFile's ACK may carry a session the server chose (PX4); everything else echoes ours
    return reply.session == req.session or (req.opcode == Opcode.CREATE_FILE and reply.opcode == Opcode.ACK)


def _call(link: _Link, what: str, session: int, opcode: Opcode, data: bytes = b"") -> Frame:
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
            req = link.request(session, Opcode.WRITE_FILE, offset, data[offset:offset + MAX_DATA])
            pending[_reply_seq(req)] = _Pending(req, time.monotonic())
        oldest = min(pending.values(), key=lambda p: p.sent_s)
        reply = link.receive(oldest.sent_s + link.timeout_s)
        if reply is not None:
            entry = pending.get(reply.seq)
            if entry is not None and _matches(reply, entry.request) and reply.offset == entry.request.offset:
                if reply.opcode == Opcode.NAK:
                    raise FtpUploadError(f"{what}: WriteFile at offset {reply.offset} refused by the vehicle: "
                                         f"NAK {_nak_name(reply)}")
                del pending[reply.seq]
            continue
        if oldest.attempts > link.retries:
            raise link.give_up(oldest.request, f"{what} (WriteFile at offset {oldest.request.offset})")
        link.send(oldest.request)
        oldest.sent_s = time.monotonic()
        oldest.attempts += 1


def put_file(conn: Any, data: bytes, remote_path: str, *, target_system: int = EXECUTIVE_SYSTEM,
             target_component: int = EXECUTIVE_COMPONENT,
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
    created = _call(link, what, 0, Opcode.CREATE_FILE, path)  # session 0, as PX4 expects
    if created.opcode == Opcode.NAK:
        raise FtpUploadError(f"{what}: CreateFile refused by the vehicle: NAK {_nak_name(created)}")
    _write_all(link, what, created.session, bytes(data))
    closed = _call(link, what, created.session, Opcode.TERMINATE_SESSION)
    if closed.opcode == Opcode.NAK:
        linger(link.conn, link.texts, link.target, (conn.source_system, conn.source_component), _REFUSED)
        reason = link.texts.reason(_REFUSED)
        raise FtpUploadError(f"{what}: refused by the vehicle (TerminateSession NAK {_nak_name(closed)})"
                             + (f": {reason}" if reason else ""))
