"""``lrauv sim`` behaves like ArduSub SITL in each point of the facts file, over real UDP and MAVLink.

What ArduSub SITL did (ardusub-sitl-facts.md): turned 45 deg in 1.3-2.0 s with no yaw rate
commanded and obeyed a commanded one; changed depth at about 1 m/s (0 -> 5 m in 5 s) toward an
ALT_HOLD target and at a commanded vz as given; switched SURFACE to ALT_HOLD by itself at the
surface; counted only MAV_GCS_SYSID's heartbeats for its GCS failsafe and never fired before
one was seen; sent lat = lon = 0 before its GPS was found (about 9 s) and refused GUIDED until
its EKF had a position (41 s), arming in MANUAL before; streamed its other defaults (AHRS2 and
SIMSTATE at 10 Hz, NAMED_VALUE_FLOAT at 18 Hz, ...), each switchable with
MAV_CMD_SET_MESSAGE_INTERVAL; and its positions were smooth. The simulator is stepped from the
test thread (``tests.vehicle_sim.harness``), so simulated time is exact.
"""

from __future__ import annotations

import math
import random
import subprocess
import sys
from collections import Counter

import pytest

from tests.support import REPO
from tests.support.helpers import sim_cli, wait_until
from tests.vehicle_sim.harness import QUIET, Bench, Peer, north_m, vel_yaw
from planner.contract.modes import SubMode
from planner.contract.vehicle import VehicleParams
from vehicle_sim.autopilot import ARDUSUB_EXTRA_INTERVALS_S, AutopilotSettings, FailsafeAction
from vehicle_sim.dynamics import M_PER_DEG_LAT, NO_ERROR, drift_error
from vehicle_sim.endpoint import SimConfig
from vehicle_sim.profile import Profile, with_profile

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # after harness: MAVLink 2 set there

MASK_VEL_YAW = 2503  # velocity + yaw; yaw rate ignored (YAW_RATE_IGNORE 2048)
MASK_VEL_YAW_RATE = MASK_VEL_YAW - 2048  # velocity + yaw + yaw rate
MASK_VEL = MASK_VEL_YAW + 1024  # velocity only
MASK_DEPTH_ONLY = 3579  # SET_POSITION_TARGET_GLOBAL_INT: z only


def _heading_error(b: Bench, target_deg: float) -> float:
    return abs((b.sim.body.heading_deg - target_deg + 180.0) % 360.0 - 180.0)


def _seconds_until(b: Bench, done, limit_s: float = 60.0) -> float:  # type: ignore[no-untyped-def]
    """Simulated seconds stepped until ``done()``."""
    t0 = b.sim.time_s
    while not done():
        assert b.sim.time_s - t0 < limit_s, "not reached"
        b.step(1)
    return b.sim.time_s - t0


# -- yaw and depth at ArduSub's rates, or the commanded ones ---------------------------------------


def test_yaw_without_a_commanded_rate_turns_45_deg_in_1_3_to_2_s(bench):
    b = bench()
    b.guided_and_armed()
    vel_yaw(b.peer, 0.0, 0.0, 45.0)  # YAW_RATE_IGNORE set: ArduSub's own slew
    took = _seconds_until(b, lambda: _heading_error(b, 45.0) < 1.0)
    assert 1.3 <= took <= 2.0  # the mission's 10 deg/s took 4.5 s
    assert max(m.yawspeed for m in b.peer.of("ATTITUDE")) == pytest.approx(math.radians(30.0))


