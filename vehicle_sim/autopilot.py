"""ArduSub's behaviour as a MAVLink peer, as pure logic: modes, arming, GUIDED targets, failsafes.

No sockets and no pymavlink: ``vehicle_sim.endpoint`` decodes messages into calls on an
``Autopilot`` and encodes what it returns (``Ack``, ``Text``, ``Interval``, ``SendOnce``).
All times are simulated seconds since boot. What ArduSub does was observed on ArduSub SITL
and read in ArduSub's GCS_MAVLink handlers:

- boots in MANUAL, disarmed; arming is accepted at once, in MANUAL, before the EKF is ready;
- no GPS for ``gps_delay_s`` (about 9 s on SITL): GLOBAL_POSITION_INT then has lat = lon = 0;
- GUIDED is refused ("Mode change failed: GUIDED requires position") until the EKF has a
  position (EKF_POS_HORIZ_ABS), ``position_delay_s`` (41 s on SITL) after boot;
- GUIDED velocity targets are zeroed 3 s after the last update; position targets persist;
- SET_POSITION_TARGET_GLOBAL_INT's yaw fields are ignored; yaw comes from LOCAL_NED (its yaw
  rate, when given, is the rate the heading target is approached at) or MAV_CMD_CONDITION_YAW;
  in ALT_HOLD a GLOBAL_INT target with Z sets the held depth;
- heading and depth follow their targets at the autopilot's own rates (``Tracking``: about
  30 deg/s and 1 m/s), not at the mission's figures;
- SURFACE climbs at that vertical rate and, once at the surface (shallower than SURFACE_DEPTH,
  10 cm), switches itself to ALT_HOLD (mode reason SURFACE_COMPLETE, no STATUSTEXT);
- the GCS heartbeat failsafe (FS_GCS_ENABLE) counts only heartbeats from system MAV_GCS_SYSID
  (SYSID_MYGCS, 255 by default) and never fires before one was seen; the companion computer
  (1/191) feeds it only on a vehicle whose MAV_GCS_SYSID is set to 1.

Deviations, chosen for an LRAUV and documented where they act: velocities are through the
water (ArduSub's are over ground, from its EKF); the default failsafe action is SURFACE
(ArduSub's default disarms; ``--failsafe disarm`` or ``--profile ardusub``); an empty battery
surfaces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum, IntEnum, unique
from typing import TypedDict

from planner.contract.modes import SubMode  # ArduSub's mode numbers, shared with the executive
from vehicle_sim.dynamics import ARDUSUB_TRACKING, IDLE, Body, Setpoint, SetpointKind, Tracking, TurnDirection
from planner.contract.geodesy import M_PER_DEG_LAT


@unique
class FailsafeAction(Enum):
    """What the heartbeat failsafe does (FS_GCS_ENABLE: warn, disarm, ALT_HOLD, SURFACE)."""

    SURFACE = "surface"
    ALT_HOLD = "alt_hold"
    DISARM = "disarm"
    WARN = "warn"


@unique
class Result(IntEnum):
    """MAV_RESULT."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


@unique
class Severity(IntEnum):
    """MAV_SEVERITY."""

    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6
    DEBUG = 7


# MAVLink ids used here (common.xml), kept numeric so that this module needs no pymavlink.
class Msg(IntEnum):
    HEARTBEAT = 0
    SYS_STATUS = 1
    SYSTEM_TIME = 2
    SET_MODE = 11
    ATTITUDE = 30
    GLOBAL_POSITION_INT = 33
    VFR_HUD = 74
    BATTERY_STATUS = 147
    AUTOPILOT_VERSION = 148
    EKF_STATUS_REPORT = 193
    # ArduSub's other default streams (ardusub-sitl-facts.md); off unless asked for.
    GPS_RAW_INT = 24
    RAW_IMU = 27
    SCALED_PRESSURE = 29
    LOCAL_POSITION_NED = 32
    SERVO_OUTPUT_RAW = 36
    NAV_CONTROLLER_OUTPUT = 62
    RC_CHANNELS = 65
    SCALED_IMU2 = 116
    SCALED_IMU3 = 129
    DISTANCE_SENSOR = 132
    TERRAIN_REPORT = 136
    SCALED_PRESSURE2 = 137
    SCALED_PRESSURE3 = 143
    AHRS = 163
    SIMSTATE = 164
    RANGEFINDER = 173
    AHRS2 = 178
    VIBRATION = 241
    NAMED_VALUE_FLOAT = 251


