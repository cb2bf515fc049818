"""MAVLink FTP: the executive's server (executive/ftp.py) and the planner's uploader (planner/shore/ftp_client.py).

Over real UDP on 127.0.0.1 (ephemeral ports): the server runs behind a pymavlink
``udpin`` endpoint in a thread, as the executive's system 1 component 191; clients
are ``put_file`` and pymavlink's own ``MAVFTP``, directly or through a relay that
drops datagrams. The state machine is also driven directly, and fuzzed.
"""

from __future__ import annotations

import io
import logging
import os
import random
import re
import threading
import zlib
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavftp, mavutil  # noqa: E402

from executive.ftp import MAX_DATA, PAYLOAD_LEN, ErrorCode, Frame, FtpServer, Opcode, ftp_crc32  # noqa: E402
from planner.contract.errors import LrauvError  # noqa: E402
from planner.shore.ftp_client import FtpUploadError, put_file  # noqa: E402
from tests.support.udp_relay import LossyRelay, bound_socket  # noqa: E402

SYSTEM, COMPONENT = 1, 191


class Vehicle:
    """An FtpServer behind a real UDP pymavlink endpoint, answering in a thread until ``stop``."""

    def __init__(self, refuse: Callable[[str, bytes], str | None] = lambda path, data: None, **limits: Any) -> None:
        self.accepted: list[tuple[str, bytes]] = []
        self.refused: list[tuple[str, bytes]] = []
        self._refuse = refuse
        self.server = FtpServer(accept=self._accept, **limits)
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=SYSTEM, source_component=COMPONENT)
        self.port = self.conn.port.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _accept(self, path: str, data: bytes) -> str | None:
        reason = self._refuse(path, data)
        (self.accepted if reason is None else self.refused).append((path, data))
        return reason

    def _serve(self) -> None:
        while not self._stop.is_set():
            msg = self.conn.recv_match(type="FILE_TRANSFER_PROTOCOL", blocking=True, timeout=0.05)
            if msg is None or (msg.target_system, msg.target_component) != (SYSTEM, COMPONENT):
                continue
            reply = self.server.handle(bytes(msg.payload))
            if reply is not None:
                self.conn.mav.file_transfer_protocol_send(0, msg.get_srcSystem(), msg.get_srcComponent(), reply)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        assert not self._thread.is_alive()
        self.conn.close()


def _client(port: int, component: int = 190):  # type: ignore[no-untyped-def]
    return mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255, source_component=component)


def _mavftp(conn) -> mavftp.MAVFTP:  # type: ignore[no-untyped-def]
    """pymavlink's client with a short idle detection: cmd_crc and cmd_rm end on link silence."""
    ftp_settings = mavftp.MAVFTPSettings([
        ("debug", int, 0), ("pkt_loss_tx", int, 0), ("pkt_loss_rx", int, 0), ("max_backlog", int, 5),
        ("burst_read_size", int, 80), ("write_size", int, 80), ("write_qsize", int, 5),
        ("idle_detection_time", float, 0.4), ("read_retry_time", float, 0.2), ("retry_time", float, 0.5),
    ])
    return mavftp.MAVFTP(conn, target_system=SYSTEM, target_component=COMPONENT, settings=ftp_settings)


@pytest.fixture()
def vehicle() -> Iterator[Vehicle]:
    v = Vehicle()
    yield v
    v.stop()


def _refuse_all(path: str, data: bytes) -> str:
    return f"{path}: table checksum mismatch"


@pytest.fixture()
def refusing_vehicle() -> Iterator[Vehicle]:
    v = Vehicle(refuse=_refuse_all)
    yield v
    v.stop()


# --- over UDP ---------------------------------------------------------------------------------------

def test_put_file_uploads_100_kb(vehicle: Vehicle) -> None:
    blob = random.Random(1).randbytes(100_003)
    conn = _client(vehicle.port)
    try:
        put_file(conn, blob, "/tables/policy.bin", timeout_s=1.0)
    finally:
        conn.close()
    assert vehicle.accepted == [("/tables/policy.bin", blob)]
    assert vehicle.server.files["/tables/policy.bin"] == blob


