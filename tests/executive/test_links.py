"""The executive's links over real UDP: locked to the autopilot's address; ground stations time out.

Plain sockets on 127.0.0.1 play the autopilot, a rogue on another port, and ground stations;
the executive runs in a thread (``Executive.run``) with no table (it only has to listen).
"""

from __future__ import annotations

import os
import socket
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from executive.loop import ExecConfig, Executive  # noqa: E402
from executive.recorder import read_messages  # noqa: E402
from tests.support.helpers import wait_until  # noqa: E402

AUTOPILOT = (1, 1)
GCS = (255, 190)


class Endpoint:
    """A UDP socket that speaks MAVLink 2 as ``source`` and parses what it receives."""

    def __init__(self, source: tuple[int, int]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.mav = mavlink.MAVLink(None, srcSystem=source[0], srcComponent=source[1])
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self.peer: tuple[str, int] | None = None
        self.got: list[object] = []

    def send(self, msg: object, to: tuple[str, int] | None = None) -> None:
        target = to or self.peer
        assert target is not None
        self.sock.sendto(msg.pack(self.mav), target)  # type: ignore[attr-defined]

    def read(self) -> list[object]:
        """Everything waiting now; remembers the last sender as ``peer``."""
        new = []
        while True:
            try:
                data, self.peer = self.sock.recvfrom(65535)
            except BlockingIOError:
                break
            new += [m for m in (self.parser.parse_buffer(data) or []) if m.get_msgId() >= 0]
        self.got += new
        return new

    def of(self, kind: str) -> list[object]:
        return [m for m in self.got if m.get_type() == kind]  # type: ignore[attr-defined]

    def close(self) -> None:
        self.sock.close()


class Running:
    """An executive (given, or made with no table) in a thread; ``stop`` ends it and closes its links."""

    def __init__(self, config: ExecConfig | Executive) -> None:
        self.executive = config if isinstance(config, Executive) else Executive(config, None)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self.executive.run, args=(self._stop,), daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10)
        assert not self._thread.is_alive()


def _position(mav: mavlink.MAVLink, time_boot_ms: int, lat_deg: float, lon_deg: float) -> object:
    return mav.global_position_int_encode(time_boot_ms, round(lat_deg * 1e7), round(lon_deg * 1e7), -2000, -2000,
                                          0, 0, 0, 9000)


def _heartbeat(mav: mavlink.MAVLink) -> object:
    return mav.heartbeat_encode(mavlink.MAV_TYPE_SUBMARINE, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 19, mavlink.MAV_STATE_STANDBY)


def test_the_autopilot_link_locks_to_the_autopilots_address(tmp_path: Path):
    autopilot, rogue = Endpoint(AUTOPILOT), Endpoint(AUTOPILOT)  # the rogue claims system 1 too
    run = Running(ExecConfig(link=f"udpout:127.0.0.1:{autopilot.port}", log_path=tmp_path / "x.mcap"))
    ex = run.executive
    try:
        assert wait_until(lambda: autopilot.read() is not None and autopilot.peer is not None, 10)
        exec_addr = autopilot.peer
        autopilot.send(_heartbeat(autopilot.mav))
        autopilot.send(autopilot.mav.ekf_status_report_encode(mavlink.EKF_POS_HORIZ_ABS, 0, 0, 0, 0, 0))  # positions used
        autopilot.send(_position(autopilot.mav, 10_000, 33.5, -118.0))
        assert wait_until(lambda: ex.vehicle.time_s == 10.0, 10), ex.vehicle
        # From another port, valid frames as system 1: a heartbeat and a position far away, newer.
        rogue.send(_heartbeat(rogue.mav), exec_addr)
        rogue.send(_position(rogue.mav, 11_000, 10.0, -100.0), exec_addr)
        assert wait_until(lambda: ex.link.foreign == 2, 10), ex.link.foreign
        autopilot.send(_position(autopilot.mav, 12_000, 33.5001, -118.0))  # the autopilot is still heard
        assert wait_until(lambda: ex.vehicle.time_s == 12.0, 10), ex.vehicle
    finally:
        run.stop()
        autopilot.close()
        rogue.close()
    assert ex.vehicle.lat_deg is not None and abs(ex.vehicle.lat_deg - 33.5) < 0.01
    assert ex.clock.last_s == 12.0  # the rogue's 11 s never reached the clock
    logs = [p["message"] for _, _, p in read_messages(tmp_path / "x.mcap", ["/log"])]
    assert any(m.startswith(f"autopilot link locked to 127.0.0.1:{autopilot.port}") for m in logs), logs
    warned = [m for m in logs if m.startswith("ignored 1 datagram(s) from 127.0.0.1:")]
    assert len(warned) == 1, logs  # rate-limited: the second within 10 s is counted, not logged


