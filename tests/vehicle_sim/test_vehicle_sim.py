"""The simulated vehicle: pure physics and currents, then ArduSub behaviour over real UDP and MAVLink.

Most UDP tests drive the ``Simulator`` step by step (``step_once``) from the test thread while a
pymavlink ``udpout`` peer talks to it over 127.0.0.1 (``tests.vehicle_sim.harness``): simulated
time is then exact and the tests are deterministic. A few run it in a background thread at a high speedup, and the CLI
as a subprocess; every simulator, thread and process is stopped by the test that started it.
"""

from __future__ import annotations

import csv
import math
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from vehicle_sim.autopilot import AutopilotSettings  # noqa: E402
from planner.contract.modes import SubMode
from vehicle_sim.dynamics import (  # noqa: E402
    M_PER_DEG_LAT,
    Body,
    Setpoint,
    SetpointKind,
    PositionError,
    VehicleParams,
    observe,
    step,
)
from vehicle_sim.endpoint import SimConfig, Simulator  # noqa: E402
from vehicle_sim.world import World  # noqa: E402

from tests.support import REPO  # noqa: E402
from tests.support.helpers import sim_cli  # noqa: E402
from tests.vehicle_sim.harness import DT, QUIET, Peer, north_m, vel_yaw  # noqa: E402

WATER = (33.45, -118.10)  # lat, lon of open water in the synthetic forecast
LAND = (33.69, -117.71)  # the north-east corner: coast

# -- pure physics ------------------------------------------------------------------------


def _run(body: Body, sp: Setpoint, seconds: float, current=(0.0, 0.0), params=QUIET) -> Body:  # type: ignore[no-untyped-def]
    for _ in range(round(seconds / DT)):
        body = step(body, sp, current, params, DT)
    return body


def test_energy_is_hotel_plus_cubic_propulsion_plus_buoyancy():
    start = Body(lat_deg=33.0, lon_deg=-118.0)
    still = _run(start, Setpoint(), 3600.0)
    assert still.energy_used_wh == pytest.approx(8.0, rel=1e-9)  # hotel only
    cruising = _run(start._replace(water_north_m_s=1.0), Setpoint(kind=SetpointKind.VELOCITY, north_m_s=1.0), 3600.0)
    assert cruising.energy_used_wh == pytest.approx(8.0 + 12.0, rel=1e-6)
    half = _run(start._replace(water_north_m_s=0.5), Setpoint(kind=SetpointKind.VELOCITY, north_m_s=0.5), 3600.0)
    assert half.energy_used_wh == pytest.approx(8.0 + 12.0 / 8.0, rel=1e-6)
    gliding = _run(start, Setpoint(kind=SetpointKind.DEPTH, depth_m=100.0), 100.0)  # 0.2 m/s for 100 s: 20 m
    assert gliding.depth_m == pytest.approx(20.0)
    assert gliding.energy_used_wh == pytest.approx((8.0 + 15.0) * 100.0 / 3600.0, rel=1e-6)


def test_yaw_slews_at_the_yaw_rate_the_short_way_or_as_told():
    start = Body(lat_deg=33.0, lon_deg=-118.0, heading_deg=350.0)
    sp = Setpoint(kind=SetpointKind.VELOCITY, yaw_deg=80.0)  # 90 deg clockwise through north
    assert _run(start, sp, 5.0).heading_deg == pytest.approx(40.0)
    assert _run(start, sp, 9.0).heading_deg == pytest.approx(80.0)
    assert _run(start, sp, 30.0).heading_deg == 80.0
    from vehicle_sim.dynamics import TurnDirection

    ccw = Setpoint(kind=SetpointKind.VELOCITY, yaw_deg=80.0, turn=TurnDirection.COUNTER_CLOCKWISE)
    assert _run(start, ccw, 5.0).heading_deg == pytest.approx(300.0)  # the long way round
    slow = Setpoint(kind=SetpointKind.VELOCITY, yaw_deg=80.0, yaw_rate_deg_s=2.0)
    assert _run(start, slow, 6.0).heading_deg == pytest.approx(2.0)


def test_depth_changes_at_the_glide_rate_and_stops_at_the_surface():
    start = Body(lat_deg=33.0, lon_deg=-118.0, depth_m=1.0)
    down = Setpoint(kind=SetpointKind.DEPTH, depth_m=5.0)
    assert _run(start, down, 10.0).depth_m == pytest.approx(3.0)
    assert _run(start, down, 60.0).depth_m == pytest.approx(5.0)
    up_fast = Setpoint(kind=SetpointKind.VELOCITY, down_m_s=-3.0)  # faster than the glide rate, above the surface
    after = _run(start, up_fast, 2.0)
    assert after.depth_m == pytest.approx(0.6)
    assert _run(start, up_fast, 60.0).depth_m == 0.0