def test_mavftp_put_get_list_crc(vehicle: Vehicle, tmp_path, caplog) -> None:  # type: ignore[no-untyped-def]
    blob = random.Random(2).randbytes(10_007)
    conn = _client(vehicle.port)
    try:
        ftp = _mavftp(conn)
        assert ftp.cmd_put(["policy.bin", "/tables/policy.bin"], fh=io.BytesIO(blob)).error_code == 0
        assert ftp.process_ftp_reply("put", timeout=10).error_code == mavftp.FtpError.Success
        assert vehicle.server.files["/tables/policy.bin"] == blob

        local = tmp_path / "back.bin"
        assert ftp.cmd_get(["/tables/policy.bin", str(local)]).error_code == 0
        assert ftp.process_ftp_reply("get", timeout=10).error_code == mavftp.FtpError.Success
        assert local.read_bytes() == blob

        listing = ftp.cmd_list(["/tables"])
        assert listing.error_code == mavftp.FtpError.Success
        assert [(e.name, e.is_dir, e.size_b) for e in listing.directory_listing] == [("policy.bin", False, len(blob))]

        with caplog.at_level(logging.INFO):
            assert ftp.cmd_crc(["/tables/policy.bin"]).error_code == mavftp.FtpError.Success
        crc = int(re.search(r"crc: /tables/policy.bin 0x([0-9a-f]{8})", caplog.text).group(1), 16)  # type: ignore[union-attr]
    finally:
        conn.close()
    assert crc == _crc_crc32(0, blob) == ftp_crc32(blob)
    assert crc != zlib.crc32(blob)  # initial value 0 and no final XOR: not the zlib/PNG CRC-32


def _crc_crc32(crc: int, buf: bytes) -> int:
    """ArduPilot's AP_Math crc_crc32 (called with crc = 0 by its FTP server), bit by bit."""
    for byte in buf:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0xEDB88320 if crc & 1 else 0)
    return crc


def test_refused_file_makes_put_file_raise(refusing_vehicle: Vehicle) -> None:
    conn = _client(refusing_vehicle.port)
    try:
        with pytest.raises(FtpUploadError, match=r"refused by the vehicle \(TerminateSession NAK Fail\)") as err:
            put_file(conn, b"not a table" * 100, "/tables/bad.bin", timeout_s=1.0)
    finally:
        conn.close()
    assert isinstance(err.value, LrauvError)
    assert "/tables/bad.bin" in str(err.value)
    assert [path for path, _ in refusing_vehicle.refused] == ["/tables/bad.bin"]
    assert "/tables/bad.bin" not in refusing_vehicle.server.files


def test_refused_file_is_reported_as_success_by_mavftp(refusing_vehicle: Vehicle) -> None:
    """MAVFTP (pymavlink 2.4.50) ignores the NAK to its TerminateSession: put succeeds, the file is not there."""
    conn = _client(refusing_vehicle.port)
    try:
        ftp = _mavftp(conn)
        ftp.cmd_put(["bad.bin", "/tables/bad.bin"], fh=io.BytesIO(b"x" * 1000))
        assert ftp.process_ftp_reply("put", timeout=10).error_code == mavftp.FtpError.Success  # cannot tell
        # what a MAVFTP user can do: look for the file afterwards
        assert ftp.cmd_crc(["/tables/bad.bin"]).error_code == mavftp.FtpError.FileNotFound
    finally:
        conn.close()
    assert [path for path, _ in refusing_vehicle.refused] == ["/tables/bad.bin"]
    assert refusing_vehicle.server.files == {}


def test_put_file_through_a_lossy_link(vehicle: Vehicle) -> None:
    blob = random.Random(3).randbytes(100_000)
    relay = LossyRelay(vehicle.port, drop=0.2, seed=4)
    conn = _client(relay.port)
    try:
        put_file(conn, blob, "/tables/lossy.bin", timeout_s=0.05, retries=40)
    finally:
        conn.close()
        relay.stop()
    assert relay.dropped > 50
    assert vehicle.accepted == [("/tables/lossy.bin", blob)]  # once: retransmitted terminates are not re-run
    assert vehicle.server.files["/tables/lossy.bin"] == blob


