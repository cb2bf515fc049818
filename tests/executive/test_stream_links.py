"""The autopilot link over TCP: read in whole buffers, and the other end's close is a lost link at once.

A plain TCP socket on 127.0.0.1 plays ArduSub SITL's SERIAL0 (``tcp:127.0.0.1:5760``) or its
client; the executive runs in a thread with no table. The executive's own socket is wrapped in
a thin counter (every call goes to the real socket) to see how it is read.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from executive.loop import ExecConfig, Executive  # noqa: E402
from executive.recorder import read_messages  # noqa: E402
from executive.state import Phase  # noqa: E402
from tests.executive.test_links import Running  # noqa: E402
from tests.support.ardusub_streams import frames, message  # noqa: E402
from tests.support.helpers import wait_until  # noqa: E402

LINK_LOSS_TIMEOUT_S = 30.0  # HelmConfig's default


class CountingSocket:
    """The executive's real socket, counting the calls to ``recv`` that returned data and their bytes."""

    def __init__(self, sock: socket.socket) -> None:
        self._sock = sock
        self.calls = 0
        self.bytes = 0

    def recv(self, n: int, *flags: int) -> bytes:
        data = self._sock.recv(n, *flags)
        self.calls += 1
        self.bytes += len(data)
        return data

    def __getattr__(self, name: str) -> object:
        return getattr(self._sock, name)


def _server() -> socket.socket:
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    return server


def _logs(path: Path) -> list[tuple[float, str]]:
    return [(t, p["message"]) for _, t, p in read_messages(path, ["/log"])]


def test_a_tcp_link_is_read_in_whole_buffers(tmp_path: Path):
    """A minute of ArduSub's default telemetry arrives at once (a simulator at 60x): a few reads take it all.

    pymavlink's ``recv()`` reads 8 bytes per call between frames: thousands of calls for this.
    """
    server = _server()
    run = None
    try:
        ex = Executive(ExecConfig(link=f"tcp:127.0.0.1:{server.getsockname()[1]}", log_path=tmp_path / "t.mcap"), None)
        peer, _ = server.accept()
        counting = ex.conn.port = CountingSocket(ex.conn.port)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        sent = list(frames(mav, 50_000, 60.0))
        blob = b"".join(frame for _, frame in sent)
        run = Running(ex)
        peer.sendall(blob)
        last_s = sent[-1][0] / 1000.0
        assert wait_until(lambda: ex.clock.last_s == last_s and ex._counts["in"] == len(sent), 20), \
            (ex.clock.last_s, ex._counts["in"], len(sent))
    finally:
        if run is not None:
            run.stop()
        server.close()
    assert counting.bytes == len(blob) and ex._counts["bad"] == 0  # every frame, none cut at a buffer's edge
    print(f"\n{len(sent)} frames, {len(blob)} bytes in {counting.calls} reads")
    assert counting.calls <= len(blob) // 4096, counting.calls  # whole buffers: 8 bytes a call would be ~30,000


def test_the_other_ends_close_is_a_lost_link_at_once(tmp_path: Path):
    """The autopilot's side closes the TCP connection: link lost now, not after link_loss_timeout_s of silence."""
    server = _server()
    log = tmp_path / "c.mcap"
    run = Running(ExecConfig(link=f"tcp:127.0.0.1:{server.getsockname()[1]}", log_path=log))
    ex = run.executive
    try:
        peer, _ = server.accept()
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        peer.sendall(message("HEARTBEAT", 0).pack(mav) + message("GLOBAL_POSITION_INT", 10_000).pack(mav))  # type: ignore[attr-defined]
        assert wait_until(lambda: ex.vehicle.time_s == 10.0 and ex.helm.phase is not Phase.WAIT_LINK, 10)
        peer.close()
        assert wait_until(lambda: ex.helm.phase is Phase.LINK_LOST, 10), ex.helm.phase
    finally:
        run.stop()
        server.close()
    logs = _logs(log)
    closed = [t for t, m in logs if m.startswith("autopilot link closed by the other end")]
    lost = [t for t, m in logs if m.startswith("link lost")]
    assert len(closed) == 1 and len(lost) == 1, logs
    assert lost[0] - 10.0 < LINK_LOSS_TIMEOUT_S  # before any silence could have counted


def test_a_listening_tcp_link_takes_the_next_client_after_a_close(tmp_path: Path):
    """``tcpin:``: the client's close is a lost link at once; a new client is read, and the link is regained."""
    log = tmp_path / "l.mcap"
    run = Running(ExecConfig(link="tcpin:127.0.0.1:0", log_path=log))
    ex = run.executive
    address = ex.conn.listen.getsockname()
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    try:
        for n, time_ms in enumerate((10_000, 20_000)):
            client = socket.create_connection(address)
            try:
                client.sendall(message("HEARTBEAT", 0).pack(mav)  # type: ignore[attr-defined]
                               + message("GLOBAL_POSITION_INT", time_ms).pack(mav))  # type: ignore[attr-defined]
                assert wait_until(lambda t=time_ms: ex.vehicle.time_s == t / 1000.0, 10), (n, ex.vehicle)
                assert wait_until(lambda: ex.helm.phase not in (Phase.WAIT_LINK, Phase.LINK_LOST), 10), ex.helm.phase
            finally:
                client.close()
            assert wait_until(lambda: ex.helm.phase is Phase.LINK_LOST, 10), (n, ex.helm.phase)
    finally:
        run.stop()
    messages = [m for _, m in _logs(log)]
    assert sum(m.startswith("autopilot link closed by the other end") for m in messages) == 2, messages
    assert any(m.startswith("link regained") for m in messages), messages