def test_drift_is_advection_by_the_current():
    start = Body(lat_deg=33.0, lon_deg=-118.0)
    end = _run(start, Setpoint(), 100.0, current=(0.3, -0.4))
    north_m = (end.lat_deg - start.lat_deg) * M_PER_DEG_LAT
    east_m = (end.lon_deg - start.lon_deg) * M_PER_DEG_LAT * math.cos(math.radians(33.0))
    assert north_m == pytest.approx(-40.0, rel=1e-6)
    assert east_m == pytest.approx(30.0, rel=1e-4)
    assert end.energy_used_wh == pytest.approx(8.0 * 100.0 / 3600.0)


def test_velocity_through_water_accelerates_and_adds_to_the_current():
    start = Body(lat_deg=33.0, lon_deg=-118.0)
    sp = Setpoint(kind=SetpointKind.VELOCITY, north_m_s=1.0)
    assert _run(start, sp, 2.5).water_north_m_s == pytest.approx(0.5)  # 0.2 m/s^2
    b = _run(start, sp, 10.0, current=(0.0, -0.25))
    assert b.water_north_m_s == pytest.approx(1.0)
    assert b.ground_north_m_s == pytest.approx(0.75)
    capped = _run(start, Setpoint(kind=SetpointKind.VELOCITY, north_m_s=5.0), 60.0)
    assert capped.water_speed_m_s == pytest.approx(1.5)  # max speed


def test_position_target_is_held_against_the_current():
    start = Body(lat_deg=33.0, lon_deg=-118.0)
    target_lat = 33.0 + 50.0 / M_PER_DEG_LAT  # 50 m north
    sp = Setpoint(kind=SetpointKind.POSITION, lat_deg=target_lat, lon_deg=-118.0, depth_m=3.0)
    end = _run(start, sp, 600.0, current=(0.3, 0.0))
    assert abs(end.lat_deg - target_lat) * M_PER_DEG_LAT < 0.5
    assert abs(end.lon_deg + 118.0) * M_PER_DEG_LAT * math.cos(math.radians(33.0)) < 0.5
    assert end.depth_m == pytest.approx(3.0)
    assert end.water_east_m_s == pytest.approx(-0.3, abs=0.01)  # pushing against the current


def test_noise_only_on_readings_and_repeatable_from_a_seed():
    body = Body(lat_deg=33.0, lon_deg=-118.0, depth_m=2.0, heading_deg=10.0)
    noisy = VehicleParams(position_noise_m=1.0, heading_noise_deg=1.0, depth_noise_m=0.1)
    a = [observe(body, noisy, rng) for rng in [random.Random(3)] for _ in range(5)]
    b = [observe(body, noisy, rng) for rng in [random.Random(3)] for _ in range(5)]
    assert a == b and len(set(a)) == 5
    assert observe(body, QUIET, random.Random(3)) == (33.0, -118.0, 2.0, 10.0)
    off = observe(body, QUIET, random.Random(3), PositionError(north_m=10.0, east_m=-5.0))
    assert north_m(Body(lat_deg=off.lat_deg), 33.0) == pytest.approx(10.0)
    assert off.lon_deg < -118.0 and (off.depth_m, off.heading_deg) == (2.0, 10.0)


# -- the world -------------------------------------------------------------------------------


def test_world_matches_the_analytic_field_and_marks_land(synthetic_forecast):
    from planner.forecast.synthetic.scb import SyntheticSettings, current_at

    world = World.load(synthetic_forecast)
    settings = SyntheticSettings(seed=0, hours=24)
    assert world.max_depth_m == 15.0 and world.duration_s == 24 * 3600.0
    assert world.start_unix_s == 1768435200.0  # 2026-01-15T00:00:00Z
    box = world.bbox
    assert (box.west_deg, box.south_deg, box.east_deg, box.north_deg) == pytest.approx((-118.26, 33.30, -117.70, 33.70))
    lat, lon = WATER
    # On grid nodes the interpolation is exact (up to the file's float32).
    for t_s, depth in ((0.0, 0.0), (3600.0, 5.0), (7200.0, 10.0)):
        got = world.current_at(t_s, lat, lon, depth)
        want = [float(x) for x in current_at(settings, t_s, lon, lat, depth)]
        assert got == pytest.approx(want, abs=1e-6)
    # Between nodes: bounded by the surrounding nodes, smooth.
    mid = world.current_at(1800.0, lat + 0.005, lon + 0.005, 2.5)
    assert mid == pytest.approx([float(x) for x in current_at(settings, 1800.0, lon + 0.005, lat + 0.005, 2.5)],
                                abs=0.02)
    assert world.is_water(lat, lon, 0.0)
    assert not world.is_water(*LAND, 0.0) and world.current_at(0.0, *LAND, 0.0) == (0.0, 0.0)
    assert not world.is_water(33.0, -118.0, 0.0)  # outside the box
    assert not world.is_water(lat, lon, 16.0)  # deeper than the last level
    # Times beyond the ends take the end fields.
    assert world.current_at(-50.0, lat, lon, 0.0) == world.current_at(0.0, lat, lon, 0.0)
    assert world.current_at(1e7, lat, lon, 0.0) == world.current_at(86400.0, lat, lon, 0.0)


