"""ArduSub's other default streams: the messages a real ArduSub sends that the executive does not need.

ArduSub SITL streams 27 message types by default (ardusub-sitl-facts.md, the rate table, and
NAMED_VALUE_FLOAT at 18 Hz); ``vehicle_sim.endpoint`` always streams the eight the executive
reads and, with ``SimConfig.ardusub_streams`` (``lrauv sim --ardusub-streams``), these
nineteen too, at ArduSub's rates (``autopilot.ARDUSUB_EXTRA_INTERVALS_S``). They are real
pymavlink messages with plausible content: what the simulated vehicle knows (attitude,
position, depth, speeds, targets) where the field means something here, ArduSub-like
constants (seafloor at 50 m as SITL's, sea-level pressure, 15 degC water) or zeros where
it means nothing (vibration, AHRS drift, radio).
"""

from __future__ import annotations

import math
from typing import Any

from planner.contract.geodesy import M_PER_DEG_LAT
from planner.contract.vehicle import VehicleParams
from vehicle_sim.autopilot import Autopilot, Msg
from vehicle_sim.dynamics import Body, Reading, SetpointKind

SEAFLOOR_DEPTH_M = 50.0  # ArduSub SITL's flat seafloor
_SEA_LEVEL_HPA = 1013.25
_HPA_PER_M = 100.5  # seawater, about 1 dbar per metre
_WATER_C = 15.0
_G_MG = 1000.0  # 1 g in milli-g, RAW_IMU / SCALED_IMU units
_FIELD_MGAUSS = 400.0  # a plausible horizontal magnetic field
_PITCH_270 = 25  # MAV_SENSOR_ROTATION_PITCH_270: a rangefinder looking down
# ArduSub's GCS_MAVLINK_Sub::send_info: nine named values, all sent whenever NAMED_VALUE_FLOAT is due.
NAMED_VALUES: tuple[tuple[str, float], ...] = (
    ("CamTilt", 0.5), ("CamPan", 0.5), ("TetherTrn", 0.0), ("Lights1", 0.0), ("Lights2", 0.0),
    ("PilotGain", 0.5), ("InputHold", 0.0), ("StickMode", 0.0), ("RFTarget", 0.0),
)


def _deg_e7(x: float) -> int:
    return round(x * 1e7)


def _u16(x: float) -> int:
    return max(0, min(65535, round(x)))


