"""Value objects that cross the executive's boundaries, in SI units with units in the names.

The MAVLink bridge turns messages into ``VehicleState`` updates and ``Command``
objects into messages; everything between works on these.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, unique

from planner.contract.modes import SubMode
from typing import Literal


@unique
class Phase(Enum):
    """What the executive is doing; every phase has a defined behaviour (README, "Executive")."""

    WAIT_LINK = "wait_link"  # no autopilot heartbeat yet: send our heartbeat only
    SETUP = "setup"  # set message rates, get a position estimate, GUIDED and armed
    RUNNING = "running"  # following the policy table
    ARRIVED = "arrived"  # at a goal: on_arrival behaviour (hold, surface, drift)
    SAFE = "safe"  # a safety limit fired (time, battery, depth, geofence): on_breach, plan suspended
    LINK_LOST = "link_lost"  # no autopilot heartbeat within the timeout: ask for on_breach's mode
    OVERRIDDEN = "overridden"  # a mode, disarm or failsafe the executive did not command: command nothing until resumed


@unique
class Situation(Enum):
    """Why the current behaviour was chosen (logged with every decision)."""

    FOLLOWING = "following"
    AT_GOAL = "at_goal"
    UNREACHABLE = "unreachable"  # table says no action reaches the goal: drift at depth
    LAND = "land"  # position in a land cell of the table: surface
    OUTSIDE_GRID = "outside_grid"  # outside the planned volume: surface
    NO_POSITION = "no_position"  # no position yet: nothing to decide
    NO_TABLE = "no_table"  # no valid table loaded: surface
    MISSION_TIME = "mission_time"  # max_mission_time_h exceeded: on_breach (surface by default)
    LOW_BATTERY = "low_battery"  # battery under min_battery_pct: on_breach
    TOO_DEEP = "too_deep"  # deeper than max_depth_m: on_breach
    GEOFENCE = "geofence"  # outside the mission's geofence: on_breach
    LINK_LOST = "link_lost"
    POSITION_LOST = "position_lost"  # no plausible position for position_timeout_s: on_breach
    NO_HEADING = "no_heading"  # the heading is unknown (NaN or missing samples): hold depth, no thrust


@dataclass(frozen=True, slots=True)
class VehicleState:
    """The executive's picture of the vehicle, built from telemetry; ``None`` = not yet known."""

    time_s: float = 0.0  # vehicle time since boot (time_boot_ms)
    lat_deg: float | None = None
    lon_deg: float | None = None
    depth_m: float | None = None  # positive down
    heading_deg: float | None = None  # compass, clockwise from north
    mode: int | None = None  # HEARTBEAT.custom_mode (SubMode when known)
    armed: bool = False
    position_ok: bool = False  # the latest EKF_STATUS_REPORT has EKF_POS_HORIZ_ABS: positions are used only then
    battery_pct: float | None = None
    energy_used_wh: float | None = None
    heartbeat_s: float | None = None  # vehicle time of the last autopilot HEARTBEAT
    interval_acks: int = 0  # COMMAND_ACKs accepting MAV_CMD_SET_MESSAGE_INTERVAL so far
    position_s: float | None = None  # vehicle time of the last position that passed the checks (executive.plausibility)
    autopilot_failsafe: bool = False  # the autopilot's HEARTBEAT says MAV_STATE_CRITICAL: one of its failsafes is on
    ekf_reported: bool = False  # an EKF_STATUS_REPORT has arrived since boot (set-up says what it waits for)

    @property
    def has_position(self) -> bool:
        return self.lat_deg is not None and self.lon_deg is not None and self.depth_m is not None


# -- commands (what the helm asks for; the bridge encodes them) -------------------------


@dataclass(frozen=True, slots=True)
class SetMode:
    mode: SubMode


@dataclass(frozen=True, slots=True)
class Arm:
    arm: bool


@dataclass(frozen=True, slots=True)
class SetMessageInterval:
    message: str  # MAVLink message name, e.g. "GLOBAL_POSITION_INT"
    interval_s: float  # vehicle time; <= 0 means "disable"


@dataclass(frozen=True, slots=True)
class VelocityYaw:
    """Through-water velocity (NED, m/s) and absolute yaw: SET_POSITION_TARGET_LOCAL_NED.

    With ``yaw_rate_deg_s`` (a magnitude: ArduSub slews toward the yaw at it) the yaw rate field is
    sent too (type_mask 455), else only the yaw (2503).
    """

    north_m_s: float
    east_m_s: float
    down_m_s: float
    yaw_deg: float
    yaw_rate_deg_s: float | None = None


@dataclass(frozen=True, slots=True)
class DepthTarget:
    """Depth only (ALT_HOLD): SET_POSITION_TARGET_GLOBAL_INT with type_mask 3579."""

    depth_m: float


@dataclass(frozen=True, slots=True)
class PositionTarget:
    """Hold a point (GUIDED): SET_POSITION_TARGET_GLOBAL_INT, position bits only."""

    lat_deg: float
    lon_deg: float
    depth_m: float


Command = SetMode | Arm | SetMessageInterval | VelocityYaw | DepthTarget | PositionTarget

LogLevelName = Literal["debug", "info", "warning", "error"]


@dataclass(frozen=True, slots=True)
class Event:
    """A line for the log (foxglove.Log) and, for warnings and errors, a STATUSTEXT."""

    level: LogLevelName
    text: str