def _write_file(frame: bytes) -> bool:
    """A MAVLink 2 FILE_TRANSFER_PROTOCOL frame (id 110) whose FTP opcode (payload byte 6) is WriteFile (7)."""
    return len(frame) > 16 and frame[0] == 0xFD and frame[7:10] == bytes((110, 0, 0)) and frame[16] == 7


def test_mavftp_put_through_a_lossy_link_holds_blocks_that_arrive_early() -> None:
    """MAVFTP keeps 5 writes in flight: with datagrams lost, later blocks come first and wait for the gap."""
    announced: list[str] = []
    vehicle = Vehicle(announce=announced.append)  # type: ignore[arg-type]
    # Only WriteFile requests are lost: MAVFTP does not resend the TerminateSession that ends a put
    # (were it lost, the file would never be closed, whatever the server does).
    relay = LossyRelay(vehicle.port, drop=0.15, seed=6, droppable=_write_file)
    conn = _client(relay.port)
    blob = random.Random(7).randbytes(6000)
    try:
        ftp = _mavftp(conn)
        assert ftp.cmd_put(["lossy.bin", "/tables/lossy.bin"], fh=io.BytesIO(blob)).error_code == 0
        assert ftp.process_ftp_reply("put", timeout=30).error_code == mavftp.FtpError.Success
    finally:
        conn.close()
        relay.stop()
        vehicle.stop()
    assert relay.dropped > 0 and announced == []
    assert vehicle.accepted == [("/tables/lossy.bin", blob)]


def test_put_file_beyond_the_quota_is_refused_by_the_vehicle() -> None:
    announced: list[str] = []
    vehicle = Vehicle(max_files=1, announce=announced.append)  # type: ignore[arg-type]
    conn = _client(vehicle.port)
    try:
        put_file(conn, b"a" * 1000, "/tables/a.bin", timeout_s=1.0)
        with pytest.raises(FtpUploadError, match="FailErrno") as err:
            put_file(conn, b"b" * 1000, "/forecasts/b.nc", timeout_s=1.0)
    finally:
        conn.close()
        vehicle.stop()
    assert "/forecasts/b.nc" in str(err.value)
    assert dict(vehicle.server.files) == {"/tables/a.bin": b"a" * 1000}
    assert len(announced) == 1 and announced[0].startswith("upload quota full: /forecasts/b.nc refused")


def test_put_file_ignores_replies_to_another_client(vehicle: Vehicle) -> None:
    """Two clients on one vehicle: udpin sends every reply to both; each keeps to its own."""
    first, second = _client(vehicle.port, component=190), _client(vehicle.port, component=191)
    try:
        put_file(first, b"a" * 5000, "/tables/a.bin", timeout_s=1.0)
        put_file(second, b"b" * 5000, "/tables/b.bin", timeout_s=1.0)
        put_file(first, b"c" * 3000, "/tables/a.bin", timeout_s=1.0)  # replaces a.bin
    finally:
        first.close()
        second.close()
    assert dict(vehicle.server.files) == {"/tables/a.bin": b"c" * 3000, "/tables/b.bin": b"b" * 5000}


def test_put_file_times_out_without_a_vehicle() -> None:
    silent = bound_socket()
    conn = _client(silent.getsockname()[1])
    try:
        with pytest.raises(FtpUploadError, match="no reply from system 1 component 191 to CREATE_FILE after 3 tries"):
            put_file(conn, b"x", "/tables/x.bin", timeout_s=0.05, retries=2)
    finally:
        conn.close()
        silent.close()


# --- the state machine, directly ------------------------------------------------------------------------

def _req(seq: int, opcode: int, *, session: int = 0, offset: int = 0, data: bytes = b"", size: int | None = None) -> bytes:
    return Frame(seq, session, opcode, len(data) if size is None else size, 0, 0, offset, data).pack()


def _reply(server: FtpServer, payload: bytes) -> Frame:
    raw = server.handle(payload)
    assert raw is not None and len(raw) == PAYLOAD_LEN
    return Frame.parse(raw)


def _nak(frame: Frame) -> ErrorCode:
    assert frame.opcode == Opcode.NAK, frame
    return ErrorCode(frame.data[0])


