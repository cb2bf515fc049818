"""The vehicle is asked to turn and glide at the rates the plan priced.

The plan prices a turn at the mission's yaw_rate_deg_s and a glide at its glide_rate_m_s;
ArduSub, given only the final yaw or depth, turned 45 deg in 1.3-2 s and changed depth at
about 1 m/s. So the executive moves its yaw and depth setpoints itself, at the plan's rates, and
sends the yaw rate with the yaw (executive.setpoints). Checked here as pure functions, through
``helm.step``, as encoded MAVLink, and over real UDP against a scripted autopilot.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from executive import mavlink_bridge as bridge
from executive.helm import HelmConfig, HelmState, step
from executive.setpoints import depth_at, yaw_at
from executive.state import DepthTarget, Phase, SubMode, VehicleState, VelocityYaw
from planner.contract.actions import Action
from planner.contract.steering import steer
from planner.contract.table import PolicyTable
from tests.support.helpers import assert_audit_clean
from tests.support.scripted_autopilot import Stepped

YAW_RATE_DEG_S, GLIDE_RATE_M_S = 10.0, 0.2  # the mission's defaults (docs/missions.md)
CONFIG = HelmConfig(cruise_speed_m_s=1.0, yaw_rate_deg_s=YAW_RATE_DEG_S, glide_rate_m_s=GLIDE_RATE_M_S, refresh_s=1.0)
MASK_YAW_AND_RATE = 455  # POSITION_TARGET_TYPEMASK: x, y, z and accelerations ignored; velocity, yaw, yaw rate used
YAW_IGNORE, YAW_RATE_IGNORE = 1024, 2048


def _wrap(deg: float) -> float:
    return (deg + 180.0) % 360.0 - 180.0


# -- the setpoint as a function of time ----------------------------------------------


@pytest.mark.parametrize(("start", "final"), [(90.0, 45.0), (45.0, 90.0), (350.0, 20.0), (20.0, 350.0),
                                               (0.0, 315.0), (200.0, 200.0)])
def test_yaw_moves_the_short_way_at_the_rate_and_stops_on_the_final_yaw(start, final):
    delta = _wrap(final - start)  # short way: -45, +45, +30 across north, -30 across north, -45, 0
    assert abs(delta) <= 45.0
    duration_s = abs(delta) / YAW_RATE_DEG_S
    assert yaw_at(start, final, YAW_RATE_DEG_S, 0.0) == pytest.approx(start % 360.0)
    previous = start
    for n in range(1, 61):
        t = n * 0.1
        yaw = yaw_at(start, final, YAW_RATE_DEG_S, t)
        assert 0.0 <= yaw < 360.0
        moved = _wrap(yaw - start)
        assert abs(moved) <= abs(delta) + 1e-9  # never beyond the final yaw
        assert moved * delta >= 0.0  # never the long way round
        expected = math.copysign(min(YAW_RATE_DEG_S * t, abs(delta)), delta)
        assert moved == pytest.approx(expected, abs=1e-9)
        step_deg = abs(_wrap(yaw - previous))
        assert step_deg <= YAW_RATE_DEG_S * 0.1 + 1e-9  # no faster than the rate
        previous = yaw
        if t >= duration_s:
            assert yaw == final  # on the final yaw itself from |delta| / rate on
    assert yaw_at(start, final, YAW_RATE_DEG_S, duration_s) == final


@pytest.mark.parametrize(("start", "final"), [(5.0, 10.0), (10.0, 5.0), (0.0, 15.0), (7.3, 7.3)])
def test_depth_moves_at_the_glide_rate_and_stops_on_the_final_depth(start, final):
    duration_s = abs(final - start) / GLIDE_RATE_M_S
    for n in range(0, 101):
        t = n * 1.0
        depth = depth_at(start, final, GLIDE_RATE_M_S, t)
        assert min(start, final) <= depth <= max(start, final)  # never overshoots
        assert depth == pytest.approx(start + math.copysign(min(GLIDE_RATE_M_S * t, abs(final - start)), final - start))
        if t >= duration_s:
            assert depth == final
    assert depth_at(start, final, GLIDE_RATE_M_S, -3.0) == start  # not before it started


# -- through the helm: the value re-sent at each refresh ------------------------------


def _state_with(table: PolicyTable, action: Action) -> tuple[int, int, int, int]:
    states = np.argwhere(table.actions == int(action))
    assert len(states), action
    return tuple(int(x) for x in states[len(states) // 2])  # type: ignore[return-value]


def _vehicle(table: PolicyTable, state: tuple[int, int, int, int], now_s: float, mode: SubMode) -> VehicleState:
    """The vehicle sitting still at the state's cell centre, layer depth and bearing (it never turns or glides)."""
    l, j, i, k = state
    lat, lon = table.cell_centre(j, i)
    return VehicleState(time_s=now_s, lat_deg=lat, lon_deg=lon, depth_m=float(table.depth_m[l]),
                        heading_deg=table.bearing_deg(j, k) % 360.0, mode=int(mode), armed=True, position_ok=True,
                        heartbeat_s=now_s, interval_acks=len(CONFIG.rates), position_s=now_s)


