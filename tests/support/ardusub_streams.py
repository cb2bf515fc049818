"""ArduSub SITL's default telemetry, as frames: what a scripted autopilot sends to load a link like ArduSub.

ArduSub (V4.7.0-dev, default parameters) keeps all its default streams on after the executive's
MAV_CMD_SET_MESSAGE_INTERVAL requests: 36 message types, about 91 messages per vehicle second
(shared/research/ardusub-sitl-facts.md, "Observed again with the project's executive"). ``RATES_HZ``
is that set, at the rates the facts file gives (the streams the executive asks for at the rates it
asks for); fields are zero except the few the executive reads, so each frame has ArduSub's length.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

RATES_HZ: dict[str, float] = {
    "NAMED_VALUE_FLOAT": 18.0,
    **dict.fromkeys(("AHRS2", "SIMSTATE"), 10.0),
    **dict.fromkeys(("AHRS", "DISTANCE_SENSOR", "RANGEFINDER", "VIBRATION", "TERRAIN_REPORT"), 3.0),
    **dict.fromkeys(("GLOBAL_POSITION_INT", "ATTITUDE", "GPS_RAW_INT", "LOCAL_POSITION_NED", "RC_CHANNELS",
                     "SERVO_OUTPUT_RAW", "RAW_IMU", "SCALED_IMU2", "SCALED_IMU3", "SCALED_PRESSURE",
                     "SCALED_PRESSURE2", "SCALED_PRESSURE3", "NAV_CONTROLLER_OUTPUT", "MEMINFO", "POWER_STATUS",
                     "MISSION_CURRENT", "POSITION_TARGET_GLOBAL_INT", "ESC_TELEMETRY_1_TO_4", "MCU_STATUS"), 2.0),
    "HEARTBEAT": 1.0,
    **dict.fromkeys(("SYSTEM_TIME", "EKF_STATUS_REPORT", "BATTERY_STATUS", "SYS_STATUS", "VFR_HUD", "HOME_POSITION",
                     "GPS_GLOBAL_ORIGIN"), 0.2),
}
_FIELDS = {  # what the executive reads: a position off the Californian coast, a heartbeat of a sub in GUIDED
    "GLOBAL_POSITION_INT": {"lat": 335_000_000, "lon": -1_180_000_000, "relative_alt": -2000, "hdg": 9000},
    "HEARTBEAT": {"type": mavlink.MAV_TYPE_SUBMARINE, "autopilot": mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                  "base_mode": mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, "custom_mode": 4,
                  "system_status": mavlink.MAV_STATE_ACTIVE, "mavlink_version": 3},
    "EKF_STATUS_REPORT": {"flags": mavlink.EKF_ATTITUDE | mavlink.EKF_POS_HORIZ_ABS},
    "BATTERY_STATUS": {"battery_remaining": 90, "energy_consumed": -1, "current_consumed": -1},
    "SYS_STATUS": {"battery_remaining": 90},
    "NAMED_VALUE_FLOAT": {"name": b"PiP"},
}


def message(name: str, time_boot_ms: int) -> object:
    """A message of type ``name`` as ArduSub fills it for the executive, every other field zero."""
    cls = getattr(mavlink, f"MAVLink_{name.lower()}_message")
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    values = _FIELDS.get(name, {})
    args: list[object] = []
    for field, kind in zip(cls.fieldnames, cls.fieldtypes, strict=True):
        blank: object = b"" if kind == "char" else [0] * lengths[field] if lengths[field] else 0
        args.append(time_boot_ms if field == "time_boot_ms" else values.get(field, blank))
    return cls(*args)


def frames(mav: mavlink.MAVLink, start_ms: int, seconds: float, step_ms: int = 10) -> Iterator[tuple[int, bytes]]:
    """(time_boot_ms, frame) of every message due in ``seconds`` of vehicle time from ``start_ms``, in time order."""
    periods = {name: round(1000.0 / hz) for name, hz in RATES_HZ.items()}
    for t in range(start_ms, start_ms + round(seconds * 1000), step_ms):
        for name, period in periods.items():
            if t % period < step_ms:
                yield t, message(name, t).pack(mav)  # type: ignore[attr-defined]
                mav.seq = (mav.seq + 1) % 256  # as MAVLink.send does: a frame never repeats the one before