def test_upload_out_of_order_with_retransmissions() -> None:
    seen: list[tuple[str, bytes]] = []
    server = FtpServer(accept=lambda path, data: seen.append((path, data)))  # type: ignore[func-returns-value]
    create = _req(10, Opcode.CREATE_FILE, session=5, data=b"/tables/t.bin")
    ack = _reply(server, create)
    assert (ack.opcode, ack.seq, ack.req_opcode, ack.size) == (Opcode.ACK, 11, Opcode.CREATE_FILE, 0)
    assert ack.session == 5  # the client's own session id, echoed (ArduPilot; MAVProxy routes replies by it)
    assert _reply(server, create) == ack  # the reply was lost: the same reply again, from the cache
    assert _reply(server, _req(11, Opcode.WRITE_FILE, session=5, data=b"stale")).opcode == Opcode.ACK
    # A new CreateFile of the path (not a resend) gets its own session and supersedes the open upload.
    again = _reply(server, _req(99, Opcode.CREATE_FILE, session=6, data=b"/tables/t.bin\0"))
    assert (again.opcode, again.session) == (Opcode.ACK, 6)
    assert _nak(_reply(server, _req(98, Opcode.WRITE_FILE, session=5, data=b"x"))) == ErrorCode.INVALID_SESSION
    sid = again.session
    # The first block was lost: the next two arrive first and are held, not zero-filled.
    w3 = _req(12, Opcode.WRITE_FILE, session=sid, offset=2 * MAX_DATA, data=b"C" * 10)
    assert _reply(server, w3).offset == 2 * MAX_DATA  # MAVFTP finds the block by the echoed offset
    assert _reply(server, w3).opcode == Opcode.ACK  # resent: harmless
    assert _reply(server, _req(13, Opcode.WRITE_FILE, session=sid, offset=MAX_DATA, data=b"B" * MAX_DATA)).opcode \
        == Opcode.ACK
    assert _reply(server, _req(14, Opcode.WRITE_FILE, session=sid, offset=0, data=b"A" * MAX_DATA)).opcode == Opcode.ACK
    terminate = _req(15, Opcode.TERMINATE_SESSION, session=sid)
    assert _reply(server, terminate).opcode == Opcode.ACK
    assert _reply(server, terminate).opcode == Opcode.ACK  # resent after a lost ACK: same verdict
    expected = b"A" * MAX_DATA + b"B" * MAX_DATA + b"C" * 10
    assert seen == [("/tables/t.bin", expected)] and server.files == {"/tables/t.bin": expected}
    other = _req(16, Opcode.TERMINATE_SESSION, session=sid)  # a new request for the closed session
    assert _nak(_reply(server, other)) == ErrorCode.INVALID_SESSION


def test_no_sparse_files_a_write_far_beyond_the_end_is_refused() -> None:
    """A 1-byte write at a large offset once made a file of that size (zero-filled); now it is NAKed EINVAL."""
    seen: list[str] = []
    announced: list[str] = []
    server = FtpServer(accept=lambda path, data: seen.append(path), announce=announced.append)  # type: ignore[func-returns-value]
    sid = _reply(server, _req(0, Opcode.CREATE_FILE, session=1, data=b"/forecasts/big.nc")).session
    far = _reply(server, _req(1, Opcode.WRITE_FILE, session=sid, offset=60_000_000, data=b"x"))
    assert (_nak(far), far.data[1]) == (ErrorCode.FAIL_ERRNO, 22)  # EINVAL
    assert announced == [("upload refused: /forecasts/big.nc: a write at byte 60000000, beyond its end (0 bytes);"
                          " no sparse files")]
    assert _nak(_reply(server, _req(2, Opcode.TERMINATE_SESSION, session=sid))) == ErrorCode.FAIL  # poisoned
    assert seen == [] and server.files == {}
    # A gap that is never written: the blocks beyond it are held (their own bytes), and the file is refused.
    sid = _reply(server, _req(3, Opcode.CREATE_FILE, session=2, data=b"/forecasts/gap.nc")).session
    assert _reply(server, _req(4, Opcode.WRITE_FILE, session=sid, data=b"a" * 10)).opcode == Opcode.ACK
    assert _reply(server, _req(5, Opcode.WRITE_FILE, session=sid, offset=500, data=b"b" * 10)).opcode == Opcode.ACK
    assert _nak(_reply(server, _req(6, Opcode.TERMINATE_SESSION, session=sid))) == ErrorCode.FAIL
    assert seen == [] and server.files == {}


