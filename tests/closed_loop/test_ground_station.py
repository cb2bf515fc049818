"""A ground station sees the vehicle through the executive, as through a MAVLink router on a companion computer.

Real UDP on 127.0.0.1, ephemeral ports: a scripted ArduSub-like autopilot
(tests/support/scripted_autopilot.py), the executive's loop in a thread with its ground-station
link, and a pymavlink client as the ground station (system 255, component 190). Each test waits
for what it expects with a generous time-out; nothing depends on how fast the machine is.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from executive import ground_station, parameters  # noqa: E402
from executive.helm import HelmConfig  # noqa: E402
from executive.loop import ExecConfig, Executive  # noqa: E402
from executive.recorder import read_messages  # noqa: E402
from planner.contract.modes import SubMode  # noqa: E402
from planner.shore.ftp_client import put_file  # noqa: E402
from planner.shore.mission_client import download_items  # noqa: E402
from tests.support.helpers import wait_until  # noqa: E402
from tests.support.scripted_autopilot import Autopilot  # noqa: E402

MAV = mavutil.mavlink
TIMEOUT_S = 5.0
EXECUTIVE = (1, 191)
AUTOPILOT = (1, 1)
GCS = (255, 190)


class Station:
    """The scripted autopilot, the executive (in a thread) and a ground-station client."""

    def __init__(self, table: Any, log: Path) -> None:
        self.ap = Autopilot()
        config = ExecConfig(link=f"udpout:127.0.0.1:{self.ap.port}", log_path=log, gcs_link="udpin:127.0.0.1:0",
                            max_wall_s=60.0, helm=HelmConfig(max_depth_m=200.0, min_battery_pct=20.0))
        self.executive = Executive(config, table)
        port = self.executive.gcs.port.getsockname()[1]
        self.gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=GCS[0], source_component=GCS[1])
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self.executive.run, args=(self._stop,), daemon=True)
        self._thread.start()
        # The executive speaks first on its autopilot link (udpout): the autopilot learns its address.
        assert self.ap.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=TIMEOUT_S) is not None
        self.gcs.mav.heartbeat_send(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID, 0, 0, MAV.MAV_STATE_ACTIVE)
        assert wait_until(lambda: bool(self.executive.gcs.heard), TIMEOUT_S), "the executive never heard the GCS"

    def gcs_expect(self, kind: str, source: tuple[int, int], where: Callable[[Any], bool] = lambda m: True,
                   skipped: list[Any] | None = None) -> Any:
        return _expect(self.gcs, kind, source, where, skipped)

    def ap_expect(self, kind: str, where: Callable[[Any], bool] = lambda m: True) -> Any:
        return _expect(self.ap.conn, kind, GCS, where)

    def send_frame(self, msg: Any) -> bytes:
        """Send an autopilot message; its exact frame."""
        frame = bytes(msg.pack(self.ap.conn.mav))
        self.ap.conn.write(frame)
        return frame

    def stop(self) -> None:
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=10)
        assert not self._thread.is_alive()
        self.gcs.close()
        self.ap.close()


def _expect(conn: Any, kind: str, source: tuple[int, int], where: Callable[[Any], bool],
            skipped: list[Any] | None = None) -> Any:
    """The first ``kind`` from ``source`` that satisfies ``where``; other ``kind`` messages go to ``skipped``."""
    deadline = time.monotonic() + TIMEOUT_S
    while (left := deadline - time.monotonic()) > 0:
        msg = conn.recv_match(type=kind, blocking=True, timeout=left)
        if msg is not None and (msg.get_srcSystem(), msg.get_srcComponent()) == source and where(msg):
            return msg
        if msg is not None and skipped is not None:
            skipped.append(msg)
    raise AssertionError(f"no {kind} from {source[0]}/{source[1]} within {TIMEOUT_S} s")


@pytest.fixture()
def station(demo_plan: Any, tmp_path: Path) -> Iterator[Station]:
    rig = Station(demo_plan.table, tmp_path / "exec.mcap")
    try:
        yield rig
    finally:
        rig.stop()


def test_the_ground_station_sees_the_autopilots_vehicle_and_telemetry_as_sent(station: Station) -> None:
    ap = station.ap.conn.mav
    base = MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | MAV.MAV_MODE_FLAG_SAFETY_ARMED
    frames = {
        "HEARTBEAT": station.send_frame(ap.heartbeat_encode(MAV.MAV_TYPE_SUBMARINE, MAV.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                            base, int(SubMode.GUIDED), MAV.MAV_STATE_ACTIVE)),
        "GLOBAL_POSITION_INT": station.send_frame(ap.global_position_int_encode(60_000, 334_000_000, -1_178_000_000,
                                                                                -20_000, -20_000, 0, 0, 0, 9000)),
        "ATTITUDE": station.send_frame(ap.attitude_encode(60_100, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0)),
        "SYS_STATUS": station.send_frame(ap.sys_status_encode(0, 0, 0, 500, 16000, 1000, 87, 0, 0, 0, 0, 0, 0)),
        "BATTERY_STATUS": station.send_frame(ap.battery_status_encode(0, 0, 0, 2000, [16000] + [65535] * 9, 1000,
                                                                      -1, -1, 87)),
        "STATUSTEXT": station.send_frame(ap.statustext_encode(MAV.MAV_SEVERITY_WARNING, b"Leak Detected")),
    }
    for kind, frame in frames.items():
        texts: list[Any] = []  # the executive's STATUSTEXTs before the autopilot's arrives
        got = station.gcs_expect(kind, AUTOPILOT, lambda m: True, texts)
        assert bytes(got.get_msgbuf()) == frame, kind  # the autopilot's own frame, not re-packed
    assert not [t for t in texts if "Leak" in t.text]  # the autopilot's text is not repeated by the executive
    # pymavlink (as MAVProxy) picks the vehicle from the autopilot's heartbeat: ArduSub's modes, not ArduPlane's.
    assert station.gcs.mav_type == MAV.MAV_TYPE_SUBMARINE
    assert {"MANUAL", "ALT_HOLD", "GUIDED", "SURFACE", "POSHOLD"} <= set(station.gcs.mode_mapping())
    assert station.gcs.flightmode == "GUIDED"
    # The executive's own heartbeat is still the companion's: a ground station never takes it for a vehicle.
    own = station.gcs_expect("HEARTBEAT", EXECUTIVE)
    assert (own.type, own.autopilot) == (MAV.MAV_TYPE_ONBOARD_CONTROLLER, MAV.MAV_AUTOPILOT_INVALID)
    assert station.executive.router.to_ground >= len(frames)


def test_the_ground_stations_heartbeat_and_commands_reach_the_autopilot_and_its_ack_comes_back(station: Station) -> None:
    station.ap.heartbeat()  # the autopilot is heard: commands for it go through
    assert station.ap_expect("HEARTBEAT").type == MAV.MAV_TYPE_GCS  # ArduSub's GCS failsafe watches these
    assert wait_until(lambda: station.executive.vehicle.heartbeat_s is not None, TIMEOUT_S)
    # A person takes over: the mode change goes to the autopilot untouched (signature and all), never blocked.
    sent = station.gcs.mav.command_long_encode(1, 1, MAV.MAV_CMD_DO_SET_MODE, 0,
                                               MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, int(SubMode.SURFACE), 0, 0, 0, 0, 0)
    frame = bytes(sent.pack(station.gcs.mav))
    station.gcs.write(frame)
    got = station.ap_expect("COMMAND_LONG")
    assert bytes(got.get_msgbuf()) == frame
    station.ap.conn.mav.command_ack_send(MAV.MAV_CMD_DO_SET_MODE, MAV.MAV_RESULT_ACCEPTED, 0, 0, *GCS)
    ack = station.gcs_expect("COMMAND_ACK", AUTOPILOT)
    assert (ack.command, ack.result, ack.target_system, ack.target_component) == (
        MAV.MAV_CMD_DO_SET_MODE, MAV.MAV_RESULT_ACCEPTED, *GCS)
    # The autopilot's answer to the ground station is not taken for one to the executive's own requests.
    station.gcs.mav.command_long_send(1, 1, MAV.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 33, 100_000, 0, 0, 0, 0, 0)
    assert station.ap_expect("COMMAND_LONG", lambda m: m.command == MAV.MAV_CMD_SET_MESSAGE_INTERVAL)
    station.ap.conn.mav.command_ack_send(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, MAV.MAV_RESULT_ACCEPTED, 0, 0, *GCS)
    station.gcs_expect("COMMAND_ACK", AUTOPILOT, lambda m: m.command == MAV.MAV_CMD_SET_MESSAGE_INTERVAL)
    assert station.executive.vehicle.interval_acks == 0
    # PARAM_REQUEST_LIST to component 0 goes to the autopilot as well as to the executive's component.
    station.gcs.mav.param_request_list_send(1, 0)
    station.ap_expect("PARAM_REQUEST_LIST")
    station.gcs_expect("PARAM_VALUE", EXECUTIVE)


def test_a_command_for_a_silent_autopilot_is_temporarily_rejected(station: Station) -> None:
    station.gcs.mav.command_long_send(1, 1, MAV.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    ack = station.gcs_expect("COMMAND_ACK", EXECUTIVE)
    assert (ack.command, ack.result, ack.target_system, ack.target_component) == (
        MAV.MAV_CMD_COMPONENT_ARM_DISARM, MAV.MAV_RESULT_TEMPORARILY_REJECTED, *GCS)
    text = station.gcs_expect("STATUSTEXT", EXECUTIVE, lambda m: "autopilot silent" in m.text)
    assert text.severity == MAV.MAV_SEVERITY_WARNING
    # Not sent into the void: the refusal and any forwarding happen in one step, so it would be waiting by now.
    while (msg := station.ap.conn.recv_match(blocking=False)) is not None:
        assert msg.get_type() != "COMMAND_LONG" or msg.get_srcSystem() != GCS[0], msg
    assert station.executive.router.refused == 1


def _parameters(station: Station) -> dict[int, Any]:
    values: dict[int, Any] = {}
    first = station.gcs_expect("PARAM_VALUE", EXECUTIVE)
    values[first.param_index] = first
    while len(values) < first.param_count:
        msg = station.gcs_expect("PARAM_VALUE", EXECUTIVE)
        values[msg.param_index] = msg
    return values


def test_the_executives_component_answers_the_parameter_protocol(station: Station) -> None:
    station.gcs.mav.param_request_list_send(*EXECUTIVE)
    values = _parameters(station)
    by_name = {m.param_id: m for m in values.values()}
    assert sorted(values) == list(range(len(values)))
    assert {m.param_count for m in values.values()} == {len(values)}
    assert {m.param_type for m in values.values()} == {MAV.MAV_PARAM_TYPE_REAL32}
    assert {name: m.param_value for name, m in by_name.items()} == {
        "EXEC_GOAL_INDEX": 0.0, "EXEC_GOAL_COUNT": 1.0, "EXEC_SAFE_STOP": 0.0, "EXEC_MAX_DEPTH_M": 200.0,
        "EXEC_MINBATT_PCT": 20.0}
    # Read by name (param_index -1) and by index.
    station.gcs.mav.param_request_read_send(*EXECUTIVE, b"EXEC_MAX_DEPTH_M", -1)
    got = station.gcs_expect("PARAM_VALUE", EXECUTIVE)
    assert (got.param_id, got.param_index) == ("EXEC_MAX_DEPTH_M", by_name["EXEC_MAX_DEPTH_M"].param_index)
    station.gcs.mav.param_request_read_send(*EXECUTIVE, b"", by_name["EXEC_GOAL_COUNT"].param_index)
    assert station.gcs_expect("PARAM_VALUE", EXECUTIVE).param_id == "EXEC_GOAL_COUNT"
    # A set that cannot be applied is answered with the current value, and said.
    station.gcs.mav.param_set_send(*EXECUTIVE, b"EXEC_MAX_DEPTH_M", 500.0, MAV.MAV_PARAM_TYPE_REAL32)
    got = station.gcs_expect("PARAM_VALUE", EXECUTIVE)
    assert (got.param_id, got.param_value) == ("EXEC_MAX_DEPTH_M", 200.0)
    assert "read-only" in station.gcs_expect("STATUSTEXT", EXECUTIVE).text
    # Nothing of it went to the autopilot.
    while (msg := station.ap.conn.recv_match(blocking=False)) is not None:
        assert not msg.get_type().startswith("PARAM_"), msg


def test_the_executives_component_answers_commands_addressed_to_it(station: Station) -> None:
    station.gcs.mav.command_long_send(*EXECUTIVE, MAV.MAV_CMD_REQUEST_MESSAGE, 0, MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                                      0, 0, 0, 0, 0, 0)
    ack = station.gcs_expect("COMMAND_ACK", EXECUTIVE)
    assert (ack.command, ack.result) == (MAV.MAV_CMD_REQUEST_MESSAGE, MAV.MAV_RESULT_ACCEPTED)
    version = station.gcs_expect("AUTOPILOT_VERSION", EXECUTIVE)
    assert version.capabilities & MAV.MAV_PROTOCOL_CAPABILITY_FTP
    assert version.capabilities & MAV.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    station.gcs.mav.command_long_send(*EXECUTIVE, MAV.MAV_CMD_REQUEST_MESSAGE, 0, MAV.MAVLINK_MSG_ID_HEARTBEAT,
                                      0, 0, 0, 0, 0, 0)
    assert station.gcs_expect("COMMAND_ACK", EXECUTIVE).result == MAV.MAV_RESULT_ACCEPTED
    station.gcs_expect("HEARTBEAT", EXECUTIVE)
    station.gcs.mav.command_long_send(*EXECUTIVE, MAV.MAV_CMD_REQUEST_MESSAGE, 0, MAV.MAVLINK_MSG_ID_VFR_HUD,
                                      0, 0, 0, 0, 0, 0)
    assert station.gcs_expect("COMMAND_ACK", EXECUTIVE).result == MAV.MAV_RESULT_FAILED
    station.gcs.mav.command_int_send(*EXECUTIVE, 0, MAV.MAV_CMD_DO_SET_ROI_LOCATION, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    ack = station.gcs_expect("COMMAND_ACK", EXECUTIVE)
    assert (ack.command, ack.result, ack.target_system) == (MAV.MAV_CMD_DO_SET_ROI_LOCATION,
                                                            MAV.MAV_RESULT_UNSUPPORTED, GCS[0])


def test_mission_download_and_ftp_upload_still_work_and_the_log_counts_the_forwarding(station: Station,
                                                                                    tmp_path: Path) -> None:
    station.ap.heartbeat()
    station.gcs_expect("HEARTBEAT", AUTOPILOT)
    items = download_items(station.gcs)
    assert len(items) == 2  # home and the mission's goal
    table = station.executive.table
    assert table is not None
    put_file(station.gcs, table.to_bytes(), "/tables/goal-0.lrpt")  # raises if refused
    assert "/tables/goal-0.lrpt" in station.executive.uploads.ftp.files
    station.stop()
    lines = [p["message"] for _t, _s, p in read_messages(tmp_path / "exec.mcap", ["/log"])]
    summary = [line for line in lines if line.startswith("ground station:")]
    assert len(summary) == 1 and "0 commands refused" in summary[0], summary
    assert int(summary[0].split()[2].replace(",", "")) >= 1  # the autopilot's heartbeat, at least


@pytest.mark.parametrize(("target", "autopilot", "executive"), [
    (None, True, True),  # no target fields: the station's heartbeat, which ArduSub's GCS failsafe watches
    ((0, 0), True, True),
    ((1, 0), True, True),  # PARAM_REQUEST_LIST to the vehicle: both components answer
    ((1, 1), True, False),
    ((1, 100), True, False),  # another component of the vehicle: behind the autopilot
    ((1, 191), False, True),
    ((7, 1), False, False),  # no such system here
])
def test_route(target: tuple[int, int] | None, autopilot: bool, executive: bool) -> None:
    assert ground_station.route(target, autopilot_system=1, executive=EXECUTIVE) == ground_station.Route(
        autopilot=autopilot, executive=executive)


def test_parameters_are_float32_with_short_names_and_a_fixed_count() -> None:
    facts = parameters.Facts(goal_index=2, goal_count=3, safety_stop=True, max_depth_m=150.3, min_battery_pct=None)
    table = parameters.table(facts)
    assert [p.name for p in table] == ["EXEC_GOAL_INDEX", "EXEC_GOAL_COUNT", "EXEC_SAFE_STOP", "EXEC_MAX_DEPTH_M"]
    assert table[3].value == parameters.float32(150.3) != 150.3  # what REAL32 carries
    assert parameters.answer(table, "PARAM_REQUEST_READ", index=4).values == ()  # past the end: not answered
    with pytest.raises(ValueError, match="1 to 16 ASCII"):
        parameters.Parameter("EXEC_A_NAME_TOO_LONG", 1.0)