def test_a_curvilinear_forecast_is_resampled_once_at_load(synthetic_forecast):
    import numpy as np

    from planner.forecast import Forecast, open_forecast

    f = open_forecast(synthetic_forecast)
    lon2, lat2 = np.meshgrid(f.lon_deg, f.lat_deg)  # the same points, as a 2-D (curvilinear) grid
    curvy = Forecast(source="curvy.nc", identity="test", time_s=f.time_s[:3], time_origin=f.time_origin,
                     lon_deg=lon2, lat_deg=lat2, depth_m=f.depth_m, u_east_m_s=f.u_east_m_s[:3],
                     v_north_m_s=f.v_north_m_s[:3])
    world, regular = World.from_forecast(curvy), World.from_forecast(f)
    assert len(world.lon_deg) == pytest.approx(len(regular.lon_deg), abs=2)  # about the native resolution
    lat, lon = WATER
    for t_s, depth in ((0.0, 0.0), (5400.0, 7.5)):
        assert world.current_at(t_s, lat + 0.003, lon, depth) == pytest.approx(
            regular.current_at(t_s, lat + 0.003, lon, depth), abs=0.01)
    assert not world.is_water(*LAND, 0.0)


def test_world_lookup_costs_microseconds(synthetic_forecast):
    world = World.load(synthetic_forecast)
    lat, lon = WATER
    n = 20_000
    t0 = time.perf_counter()
    for i in range(n):
        world.current_at(i * 0.1, lat + i * 1e-6, lon, 3.0)
    per_call_us = (time.perf_counter() - t0) / n * 1e6
    assert per_call_us < 100.0  # a loose bound (about 5 us on a laptop); the real check is the speedup figure


def test_calm_and_uniform_worlds():
    assert World.calm().current_at(0.0, 10.0, 20.0, 300.0) == (0.0, 0.0)
    assert World.uniform(0.2, -0.1).current_at(1e6, -40.0, 170.0, 5.0) == pytest.approx((0.2, -0.1))
    assert World.calm().is_water(0.0, 0.0, 1000.0)


# -- identity, modes, arming, rates ----------------------------------------------------------------


def test_boots_as_a_disarmed_submarine_in_manual(bench):
    b = bench()
    b.advance(3.0)
    hb = [m for m in b.peer.of("HEARTBEAT") if m.get_srcComponent() == 1]
    assert len(hb) == 4 and all(m.get_srcSystem() == 1 for m in hb)  # 1 Hz from the first step: 0.1 .. 3.1 s
    m = hb[-1]
    assert (m.type, m.autopilot) == (mavlink.MAV_TYPE_SUBMARINE, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
    assert m.custom_mode == SubMode.MANUAL and not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert m.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert m.system_status == mavlink.MAV_STATE_STANDBY
    assert hb[0].get_header().mlen > 0 and b.peer.conn.WIRE_PROTOCOL_VERSION == "2.0"
    st = b.peer.of("SYSTEM_TIME")[-1]
    assert st.time_boot_ms <= 3100 and st.time_unix_usec == pytest.approx(st.time_boot_ms * 1000, abs=1)


def test_guided_is_refused_until_the_position_estimate_exists(bench):
    b = bench(position_delay_s=41.0)
    b.advance(10.0)
    assert not b.peer.of("EKF_STATUS_REPORT")[-1].flags & mavlink.EKF_POS_HORIZ_ABS
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.GUIDED)
    assert b.peer.acks(mavlink.MAV_CMD_DO_SET_MODE) == [mavlink.MAV_RESULT_FAILED]
    assert "Mode change failed: GUIDED requires position" in b.peer.texts()  # ArduSub's words
    assert b.sim.mode is SubMode.MANUAL
    b.advance(32.0)  # past 41 s
    assert b.peer.of("EKF_STATUS_REPORT")[-1].flags & mavlink.EKF_POS_HORIZ_ABS
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.GUIDED)
    assert b.peer.acks(mavlink.MAV_CMD_DO_SET_MODE)[-1] == mavlink.MAV_RESULT_ACCEPTED
    b.advance(1.0)
    hb = [m for m in b.peer.of("HEARTBEAT") if m.get_srcComponent() == 1][-1]
    assert hb.custom_mode == SubMode.GUIDED and hb.base_mode & mavlink.MAV_MODE_FLAG_GUIDED_ENABLED