def test_the_quota_refuses_files_beyond_its_count_and_announces_once() -> None:
    announced: list[str] = []
    server = FtpServer(accept=lambda path, data: None, max_files=2, max_sessions=2, announce=announced.append)
    # The client picks the session id and the reply echoes it (ArduPilot; MAVProxy routes replies by it).
    sessions = [_reply(server, _req(i, Opcode.CREATE_FILE, session=40 + i, data=b"/tables/f%d" % i)).session
                for i in range(2)]
    assert sessions == [40, 41]
    for i, sid in enumerate(sessions, start=11):
        assert _reply(server, _req(i, Opcode.TERMINATE_SESSION, session=sid)).opcode == Opcode.ACK
    # A third file: refused (FailErrno ENOSPC), the stored files kept, the refusal announced once.
    for seq in (20, 21):
        full = _reply(server, _req(seq, Opcode.CREATE_FILE, session=50, data=b"/tables/f%d" % seq))
        assert (_nak(full), full.data[1]) == (ErrorCode.FAIL_ERRNO, 28)
    assert list(server.files) == ["/tables/f0", "/tables/f1"]
    assert len(announced) == 1 and announced[0].startswith("upload quota full: /tables/f20 refused; 2 files")
    assert _reply(server, _req(22, Opcode.CREATE_FILE, session=51, data=b"/tables/f1")).opcode == Opcode.ACK  # replacing
    assert _reply(server, _req(23, Opcode.TERMINATE_SESSION, session=51)).opcode == Opcode.ACK
    # Room made by RemoveFile: a new file fits, and the next refusal is announced again.
    assert _reply(server, _req(24, Opcode.REMOVE_FILE, data=b"/tables/f0")).opcode == Opcode.ACK
    assert _reply(server, _req(25, Opcode.CREATE_FILE, session=52, data=b"/tables/f9")).opcode == Opcode.ACK
    assert _nak(_reply(server, _req(26, Opcode.CREATE_FILE, session=53, data=b"/tables/f8"))) == ErrorCode.FAIL_ERRNO
    assert len(announced) == 2


def test_refusal_write_limits_and_reset() -> None:
    server = FtpServer(accept=lambda path, data: None if data.startswith(b"OK") else "bad magic", max_file_bytes=1000)
    sid = _reply(server, _req(0, Opcode.CREATE_FILE, data=b"/tables/a")).session
    _reply(server, _req(1, Opcode.WRITE_FILE, session=sid, data=b"NO"))
    assert _nak(_reply(server, _req(2, Opcode.TERMINATE_SESSION, session=sid))) == ErrorCode.FAIL
    assert "/tables/a" not in server.files

    sid = _reply(server, _req(3, Opcode.CREATE_FILE, data=b"/tables/a")).session
    _reply(server, _req(4, Opcode.WRITE_FILE, session=sid, data=b"OK"))
    too_far = _reply(server, _req(5, Opcode.WRITE_FILE, session=sid, offset=999, data=b"xy"))
    assert (_nak(too_far), too_far.data[1], too_far.size) == (ErrorCode.FAIL_ERRNO, 27, 2)  # EFBIG
    assert _nak(_reply(server, _req(6, Opcode.TERMINATE_SESSION, session=sid))) == ErrorCode.FAIL  # poisoned
    assert "/tables/a" not in server.files

    sid = _reply(server, _req(7, Opcode.CREATE_FILE, data=b"a")).session  # relative to "/"
    _reply(server, _req(8, Opcode.WRITE_FILE, session=sid, data=b"OK!"))
    assert _reply(server, _req(9, Opcode.RESET_SESSIONS)).opcode == Opcode.ACK  # closes the upload: PX4/QGC style
    assert server.files == {"/a": b"OK!"}


