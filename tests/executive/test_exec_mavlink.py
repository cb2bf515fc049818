"""The executive over real UDP: each action becomes the right MAVLink message (issue 2, point 5).

The test is the autopilot here: a pymavlink endpoint on 127.0.0.1 (ephemeral
port) that speaks like ArduSub (HEARTBEAT with custom modes, GLOBAL_POSITION_INT
with negative relative_alt) and checks every message the executive sends back,
field by field, against research/executive-anchors.md section 2.3.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil

from executive.helm import HelmConfig
from executive.plausibility import Limits
from executive.recorder import read_messages
from planner.contract.actions import Action
from planner.contract.modes import SubMode
from tests.support.scripted_autopilot import Autopilot, Rig

MAV = mavutil.mavlink
# The scripted autopilot moves the vehicle from state to state at once: no jump is implausible here.
TELEPORTS = Limits(max_ground_speed_m_s=1e9, max_vertical_speed_m_s=1e9)


@pytest.fixture()
def rig(demo_plan, tmp_path: Path):
    rig = Rig(demo_plan.table, tmp_path / "exec.mcap",
              helm=HelmConfig(cruise_speed_m_s=1.0, on_arrival="hold", limits=TELEPORTS))
    try:
        rig.ap.expect("HEARTBEAT")  # the executive speaks first (udpout), so the autopilot learns its address
        yield rig
    finally:
        rig.stop()
        rig.ap.close()


def _state(table, action: Action) -> tuple[int, int, int, int]:
    states = np.argwhere(table.actions == int(action))
    return tuple(int(x) for x in states[len(states) // 2])  # type: ignore[return-value]


def _go(ap: Autopilot, table, state, *, heading=None) -> None:  # type: ignore[no-untyped-def]
    l, j, i, k = state
    lat, lon = table.cell_centre(j, i)
    ap.heartbeat()
    ap.ekf(position_ok=True)  # the EKF has its absolute position: set-up arms and asks for GUIDED only then
    ap.position(lat, lon, table.depth_m[l], table.bearing_deg(j, k) if heading is None else heading)


def _yaw_deg(msg) -> float:  # type: ignore[no-untyped-def]
    return math.degrees(msg.yaw) % 360.0


def test_setup_then_each_action_becomes_the_documented_message(rig):
    ap, table = rig.ap, rig.table
    fwd = _state(table, Action.FORWARD)
    _go(ap, table, fwd)
    # Set-up: message rates (SET_MESSAGE_INTERVAL to 1/1), then GUIDED and arming.
    rate = ap.expect("COMMAND_LONG", where=lambda m: m.command == MAV.MAV_CMD_SET_MESSAGE_INTERVAL)
    assert (rate.target_system, rate.target_component) == (1, 1)
    assert rate.param1 == MAV.MAVLINK_MSG_ID_GLOBAL_POSITION_INT and rate.param2 == 500_000
    ap.expect("COMMAND_LONG", where=lambda m: m.command == MAV.MAV_CMD_DO_SET_MODE and m.param2 == SubMode.GUIDED)
    ap.expect("COMMAND_LONG", where=lambda m: m.command == MAV.MAV_CMD_COMPONENT_ARM_DISARM and m.param1 == 1)

    # FORWARD: LOCAL_NED velocity, yaw and yaw rate (mask 455), along the cell's bearing at cruise speed.
    _go(ap, table, fwd)
    msg = ap.expect("SET_POSITION_TARGET_LOCAL_NED")
    bearing = table.bearing_deg(fwd[1], fwd[3])
    assert msg.type_mask == 455 and msg.coordinate_frame == MAV.MAV_FRAME_LOCAL_NED
    assert msg.yaw_rate == pytest.approx(math.radians(10.0))  # the mission's yaw_rate_deg_s
    assert (msg.target_system, msg.target_component) == (1, 1)
    assert math.hypot(msg.vx, msg.vy) == pytest.approx(1.0, rel=1e-6) and msg.vz == 0.0
    assert math.degrees(math.atan2(msg.vy, msg.vx)) % 360 == pytest.approx(bearing % 360, abs=1e-3)
    assert _yaw_deg(msg) == pytest.approx(bearing % 360, abs=0.01)  # from the heading (hdg: centidegrees)
    # Re-sent while the action lasts (ArduSub drops velocity targets after 3 s).
    for _ in range(6):
        _go(ap, table, fwd)
    again = ap.expect("SET_POSITION_TARGET_LOCAL_NED")
    assert again.vx == pytest.approx(msg.vx) and again.time_boot_ms > msg.time_boot_ms

    # DRIFT: ALT_HOLD, then a depth-only GLOBAL_INT target (mask 3579) at the layer's depth.
    drift = _state(table, Action.DRIFT)
    _go(ap, table, drift)
    ap.expect("COMMAND_LONG", where=lambda m: m.command == MAV.MAV_CMD_DO_SET_MODE and m.param2 == SubMode.ALT_HOLD)
    _go(ap, table, drift)
    depth = ap.expect("SET_POSITION_TARGET_GLOBAL_INT")
    assert depth.type_mask == 3579 and depth.alt == pytest.approx(-table.depth_m[drift[0]])
    assert depth.coordinate_frame == MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT

    # DOWN: toward the neighbouring layer's depth, still in ALT_HOLD; the target starts at the
    # vehicle's depth and moves at the glide rate (tests/executive/test_setpoints.py).
    down = _state(table, Action.DOWN)
    _go(ap, table, down)
    glide = ap.expect("SET_POSITION_TARGET_GLOBAL_INT", where=lambda m: m.alt != depth.alt or down[0] == drift[0])
    assert glide.type_mask == 3579 and glide.alt == pytest.approx(-table.depth_m[down[0]])

    # ROTATE_LEFT: GUIDED, zero velocity, yaw to the next direction counter-clockwise (45 deg left).
    rot = _state(table, Action.ROTATE_LEFT)
    _go(ap, table, rot)
    ap.expect("COMMAND_LONG", where=lambda m: m.command == MAV.MAV_CMD_DO_SET_MODE and m.param2 == SubMode.GUIDED)
    _go(ap, table, rot)
    turn = ap.expect("SET_POSITION_TARGET_LOCAL_NED")
    assert turn.type_mask == 455 and (turn.vx, turn.vy, turn.vz) == (0.0, 0.0, 0.0)
    # The yaw setpoint starts on the heading and turns at the yaw rate (tests/executive/test_setpoints.py).
    assert _yaw_deg(turn) == pytest.approx(table.bearing_deg(rot[1], rot[3]) % 360, abs=0.01)
    assert turn.yaw_rate == pytest.approx(math.radians(10.0))

    # Outside the grid: SURFACE (DO_SET_MODE 9), logged.
    ap.heartbeat()
    ap.position(table.lat0_deg - 0.5, table.lon0_deg, 5.0, 0.0)
    text = ap.expect("STATUSTEXT")  # the event is logged and sent before the command
    assert "outside the planned grid" in text.text and text.severity == MAV.MAV_SEVERITY_WARNING
    ap.expect("COMMAND_LONG", where=lambda m: m.command == MAV.MAV_CMD_DO_SET_MODE and m.param2 == SubMode.SURFACE)

    # Goal: hold station with a position-only GLOBAL_INT target (mask 3576) at the goal depth.
    goal = _state(table, Action.AT_GOAL)
    _go(ap, table, goal)
    ap.expect("COMMAND_LONG", where=lambda m: m.command == MAV.MAV_CMD_DO_SET_MODE and m.param2 == SubMode.GUIDED)
    _go(ap, table, goal)
    hold = ap.expect("SET_POSITION_TARGET_GLOBAL_INT", where=lambda m: m.type_mask == 3576)
    lat, lon = table.cell_centre(goal[1], goal[2])
    assert hold.lat_int == round(lat * 1e7) and hold.lon_int == round(lon * 1e7)
    assert hold.alt == pytest.approx(-table.goal_depth_m)


def test_heartbeat_is_1hz_in_vehicle_time_and_identifies_a_companion(rig):
    ap, table = rig.ap, rig.table
    hb = ap.expect("HEARTBEAT")
    assert hb.type == MAV.MAV_TYPE_ONBOARD_CONTROLLER and hb.autopilot == MAV.MAV_AUTOPILOT_INVALID
    # Vehicle time running 50x faster than wall time: heartbeats come about 50 times a second.
    state = _state(table, Action.FORWARD)
    lat, lon = table.cell_centre(state[1], state[2])
    t_end = time.monotonic() + 1.0
    while time.monotonic() < t_end:
        ap.position(lat, lon, 0.0, 0.0, dt_ms=1000)  # 1 s of vehicle time ...
        time.sleep(0.02)  # ... every 20 ms of wall time
    seen = 0
    t_end = time.monotonic() + 0.5
    while time.monotonic() < t_end:
        msg = ap.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.05)
        seen += msg is not None
    assert seen >= 8  # wall-paced 1 Hz would give at most 1 in 0.5 s


def test_the_log_has_every_run_element(rig):
    ap, table = rig.ap, rig.table
    fwd = _state(table, Action.FORWARD)
    for _ in range(3):
        _go(ap, table, fwd)
    ap.expect("SET_POSITION_TARGET_LOCAL_NED")
    for _ in range(3):
        _go(ap, table, fwd)
    # The positions are in flight over UDP: stop once the executive has acted on them, not before
    # (on a busy machine its thread can be a few datagrams behind the script).
    deadline = time.monotonic() + 20.0
    while rig.executive._counts["decisions"] < 3 and time.monotonic() < deadline:
        time.sleep(0.01)
    summary = rig.stop()
    assert summary.decisions >= 3
    log_path = rig.log_path
    topics = {t for t, _, _ in read_messages(log_path)}
    assert {"/vehicle/fix", "/vehicle/state", "/executive/decision", "/executive/command", "/executive/policy",
            "/mavlink/rx", "/mavlink/tx", "/log"} <= topics
    policy = next(p for t, _, p in read_messages(log_path, ["/executive/policy"]))
    assert policy["table_crc32"] == f"{table.crc32:08x}"
    assert policy["forecast"]["identity"] == table.forecast_identity
    decisions = [p for _, _, p in read_messages(log_path, ["/executive/decision"])]
    assert decisions and decisions[-1]["action"] == "FORWARD" and decisions[-1]["cell"] == list(fwd)


def test_an_autopilot_booted_long_ago_is_not_taken_for_a_silent_one(rig):
    """ArduSub's first HEARTBEAT has no time_boot_ms; its uptime may exceed the link-loss timeout."""
    ap = rig.ap
    ap.time_ms = 600_000  # booted 10 minutes ago; link-loss timeout 30 s
    ap.heartbeat()
    time.sleep(0.3)  # the executive runs its housekeeping with only the heartbeat heard
    ap.position(33.45, -118.1, 0.0, 0.0)
    time.sleep(0.3)
    rig.stop()
    texts = [p["message"] for _, _, p in read_messages(rig.log_path, ["/log"])]
    assert "autopilot heartbeat received" in texts
    assert not [t for t in texts if "link lost" in t], texts