def test_a_commanded_yaw_rate_is_obeyed_and_a_moving_yaw_target_followed_at_its_rate(bench):
    b = bench()
    b.guided_and_armed()
    b.peer.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, MASK_VEL_YAW_RATE, 0, 0, 0,
                                                  0.0, 0.0, 0.0, 0, 0, 0, math.radians(90.0), math.radians(20.0))
    b.advance(3.0)
    assert b.sim.body.heading_deg == pytest.approx(20.0 * 3.0, abs=0.5)  # 20 deg/s, not 10 and not 30
    # The executive's way: the yaw field moved toward the final heading at the plan's rate (5 deg/s,
    # re-sent every second) with that rate as yaw_rate: the vehicle turns at 5 deg/s on average.
    start = b.sim.body.heading_deg
    for k in range(1, 9):
        b.peer.mav.set_position_target_local_ned_send(
            0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, MASK_VEL_YAW_RATE, 0, 0, 0, 0.0, 0.0, 0.0, 0, 0, 0,
            math.radians(start + 5.0 * k), math.radians(5.0))
        b.advance(1.0)
    assert b.sim.body.heading_deg - start == pytest.approx(40.0, abs=1.0)  # less a lag under a degree


def test_depth_target_in_alt_hold_is_flown_at_about_1_m_s_and_draws_power_only_meanwhile(bench):
    b = bench()
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.ALT_HOLD)
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    b.peer.mav.set_position_target_global_int_send(
        0, 1, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, MASK_DEPTH_ONLY, 0, 0, -5.0, 0, 0, 0, 0, 0, 0, 0, 0)
    e0 = b.sim.energy_used_wh
    took = _seconds_until(b, lambda: b.sim.body.depth_m > 4.9)
    assert 4.5 <= took <= 5.5  # 0 -> 5 m in about 5 s (the mission's 0.2 m/s took 25 s)
    assert max(m.climb for m in b.peer.of("VFR_HUD")) == pytest.approx(0.0) and \
        min(m.climb for m in b.peer.of("VFR_HUD")) == pytest.approx(-1.0)
    hotel_w, buoyancy_w = QUIET.hotel_w, QUIET.buoyancy_w
    gliding_wh = b.sim.energy_used_wh - e0
    assert gliding_wh == pytest.approx((hotel_w + buoyancy_w) * took / 3600.0, rel=0.05)
    b.advance(5.0)  # settled: hotel power only
    e1 = b.sim.energy_used_wh
    b.advance(10.0)
    assert b.sim.energy_used_wh - e1 == pytest.approx(hotel_w * 10.0 / 3600.0, rel=1e-6)
    assert b.sim.body.depth_m == pytest.approx(5.0, abs=0.001)


def test_a_commanded_vertical_speed_in_guided_is_flown_as_given(bench):
    b = bench(depth_m=5.0)
    b.guided_and_armed()
    for _ in range(12):  # vz +0.25 m/s re-sent every second: 5 -> 8 m in 12 s, as on ArduSub
        b.peer.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, MASK_VEL, 0, 0, 0,
                                                      0.0, 0.0, 0.25, 0, 0, 0, 0, 0)
        b.advance(1.0)
    assert b.sim.body.depth_m == pytest.approx(8.0, abs=0.05)  # the mission's glide rate capped it at 0.2 m/s


# -- SURFACE completes by itself -----------------------------------------------------------------------


def test_surface_switches_itself_to_alt_hold_at_the_surface_without_a_text(bench):
    b = bench(depth_m=3.0)
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.SURFACE)
    assert b.peer.acks(mavlink.MAV_CMD_DO_SET_MODE) == [mavlink.MAV_RESULT_ACCEPTED]
    b.advance(2.0)
    assert b.sim.mode is SubMode.SURFACE and b.sim.body.depth_m > 0.5
    took = _seconds_until(b, lambda: b.sim.mode is SubMode.ALT_HOLD)
    assert b.sim.body.depth_m <= 0.1 and took < 2.0  # up at 1 m/s
    b.advance(3.0)
    modes = [m.custom_mode for m in b.peer.of("HEARTBEAT") if m.get_srcComponent() == 1]
    assert SubMode.SURFACE in modes and modes[-1] == SubMode.ALT_HOLD and b.sim.armed
    assert b.peer.texts() == []  # ArduSub announces nothing
    assert b.sim.body.depth_m <= 0.1  # held there
    # Asked again at the surface: accepted, and at once ALT_HOLD again.
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.SURFACE)
    assert b.peer.acks(mavlink.MAV_CMD_DO_SET_MODE)[-1] == mavlink.MAV_RESULT_ACCEPTED
    b.step(1)
    assert b.sim.mode is SubMode.ALT_HOLD