def test_arming_set_mode_message_and_unknown_commands_are_acknowledged(bench):
    b = bench()
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert b.peer.acks(mavlink.MAV_CMD_COMPONENT_ARM_DISARM) == [mavlink.MAV_RESULT_ACCEPTED] and b.sim.armed
    b.advance(1.0)
    hb = [m for m in b.peer.of("HEARTBEAT") if m.get_srcComponent() == 1][-1]
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and hb.system_status == mavlink.MAV_STATE_ACTIVE
    b.peer.mav.set_mode_send(1, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, SubMode.ALT_HOLD)
    b.step(1)
    assert b.sim.mode is SubMode.ALT_HOLD
    assert b.peer.acks(mavlink.MAVLINK_MSG_ID_SET_MODE) == [mavlink.MAV_RESULT_ACCEPTED]  # as ArduPilot does
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 7)  # CIRCLE: not simulated
    assert b.peer.acks(mavlink.MAV_CMD_DO_SET_MODE) == [mavlink.MAV_RESULT_FAILED]
    b.command(mavlink.MAV_CMD_NAV_TAKEOFF)
    assert b.peer.acks(mavlink.MAV_CMD_NAV_TAKEOFF) == [mavlink.MAV_RESULT_UNSUPPORTED]
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0)
    assert b.peer.acks(mavlink.MAV_CMD_COMPONENT_ARM_DISARM)[-1] == mavlink.MAV_RESULT_ACCEPTED and not b.sim.armed


def test_messages_for_another_system_or_component_are_ignored(bench):
    b = bench()
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=(2, 1))
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=(1, 191))
    assert not b.sim.armed and b.peer.acks(mavlink.MAV_CMD_COMPONENT_ARM_DISARM) == []
    assert b.sim.stats.ignored == 2
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=(0, 0))  # broadcast
    assert b.sim.armed


def _per_second(msgs: list, kind: str, start_ms: int, end_ms: int) -> float:  # type: ignore[type-arg]
    times = [m.time_boot_ms for m in msgs if m.get_type() == kind and start_ms <= m.time_boot_ms < end_ms]
    return len(times) / ((end_ms - start_ms) / 1000.0)


def test_set_message_interval_changes_rates_in_simulated_time(bench):
    b = bench()
    b.advance(10.0)
    assert _per_second(b.peer.got, "GLOBAL_POSITION_INT", 1000, 10000) == pytest.approx(3.0, abs=0.2)
    assert _per_second(b.peer.got, "ATTITUDE", 1000, 10000) == pytest.approx(10.0, abs=0.2)
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 100_000)
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, 500_000)
    assert b.peer.acks(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL) == [mavlink.MAV_RESULT_ACCEPTED] * 2
    t0 = b.sim._t_ms
    b.advance(10.0)
    assert _per_second(b.peer.got, "GLOBAL_POSITION_INT", t0, t0 + 10000) == pytest.approx(10.0, abs=0.2)
    assert _per_second(b.peer.got, "ATTITUDE", t0, t0 + 10000) == pytest.approx(2.0, abs=0.2)
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, -1)  # stop
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 0)  # default
    t1 = b.sim._t_ms
    b.advance(6.0)
    assert _per_second(b.peer.got, "ATTITUDE", t1 + 1, t1 + 6000) == 0.0
    assert _per_second(b.peer.got, "GLOBAL_POSITION_INT", t1, t1 + 6000) == pytest.approx(3.0, abs=0.4)
    n = len(b.peer.of("AUTOPILOT_VERSION"))
    b.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert b.peer.acks(mavlink.MAV_CMD_REQUEST_MESSAGE) == [mavlink.MAV_RESULT_ACCEPTED]
    assert len(b.peer.of("AUTOPILOT_VERSION")) == n + 1
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 9999, 100_000)
    assert b.peer.acks(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)[-1] == mavlink.MAV_RESULT_FAILED


