"""A scripted ArduSub-like autopilot on a real UDP socket, and an executive in a thread connected to it.

The test is the autopilot: it sends what ArduSub sends (HEARTBEAT with custom modes,
GLOBAL_POSITION_INT with negative relative_alt, ATTITUDE, ...) when the test says, and returns
what the executive sends back, so that each message can be checked field by field.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega

from executive.helm import HelmConfig
from executive.loop import ExecConfig, Executive
from planner.contract.modes import SubMode

MAV = mavutil.mavlink


class Autopilot:
    """A scripted ArduSub-like peer: sends what ArduSub sends, returns what it receives."""

    def __init__(self) -> None:
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=1, source_component=1)
        self.port = self.conn.port.getsockname()[1]
        self.time_ms = 50_000
        self.mode = SubMode.MANUAL
        self.armed = False

    def heartbeat(self, status: int = MAV.MAV_STATE_ACTIVE) -> None:
        """``status`` MAV_STATE_CRITICAL is how ArduPilot reports an active failsafe."""
        base = MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (MAV.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        self.conn.mav.heartbeat_send(MAV.MAV_TYPE_SUBMARINE, MAV.MAV_AUTOPILOT_ARDUPILOTMEGA, base, int(self.mode),
                                     status)

    def attitude(self, yaw_rad: float, dt_ms: int = 0) -> None:
        self.time_ms += dt_ms
        self.conn.mav.attitude_send(self.time_ms, 0.0, 0.0, yaw_rad, 0.0, 0.0, 0.0)

    def battery(self, pct: int) -> None:
        self.conn.mav.battery_status_send(0, 0, 0, 2000, [65535] * 10, -1, -1, -1, pct)

    def ekf(self, position_ok: bool) -> None:
        flags = MAV.EKF_ATTITUDE | MAV.EKF_VELOCITY_HORIZ | (MAV.EKF_POS_HORIZ_ABS if position_ok else 0)
        self.conn.mav.ekf_status_report_send(flags, 0.1, 0.1, 0.1, 0.1, 0.1)

    def position(self, lat: float, lon: float, depth: float, heading: float, dt_ms: int = 200) -> None:
        self.time_ms += dt_ms
        self.conn.mav.global_position_int_send(self.time_ms, round(lat * 1e7), round(lon * 1e7), round(-depth * 1000),
                                               round(-depth * 1000), 0, 0, 0, round(heading * 100) % 36000)

    def expect(self, kind: str, *, timeout_s: float = 5.0, where=lambda m: True):  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            msg = self.conn.recv_match(blocking=True, timeout=0.1)
            if msg is None:
                continue
            assert (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 191)
            self._obey(msg)
            if msg.get_type() == kind and where(msg):
                return msg
        raise AssertionError(f"no {kind} from the executive within {timeout_s} s")

    def _obey(self, msg, *, answer: bool = True) -> None:  # type: ignore[no-untyped-def]
        """Mode and arming requests take effect, as on ArduSub (acknowledged, then in the next HEARTBEAT)."""
        if msg.get_type() == "COMMAND_LONG" and msg.target_system == 1 and msg.target_component in (0, 1):
            if msg.command == MAV.MAV_CMD_DO_SET_MODE:
                self.mode = SubMode(int(msg.param2))
            elif msg.command == MAV.MAV_CMD_COMPONENT_ARM_DISARM:
                self.armed = msg.param1 == 1
            if answer:
                self.conn.mav.command_ack_send(msg.command, MAV.MAV_RESULT_ACCEPTED)
                self.heartbeat()

    def close(self) -> None:
        self.conn.close()


class Rig:
    """The executive in a thread, connected to a scripted autopilot."""

    def __init__(self, table, log_path: Path, helm: HelmConfig | None = None, **executive) -> None:  # type: ignore[no-untyped-def]
        self.ap = Autopilot()
        self.table = table
        self.log_path = log_path
        config = ExecConfig(link=f"udpout:127.0.0.1:{self.ap.port}", log_path=log_path,
                            helm=helm or HelmConfig(cruise_speed_m_s=1.0, on_arrival="hold"))
        self.executive = Executive(config, table, **executive)
        self._stop = threading.Event()
        self.summary = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        self.summary = self.executive.run(self._stop)

    def stop(self):  # type: ignore[no-untyped-def]
        self._stop.set()
        self.thread.join(timeout=10)
        assert not self.thread.is_alive()
        return self.summary




class Stepped:
    """The executive in this thread behind a scripted autopilot: each datagram is handled before the next is sent.

    Messages go both ways over real UDP; ``pump`` runs the loop's input handling and its
    time-driven work (heartbeats, link checks) until no datagram waits, so a script's outcome
    never depends on how fast the machine is.
    """

    def __init__(self, table, log_path: Path, helm: HelmConfig | None = None, state_dir: Path | None = None,  # type: ignore[no-untyped-def]
                 ekf_ready: bool = True, **executive) -> None:
        self.ap = Autopilot()
        self.ap.mode, self.ap.armed = SubMode.GUIDED, True
        self.log_path = log_path
        config = ExecConfig(link=f"udpout:127.0.0.1:{self.ap.port}", log_path=log_path, state_dir=state_dir,
                            helm=helm or HelmConfig(cruise_speed_m_s=1.0, on_arrival="hold"))
        self.executive = Executive(config, table, **executive)
        self._wall0 = time.monotonic()
        self.executive._heartbeat(self._wall0)  # udpout speaks first: the autopilot learns the executive's address
        assert self.ap.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5.0) is not None
        if ekf_ready:  # a running autopilot's EKF has its position (positions are used only then)
            self.ap.ekf(position_ok=True)
            self.pump()
        self.gcs = ardupilotmega.MAVLink(None, srcSystem=255, srcComponent=190)  # a GCS behind the autopilot

    def pump(self) -> list:  # type: ignore[type-arg]
        """Handle every datagram waiting; return what the executive sent (mode and arming requests take effect)."""
        ex = self.executive
        while ex._input_waiting():
            ex._drain(time.monotonic())
        ex._housekeeping(time.monotonic(), self._wall0)
        sent = []
        while (msg := self.ap.conn.recv_match(blocking=False)) is not None:
            self.ap._obey(msg, answer=False)
            sent.append(msg)
        return sent

    def send_as_gcs(self, msg) -> None:  # type: ignore[no-untyped-def]
        """A ground station's message routed through the autopilot to the executive (system 1, component 191)."""
        self.ap.conn.write(msg.pack(self.gcs))

    def close(self) -> None:
        self.executive.close()
        self.ap.close()