def test_the_quota_bytes_cover_open_uploads_and_stored_files() -> None:
    accepted: list[str] = []
    announced: list[str] = []
    server = FtpServer(accept=lambda path, data: accepted.append(path), max_file_bytes=800,  # type: ignore[func-returns-value]
                       max_total_bytes=1000, max_sessions=3, announce=announced.append)

    def store(seq: int, sid: int, path: bytes, size: int) -> None:
        assert _reply(server, _req(seq, Opcode.CREATE_FILE, session=sid, data=path)).opcode == Opcode.ACK
        assert _reply(server, _req(seq + 1, Opcode.WRITE_FILE, session=sid, data=b"s" * size)).opcode == Opcode.ACK
        assert _reply(server, _req(seq + 2, Opcode.TERMINATE_SESSION, session=sid)).opcode == Opcode.ACK

    store(0, 1, b"/tables/a", 200)
    store(3, 1, b"/tables/b", 200)
    assert _reply(server, _req(9, Opcode.OPEN_FILE_RO, session=2, data=b"/tables/a")).opcode == Opcode.ACK
    # An upload grows up to the quota (400 stored + 600), never by dropping a stored file.
    assert _reply(server, _req(10, Opcode.CREATE_FILE, session=3, data=b"/tables/big")).opcode == Opcode.ACK
    assert _reply(server, _req(11, Opcode.WRITE_FILE, session=3, offset=0, data=b"x" * 239)).opcode == Opcode.ACK
    assert _reply(server, _req(12, Opcode.WRITE_FILE, session=3, offset=239, data=b"y" * 239)).opcode == Opcode.ACK
    full = _reply(server, _req(13, Opcode.WRITE_FILE, session=3, offset=478, data=b"z" * 239))
    assert (_nak(full), full.data[1]) == (ErrorCode.FAIL_ERRNO, 28)  # ENOSPC: 400 + 717 bytes > 1000
    assert list(server.files) == ["/tables/a", "/tables/b"]  # nothing evicted
    assert _reply(server, _req(14, Opcode.READ_FILE, session=2)).opcode == Opcode.ACK  # the read goes on
    assert _nak(_reply(server, _req(15, Opcode.TERMINATE_SESSION, session=3))) == ErrorCode.FAIL  # poisoned
    assert len(announced) == 1 and "1.0 MB" not in announced[0] and "0.0 MB" in announced[0]
    # OpenFileWO copies the stored file into the upload: the copy counts too.
    assert _reply(server, _req(16, Opcode.OPEN_FILE_WO, session=4, data=b"/tables/a")).opcode == Opcode.ACK
    assert _reply(server, _req(17, Opcode.CREATE_FILE, session=5, data=b"/tables/e")).opcode == Opcode.ACK
    assert _reply(server, _req(18, Opcode.WRITE_FILE, session=5, data=b"e" * 239)).opcode == Opcode.ACK
    assert _nak(_reply(server, _req(19, Opcode.WRITE_FILE, session=5, offset=239, data=b"e" * 239))) == \
        ErrorCode.FAIL_ERRNO  # 400 stored + 200 copy + 478 > 1000
    # The executive removes a superseded file: room again.
    assert server.discard("/tables/b") and not server.discard("/tables/b")
    assert _reply(server, _req(20, Opcode.CREATE_FILE, session=6, data=b"/tables/f")).opcode == Opcode.ACK
    assert _reply(server, _req(21, Opcode.WRITE_FILE, session=6, data=b"f" * 239)).opcode == Opcode.ACK
    assert accepted == ["/tables/a", "/tables/b"]


def test_crc_is_computed_once_per_stored_file(monkeypatch: pytest.MonkeyPatch) -> None:
    import executive.ftp as ftp_module

    calls: list[int] = []

    def counting_crc(data: bytes) -> int:
        calls.append(len(data))
        return ftp_crc32(data)

    monkeypatch.setattr(ftp_module, "ftp_crc32", counting_crc)
    server = FtpServer(accept=lambda path, data: None)
    for seq, payload in ((0, b"123456789"), (10, b"12345")):
        _reply(server, _req(seq, Opcode.CREATE_FILE, data=b"/tables/t"))
        _reply(server, _req(seq + 1, Opcode.WRITE_FILE, data=payload))
        _reply(server, _req(seq + 2, Opcode.TERMINATE_SESSION))
        for n in range(3):
            crc = _reply(server, _req(seq + 3 + n, Opcode.CALC_FILE_CRC32, data=b"/tables/t"))
            assert int.from_bytes(crc.data, "little") == _crc_crc32(0, payload)
    assert calls == [9, 5]  # once per stored version, however often asked