def test_telemetry_units_follow_ardusub(bench):
    b = bench(depth_m=4.0, heading_deg=270.0)
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    b.advance(2.0)
    gpi = b.peer.of("GLOBAL_POSITION_INT")[-1]
    assert gpi.relative_alt == -4000 and gpi.alt == -4000  # mm, negative below the surface
    assert gpi.hdg == 27000 and (gpi.lat, gpi.lon) == (330000000, -1180000000)
    att = b.peer.of("ATTITUDE")[-1]
    assert att.yaw == pytest.approx(-math.pi / 2)  # -pi..pi
    hud = b.peer.of("VFR_HUD")[-1]
    assert hud.heading == 270 and hud.alt == pytest.approx(-4.0)
    bat = b.peer.of("BATTERY_STATUS")[-1]
    assert bat.energy_consumed == round(b.sim.energy_used_wh * 36.0) or bat.energy_consumed > 0
    assert bat.battery_remaining == 100 and b.peer.of("SYS_STATUS")[-1].battery_remaining == 100


# -- GUIDED targets ------------------------------------------------------------------------------------


def test_local_ned_velocity_moves_north_and_expires_after_3_s(bench):
    b = bench()
    b.guided_and_armed()
    lat0 = b.sim.body.lat_deg
    for _ in range(20):  # 1 m/s north, yaw 0, re-sent at 1 Hz for 20 s
        vel_yaw(b.peer, 1.0, 0.0, 0.0)
        b.advance(1.0)
    moved = north_m(b.sim.body, lat0)
    assert 15.0 < moved < 20.0 and b.sim.body.water_north_m_s == pytest.approx(1.0)
    # The last update was 1 s ago: still going until 3 s after it ...
    b.advance(1.9)
    assert b.sim.body.water_north_m_s == pytest.approx(1.0)
    # ... then it stops (zero velocity through the water, 0.2 m/s^2 deceleration).
    b.advance(0.3)
    assert b.sim.body.water_north_m_s < 1.0
    b.advance(5.0)
    assert b.sim.body.water_speed_m_s == 0.0
    held = b.sim.body.lat_deg
    b.advance(10.0)
    assert b.sim.body.lat_deg == held and b.sim.mode is SubMode.GUIDED


def test_global_int_yaw_is_ignored_but_condition_yaw_turns(bench):
    b = bench()
    b.guided_and_armed()
    b.peer.mav.set_position_target_global_int_send(  # velocity only, with a yaw that ArduSub ignores
        0, 1, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 3527 - 1024, 0, 0, 0.0, 0.5, 0.0, 0.0, 0, 0, 0,
        math.radians(90.0), 0)
    b.advance(2.9)
    assert b.sim.body.heading_deg == 0.0 and b.sim.body.water_north_m_s == pytest.approx(0.5)
    b.command(mavlink.MAV_CMD_CONDITION_YAW, 90.0, 0.0, 1.0, 0.0)  # no rate: ArduSub's own slew
    assert b.peer.acks(mavlink.MAV_CMD_CONDITION_YAW) == [mavlink.MAV_RESULT_ACCEPTED]
    b.advance(0.9)
    assert b.sim.body.heading_deg == pytest.approx(30.0)  # 30 deg/s for 1.0 s (the command's step too)
    b.advance(10.0)
    assert b.sim.body.heading_deg == pytest.approx(90.0)
    b.command(mavlink.MAV_CMD_CONDITION_YAW, 45.0, 5.0, -1.0, 1.0)  # 45 deg to the left, 5 deg/s
    b.advance(5.0)
    assert b.sim.body.heading_deg == pytest.approx(90.0 - 5.0 * 5.1)
    b.command(mavlink.MAV_CMD_CONDITION_YAW, 400.0)
    assert b.peer.acks(mavlink.MAV_CMD_CONDITION_YAW)[-1] == mavlink.MAV_RESULT_FAILED