class Cmd(IntEnum):
    CONDITION_YAW = 115
    DO_SET_MODE = 176
    COMPONENT_ARM_DISARM = 400
    SET_MESSAGE_INTERVAL = 511
    REQUEST_MESSAGE = 512


# Streamed messages and their default intervals in simulated seconds (ardusub-sitl-facts.md table).
DEFAULT_INTERVALS_S: dict[int, float] = {
    Msg.HEARTBEAT: 1.0,
    Msg.ATTITUDE: 0.1,
    Msg.VFR_HUD: 0.1,
    Msg.GLOBAL_POSITION_INT: 1 / 3,
    Msg.SYSTEM_TIME: 1 / 3,
    Msg.EKF_STATUS_REPORT: 1 / 3,
    Msg.BATTERY_STATUS: 1 / 3,
    Msg.SYS_STATUS: 0.5,
}
# ArduSub's other default streams, as observed on SITL (the facts file's rate table); NAMED_VALUE_FLOAT
# is ArduSub's nine named values (CamTilt, Lights1, PilotGain, ...) at 2 Hz each: 18 messages a second.
ARDUSUB_EXTRA_INTERVALS_S: dict[int, float] = {
    Msg.AHRS2: 0.1, Msg.SIMSTATE: 0.1,
    Msg.AHRS: 1 / 3, Msg.DISTANCE_SENSOR: 1 / 3, Msg.RANGEFINDER: 1 / 3, Msg.VIBRATION: 1 / 3,
    Msg.TERRAIN_REPORT: 1 / 3,
    Msg.GPS_RAW_INT: 0.5, Msg.LOCAL_POSITION_NED: 0.5, Msg.RC_CHANNELS: 0.5, Msg.SERVO_OUTPUT_RAW: 0.5,
    Msg.RAW_IMU: 0.5, Msg.SCALED_IMU2: 0.5, Msg.SCALED_IMU3: 0.5, Msg.SCALED_PRESSURE: 0.5,
    Msg.SCALED_PRESSURE2: 0.5, Msg.SCALED_PRESSURE3: 0.5, Msg.NAV_CONTROLLER_OUTPUT: 0.5, Msg.NAMED_VALUE_FLOAT: 0.5,
}
STREAM_INTERVALS_S: dict[int, float] = {**DEFAULT_INTERVALS_S, **ARDUSUB_EXTRA_INTERVALS_S}  # what can stream
REQUESTABLE = frozenset(STREAM_INTERVALS_S) | {Msg.AUTOPILOT_VERSION}

MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
# POSITION_TARGET_TYPEMASK bits (1 = ignore).
_POS_BITS = 1 | 2 | 4
_VEL_BITS = 8 | 16 | 32
_ACC_BITS = 64 | 128 | 256
_Z_BIT = 4
_YAW_BIT = 1024
_YAW_RATE_BIT = 2048
# MAV_FRAME values accepted by ArduSub's handlers.
_LOCAL_NED, _LOCAL_OFFSET_NED, _BODY_NED, _BODY_OFFSET_NED = 1, 7, 8, 9
_GLOBAL_FRAMES = frozenset({0, 3, 5, 6})  # GLOBAL, GLOBAL_RELATIVE_ALT, and their _INT forms: alt = -depth
_STATUSTEXT_MAX = 50