def send_extra(mav: Any, msg_id: int, t_ms: int, body: Body, reading: Reading, autopilot: Autopilot,
               params: VehicleParams) -> int:
    """Send one of ArduSub's other streams (several frames for NAMED_VALUE_FLOAT); returns how many went out."""
    now_s = t_ms / 1000.0
    gps = autopilot.gps_ok(now_s)
    lat, lon = (reading.lat_deg, reading.lon_deg) if gps else (0.0, 0.0)  # no position before the GPS
    yaw = math.radians(reading.heading_deg)
    yaw = yaw - 2.0 * math.pi if yaw > math.pi else yaw
    t_us = t_ms * 1000
    heading_rad = math.radians(body.heading_deg)
    mag_x, mag_y = _FIELD_MGAUSS * math.cos(heading_rad), -_FIELD_MGAUSS * math.sin(heading_rad)
    gyro_z = math.radians(body.yaw_rate_deg_s)
    if msg_id == Msg.AHRS2:
        mav.ahrs2_send(0.0, 0.0, yaw, -reading.depth_m, _deg_e7(lat), _deg_e7(lon))
    elif msg_id == Msg.SIMSTATE:  # the simulator's truth
        mav.simstate_send(0.0, 0.0, heading_rad if heading_rad <= math.pi else heading_rad - 2.0 * math.pi,
                          0.0, 0.0, -9.80665, 0.0, 0.0, gyro_z, _deg_e7(body.lat_deg), _deg_e7(body.lon_deg))
    elif msg_id == Msg.AHRS:
        mav.ahrs_send(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    elif msg_id == Msg.DISTANCE_SENSOR:
        altitude_cm = (SEAFLOOR_DEPTH_M - body.depth_m) * 100.0
        mav.distance_sensor_send(t_ms, 20, 7000, _u16(altitude_cm), 0, 0, _PITCH_270, 255)
    elif msg_id == Msg.RANGEFINDER:
        mav.rangefinder_send(SEAFLOOR_DEPTH_M - body.depth_m, 0.0)
    elif msg_id == Msg.VIBRATION:
        mav.vibration_send(t_us, 0.0, 0.0, 0.0, 0, 0, 0)
    elif msg_id == Msg.TERRAIN_REPORT:
        mav.terrain_report_send(_deg_e7(lat), _deg_e7(lon), 0, -SEAFLOOR_DEPTH_M, SEAFLOOR_DEPTH_M - reading.depth_m, 0, 0)
    elif msg_id == Msg.GPS_RAW_INT:
        fix, sats, eph = (3, 10, 121) if gps else (1, 0, 65535)  # GPS_FIX_TYPE_3D_FIX / NO_FIX
        cog = math.degrees(math.atan2(body.ground_east_m_s, body.ground_north_m_s)) % 360.0
        mav.gps_raw_int_send(t_us, fix, _deg_e7(lat), _deg_e7(lon), round(-reading.depth_m * 1000.0), eph, eph,
                             _u16(body.ground_speed_m_s * 100.0), round(cog * 100.0) % 36000, sats)
    elif msg_id == Msg.LOCAL_POSITION_NED:
        if not autopilot.position_ok(now_s):
            return 0  # ArduSub sends it only once the EKF has an origin
        lat0, lon0 = autopilot.origin
        north = (reading.lat_deg - lat0) * M_PER_DEG_LAT
        east = (reading.lon_deg - lon0) * M_PER_DEG_LAT * math.cos(math.radians(lat0))
        mav.local_position_ned_send(t_ms, north, east, reading.depth_m, body.ground_north_m_s, body.ground_east_m_s,
                                    body.down_m_s)
    elif msg_id == Msg.RC_CHANNELS:  # no pilot: every stick centred
        mav.rc_channels_send(t_ms, 16, *([1500] * 16), 65535, 65535, 255)
    elif msg_id == Msg.SERVO_OUTPUT_RAW:
        mav.servo_output_raw_send(t_us % (1 << 32), 0, *_thrusters(body, params, autopilot.armed))
    elif msg_id in (Msg.RAW_IMU, Msg.SCALED_IMU2, Msg.SCALED_IMU3):
        imu = (0, 0, -round(_G_MG), 0, 0, round(gyro_z * 1000.0), round(mag_x), round(mag_y), 0)
        if msg_id == Msg.RAW_IMU:
            mav.raw_imu_send(t_us, *imu)
        elif msg_id == Msg.SCALED_IMU2:
            mav.scaled_imu2_send(t_ms, *imu)
        else:
            mav.scaled_imu3_send(t_ms, *imu)
    elif msg_id == Msg.SCALED_PRESSURE:  # the hull's internal barometer
        mav.scaled_pressure_send(t_ms, _SEA_LEVEL_HPA, 0.0, 2500)
    elif msg_id == Msg.SCALED_PRESSURE2:  # the external (water) pressure sensor that gives the depth
        mav.scaled_pressure2_send(t_ms, _SEA_LEVEL_HPA + _HPA_PER_M * reading.depth_m, 0.0, round(_WATER_C * 100))
    elif msg_id == Msg.SCALED_PRESSURE3:  # ArduSub's water temperature sensor
        mav.scaled_pressure3_send(t_ms, 0.0, 0.0, round(_WATER_C * 100))
    elif msg_id == Msg.NAV_CONTROLLER_OUTPUT:
        mav.nav_controller_output_send(0.0, 0.0, *_navigation(body, autopilot))
    elif msg_id == Msg.NAMED_VALUE_FLOAT:
        for name, value in NAMED_VALUES:
            mav.named_value_float_send(t_ms, name.encode("ascii"), value)
        return len(NAMED_VALUES)
    else:
        return 0
    return 1


def _thrusters(body: Body, params: VehicleParams, armed: bool) -> list[int]:
    """PWM of the vectored frame's eight outputs: four horizontal, four vertical (1500 = stopped)."""
    if not armed:
        return [1500] * 16
    horizontal = round(400.0 * min(1.0, body.water_speed_m_s / params.max_speed_m_s))
    vertical = round(400.0 * max(-1.0, min(1.0, body.down_m_s)))
    return [1500 + horizontal] * 4 + [1500 + vertical] * 4 + [0] * 8


def _navigation(body: Body, autopilot: Autopilot) -> tuple[int, int, int, float, float, float]:
    """NAV_CONTROLLER_OUTPUT's bearings (deg), distance to the position target (m) and depth error (m, up +)."""
    sp = autopilot.setpoint
    nav_bearing = round(sp.yaw_deg if sp.yaw_deg is not None else body.heading_deg)
    target_bearing, distance = nav_bearing, 0
    if sp.kind is SetpointKind.POSITION and sp.lat_deg is not None and sp.lon_deg is not None:
        north = (sp.lat_deg - body.lat_deg) * M_PER_DEG_LAT
        east = (sp.lon_deg - body.lon_deg) * M_PER_DEG_LAT * math.cos(math.radians(body.lat_deg))
        target_bearing = round(math.degrees(math.atan2(east, north)) % 360.0)
        distance = _u16(math.hypot(north, east))
    alt_error = 0.0 if sp.depth_m is None else body.depth_m - sp.depth_m  # target altitude minus altitude
    return nav_bearing % 360, target_bearing % 360, distance, alt_error, 0.0, 0.0
