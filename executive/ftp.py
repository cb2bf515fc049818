"""MAVLink FTP server for policy-table and forecast uploads: a pure state machine, no sockets, no disk.

Protocol: FILE_TRANSFER_PROTOCOL (message 110), https://mavlink.io/en/services/ftp.html
(section names below are that page's). ``FtpServer.handle`` takes one request payload
and returns the reply payload, or None when no reply is due (the payload is a reply
itself). The caller owns the link: it answers the requester (sysid, compid) with
``file_transfer_protocol_send(0, sysid, compid, reply)``.

The file system is virtual and tiny: directories ``/``, ``/tables`` and ``/forecasts``
(fixed), files only in them. A write session (CreateFile, OpenFileWO) collects bytes in memory; when
it is closed (TerminateSession, or ResetSessions as PX4 and QGroundControl close an
upload) the file goes to ``accept(path, data)``. None stores it in ``files`` (replacing
an older file of that path) and the terminate is ACKed; a reason string discards it
and the terminate is NAKed with Fail (the reason is logged; FTP has no field for it).
An exception from ``accept`` refuses the file too. ``files`` holds the accepted files,
within a storage quota (see "Storage quota" below).
``accept`` must judge the content itself (a policy table's own checks): a GCS that
aborts an upload with ResetSessions ("Uploading a File": on a NAK the GCS "should
cancel ... by sending ResetSessions") hands it a partial file. Sessions with a refused
write are poisoned instead: closing them discards the data without calling ``accept``.

What a client learns of a refusal depends on the client:

* ``planner.shore.ftp_client.put_file`` raises ``FtpUploadError`` ("refused by the vehicle").
* pymavlink's ``MAVFTP.cmd_put`` (2.4.50) does not notice. After the last WriteFile
  ACK it calls its progress/put callback with the full length ("Put N bytes" is
  logged), then sends TerminateSession and waits for the reply with
  ``process_ftp_reply("TerminateSession")``, which treats ACK and NAK alike ("Ack or
  Nack ...: the handshake has been answered"). ``process_ftp_reply("put")`` then
  returns the last WriteFile reply's result: ``FtpError.Success``. The spec allows
  this ("Uploading a File": the terminate reply "may (generally speaking) be ignored
  by the GCS"). A MAVFTP user learns of a refusal only by looking afterwards, e.g.
  ``cmd_crc``/``cmd_list`` answer FileNotFound / do not list the file.

Choices where the spec leaves room:

* Sessions: the reply to OpenFileRO, CreateFile and OpenFileWO echoes the session id
  of the request, as ArduPilot does (MAVProxy routes replies by it); an open session
  with that id is closed first (without ``accept``).
* Retransmissions ("Timeouts/Resending": "the drone must re-send its response if a
  request with the same sequence number is received"): the last replies are kept,
  keyed by the whole request, and a repeated request gets the same reply without
  being executed again. So a resent CreateFile gets the same session and a resent
  TerminateSession the same verdict. A request evicted from that cache is executed
  again: harmless for reads and writes; a TerminateSession then gets InvalidSession.
* A CreateFile or OpenFileWO for the path of an open write session drops the older
  session (an abandoned upload, discarded without ``accept``) and opens the new one.
* BurstReadFile answers one packet per request with ``burst_complete`` set (``handle``
  returns one reply); clients ask again from the next offset.
* CalcFileCRC32 is the CRC-32 of ArduPilot's ``crc_crc32(0, ...)`` and PX4's
  ``crc32part(..., 0)``: the reflected 0xEDB88320 polynomial with initial value 0 and
  no final XOR, i.e. ``zlib.crc32(data, 0xFFFFFFFF) ^ 0xFFFFFFFF`` (not ``zlib.crc32``).
* CreateDirectory answers FileExists for the fixed directories and FileProtected
  otherwise; RemoveDirectory, TruncateFile and Rename are not supported
  (UnknownCommand), so stored files change only through ``accept``, RemoveFile and
  ``discard`` (the executive removes superseded forecasts).
* Storage quota: ``max_files`` files and ``max_total_bytes`` bytes, counting the stored
  files and the open uploads together (an upload that replaces a stored file counts both
  until it is stored). A write beyond the quota is refused, never made room for by
  dropping another file: CreateFile/OpenFileWO of a new path when ``max_files`` are held
  or open, or a WriteFile/OpenFileWO that would take the bytes over ``max_total_bytes``,
  is NAKed FailErrno ENOSPC (a WriteFile also poisons its session), and ``announce`` is
  told once until room is made (RemoveFile, ``discard``). Files are at most
  ``max_file_bytes`` (beyond: FailErrno EFBIG). Also bounded: ``max_sessions`` open sessions
  (the oldest is dropped, without ``accept``, to open another) and the reply cache.
  Removing or replacing a file closes the read sessions on it.
* No sparse files: a WriteFile beyond the current end is not zero-filled. Clients keep
  several writes in flight ("Uploading a File"), so a lost datagram lets later blocks
  arrive first: such a block is held (its own bytes count) until the gap is written, if it
  starts at most ``MAX_GAP_BYTES`` beyond the end and at most ``MAX_HELD_BLOCKS`` are held;
  a write further out is NAKed FailErrno EINVAL and poisons its session (so a 1-byte write
  at a large offset makes no large file), and a session closed with a gap is refused.
* CalcFileCRC32 is computed once per stored file, on the first request, and kept with it.

Not thread-safe: call ``handle`` from one thread.
"""