@dataclass(frozen=True, kw_only=True)
class AutopilotSettings:
    """Timeouts and failsafe choices (the ArduSub parameters they stand for in comments)."""

    position_delay_s: float = 41.0  # EKF position after boot (SITL: ~41 s)
    gps_delay_s: float = 9.0  # GPS found after boot (SITL: ~9 s); never later than position_delay_s
    heartbeat_timeout_s: float = 5.0  # FS_GCS_TIMEOUT; 0 disables (FS_GCS_ENABLE 0)
    failsafe: FailsafeAction = FailsafeAction.SURFACE  # FS_GCS_ENABLE action
    velocity_timeout_s: float = 3.0  # GUIDED velocity targets are zeroed after this
    gcs_system: int = 255  # MAV_GCS_SYSID (SYSID_MYGCS): the only system whose heartbeats feed the failsafe
    prearm_delay_s: float = 3.0  # SYS_STATUS pre-arm bit
    surface_depth_m: float = 0.1  # SURFACE_DEPTH (-10 cm): shallower than this is at the surface
    tracking: Tracking = ARDUSUB_TRACKING  # how heading and depth follow their targets

    def __post_init__(self) -> None:
        if not 1 <= self.gcs_system <= 255:
            raise ValueError(f"AutopilotSettings.gcs_system: expected a system id 1..255; got {self.gcs_system!r}")
        for name in ("position_delay_s", "gps_delay_s", "heartbeat_timeout_s", "prearm_delay_s", "surface_depth_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"AutopilotSettings.{name}: expected a number >= 0; got {value!r}")
        if not (math.isfinite(self.velocity_timeout_s) and self.velocity_timeout_s > 0):
            raise ValueError(f"AutopilotSettings.velocity_timeout_s: expected > 0; got {self.velocity_timeout_s!r}")


# -- what the autopilot asks the endpoint to send -------------------------------------------


@dataclass(frozen=True, slots=True)
class Ack:
    """COMMAND_ACK to the sender."""

    command: int
    result: Result
    target_system: int
    target_component: int


@dataclass(frozen=True, slots=True)
class Text:
    """STATUSTEXT (at most 50 characters)."""

    severity: Severity
    text: str


@dataclass(frozen=True, slots=True)
class Interval:
    """New stream interval of a message; None stops it."""

    message_id: int
    interval_s: float | None


@dataclass(frozen=True, slots=True)
class SendOnce:
    """Send one instance of a message now (MAV_CMD_REQUEST_MESSAGE)."""

    message_id: int


Output = Ack | Text | Interval | SendOnce


class YawFields(TypedDict):
    """The yaw part of a GUIDED ``Setpoint``: what a target's yaw and yaw-rate fields set, or keep."""

    yaw_deg: float | None
    yaw_rate_deg_s: float | None
    turn: TurnDirection


class Autopilot:
    """Mode, arming, the active setpoint and failsafe state of the simulated ArduSub."""

    def __init__(self, settings: AutopilotSettings, *, battery_wh: float, origin_lat_deg: float,
                 origin_lon_deg: float) -> None:
        self.settings = settings
        self.battery_wh = battery_wh
        self.origin = (origin_lat_deg, origin_lon_deg)  # EKF origin for LOCAL_NED positions (at the surface)
        self.mode = SubMode.MANUAL
        self.armed = False
        self.setpoint: Setpoint = IDLE  # what the vehicle does now; kept current by every change
        self._guided: Setpoint = IDLE
        self._hold_depth_m = 0.0
        self._velocity_deadline_s: float | None = None
        self._last_heartbeat_s: float | None = None
        self._last_peer = (0, 0)
        self.failsafe_active = False
        self.battery_failsafe = False

    # -- state queries -----------------------------------------------------------------------

    def position_ok(self, now_s: float) -> bool:
        """True once the EKF has an absolute horizontal position (EKF_POS_HORIZ_ABS)."""
        return now_s >= self.settings.position_delay_s

    def gps_ok(self, now_s: float) -> bool:
        """True once the GPS has been found; before, positions read lat = lon = 0 (as ArduSub's do)."""
        return now_s >= min(self.settings.gps_delay_s, self.settings.position_delay_s)

    def prearm_ok(self, now_s: float) -> bool:
        return now_s >= self.settings.prearm_delay_s

    # -- inputs ---------------------------------------------------------------------------------

    def heartbeat(self, now_s: float, system: int, component: int) -> list[Output]:
        """A HEARTBEAT arrived; only the GCS system's (MAV_GCS_SYSID, any component) feed the failsafe."""
        if system != self.settings.gcs_system:
            return []
        self._last_heartbeat_s = now_s
        self._last_peer = (system, component)
        if self.failsafe_active:
            self.failsafe_active = False  # the mode stays where the failsafe put it (as ArduSub)
            return [Text(Severity.INFO, "GCS Failsafe cleared: heartbeat regained")]
        return []

    def tick(self, now_s: float, body: Body) -> list[Output]:
        """Timeouts and failsafes; call every physics step."""
        out: list[Output] = []
        deadline = self._velocity_deadline_s
        if deadline is not None and now_s > deadline:
            # ArduSub zeroes a stale GUIDED velocity target: hold (zero velocity through the water).
            self._velocity_deadline_s = None
            self._guided = replace(self._guided, north_m_s=0.0, east_m_s=0.0, down_m_s=0.0)
            self._refresh()
        timeout = self.settings.heartbeat_timeout_s
        last = self._last_heartbeat_s
        if (timeout > 0 and self.armed and not self.failsafe_active and last is not None
                and now_s - last > timeout):
            self.failsafe_active = True
            s, c = self._last_peer
            out.append(Text(Severity.CRITICAL, f"GCS Failsafe: heartbeat lost from {s}/{c}"))
            out.extend(self._failsafe_action(body))
        if self.mode is SubMode.SURFACE and self.armed and body.depth_m <= self.settings.surface_depth_m:
            self._enter(SubMode.ALT_HOLD, body)  # SURFACE_COMPLETE: ArduSub says nothing
        if not self.battery_failsafe and body.energy_used_wh >= self.battery_wh:
            self.battery_failsafe = True
            out.append(Text(Severity.CRITICAL, "Battery empty: surfacing"))
            self._enter(SubMode.SURFACE, body)
        return out

    def command(self, now_s: float, body: Body, command: int, params: tuple[float, ...],
                source: tuple[int, int]) -> list[Output]:
        """COMMAND_LONG / COMMAND_INT (params p1..p7); always answered with a COMMAND_ACK."""
        p = tuple(params) + (0.0,) * (7 - len(params))
        out: list[Output] = []
        if command == Cmd.DO_SET_MODE:
            if int(p[0]) & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                result = self._set_mode(now_s, body, p[1], out)
            else:
                result = Result.FAILED
        elif command == Cmd.COMPONENT_ARM_DISARM:
            result = self._arm(p[0], out)
        elif command == Cmd.SET_MESSAGE_INTERVAL:
            result = self._set_interval(p[0], p[1], out)
        elif command == Cmd.REQUEST_MESSAGE:
            msg_id = int(p[0]) if math.isfinite(p[0]) else -1
            result = Result.ACCEPTED if msg_id in REQUESTABLE else Result.FAILED
            if result is Result.ACCEPTED:
                out.append(SendOnce(msg_id))
        elif command == Cmd.CONDITION_YAW:
            result = self._condition_yaw(body, p[0], p[1], p[2], p[3])
        else:
            result = Result.UNSUPPORTED
        return [Ack(int(command), result, *source), *out]

    def set_mode_message(self, now_s: float, body: Body, base_mode: int, custom_mode: int,
                         source: tuple[int, int]) -> list[Output]:
        """SET_MODE (id 11). ArduPilot answers it with a COMMAND_ACK whose command is 11."""
        out: list[Output] = []
        if base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            result = self._set_mode(now_s, body, custom_mode, out)
        else:
            result = Result.FAILED
        return [Ack(Msg.SET_MODE, result, *source), *out]

    def position_target_local(self, now_s: float, body: Body, *, frame: int, type_mask: int, x: float, y: float,
                              z: float, vx: float, vy: float, vz: float, yaw_rad: float, yaw_rate_rad_s: float) -> None:
        """SET_POSITION_TARGET_LOCAL_NED, obeyed in GUIDED (ArduSub ignores it elsewhere)."""
        if self.mode is not SubMode.GUIDED or frame not in (_LOCAL_NED, _LOCAL_OFFSET_NED, _BODY_NED, _BODY_OFFSET_NED):
            return
        pos = not type_mask & _POS_BITS
        vel = not type_mask & _VEL_BITS
        if (type_mask & _ACC_BITS) != _ACC_BITS or not (pos or vel):
            return  # acceleration targets are not supported by ArduSub's handler; nothing usable
        body_frame = frame in (_BODY_NED, _BODY_OFFSET_NED)
        if body_frame:  # x forward, y right: rotate into north/east by the heading
            h = math.radians(body.heading_deg)
            x, y = x * math.cos(h) - y * math.sin(h), x * math.sin(h) + y * math.cos(h)
            vx, vy = vx * math.cos(h) - vy * math.sin(h), vx * math.sin(h) + vy * math.cos(h)
        yaw = self._guided_yaw(type_mask, yaw_rad, yaw_rate_rad_s, body,
                               relative=frame == _BODY_OFFSET_NED)
        if pos:
            if frame in (_LOCAL_OFFSET_NED, _BODY_OFFSET_NED):
                lat, lon = _offset(body.lat_deg, body.lon_deg, x, y)
                depth = body.depth_m + z
            else:
                lat, lon = _offset(self.origin[0], self.origin[1], x, y)
                depth = z
            self._set_guided(Setpoint(kind=SetpointKind.POSITION, lat_deg=lat, lon_deg=lon,
                                      depth_m=max(0.0, depth), **yaw), None)
        else:
            self._set_guided(Setpoint(kind=SetpointKind.VELOCITY, north_m_s=vx, east_m_s=vy, down_m_s=vz, **yaw),
                             now_s + self.settings.velocity_timeout_s)

    def position_target_global(self, now_s: float, body: Body, *, frame: int, type_mask: int, lat_int: int,
                               lon_int: int, alt_m: float, vx: float, vy: float, vz: float) -> None:
        """SET_POSITION_TARGET_GLOBAL_INT: GUIDED position/velocity, or the held depth in ALT_HOLD.

        Its yaw and yaw-rate fields are ignored, as ArduSub's handler does ("for future use").
        """
        if frame not in _GLOBAL_FRAMES:
            return  # terrain frames: no terrain under water
        depth = max(0.0, -alt_m)  # Sub: altitude is negative below the surface
        if self.mode is SubMode.ALT_HOLD:
            if not type_mask & _Z_BIT:
                self._hold_depth_m = depth
                self._refresh()
            return
        if self.mode is not SubMode.GUIDED or (type_mask & _ACC_BITS) != _ACC_BITS:
            return
        pos = not type_mask & _POS_BITS
        vel = not type_mask & _VEL_BITS
        keep: YawFields = {"yaw_deg": self._guided.yaw_deg, "yaw_rate_deg_s": self._guided.yaw_rate_deg_s,
                           "turn": self._guided.turn}
        if pos:  # position, or position + velocity (taken as position)
            self._set_guided(Setpoint(kind=SetpointKind.POSITION, lat_deg=lat_int / 1e7, lon_deg=lon_int / 1e7,
                                      depth_m=depth, **keep), None)
        elif vel:
            self._set_guided(Setpoint(kind=SetpointKind.VELOCITY, north_m_s=vx, east_m_s=vy, down_m_s=vz, **keep),
                             now_s + self.settings.velocity_timeout_s)
        # Neither (e.g. depth only, mask 3579, in GUIDED): ArduSub ignores it too.

    # -- internals ----------------------------------------------------------------------------

    def _set_mode(self, now_s: float, body: Body, value: float, out: list[Output]) -> Result:
        try:
            mode = SubMode(int(value))
        except (ValueError, OverflowError):
            out.append(Text(Severity.WARNING, f"Mode {value:g} not available in this simulator"))
            return Result.FAILED
        if mode is SubMode.GUIDED and not self.position_ok(now_s):
            out.append(Text(Severity.WARNING, "Mode change failed: GUIDED requires position"))
            return Result.FAILED
        if mode is not self.mode:
            self._enter(mode, body)
        return Result.ACCEPTED

    def _enter(self, mode: SubMode, body: Body) -> None:
        self.mode = mode
        self._velocity_deadline_s = None
        if mode is SubMode.GUIDED:  # guided_init: hold the current position, depth and heading
            self._guided = Setpoint(kind=SetpointKind.POSITION, lat_deg=body.lat_deg, lon_deg=body.lon_deg,
                                    depth_m=body.depth_m)
        elif mode is SubMode.ALT_HOLD:
            self._hold_depth_m = body.depth_m
        self._refresh()

    def _arm(self, value: float, out: list[Output]) -> Result:
        if value == 1.0:
            if self.battery_failsafe:
                out.append(Text(Severity.CRITICAL, "PreArm: Battery empty"))
                return Result.FAILED
            self.armed = True
        elif value == 0.0:
            self.armed = False
        else:
            return Result.UNSUPPORTED
        self._refresh()
        return Result.ACCEPTED

    def _set_interval(self, message_id: float, interval_us: float, out: list[Output]) -> Result:
        msg_id = int(message_id) if math.isfinite(message_id) else -1
        if msg_id not in STREAM_INTERVALS_S or not math.isfinite(interval_us):
            return Result.FAILED
        if interval_us < 0:
            out.append(Interval(msg_id, None))  # -1: stop
        elif interval_us == 0:
            out.append(Interval(msg_id, STREAM_INTERVALS_S[msg_id]))  # 0: default rate
        else:
            out.append(Interval(msg_id, interval_us / 1e6))
        return Result.ACCEPTED

    def _condition_yaw(self, body: Body, angle: float, rate: float, direction: float, relative: float) -> Result:
        if not (0.0 <= angle <= 360.0) or relative not in (0.0, 1.0) or not math.isfinite(rate):
            return Result.FAILED
        turn = (TurnDirection.CLOCKWISE if direction > 0 else
                TurnDirection.COUNTER_CLOCKWISE if direction < 0 else TurnDirection.SHORTEST)
        if relative:
            target = body.heading_deg + angle * (-1.0 if direction < 0 else 1.0)
        else:
            target = angle
        # Kept in the GUIDED target; like ArduSub's auto-yaw it only steers in GUIDED.
        self._guided = replace(self._guided, yaw_deg=target % 360.0, turn=turn,
                               yaw_rate_deg_s=abs(rate) if rate else None)
        self._refresh()
        return Result.ACCEPTED

    def _guided_yaw(self, type_mask: int, yaw_rad: float, yaw_rate_rad_s: float, body: Body,
                    *, relative: bool) -> YawFields:
        """Yaw fields of a LOCAL_NED target; when both yaw bits say ignore, the previous yaw target stays.

        With a yaw, a yaw rate given too (YAW_RATE_IGNORE clear, non-zero) is the rate the heading
        is slewed at (ArduSub's auto-yaw "look at heading" rate); without one, ArduSub's own slew.
        """
        if not type_mask & _YAW_BIT and math.isfinite(yaw_rad):
            deg = math.degrees(yaw_rad) + (body.heading_deg if relative else 0.0)
            rate = None
            if not type_mask & _YAW_RATE_BIT and math.isfinite(yaw_rate_rad_s) and yaw_rate_rad_s != 0.0:
                rate = abs(math.degrees(yaw_rate_rad_s))
            return {"yaw_deg": deg % 360.0, "yaw_rate_deg_s": rate, "turn": TurnDirection.SHORTEST}
        if not type_mask & _YAW_RATE_BIT and math.isfinite(yaw_rate_rad_s):
            return {"yaw_deg": None, "yaw_rate_deg_s": math.degrees(yaw_rate_rad_s), "turn": TurnDirection.SHORTEST}
        g = self._guided
        return {"yaw_deg": g.yaw_deg, "yaw_rate_deg_s": g.yaw_rate_deg_s, "turn": g.turn}

    def _set_guided(self, sp: Setpoint, deadline_s: float | None) -> None:
        self._guided = sp
        self._velocity_deadline_s = deadline_s
        self._refresh()

    def _failsafe_action(self, body: Body) -> list[Output]:
        action = self.settings.failsafe
        if action is FailsafeAction.SURFACE:
            self._enter(SubMode.SURFACE, body)
        elif action is FailsafeAction.ALT_HOLD:
            self._enter(SubMode.ALT_HOLD, body)
        elif action is FailsafeAction.DISARM:
            self.armed = False
            self._refresh()
        return []

    def _refresh(self) -> None:
        """Recompute the active setpoint from mode, arming and targets."""
        if not self.armed or self.mode is SubMode.MANUAL:
            self.setpoint = IDLE  # no thrust (no pilot input in MANUAL)
        elif self.mode is SubMode.GUIDED:
            self.setpoint = self._guided
        elif self.mode is SubMode.ALT_HOLD:
            self.setpoint = Setpoint(kind=SetpointKind.DEPTH, depth_m=self._hold_depth_m)
        else:  # SURFACE: straight up at the autopilot's vertical rate, no horizontal thrust
            self.setpoint = Setpoint(kind=SetpointKind.DEPTH, down_m_s=-self.settings.tracking.depth_rate_m_s)


def _offset(lat_deg: float, lon_deg: float, north_m: float, east_m: float) -> tuple[float, float]:
    """A point ``north_m``/``east_m`` from (lat, lon), flat earth (spec section 1)."""
    lat = lat_deg + north_m / M_PER_DEG_LAT
    return lat, lon_deg + east_m / (M_PER_DEG_LAT * (math.cos(math.radians(lat_deg)) or 1e-12))


def clip_text(text: str) -> str:
    """STATUSTEXT holds 50 characters."""
    return text if len(text) <= _STATUSTEXT_MAX else text[: _STATUSTEXT_MAX - 3] + "..."