def _stream(table: PolicyTable, state: tuple[int, int, int, int], mode: SubMode, seconds: float) -> list:  # type: ignore[type-arg]
    """``(now_s, command)`` for each target the helm sends, telemetry every 0.5 s for ``seconds``."""
    helm = HelmState(phase=Phase.RUNNING, rates_sent=True, rates_acks=len(CONFIG.rates), mission_start_s=0.0)
    sent = []
    for n in range(int(seconds / 0.5) + 1):
        now_s = 100.0 + 0.5 * n
        tick = step(helm, _vehicle(table, state, now_s, mode), table, CONFIG, now_s=now_s, link_ok=True)
        assert tick.decision is not None and tick.decision.cell == state and not (n and tick.decision.changed)
        helm = tick.helm
        sent += [(now_s, c) for c in tick.commands if isinstance(c, (VelocityYaw, DepthTarget))]
    return sent


@pytest.mark.parametrize("action", [Action.ROTATE_LEFT, Action.ROTATE_RIGHT])
def test_a_turns_yaw_setpoint_is_re_sent_each_refresh_moved_at_the_yaw_rate(demo_plan, action):
    table = demo_plan.table
    state = _state_with(table, action)
    _l, j, _i, k = state
    start = table.bearing_deg(j, k) % 360.0
    final = table.bearing_deg(j, (k + (1 if action is Action.ROTATE_LEFT else -1)) % 8)
    delta = _wrap(final - start)
    assert (delta < 0) == (action is Action.ROTATE_LEFT)  # left is counter-clockwise
    sent = _stream(table, state, SubMode.GUIDED, seconds=8.0)
    assert [t for t, _ in sent] == [100.0 + n for n in range(9)]  # once per refresh_s
    for t, cmd in sent:
        assert isinstance(cmd, VelocityYaw) and (cmd.north_m_s, cmd.east_m_s, cmd.down_m_s) == (0.0, 0.0, 0.0)
        assert cmd.yaw_rate_deg_s == YAW_RATE_DEG_S  # the plan's rate goes with every yaw
        moved = math.copysign(min(YAW_RATE_DEG_S * (t - 100.0), abs(delta)), delta)
        assert _wrap(cmd.yaw_deg - start) == pytest.approx(moved, abs=1e-9)
    assert sent[-1][1].yaw_deg == final  # 45 deg at 10 deg/s: on the final bearing after 4.5 s


def test_a_glides_depth_setpoint_is_re_sent_each_refresh_moved_at_the_glide_rate(demo_plan):
    table = demo_plan.table
    state = _state_with(table, Action.DOWN)
    start, final = float(table.depth_m[state[0]]), float(table.depth_m[state[0] + 1])
    sent = _stream(table, state, SubMode.ALT_HOLD, seconds=30.0)
    assert [t for t, _ in sent] == [100.0 + n for n in range(31)]
    for t, cmd in sent:
        assert cmd == DepthTarget(pytest.approx(min(final, start + GLIDE_RATE_M_S * (t - 100.0))))  # type: ignore[arg-type]
    assert sent[-1][1] == DepthTarget(final)