from __future__ import annotations

import errno
import logging
import struct
import zlib
from collections import OrderedDict
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from enum import IntEnum

log = logging.getLogger(__name__)

PAYLOAD_LEN = 251  # FILE_TRANSFER_PROTOCOL.payload
MAX_DATA = 239  # "Payload Format": data[] after the 12-byte header
# seq_number u16, session, opcode, size, req_opcode, burst_complete, padding, offset u32 (little endian)
_HEADER = struct.Struct("<HBBBBBxI")
DIRECTORIES = frozenset({"/", "/tables", "/forecasts"})  # policy tables (*.lrpt), forecasts (*.nc)
_CACHE_ENTRIES = 64
MAX_GAP_BYTES = 64 * 1024  # how far beyond a file's end a WriteFile may start (held until the gap is written)
MAX_HELD_BLOCKS = 512  # out-of-order blocks held per upload


class Opcode(IntEnum):
    """"OpCodes/Command" and the two reply opcodes."""

    NONE = 0
    TERMINATE_SESSION = 1
    RESET_SESSIONS = 2
    LIST_DIRECTORY = 3
    OPEN_FILE_RO = 4
    READ_FILE = 5
    CREATE_FILE = 6
    WRITE_FILE = 7
    REMOVE_FILE = 8
    CREATE_DIRECTORY = 9
    REMOVE_DIRECTORY = 10
    OPEN_FILE_WO = 11
    TRUNCATE_FILE = 12
    RENAME = 13
    CALC_FILE_CRC32 = 14
    BURST_READ_FILE = 15
    ACK = 128
    NAK = 129


class ErrorCode(IntEnum):
    """"NAK Error Information": data[0] of a NAK (data[1] is an errno after FAIL_ERRNO)."""

    NONE = 0
    FAIL = 1
    FAIL_ERRNO = 2
    INVALID_DATA_SIZE = 3
    INVALID_SESSION = 4
    NO_SESSIONS_AVAILABLE = 5
    EOF = 6
    UNKNOWN_COMMAND = 7
    FILE_EXISTS = 8
    FILE_PROTECTED = 9
    FILE_NOT_FOUND = 10

    @property
    def spec_name(self) -> str:
        """The name on mavlink.io ("FailErrno", "EOF")."""
        return "EOF" if self is ErrorCode.EOF else "".join(w.capitalize() for w in self.name.split("_"))


def ftp_crc32(data: bytes) -> int:
    """The CRC that CalcFileCRC32 returns (ArduPilot ``crc_crc32(0, data, len)``)."""
    return zlib.crc32(data, 0xFFFFFFFF) ^ 0xFFFFFFFF