def test_read_list_crc_and_refusals() -> None:
    server = FtpServer(accept=lambda path, data: None)
    sid = _reply(server, _req(0, Opcode.CREATE_FILE, data=b"/tables/t")).session
    _reply(server, _req(1, Opcode.WRITE_FILE, session=sid, data=b"123456789"))
    _reply(server, _req(2, Opcode.TERMINATE_SESSION, session=sid))

    crc = _reply(server, _req(3, Opcode.CALC_FILE_CRC32, data=b"/tables/t"))
    assert int.from_bytes(crc.data, "little") == _crc_crc32(0, b"123456789") == 0x2DFD2D88
    opened = _reply(server, _req(4, Opcode.OPEN_FILE_RO, data=b"/tables/t"))
    assert (opened.size, int.from_bytes(opened.data, "little")) == (4, 9)
    read = _reply(server, _req(5, Opcode.READ_FILE, session=opened.session, offset=2, size=4))
    assert (read.data, read.offset) == (b"3456", 2)
    burst = _reply(server, _req(6, Opcode.BURST_READ_FILE, session=opened.session, offset=5, size=80))
    assert (burst.data, burst.burst_complete) == (b"6789", 1)
    assert _nak(_reply(server, _req(7, Opcode.READ_FILE, session=opened.session, offset=9))) == ErrorCode.EOF
    assert _nak(_reply(server, _req(8, Opcode.WRITE_FILE, session=opened.session, data=b"x"))) == ErrorCode.INVALID_SESSION

    assert _reply(server, _req(9, Opcode.LIST_DIRECTORY, data=b"/")).data == b"Dforecasts\0Dtables\0"
    assert _reply(server, _req(10, Opcode.LIST_DIRECTORY, data=b"/tables/")).data == b"Ft\t9\0"
    assert _nak(_reply(server, _req(11, Opcode.LIST_DIRECTORY, offset=1, data=b"/tables"))) == ErrorCode.EOF
    assert _nak(_reply(server, _req(12, Opcode.LIST_DIRECTORY, data=b"/nope"))) == ErrorCode.FILE_NOT_FOUND
    assert _nak(_reply(server, _req(13, Opcode.CREATE_FILE, data=b"/nope/x"))) == ErrorCode.FILE_NOT_FOUND
    assert _nak(_reply(server, _req(14, Opcode.CREATE_FILE, data=b"/tables/../x"))) == ErrorCode.FAIL
    assert _nak(_reply(server, _req(15, Opcode.CREATE_DIRECTORY, data=b"/tables"))) == ErrorCode.FILE_EXISTS
    assert _nak(_reply(server, _req(16, Opcode.CREATE_DIRECTORY, data=b"/new"))) == ErrorCode.FILE_PROTECTED
    assert _nak(_reply(server, _req(17, Opcode.TRUNCATE_FILE, data=b"/tables/t"))) == ErrorCode.UNKNOWN_COMMAND
    assert _nak(_reply(server, _req(18, Opcode.OPEN_FILE_RO, data=b"/tables/u"))) == ErrorCode.FILE_NOT_FOUND
    assert _reply(server, _req(19, Opcode.REMOVE_FILE, data=b"/tables/t")).opcode == Opcode.ACK
    assert _nak(_reply(server, _req(20, Opcode.REMOVE_FILE, data=b"/tables/t"))) == ErrorCode.FILE_NOT_FOUND
    assert _nak(_reply(server, _req(21, Opcode.WRITE_FILE, size=240))) == ErrorCode.INVALID_DATA_SIZE
    assert _reply(server, _req(65535, Opcode.NONE)).seq == 0  # seq wraps
    assert server.handle(_req(22, Opcode.ACK)) is None and server.handle(_req(23, Opcode.NAK)) is None


# --- fuzz -----------------------------------------------------------------------------------------------