# -- GCS failsafe on MAV_GCS_SYSID only ------------------------------------------------------------------


@pytest.mark.parametrize("gcs_system", [255, 1])
def test_gcs_failsafe_counts_only_mav_gcs_sysid(bench, gcs_system):
    """The companion computer (1/191) feeds the failsafe only where MAV_GCS_SYSID is 1."""
    b = bench(system=1, component=191, gcs_system=gcs_system)
    b.guided_and_armed()
    b.beating = False
    b.advance(30.0)
    lost = [t for t in b.peer.texts() if "heartbeat lost" in t]
    if gcs_system == 255:
        assert lost == [] and b.sim.mode is SubMode.GUIDED  # no GCS ever seen: never fires
    else:
        assert len(lost) == 1 and b.sim.mode is not SubMode.GUIDED


def test_gcs_failsafe_never_fires_before_a_gcs_heartbeat(bench):
    b = bench(system=42, component=1)  # a peer whose heartbeats do not count
    b.guided_and_armed()
    b.advance(20.0)
    assert not any("heartbeat lost" in t for t in b.peer.texts()) and b.sim.mode is SubMode.GUIDED
    gcs = Peer(b.sim.port, 255, 190)
    try:
        gcs.heartbeat()  # a ground station is heard once, then falls silent
        b.advance(6.0)
    finally:
        gcs.close()
    assert any("heartbeat lost from 255/190" in t for t in b.peer.texts())


# -- no position before the EKF is ready -------------------------------------------------------------------


def test_no_position_before_the_gps_and_no_guided_before_the_ekf_but_arming_in_manual(bench):
    b = bench(position_delay_s=41.0, gps_delay_s=9.0)
    b.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)  # in MANUAL, long before the EKF: accepted
    assert b.peer.acks(mavlink.MAV_CMD_COMPONENT_ARM_DISARM) == [mavlink.MAV_RESULT_ACCEPTED] and b.sim.armed
    b.advance(8.5)
    early = b.peer.of("GLOBAL_POSITION_INT")
    assert early and all((m.lat, m.lon) == (0, 0) for m in early)  # not a position
    assert all(m.relative_alt == 0 for m in early)  # the depth sensor works from boot
    b.advance(1.0)
    gpi = b.peer.of("GLOBAL_POSITION_INT")[-1]
    assert (gpi.lat, gpi.lon) == (330000000, -1180000000)  # the GPS is found at 9 s
    assert not b.peer.of("EKF_STATUS_REPORT")[-1].flags & mavlink.EKF_POS_HORIZ_ABS
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.GUIDED)
    assert b.peer.acks(mavlink.MAV_CMD_DO_SET_MODE) == [mavlink.MAV_RESULT_FAILED]
    b.advance(41.0 - b.sim.time_s + 0.5)
    assert b.peer.of("EKF_STATUS_REPORT")[-1].flags & mavlink.EKF_POS_HORIZ_ABS
    b.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.GUIDED)
    assert b.peer.acks(mavlink.MAV_CMD_DO_SET_MODE)[-1] == mavlink.MAV_RESULT_ACCEPTED


# -- ArduSub's other default streams ---------------------------------------------------------------------


def _rates(b: Bench, seconds: float) -> dict[str, float]:
    """Messages per second of each type the autopilot sends over the next ``seconds`` of simulated time."""
    mark = len(b.peer.got)
    b.advance(seconds)
    counts = Counter(m.get_type() for m in b.peer.got[mark:] if m.get_srcComponent() == 1)
    return {kind: n / seconds for kind, n in counts.items()}