@dataclass(frozen=True)
class Frame:
    """One FTP payload ("Payload Format"); ``data`` holds ``size`` bytes when well formed."""

    seq: int
    session: int
    opcode: int
    size: int
    req_opcode: int
    burst_complete: int
    offset: int
    data: bytes

    @classmethod
    def parse(cls, payload: bytes) -> Frame:
        """Zero-extended to 251 bytes (MAVLink 2 trims trailing zeros), extra bytes ignored."""
        raw = payload[:PAYLOAD_LEN].ljust(PAYLOAD_LEN, b"\0")
        seq, session, opcode, size, req_opcode, burst, offset = _HEADER.unpack_from(raw)
        return cls(seq, session, opcode, size, req_opcode, burst, offset, raw[12:12 + min(size, MAX_DATA)])

    def pack(self) -> bytes:
        header = _HEADER.pack(self.seq, self.session, self.opcode, self.size, self.req_opcode, self.burst_complete,
                              self.offset)
        return (header + self.data).ljust(PAYLOAD_LEN, b"\0")


class _Nak(Exception):
    """Raised inside a handler to answer NAK; never leaves ``handle``."""

    def __init__(self, code: ErrorCode, number: int = 0) -> None:
        super().__init__(code.name)
        self.code = code
        self.number = number  # the errno sent in data[1] with FAIL_ERRNO


@dataclass(frozen=True)
class _Ack:
    data: bytes = b""
    burst_complete: int = 0


@dataclass
class _WriteSession:
    path: str
    data: bytearray = field(default_factory=bytearray)
    poisoned: bool = False  # a write was refused: closing discards without accept
    held: dict[int, bytes] = field(default_factory=dict)  # blocks beyond the end, by offset, until the gap is written
    new_file: bool = True  # its path is not a stored file: storing it takes one more of max_files

    @property
    def size(self) -> int:
        """Bytes this upload holds: the file so far and the blocks held beyond its end."""
        return len(self.data) + sum(map(len, self.held.values()))

    def put(self, offset: int, block: bytes) -> None:
        """Write ``block`` at ``offset`` (at most the end), then every held block the file now reaches."""
        self.data[offset:offset + len(block)] = block
        while self.held:
            start = min(self.held)
            if start > len(self.data):
                return
            held = self.held.pop(start)
            self.data[start:start + len(held)] = held


@dataclass(frozen=True)
class _ReadSession:
    path: str
    data: bytes


@dataclass
class _Stored:
    data: bytes
    crc: int | None = None  # CalcFileCRC32, computed on the first request


class _FilesView(Mapping[str, bytes]):
    """Read-only live view of the stored files, oldest first."""

    def __init__(self, files: dict[str, _Stored]) -> None:
        self._files = files

    def __getitem__(self, path: str) -> bytes:
        return self._files[path].data

    def __iter__(self) -> Iterator[str]:
        return iter(self._files)

    def __len__(self) -> int:
        return len(self._files)

    def __repr__(self) -> str:
        return f"<FTP files {list(self._files)}>"