def test_local_ned_yaw_and_global_int_position_target(bench):
    b = bench()
    b.guided_and_armed()
    vel_yaw(b.peer, 0.0, 0.0, 200.0)  # shortest way: 160 deg counter-clockwise
    b.advance(3.0)
    assert b.sim.body.heading_deg == pytest.approx(270.0, abs=0.6)  # at ArduSub's 30 deg/s
    b.advance(5.0)
    assert b.sim.body.heading_deg == pytest.approx(200.0)
    lat0, lon0 = b.sim.body.lat_deg, b.sim.body.lon_deg
    goal_lat = lat0 + 10.0 / M_PER_DEG_LAT
    goal_lon = lon0 + 10.0 / (M_PER_DEG_LAT * math.cos(math.radians(lat0)))
    b.peer.mav.set_position_target_global_int_send(
        0, 1, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 3576, round(goal_lat * 1e7), round(goal_lon * 1e7), -3.0,
        0, 0, 0, 0, 0, 0, 0, 0)
    b.advance(60.0)
    body = b.sim.body
    assert abs(body.lat_deg - goal_lat) * M_PER_DEG_LAT < 0.3 and body.depth_m == pytest.approx(3.0)
    b.peer.mav.set_position_target_global_int_send(  # depth only in GUIDED: ArduSub ignores it
        0, 1, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 3579, 0, 0, -8.0, 0, 0, 0, 0, 0, 0, 0, 0)
    b.advance(10.0)
    assert b.sim.body.depth_m == pytest.approx(3.0)


def test_alt_hold_depth_target_is_reached_at_ardusubs_rate_and_the_vehicle_drifts(bench):
    b = bench(World.uniform(0.1, 0.0))
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.ALT_HOLD)
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    b.peer.mav.set_position_target_global_int_send(
        0, 1, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 3579, 0, 0, -5.0, 0, 0, 0, 0, 0, 0, 0, 0)
    lon0 = b.sim.body.lon_deg
    b.advance(2.0)
    assert b.sim.body.depth_m == pytest.approx(2.0, abs=0.15)  # about 1 m/s, not the mission's glide rate
    b.advance(28.0)
    assert b.sim.body.depth_m == pytest.approx(5.0)
    assert b.peer.of("GLOBAL_POSITION_INT")[-1].relative_alt == -5000
    east_m = (b.sim.body.lon_deg - lon0) * M_PER_DEG_LAT * math.cos(math.radians(33.0))
    assert east_m == pytest.approx(0.1 * 30.0, abs=0.15)  # no horizontal thrust: drifts with the current
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.SURFACE)
    b.advance(3.0)
    assert b.sim.body.depth_m == pytest.approx(1.9, abs=0.05) and b.sim.mode is SubMode.SURFACE  # up at 1 m/s
    b.advance(5.0)
    assert b.sim.body.depth_m <= 0.1 and b.sim.mode is SubMode.ALT_HOLD  # at the surface: SURFACE_COMPLETE


# -- failsafes ------------------------------------------------------------------------------------------


def test_gcs_heartbeat_loss_surfaces_and_regains(bench):
    b = bench(system=255, component=190, depth_m=5.0)
    b.guided_and_armed()
    b.beating = False
    b.advance(4.0)
    assert b.sim.mode is SubMode.GUIDED and not any("heartbeat lost" in t for t in b.peer.texts())
    b.advance(2.0)
    lost = [m for m in b.peer.of("STATUSTEXT") if "heartbeat lost" in m.text]
    assert len(lost) == 1 and lost[0].severity == mavlink.MAV_SEVERITY_CRITICAL
    assert b.sim.mode is SubMode.SURFACE and b.sim.armed
    b.advance(1.0)
    hb = [m for m in b.peer.of("HEARTBEAT") if m.get_srcComponent() == 1][-1]
    assert hb.custom_mode == SubMode.SURFACE and hb.system_status == mavlink.MAV_STATE_CRITICAL
    assert 2.5 < b.sim.body.depth_m < 4.5  # up at 1 m/s since the failsafe, 1 to 2 s ago
    b.beating = True
    b.advance(2.0)
    assert any("heartbeat regained" in t for t in b.peer.texts())
    assert b.sim.mode is SubMode.SURFACE  # stays where the failsafe put it
    b.advance(5.0)
    assert b.sim.mode is SubMode.ALT_HOLD and b.sim.body.depth_m <= 0.1  # until the surface


@pytest.mark.parametrize(("action", "mode", "armed"), [("alt_hold", SubMode.ALT_HOLD, True),
                                                       ("disarm", SubMode.GUIDED, False),
                                                       ("warn", SubMode.GUIDED, True)])
def test_failsafe_actions(bench, action, mode, armed):
    from vehicle_sim.autopilot import FailsafeAction

    b = bench(failsafe=FailsafeAction(action))
    b.guided_and_armed()
    b.beating = False
    b.advance(6.0)
    assert any("heartbeat lost" in t for t in b.peer.texts())
    assert (b.sim.mode, b.sim.armed) == (mode, armed)