def test_ardusub_streams_at_ardusubs_rates_each_switchable(bench):
    b = bench(sim={"ardusub_streams": True})
    rates = _rates(b, 10.0)
    assert len(rates) == 27  # the eight the executive reads and ArduSub's nineteen others
    assert rates["AHRS2"] == rates["SIMSTATE"] == rates["ATTITUDE"] == pytest.approx(10.0, abs=0.2)
    assert rates["NAMED_VALUE_FLOAT"] == pytest.approx(18.0, abs=1.0)
    assert rates["VIBRATION"] == rates["TERRAIN_REPORT"] == pytest.approx(3.0, abs=0.2)
    assert rates["GPS_RAW_INT"] == rates["SCALED_PRESSURE2"] == rates["RC_CHANNELS"] == pytest.approx(2.0, abs=0.2)
    assert sum(rates.values()) == pytest.approx(110.0, abs=3.0)  # ArduSub SITL: about 91 to 110 a second
    names = {m.name for m in b.peer.of("NAMED_VALUE_FLOAT")}
    assert {"CamTilt", "Lights1", "PilotGain"} <= names and len(names) == 9
    gps = b.peer.of("GPS_RAW_INT")[-1]
    assert gps.fix_type == 3 and (gps.lat, gps.lon) == (330000000, -1180000000)
    press = b.peer.of("SCALED_PRESSURE2")[-1]
    assert press.press_abs == pytest.approx(1013.25)  # at the surface
    # Switched off one by one with interval -1, and set by a positive interval, as ArduPilot does.
    for name in ("AHRS2", "SIMSTATE", "NAMED_VALUE_FLOAT"):
        b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, getattr(mavlink, f"MAVLINK_MSG_ID_{name}"), -1)
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_VIBRATION, 1_000_000)
    assert b.peer.acks(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL) == [mavlink.MAV_RESULT_ACCEPTED] * 4
    after = _rates(b, 10.0)
    assert not {"AHRS2", "SIMSTATE", "NAMED_VALUE_FLOAT"} & set(after)
    assert after["VIBRATION"] == pytest.approx(1.0, abs=0.15) and after["ATTITUDE"] == pytest.approx(10.0, abs=0.2)


def test_ardusub_streams_are_off_by_default_and_any_can_be_asked_for(bench):
    b = bench()
    b.advance(5.0)
    types = {m.get_type() for m in b.peer.got if m.get_srcComponent() == 1}
    assert types == {"HEARTBEAT", "SYS_STATUS", "SYSTEM_TIME", "ATTITUDE", "GLOBAL_POSITION_INT", "VFR_HUD",
                     "BATTERY_STATUS", "EKF_STATUS_REPORT"}
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_AHRS2, 200_000)
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 0)  # its default
    rates = _rates(b, 10.0)
    assert rates["AHRS2"] == pytest.approx(5.0, abs=0.2) and rates["LOCAL_POSITION_NED"] == pytest.approx(2.0, abs=0.2)
    local = b.peer.of("LOCAL_POSITION_NED")[-1]
    assert (local.x, local.y, local.z) == (pytest.approx(0.0), pytest.approx(0.0), pytest.approx(0.0))
    assert len(ARDUSUB_EXTRA_INTERVALS_S) == 19


# -- position error of an EKF, not raw jitter ---------------------------------------------------------------