class FtpServer:
    """The FTP state machine; ``files`` is a read-only view of the most recent accepted files, oldest first."""

    def __init__(self, *, accept: Callable[[str, bytes], str | None], max_file_bytes: int = 64 * 1024 * 1024,
                 max_files: int = 16, max_sessions: int = 4, max_total_bytes: int = 64 * 1024 * 1024,
                 announce: Callable[[str], object] = lambda text: None) -> None:
        self._accept = accept
        self._announce = announce
        self.max_file_bytes = max_file_bytes
        self.max_files = max_files
        self.max_sessions = max_sessions
        self.max_total_bytes = max_total_bytes
        self._full_announced = False  # the quota's refusal is announced once until room is made
        self._files: dict[str, _Stored] = {}  # oldest first
        self._stored_bytes = 0
        self._sessions: OrderedDict[int, _WriteSession | _ReadSession] = OrderedDict()  # oldest first
        self._replies: OrderedDict[bytes, bytes] = OrderedDict()  # request -> reply ("Timeouts/Resending")
        self._handlers: dict[int, Callable[[Frame], _Ack]] = {
            Opcode.NONE: lambda _req: _Ack(),  # "Ignored, always ACKed"
            Opcode.TERMINATE_SESSION: self._terminate,
            Opcode.RESET_SESSIONS: self._reset,
            Opcode.LIST_DIRECTORY: self._list,
            Opcode.OPEN_FILE_RO: self._open_ro,
            Opcode.READ_FILE: self._read,
            Opcode.CREATE_FILE: lambda req: self._open_write(req, truncate=True),
            Opcode.WRITE_FILE: self._write,
            Opcode.REMOVE_FILE: self._remove,
            Opcode.CREATE_DIRECTORY: self._mkdir,
            Opcode.OPEN_FILE_WO: lambda req: self._open_write(req, truncate=False),
            Opcode.CALC_FILE_CRC32: self._crc,
            Opcode.BURST_READ_FILE: self._burst,
        }
        self._files_view = _FilesView(self._files)

    @property
    def files(self) -> Mapping[str, bytes]:
        return self._files_view

    def handle(self, payload: bytes) -> bytes | None:
        """The reply (251 bytes) to one request payload; None when the payload is a reply itself.

        Never raises, whatever the bytes.
        """
        raw = bytes(payload[:PAYLOAD_LEN]).ljust(PAYLOAD_LEN, b"\0")
        req = Frame.parse(raw)
        if req.opcode in (Opcode.ACK, Opcode.NAK):
            return None  # never answer a reply (two servers would ping-pong)
        cached = self._replies.get(raw)
        if cached is not None:
            self._replies.move_to_end(raw)
            return cached
        reply = self._execute(req).pack()
        if req.opcode == Opcode.RESET_SESSIONS:
            self._replies.clear()  # a new client: no earlier request is a retransmission of its own
        else:
            self._replies[raw] = reply
            while len(self._replies) > _CACHE_ENTRIES:
                self._replies.popitem(last=False)
        return reply

    # --- dispatch -----------------------------------------------------------------------------------

    def _execute(self, req: Frame) -> Frame:
        seq = (req.seq + 1) & 0xFFFF  # "Payload Format": replies carry the request's seq + 1
        try:
            if req.size > MAX_DATA:
                raise _Nak(ErrorCode.INVALID_DATA_SIZE)
            handler = self._handlers.get(req.opcode)
            if handler is None:
                raise _Nak(ErrorCode.UNKNOWN_COMMAND)
            ack = handler(req)
        except _Nak as nak:
            data = bytes([nak.code, nak.number]) if nak.code == ErrorCode.FAIL_ERRNO else bytes([nak.code])
            return Frame(seq, req.session, Opcode.NAK, len(data), req.opcode, 0, req.offset, data)
        # the session is echoed (also by the opens, see _open); the offset too: MAVFTP finds the
        # acknowledged WriteFile block by it
        return Frame(seq, req.session, Opcode.ACK, len(ack.data), req.opcode, ack.burst_complete, req.offset, ack.data)

    # --- sessions ("TerminateSession", "ResetSessions") -------------------------------------------------

    def _terminate(self, req: Frame) -> _Ack:
        session = self._sessions.pop(req.session, None)
        if session is None:
            raise _Nak(ErrorCode.INVALID_SESSION)
        if isinstance(session, _WriteSession) and not self._finish(session):
            raise _Nak(ErrorCode.FAIL)
        return _Ack()

    def _reset(self, _req: Frame) -> _Ack:
        """Closes every session; uploads are finished as by TerminateSession, always ACKed."""
        sessions, self._sessions = list(self._sessions.values()), OrderedDict()
        for session in sessions:
            if isinstance(session, _WriteSession):
                self._finish(session)
        return _Ack()

    def _finish(self, session: _WriteSession) -> bool:
        """Hands a closed upload to ``accept``; True when it was stored."""
        if session.poisoned:
            log.warning("FTP upload %s discarded: a write was refused", session.path)
            return False
        if session.held:  # a block beyond a gap that was never written: the file is not whole
            log.warning("FTP upload %s discarded: %d blocks beyond a gap at byte %d", session.path, len(session.held),
                        len(session.data))
            return False
        data, session.data = bytes(session.data), bytearray()  # the one copy; the buffer is freed
        try:
            reason = self._accept(session.path, data)
        except Exception as exc:  # the hook's bug must not take the server down
            reason = f"accept raised {exc!r}"
        if reason is not None:
            log.warning("FTP upload %s (%d bytes) refused: %s", session.path, len(data), reason)
            return False
        self._drop_file(session.path)  # the older version
        self._files[session.path] = _Stored(data)
        self._stored_bytes += len(data)
        return True

    def _open(self, session: _WriteSession | _ReadSession, sid: int) -> None:
        """Opens ``session`` with the id the client asked for, as ArduPilot does (the reply echoes the
        request's session byte, and MAVProxy routes replies by it); drops an open session that has
        that id, and the oldest session when all are taken."""
        if sid in self._sessions:
            old = self._sessions.pop(sid)
            log.warning("FTP session %d (%s) reused by the client for a new one", sid, old.path)
        while len(self._sessions) >= self.max_sessions:
            old_id, old = self._sessions.popitem(last=False)
            log.warning("FTP session %d (%s) dropped for a new one", old_id, old.path)
        # cached replies of an earlier session with this id are no longer valid
        for key in [k for k, v in self._replies.items() if k[2] == sid or v[2] == sid]:
            del self._replies[key]
        self._sessions[sid] = session

    def _write_session(self, req: Frame) -> _WriteSession:
        session = self._sessions.get(req.session)
        if not isinstance(session, _WriteSession):
            raise _Nak(ErrorCode.INVALID_SESSION)
        return session

    def _read_session(self, req: Frame) -> _ReadSession:
        session = self._sessions.get(req.session)
        if not isinstance(session, _ReadSession):
            raise _Nak(ErrorCode.INVALID_SESSION)
        return session

    # --- the storage quota ----------------------------------------------------------------------------

    def _check_quota(self, path: str, *, extra_bytes: int = 0, new_file: bool = False) -> None:
        """NAK FailErrno ENOSPC (announced once until room is made) when ``extra_bytes`` more, or
        one more file, would go over the quota."""
        uploads = [s for s in self._sessions.values() if isinstance(s, _WriteSession)]
        used_bytes = self._stored_bytes + sum(s.size for s in uploads)
        used_files = len(self._files) + sum(s.new_file for s in uploads)
        if used_bytes + extra_bytes <= self.max_total_bytes and not (new_file and used_files >= self.max_files):
            return
        if not self._full_announced:
            self._full_announced = True
            self._announce(f"upload quota full: {path} refused; {used_files} files, {used_bytes / 1e6:.1f} MB held"
                           f" (limits {self.max_files} files, {self.max_total_bytes / 1e6:.1f} MB):"
                           " remove files with FTP RemoveFile")
        raise _Nak(ErrorCode.FAIL_ERRNO, errno.ENOSPC)

    def _drop_file(self, path: str) -> bool:
        """Forgets a stored file and closes the read sessions on it; False when there was none."""
        stored = self._files.pop(path, None)
        if stored is None:
            return False
        self._full_announced = False  # room was made: a later refusal is news again
        self._stored_bytes -= len(stored.data)
        for sid in [sid for sid, s in self._sessions.items() if isinstance(s, _ReadSession) and s.path == path]:
            del self._sessions[sid]
        return True

    # --- files ---------------------------------------------------------------------------------------

    def _open_ro(self, req: Frame) -> _Ack:
        """"OpenFileRO": ACK carries the file length (u32)."""
        path = _path(req.data)
        stored = self._files.get(path)
        if stored is None:
            raise _Nak(ErrorCode.FILE_NOT_FOUND)
        self._open(_ReadSession(path, stored.data), req.session)
        return _Ack(struct.pack("<I", len(stored.data)))

    def _open_write(self, req: Frame, *, truncate: bool) -> _Ack:
        """"CreateFile" (O_CREAT | O_TRUNC) and "OpenFileWO" (O_CREAT, keeps the content)."""
        path = _file_path(req.data)
        stored = self._files.get(path)
        initial = b"" if stored is None or truncate else stored.data
        for sid, open_session in list(self._sessions.items()):
            if isinstance(open_session, _WriteSession) and open_session.path == path:
                del self._sessions[sid]  # an abandoned upload of the same path
                log.warning("FTP session %d (%s) superseded by a new upload", sid, path)
        self._check_quota(path, extra_bytes=len(initial), new_file=stored is None)
        self._open(_WriteSession(path, bytearray(initial), new_file=stored is None), req.session)
        return _Ack()

    def _write(self, req: Frame) -> _Ack:
        """"WriteFile": at or before the end, or held a little beyond it (no sparse files); the ACK echoes the offset."""
        session = self._write_session(req)
        end = req.offset + len(req.data)
        if end > self.max_file_bytes:
            session.poisoned = True
            raise _Nak(ErrorCode.FAIL_ERRNO, errno.EFBIG)
        size = len(session.data)
        ahead = req.offset > size
        if ahead and (req.offset - size > MAX_GAP_BYTES or len(session.held) >= MAX_HELD_BLOCKS):
            if not session.poisoned:
                self._announce(f"upload refused: {session.path}: a write at byte {req.offset}, beyond its end"
                               f" ({size} bytes); no sparse files")
            session.poisoned = True
            raise _Nak(ErrorCode.FAIL_ERRNO, errno.EINVAL)
        grows = len(req.data) if ahead else max(0, end - size)
        try:
            self._check_quota(session.path, extra_bytes=grows)
        except _Nak:
            session.poisoned = True
            raise
        if ahead:
            session.held[req.offset] = req.data
        else:
            session.put(req.offset, req.data)
        return _Ack()

    def _read(self, req: Frame) -> _Ack:
        """"ReadFile": up to ``size`` bytes (0 asks for a full packet) from ``offset``."""
        data = self._read_session(req).data
        if req.offset >= len(data):
            raise _Nak(ErrorCode.EOF)
        return _Ack(data[req.offset:req.offset + (req.size or MAX_DATA)])

    def _burst(self, req: Frame) -> _Ack:
        """"BurstReadFile": one packet per request, ``burst_complete`` set."""
        ack = self._read(req)
        return _Ack(ack.data, burst_complete=1)

    def discard(self, path: str) -> bool:
        """Forget a stored file (the executive removes a superseded forecast); False when there was none."""
        return self._drop_file(path)

    def _remove(self, req: Frame) -> _Ack:
        path = _path(req.data)
        if path in DIRECTORIES:
            raise _Nak(ErrorCode.FILE_PROTECTED)
        if not self._drop_file(path):
            raise _Nak(ErrorCode.FILE_NOT_FOUND)
        return _Ack()

    def _mkdir(self, req: Frame) -> _Ack:
        raise _Nak(ErrorCode.FILE_EXISTS if _path(req.data) in DIRECTORIES else ErrorCode.FILE_PROTECTED)

    def _crc(self, req: Frame) -> _Ack:
        stored = self._files.get(_path(req.data))
        if stored is None:
            raise _Nak(ErrorCode.FILE_NOT_FOUND)
        if stored.crc is None:
            stored.crc = ftp_crc32(stored.data)
        return _Ack(struct.pack("<I", stored.crc))

    def _list(self, req: Frame) -> _Ack:
        """"List Directory": entries from index ``offset``; NAK EOF past the last one."""
        path = _path(req.data)
        if path not in DIRECTORIES:
            raise _Nak(ErrorCode.FILE_NOT_FOUND)
        entries = self._entries(path)
        if req.offset >= len(entries):
            raise _Nak(ErrorCode.EOF)
        out = b""
        for entry in entries[req.offset:]:
            if len(entry) > MAX_DATA:
                entry = b"S\0"  # cannot be sent: "S(kip)"
            if len(out) + len(entry) > MAX_DATA:
                break
            out += entry
        return _Ack(out)

    def _entries(self, directory: str) -> list[bytes]:
        dirs = sorted(d for d in DIRECTORIES if d != directory and _parent(d) == directory)
        files = sorted(p for p in self._files if _parent(p) == directory)
        return ([b"D" + _name(d).encode() + b"\0" for d in dirs]
                + [b"F" + _name(p).encode() + b"\t%d\0" % len(self._files[p].data) for p in files])


# --- paths: "<path>" in data[] (NUL-terminated or not), absolute or relative to "/" ------------------

def _path(data: bytes) -> str:
    """The normalised absolute path; NAK Fail for names this file system cannot hold."""
    try:
        text = data.split(b"\0", 1)[0].decode("ascii")
    except UnicodeDecodeError:
        raise _Nak(ErrorCode.FAIL) from None
    parts = [p for p in text.split("/") if p not in ("", ".")]
    if any(p == ".." or not p.isprintable() for p in parts):
        raise _Nak(ErrorCode.FAIL)
    return "/" + "/".join(parts)


def _file_path(data: bytes) -> str:
    """A path where a file may be: not a directory, in one of the directories."""
    path = _path(data)
    if path in DIRECTORIES:
        raise _Nak(ErrorCode.FILE_PROTECTED)
    if _parent(path) not in DIRECTORIES:
        raise _Nak(ErrorCode.FILE_NOT_FOUND)  # "All parent directories must exist"
    return path


def _parent(path: str) -> str:
    return path.rsplit("/", 1)[0] or "/"


def _name(path: str) -> str:
    return path.rsplit("/", 1)[1]