def test_an_untracked_peer_does_not_feed_the_failsafe_and_an_empty_battery_surfaces(bench):
    b = bench(system=42, component=1, depth_m=2.0, params=VehicleParams(battery_wh=0.05, position_noise_m=0.0))
    b.guided_and_armed()
    b.advance(30.0)  # untracked heartbeats: no failsafe ever started
    assert not any("heartbeat lost" in t for t in b.peer.texts())
    assert "Battery empty: surfacing" in b.peer.texts()
    assert b.sim.mode is SubMode.ALT_HOLD and b.sim.body.depth_m <= 0.1  # surfaced, then SURFACE_COMPLETE
    assert b.peer.of("BATTERY_STATUS")[-1].battery_remaining == 0


# -- currents, determinism, speed, robustness -------------------------------------------------------------


def test_the_current_carries_a_drifting_vehicle(bench, synthetic_forecast):
    world = World.load(synthetic_forecast)
    b = bench(world, lat_lon=WATER)
    b.advance(600.0)
    body = b.sim.body
    # Integrate the world's current along the way with a coarser Euler step: the same drift.
    lat, lon = WATER
    for k in range(600):
        u, v = world.current_at(k + 0.5, lat, lon, 0.0)
        lat += v / M_PER_DEG_LAT
        lon += u / (M_PER_DEG_LAT * math.cos(math.radians(lat)))
    dn = (body.lat_deg - WATER[0]) * M_PER_DEG_LAT
    assert math.hypot(dn, (body.lon_deg - WATER[1]) * M_PER_DEG_LAT * math.cos(math.radians(lat))) > 20.0
    assert abs(body.lat_deg - lat) * M_PER_DEG_LAT < 0.5 and abs(body.lon_deg - lon) * M_PER_DEG_LAT < 0.5
    gpi = b.peer.of("GLOBAL_POSITION_INT")[-1]
    u, v = world.current_at(b.sim.time_s, body.lat_deg, body.lon_deg, 0.0)
    assert (gpi.vx, gpi.vy) == (pytest.approx(v * 100, abs=1.01), pytest.approx(u * 100, abs=1.01))  # cm/s


def _scripted_run(track: Path, seed: int, world: World) -> list[tuple[int, int, int]]:
    """A fixed script of commands, stepped; returns the reported (time, lat, lon) of GLOBAL_POSITION_INT."""
    config = SimConfig(start_lat_deg=WATER[0], start_lon_deg=WATER[1], port=0, seed=seed, track_path=track,
                       autopilot=AutopilotSettings(position_delay_s=2.0))
    sim = Simulator(world, config)
    peer = Peer(sim.port, 1, 191)
    try:
        for k in range(1200):
            if k % 10 == 0:
                peer.heartbeat()
            if k == 30:
                peer.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.GUIDED)
                peer.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            if 30 < k < 800 and k % 10 == 5:
                vel_yaw(peer, 0.6, 0.6, 45.0)
            sim.step_once()
            peer.drain()
    finally:
        peer.close()
        sim.close()
    return [(m.time_boot_ms, m.lat, m.lon) for m in peer.of("GLOBAL_POSITION_INT")]


def test_same_seed_same_track_and_telemetry(tmp_path, synthetic_forecast):
    world = World.load(synthetic_forecast)
    a = _scripted_run(tmp_path / "a.csv", 7, world)
    b = _scripted_run(tmp_path / "b.csv", 7, world)
    c = _scripted_run(tmp_path / "c.csv", 8, world)
    track_a = (tmp_path / "a.csv").read_text()
    assert track_a == (tmp_path / "b.csv").read_text() and a == b and len(a) > 300
    assert track_a == (tmp_path / "c.csv").read_text()  # noise is on readings only: the truth is the same
    assert a != c
    rows = list(csv.DictReader(track_a.splitlines()))
    assert list(rows[0]) == ["time_s", "lat_deg", "lon_deg", "depth_m", "heading_deg", "mode", "armed",
                             "energy_used_wh"]
    assert rows[0]["time_s"] == "0.000" and rows[-1]["time_s"] == "120.000" and rows[-1]["mode"] == "4"


@pytest.fixture()
def threaded():
    """A simulator running in a background thread; always stopped."""
    started: list[tuple[Simulator, threading.Event, threading.Thread]] = []

    def start(world: World | None = None, **config) -> Simulator:  # type: ignore[no-untyped-def]
        sim = Simulator(world or World.calm(), SimConfig(start_lat_deg=33.0, start_lon_deg=-118.0, port=0, **config))
        stop = threading.Event()
        thread = threading.Thread(target=sim.run, kwargs={"stop_event": stop}, daemon=True)
        thread.start()
        started.append((sim, stop, thread))
        return sim

    yield start
    for sim, stop, thread in started:
        stop.set()
        thread.join(timeout=10)
        sim.close()