def _check(server: FtpServer, payload: bytes) -> None:
    raw = server.handle(payload)
    request = Frame.parse(payload)
    if raw is None:
        assert request.opcode in (Opcode.ACK, Opcode.NAK)
        return
    reply = Frame.parse(raw)
    assert len(raw) == PAYLOAD_LEN and reply.opcode in (Opcode.ACK, Opcode.NAK)
    assert (reply.seq, reply.req_opcode) == ((request.seq + 1) & 0xFFFF, request.opcode)
    assert reply.size <= MAX_DATA and (reply.opcode == Opcode.ACK or reply.size in (1, 2))


def test_unknown_opcodes_get_nak_unknown_command() -> None:
    server = FtpServer(accept=lambda path, data: None)
    for opcode in [*range(16, 128), *range(130, 256), Opcode.REMOVE_DIRECTORY, Opcode.RENAME]:
        reply = _reply(server, _req(opcode, opcode, session=3))
        assert (_nak(reply), reply.req_opcode, reply.session, reply.size) == (ErrorCode.UNKNOWN_COMMAND, opcode, 3, 1)


@settings(max_examples=1500, deadline=None)
@given(st.binary(max_size=300))
def test_fuzz_random_payloads_never_raise(payload: bytes) -> None:
    _check(_FUZZ_SERVER, payload)


_FUZZ_SERVER = FtpServer(accept=lambda path, data: None if len(data) % 2 else "odd", max_file_bytes=4096)


def test_fuzz_mutated_requests_never_raise() -> None:
    """Requests of every opcode on the sessions the server handed out, then bit-flipped, truncated or grown."""
    rng = random.Random(8)
    server = FtpServer(accept=lambda path, data: "no" if data[:1] == b"R" else None, max_file_bytes=2048,
                       max_sessions=3)
    sid = _reply(server, _req(60000, Opcode.CREATE_FILE, data=b"/tables/a")).session
    _reply(server, _req(60001, Opcode.WRITE_FILE, session=sid, data=bytes(range(200))))
    _reply(server, _req(60002, Opcode.TERMINATE_SESSION, session=sid))
    paths = [b"/tables/a", b"/tables/b", b"a", b"/", b"/tables", b"/x/y", b"\xff", b"/tables/a\0junk"]
    sessions = [sid]
    acked: set[int] = set()
    for i in range(4000):
        opcode = rng.choice([*range(0, 16), Opcode.WRITE_FILE, Opcode.READ_FILE, Opcode.BURST_READ_FILE, 200])
        data = rng.choice(paths) if rng.random() < 0.6 else rng.randbytes(rng.randrange(0, MAX_DATA + 1))
        payload = bytearray(_req(i & 0xFFFF, opcode, session=sessions[-1] if rng.random() < 0.7 else rng.choice(sessions[-4:] + [rng.randrange(256)]),
                                 offset=rng.choice([0, rng.randrange(256), rng.randrange(2100), 2**32 - 1]), data=data,
                                 size=None if rng.random() < 0.8 else rng.choice([0, 239, 240, 255])))
        mutation = rng.randrange(6)
        if mutation == 0:
            for _ in range(rng.randrange(1, 8)):
                payload[rng.randrange(len(payload))] ^= 1 << rng.randrange(8)
        elif mutation == 1:
            payload = payload[:rng.randrange(len(payload))]
        elif mutation == 2:
            payload += rng.randbytes(rng.randrange(1, 20))
        _check(server, bytes(payload))
        reply = Frame.parse(server.handle(bytes(payload)) or b"")  # a resend: answered from the cache
        if reply.opcode == Opcode.ACK:
            acked.add(reply.req_opcode)
            if reply.req_opcode in (Opcode.CREATE_FILE, Opcode.OPEN_FILE_WO, Opcode.OPEN_FILE_RO):
                sessions.append(reply.session)
    assert acked >= {Opcode.CREATE_FILE, Opcode.WRITE_FILE, Opcode.TERMINATE_SESSION, Opcode.OPEN_FILE_RO,
                     Opcode.READ_FILE, Opcode.BURST_READ_FILE, Opcode.LIST_DIRECTORY, Opcode.CALC_FILE_CRC32}
    assert server.handle(b"") is not None  # all zeros: opcode None, ACKed