def test_the_timeouts_of_turns_and_glides_allow_the_ramp_from_anywhere_in_the_state(demo_plan):
    """A held manoeuvre is given up after its timeout: it must outlast the priced ramp from any start."""
    table = demo_plan.table
    kw = {"cruise_speed_m_s": 1.0, "yaw_rate_deg_s": YAW_RATE_DEG_S, "glide_rate_m_s": GLIDE_RATE_M_S}
    for j in (0, table.ny // 2, table.ny - 1):
        headings = [(h, table.heading_index(j, h)) for h in np.arange(0.0, 360.0, 0.5)]
        for k in range(8):
            for action in (Action.ROTATE_LEFT, Action.ROTATE_RIGHT):
                steering = steer(action, (0, j, 0, k), table, **kw)
                assert steering.timeout_s is not None and steering.yaw_deg is not None
                worst_deg = max(abs(_wrap(steering.yaw_deg - h)) for h, kk in headings if kk == k)
                assert worst_deg / YAW_RATE_DEG_S < steering.timeout_s / 3.0, (j, k, action, worst_deg)
    depths = table.depth_m
    for l in range(len(depths)):
        upper = (depths[l] + depths[l - 1]) / 2 if l > 0 else depths[0]
        lower = (depths[l] + depths[l + 1]) / 2 if l + 1 < len(depths) else depths[l] + (depths[l] - depths[l - 1]) / 2
        for action in (a for a in (Action.UP, Action.DOWN) if 0 <= l + (1 if a is Action.DOWN else -1) < len(depths)):
            steering = steer(action, (l, 0, 0, 0), table, **kw)
            assert steering.timeout_s is not None and steering.goal_depth_m is not None
            worst_m = max(abs(steering.goal_depth_m - upper), abs(steering.goal_depth_m - lower))
            assert worst_m / GLIDE_RATE_M_S < steering.timeout_s / 2.0, (l, action, worst_m)


# -- the MAVLink message ---------------------------------------------------------------


@pytest.mark.parametrize("yaw_deg", [315.0, 45.0, 180.0])
def test_a_yaw_with_its_rate_is_encoded_with_both_fields_used(yaw_deg):
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    msg = bridge.encode(mav, VelocityYaw(0.0, 0.0, 0.0, yaw_deg, YAW_RATE_DEG_S), time_boot_ms=1234)
    back = mavlink.MAVLink(None).decode(bytearray(msg.pack(mav)))
    assert back.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and back.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED
    assert back.type_mask == MASK_YAW_AND_RATE and not back.type_mask & (YAW_IGNORE | YAW_RATE_IGNORE)
    assert math.degrees(back.yaw) % 360.0 == pytest.approx(yaw_deg, abs=1e-4)
    # A magnitude, whichever way the turn goes: ArduSub slews toward the yaw at min(rate, 60 deg/s), and a
    # negative rate would turn it away from the yaw (AC_AttitudeControl_Sub::input_euler_angle_roll_pitch_slew_yaw_cd).
    assert back.yaw_rate == pytest.approx(math.radians(YAW_RATE_DEG_S))
    plain = mavlink.MAVLink(None).decode(bytearray(bridge.encode(mav, VelocityYaw(0.0, 0.0, 0.0, yaw_deg),
                                                                 time_boot_ms=1234).pack(mav)))
    assert plain.type_mask == 2503 and plain.yaw_rate == 0.0  # no rate: the yaw alone, as before


# -- over real UDP: what the scripted autopilot receives --------------------------------


class Sitting:
    """A scripted autopilot whose vehicle sits at one state's cell (it never turns or glides): telemetry every 0.5 s."""

    def __init__(self, table: PolicyTable, log: Path, state: tuple[int, int, int, int]) -> None:
        self.rig = Stepped(table, log, helm=CONFIG)
        self.ap = self.rig.ap
        l, j, i, k = state
        self.lat, self.lon = table.cell_centre(j, i)
        self.depth, self.heading = float(table.depth_m[l]), table.bearing_deg(j, k) % 360.0

    def seconds(self, n: int) -> list:  # type: ignore[type-arg]
        sent = []
        for _ in range(n):
            self.ap.heartbeat()
            self.ap.ekf(position_ok=True)
            for _ in range(2):
                self.ap.position(self.lat, self.lon, self.depth, self.heading, dt_ms=500)
                self.ap.attitude(math.radians(self.heading))
                sent += self.rig.pump()
        return sent


def _fly(table: PolicyTable, log: Path, state: tuple[int, int, int, int], seconds: int, kind: str) -> list:  # type: ignore[type-arg]
    """The ``kind`` messages the executive sends in ``seconds`` at ``state``; the decision audit makes its decisions again."""
    s = Sitting(table, log, state)
    try:
        sent = [m for m in s.seconds(seconds) if m.get_type() == kind]
    finally:
        s.rig.close()
    assert_audit_clean(log)
    return sent


def test_over_udp_a_turns_yaw_setpoint_moves_at_the_plans_yaw_rate(demo_plan, tmp_path):
    table = demo_plan.table
    rotate = _state_with(table, Action.ROTATE_LEFT)
    turn = _fly(table, tmp_path / "exec.mcap", rotate, 8, "SET_POSITION_TARGET_LOCAL_NED")
    # ROTATE_LEFT: from the heading it is on toward the next bearing counter-clockwise, at 10 deg/s.
    start = table.bearing_deg(rotate[1], rotate[3]) % 360.0
    final = table.bearing_deg(rotate[1], (rotate[3] + 1) % 8)
    delta = _wrap(final - start)
    assert len(turn) >= 6 and all(m.type_mask == MASK_YAW_AND_RATE for m in turn)
    assert all(m.yaw_rate == pytest.approx(math.radians(YAW_RATE_DEG_S)) for m in turn)
    t0 = turn[0].time_boot_ms
    for m in turn:
        moved = math.copysign(min(YAW_RATE_DEG_S * (m.time_boot_ms - t0) / 1000.0, abs(delta)), delta)
        # time_boot_ms is whole milliseconds: 0.01 deg at 10 deg/s; the heading came in centidegrees
        assert _wrap(math.degrees(m.yaw) - start) == pytest.approx(moved, abs=0.03)
    assert any(1.0 < abs(_wrap(math.degrees(m.yaw) - start)) < abs(delta) - 1.0 for m in turn)  # part of the way
    assert _wrap(math.degrees(turn[-1].yaw) - final) == pytest.approx(0.0, abs=1e-3)


def test_over_udp_a_glides_depth_setpoint_moves_at_the_plans_glide_rate(demo_plan, tmp_path):
    table = demo_plan.table
    down = _state_with(table, Action.DOWN)
    glide = _fly(table, tmp_path / "exec.mcap", down, 30, "SET_POSITION_TARGET_GLOBAL_INT")
    # DOWN: the ALT_HOLD depth target (GLOBAL_INT, z only) from the layer's depth toward the next, at 0.2 m/s.
    start_m, final_m = float(table.depth_m[down[0]]), float(table.depth_m[down[0] + 1])
    assert len(glide) >= 20 and all(m.type_mask == bridge.MASK_DEPTH_ONLY for m in glide)
    t0 = glide[0].time_boot_ms
    for m in glide:
        expected = min(final_m, start_m + GLIDE_RATE_M_S * (m.time_boot_ms - t0) / 1000.0)
        assert -m.alt == pytest.approx(expected, abs=1e-3)
    assert any(start_m + 1.0 < -m.alt < final_m - 1.0 for m in glide)  # part of the way
    assert -glide[-1].alt == pytest.approx(final_m)