def _wait_for(peer: Peer, predicate, timeout_s: float = 5.0):  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for m in peer.drain(0.02):
            if predicate(m):
                return m
    return None


def test_simulated_time_runs_at_the_speedup(threaded):
    sim = threaded(speedup=100.0)
    peer = Peer(sim.port)
    try:
        wall0 = time.monotonic()
        peer.heartbeat()
        assert _wait_for(peer, lambda m: m.get_type() == "SYSTEM_TIME") is not None
        time.sleep(0.5)
        peer.drain(0.05)
        wall = time.monotonic() - wall0
    finally:
        peer.close()
    sim_s = max(m.time_boot_ms for m in peer.got if hasattr(m, "time_boot_ms")) / 1000.0
    assert sim_s > 5.0 * wall  # far faster than real time
    assert sim_s <= 100.0 * wall + 1.0  # and never ahead of the asked speedup


def test_garbage_datagrams_do_not_crash_it(threaded):
    # A modest speedup: flat out, telemetry floods the peer's socket and can push the ACK out of it.
    sim = threaded(speedup=100)
    peer = Peer(sim.port)
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        peer.heartbeat()  # known to the simulator, so it hears the ACK to the raw socket's command
        assert _wait_for(peer, lambda m: m.get_type() == "HEARTBEAT") is not None
        rng = random.Random(0)
        good = peer.mav.command_long_encode(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        frame = bytearray(good.pack(mavlink.MAVLink(None, 255, 190)))
        bad_crc = bytes(frame[:-1]) + bytes([frame[-1] ^ 0xFF])
        junk = [b"", b"\x00", b"\xfd", b"\xfd\xff" + bytes(20), bad_crc, bytes(frame[:9]), b"hello world" * 50,
                bytes(frame[:5]) + b"\xff\xff\xff" + bytes(frame[8:])]
        junk += [bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300))) for _ in range(200)]
        for data in junk:
            raw.sendto(data, ("127.0.0.1", sim.port))
        raw.sendto(bytes(frame), ("127.0.0.1", sim.port))  # a good frame right after the garbage
        ack = _wait_for(peer, lambda m: m.get_type() == "COMMAND_ACK"
                        and m.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
    finally:
        raw.close()
        peer.close()
    assert ack is not None and sim.stats.parse_errors > 100 and sim.armed


# -- the command line ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("args", [
    ("--forecast", "{fc}", "--start", "-117.71,33.69"),  # on land
    ("--forecast", "{fc}", "--start", "-119.5,33.45"),  # outside the forecast
    ("--forecast", "{fc}", "--start", "-118.10,33.45", "--speedup", "fast"),
    ("--forecast", "no/such/file.nc", "--start", "-118.10,33.45"),
])
def test_cli_bad_input_is_one_line_and_status_2(args, synthetic_forecast):
    done = sim_cli(*(a.format(fc=synthetic_forecast) for a in args))
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lrauv sim: error: ") and done.stdout == ""
    assert "Traceback" not in done.stderr


def test_cli_runs_for_a_duration_and_stops_cleanly_on_sigterm(tmp_path, synthetic_forecast):
    track = tmp_path / "t.csv"
    done = sim_cli("--forecast", str(synthetic_forecast), "--start", "-118.10,33.45", "--speedup", "1e9",
                "--no-lockstep", "--listen", "127.0.0.1:0", "--duration-s", "120", "--track", str(track), "--quiet")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("lrauv sim: listening on udp 127.0.0.1:") and done.stderr == ""
    assert len(track.read_text().splitlines()) == 1 + 121  # header, rows at 0..120 s

    proc = subprocess.Popen([sys.executable, "-m", "vehicle_sim", "sim", "--calm", "--speedup", "10", "--no-lockstep",
                             "--listen", "127.0.0.1:0", "--track", str(track)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("lrauv sim: listening on udp 127.0.0.1:")
        port = int(line.strip().rsplit(":", 1)[1])
        peer = Peer(port)
        peer.heartbeat()
        assert _wait_for(peer, lambda m: m.get_type() == "HEARTBEAT") is not None
        peer.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    rows = track.read_text().splitlines()
    assert rows[0].startswith("time_s,") and len(rows) >= 2  # flushed at exit
    assert "stopped at" in (proc.stderr.read() if proc.stderr else "")