def test_a_silent_ground_station_stops_getting_replies_after_its_time_out(tmp_path: Path):
    autopilot = Endpoint(AUTOPILOT)
    timeout_s = 0.3
    run = Running(ExecConfig(link=f"udpout:127.0.0.1:{autopilot.port}", log_path=tmp_path / "g.mcap",
                             gcs_link="udpin:127.0.0.1:0", gcs_client_timeout_s=timeout_s))
    gcs_addr = ("127.0.0.1", run.executive.gcs.port.getsockname()[1])  # type: ignore[union-attr]
    active, silent = Endpoint(GCS), Endpoint(GCS)
    ask = active.mav.mission_request_list_encode(1, 191, 0)

    def answered(n: int) -> bool:
        active.read()
        return len(active.of("MISSION_COUNT")) >= n

    try:
        silent.send(_heartbeat(silent.mav), gcs_addr)
        active.send(ask, gcs_addr)
        assert wait_until(lambda: answered(1), 10)
        assert wait_until(lambda: silent.read() is not None and len(silent.of("MISSION_COUNT")) == 1, 10)
        time.sleep(timeout_s * 1.5)  # the silent one's last datagram is now older than the time-out
        silent.read()
        before = len(silent.got)
        for n in (2, 3):  # the active one keeps asking, and keeps being answered
            active.send(ask, gcs_addr)
            assert wait_until(lambda n=n: answered(n), 10)
        silent.read()
        assert len(silent.got) == before, silent.got[before:]
        silent.send(_heartbeat(silent.mav), gcs_addr)  # heard again: replied to again
        active.send(ask, gcs_addr)
        assert wait_until(lambda: silent.read() is not None and len(silent.of("MISSION_COUNT")) == 2, 10)
    finally:
        run.stop()
        for end in (autopilot, active, silent):
            end.close()


def test_the_executive_reports_its_progress_by_timesync_and_takes_an_answer_in_its_stride(tmp_path: Path):
    """Asked by a TIMESYNC request, the executive reports its progress the same way after each burst of input;
    ArduSub would answer those reports (TIMESYNC with tc1 its own clock), and that changes nothing."""
    autopilot = Endpoint(AUTOPILOT)
    run = Running(ExecConfig(link=f"udpout:127.0.0.1:{autopilot.port}", log_path=tmp_path / "t.mcap"))
    ex = run.executive
    try:
        assert wait_until(lambda: autopilot.read() is not None and autopilot.peer is not None, 10)
        autopilot.send(_heartbeat(autopilot.mav))
        autopilot.send(_position(autopilot.mav, 10_000, 33.5, -118.0))
        reports = lambda: [m.ts1 for m in autopilot.of("TIMESYNC") if m.tc1 == 0]  # noqa: E731
        assert wait_until(lambda: ex.vehicle.time_s == 10.0, 10)
        assert autopilot.read() is not None and reports() == [] and ex.progress_reports == 0  # not asked yet
        autopilot.send(autopilot.mav.timesync_encode(0, 10_000_000_000))  # a lockstep simulator asks
        assert wait_until(lambda: autopilot.read() is not None and 10_000_000_000 in reports(), 10), reports()
        bad = ex._counts["bad"]
        for ts1 in set(reports()):  # answered as ArduPilot does: tc1 its own clock (ns), ts1 echoed
            autopilot.send(autopilot.mav.timesync_encode(987_654_321_000, ts1))
        autopilot.send(_position(autopilot.mav, 10_500, 33.5, -118.0))
        assert wait_until(lambda: ex.vehicle.time_s == 10.5, 10), ex.vehicle
    finally:
        run.stop()
        autopilot.close()
    assert ex.clock.last_s == 10.5 and ex._counts["bad"] == bad and ex.progress_reports >= 2