def test_a_straight_runs_reported_path_is_as_long_as_the_true_one(bench):
    noisy = VehicleParams(position_noise_m=2.0)  # a few metres of error
    b = bench(params=noisy, sim={"seed": 4})
    b.guided_and_armed()
    b.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 100_000)  # 10 Hz
    for _ in range(20):  # 1 m/s north, re-sent every second
        vel_yaw(b.peer, 1.0, 0.0, 0.0)
        b.advance(1.0)
    b.peer.got.clear()
    lat0 = b.sim.body.lat_deg
    for _ in range(200):
        vel_yaw(b.peer, 1.0, 0.0, 0.0)
        b.advance(1.0)
    true_m = north_m(b.sim.body, lat0)
    reported = [(m.lat / 1e7, m.lon / 1e7) for m in b.peer.of("GLOBAL_POSITION_INT")]
    cos_lat = math.cos(math.radians(33.0))
    path_m = sum(math.hypot((b2 - a2) * M_PER_DEG_LAT, (b3 - a3) * M_PER_DEG_LAT * cos_lat)
                 for (a2, a3), (b2, b3) in zip(reported, reported[1:], strict=False))
    assert len(reported) > 1900 and true_m == pytest.approx(200.0, abs=1.0)
    assert path_m == pytest.approx(true_m, rel=0.04)  # white noise of 2 m made it about 20 times as long
    off = [abs(lat - b.sim.body.lat_deg) * M_PER_DEG_LAT for lat, _ in reported[-1:]]
    assert 0.0 < off[0] < 4 * 2.0


def test_the_position_error_is_a_smooth_process_of_the_asked_spread():
    rng = random.Random(1)
    sigma, tau, dt = 3.0, 30.0, 0.1
    e = NO_ERROR
    norths, steps = [], []
    for _ in range(100_000):  # 10,000 s: some 330 time constants
        new = drift_error(e, sigma, tau, dt, rng)
        steps.append(new.north_m - e.north_m)
        norths.append(new.north_m)
        e = new
    sd = math.sqrt(sum(x * x for x in norths) / len(norths))
    assert sd == pytest.approx(sigma, rel=0.15)
    step_sd = math.sqrt(sum(x * x for x in steps) / len(steps))
    assert step_sd < 0.01 * sigma  # 0.1 s steps of about 1 cm; white noise would jump about 4 m


def test_the_noise_is_the_same_from_a_seed_whichever_streams_are_on(bench):
    noisy = VehicleParams()
    tracks = []
    for extra in (False, True):
        b = bench(params=noisy, sim={"seed": 9, "ardusub_streams": extra})
        b.advance(20.0)
        tracks.append([(m.time_boot_ms, m.lat, m.lon) for m in b.peer.of("GLOBAL_POSITION_INT")])
    assert tracks[0] == tracks[1] and len({lat for _, lat, _ in tracks[0]}) > 5


# -- one switch for every ArduSub-faithful choice ----------------------------------------------------------


def test_the_ardusub_profile_sets_every_faithful_choice():
    base = SimConfig(start_lat_deg=33.0, start_lon_deg=-118.0, autopilot=AutopilotSettings(gcs_system=1))
    assert with_profile(base, Profile.LRAUV) == base
    faithful = with_profile(base, Profile.ARDUSUB)
    assert faithful.ardusub_streams and faithful.autopilot.failsafe is FailsafeAction.DISARM
    assert faithful.params.idle_ascent_m_s == pytest.approx(0.1)
    assert faithful.autopilot.gcs_system == 1  # everything else kept


def test_lrauv_sim_profile_ardusub_streams_the_extra_messages():
    proc = subprocess.Popen([sys.executable, "-m", "vehicle_sim", "sim", "--calm", "--profile", "ardusub",
                             "--speedup", "10", "--no-lockstep", "--listen", "127.0.0.1:0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    peer = None
    try:
        assert proc.stdout is not None
        port = int(proc.stdout.readline().strip().rsplit(":", 1)[1])
        peer = Peer(port)
        peer.heartbeat()

        def heard_extras() -> bool:
            peer.drain(0.02)
            return bool(peer.of("AHRS2")) and bool(peer.of("SIMSTATE"))

        assert wait_until(heard_extras, 10.0), {m.get_type() for m in peer.got}
    finally:
        if peer is not None:
            peer.close()
        proc.terminate()
        proc.wait(timeout=10)


@pytest.mark.parametrize(("flag", "value"), [("--profile", "px4"), ("--gcs-sysid", "0")])
def test_cli_rejects_a_bad_fidelity_flag_in_one_line(flag, value):
    done = sim_cli("--calm", flag, value)
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"lrauv sim: error: {flag} ") and "Traceback" not in done.stderr