def test_a_serial_link_is_read_in_whole_buffers(tmp_path: Path):
    """A companion computer's serial port to the autopilot (``DEVICE,BAUD``), here a pseudo-terminal: a minute of
    ArduSub's default telemetry written at once is read in whole buffers and every frame parsed."""
    import termios
    import tty

    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    run = None
    try:
        ex = Executive(ExecConfig(link=f"{os.ttyname(slave)},921600", log_path=tmp_path / "s.mcap"), None)
        counting = ex.conn.port = CountingPort(ex.conn.port)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        sent = list(frames(mav, 50_000, 60.0))
        run = Running(ex)
        for _, frame in sent:
            os.write(master, frame)
        termios.tcdrain(master)
        last_s = sent[-1][0] / 1000.0
        assert wait_until(lambda: ex.clock.last_s == last_s and ex._counts["in"] == len(sent), 30), \
            (ex.clock.last_s, ex._counts["in"], len(sent))
    finally:
        if run is not None:
            run.stop()
        os.close(master)
        os.close(slave)
    assert ex._counts["bad"] == 0
    assert counting.calls < len(sent) // 4, counting.calls  # pymavlink's own recv() reads one frame's bytes a call


class CountingPort:
    """The executive's real serial port (pyserial), counting the reads that returned data."""

    def __init__(self, port: object) -> None:
        self._port = port
        self.calls = 0

    def read(self, n: int = 1) -> bytes:
        data = self._port.read(n)  # type: ignore[attr-defined]
        self.calls += bool(data)
        return data

    def __getattr__(self, name: str) -> object:
        return getattr(self._port, name)


def test_a_bad_serial_link_is_one_clear_line(demo_plan, tmp_path: Path, capsys):
    from planner.cli import main as lrauv

    table = str(demo_plan.table.save(tmp_path / "t.lrpt"))
    assert lrauv(["exec", "--table", table, "--link", "/dev/no-such-autopilot,57600", "--log", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lrauv: error: --link '/dev/no-such-autopilot,57600': cannot open the serial device") and \
        len(err.splitlines()) == 1, err
    assert lrauv(["exec", "--table", table, "--link", "/dev/ttyS0,fast", "--log", str(tmp_path / "y.mcap")]) == 2
    assert "expected a serial DEVICE,BAUD with a whole baud rate" in capsys.readouterr().err


@pytest.mark.parametrize(("flag", "address", "words"), [
    ("--link", "bogus:foo", "--link 'bogus:foo': cannot open it (invalid literal"),
    ("--link", "udpout:127.0.0.1", "--link 'udpout:127.0.0.1': expected udpout:HOST:PORT, a port 0..65535"),
    ("--link", "udpout:127.0.0.1:99999", "--link 'udpout:127.0.0.1:99999': expected udpout:HOST:PORT"),
    ("--link", "udpout:999.1.1.1:14550", "--link 'udpout:999.1.1.1:14550': the host 999.1.1.1 is not an IPv4 address"),
    ("--link", "udpout::14550", "--link 'udpout::14550': expected udpout:HOST:PORT"),
    ("--gcs", "udpin:0.0.0.0:notaport", "--gcs 'udpin:0.0.0.0:notaport': expected udpin:HOST:PORT"),
])
def test_a_bad_network_link_is_one_clear_line(demo_plan, tmp_path: Path, capsys, flag, address, words):
    from planner.cli import main as lrauv

    table = str(demo_plan.table.save(tmp_path / "t.lrpt"))
    link = ["--link", "udpin:127.0.0.1:0"] if flag == "--gcs" else []
    assert lrauv(["exec", "--table", table, *link, flag, address, "--log", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"lrauv: error: {words}") and len(err.splitlines()) == 1, err


def test_a_bad_upload_address_is_one_clear_line(tmp_path: Path, capsys):
    from planner.cli import main as lrauv
    from tests.support.helpers import DEMO_MISSION

    # No table: the goal would be planned on shore first, if the address were not checked before that.
    assert lrauv(["upload", str(DEMO_MISSION), "--to", "udpout:localhost", "--forecast", str(tmp_path / "none.nc")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "lrauv: error: --to 'udpout:localhost': expected udpout:HOST:PORT, a port 0..65535 " \
                  "(e.g. udpout:127.0.0.1:14550)", err


def test_a_listening_link_without_a_host_listens_on_every_interface():
    from executive.mavlink_bridge import open_link

    conn = open_link("udpin::0", source_system=1, source_component=191)
    try:
        assert conn.port.getsockname()[0] == "0.0.0.0"
    finally:
        conn.close()
