"""Goals as MAVLink mission items, and QGC WPL 110 waypoint files (docs/missions.md).

Standard library only, apart from ``planner.contract.errors`` and ``planner.contract.atomic``:
the executive's mission protocol imports this module and loads neither numpy nor YAML.
Goals become items and back in ``planner.contract.mission`` (``goals_to_items``, ``items_to_goals``).

The encoding (mavlink.io "Mission Protocol", sections "Mission Items" and
"Frames & Positional Information"; ArduPilot's home convention):

- item 0 is home, as ArduPilot, MAVProxy and QGroundControl expect:
  MAV_CMD_NAV_WAYPOINT (16), frame MAV_FRAME_GLOBAL (0), the home lat/lon,
  z 0, current 1. The executive ignores its content.
- each goal is one MAV_CMD_NAV_WAYPOINT (16) item, in order:

  ====== ================================================================
  frame  MAV_FRAME_GLOBAL_RELATIVE_ALT_INT (6) in MISSION_ITEM_INT;
         MAV_FRAME_GLOBAL_RELATIVE_ALT (3) in WPL files, as QGC writes;
         both are read as the same thing
  x, y   latitude, longitude in degE7 (degrees in WPL files)
  z      -depth_m: negative below the surface (ArduSub's relative altitude)
  param1 0 (hold time; anything else is refused)
  param2 goal radius in planning cells (``radius_cells``), a whole number >= 0
  param3 on_arrival: 0 hold, 1 surface, 2 drift, 3 next
  param4 0 (yaw; ignored when read, QGC may write NaN)
  ====== ================================================================

Floats travel as float32 on the wire (param1..4, z); ``items_to_goals`` turns
a float32 value back into the shortest decimal that gives it (12.3 stays 12.3).
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum, unique
from pathlib import Path

from planner.contract.atomic import write_atomic
from planner.contract.errors import ContractError

MAV_CMD_NAV_WAYPOINT = 16
WPL_HEADER = "QGC WPL 110"
WPL_COLUMNS = ("INDEX", "CURRENT_WP", "COORD_FRAME", "COMMAND", "PARAM1", "PARAM2", "PARAM3", "PARAM4",
               "LAT", "LON", "ALT", "AUTOCONTINUE")
MAX_GOALS = 1000  # goals in a mission, in YAML (planner.contract.mission) or over MAVLink
E7 = 1e7


@unique
class MavFrame(IntEnum):
    """The MAV_FRAME values a goal file may hold (global frames only)."""

    GLOBAL = 0
    GLOBAL_RELATIVE_ALT = 3
    GLOBAL_INT = 5
    GLOBAL_RELATIVE_ALT_INT = 6
    GLOBAL_TERRAIN_ALT = 10
    GLOBAL_TERRAIN_ALT_INT = 11


GOAL_FRAMES = frozenset({MavFrame.GLOBAL_RELATIVE_ALT, MavFrame.GLOBAL_RELATIVE_ALT_INT})
# _INT frames (degE7 in MISSION_ITEM_INT) and their float twins (degrees in MISSION_ITEM and WPL files).
_FLOAT_FRAME: dict[int, int] = {
    MavFrame.GLOBAL_INT: MavFrame.GLOBAL, MavFrame.GLOBAL_RELATIVE_ALT_INT: MavFrame.GLOBAL_RELATIVE_ALT,
    MavFrame.GLOBAL_TERRAIN_ALT_INT: MavFrame.GLOBAL_TERRAIN_ALT,
}


@unique
class ArrivalCode(IntEnum):
    """param3 of a goal item: what the executive does on arrival (``OnArrival``)."""

    HOLD = 0
    SURFACE = 1
    DRIFT = 2
    NEXT = 3

    @property
    def on_arrival(self) -> str:
        return self.name.lower()


@unique
class MissionResult(IntEnum):
    """MAV_MISSION_RESULT: the ``type`` of MISSION_ACK (mavlink.io Mission Protocol, "Errors/Completion")."""

    ACCEPTED = 0
    ERROR = 1
    UNSUPPORTED_FRAME = 2
    UNSUPPORTED = 3
    NO_SPACE = 4
    INVALID = 5
    INVALID_PARAM1 = 6
    INVALID_PARAM2 = 7
    INVALID_PARAM3 = 8
    INVALID_PARAM4 = 9
    INVALID_PARAM5_X = 10
    INVALID_PARAM6_Y = 11
    INVALID_PARAM7 = 12
    INVALID_SEQUENCE = 13
    DENIED = 14
    OPERATION_CANCELLED = 15

    @property
    def mav_name(self) -> str:
        """The MAVLink name, e.g. ``MAV_MISSION_INVALID_PARAM2``."""
        return f"MAV_MISSION_{self.name}"

    @property
    def description(self) -> str:
        return _RESULT_TEXT[self]


_RESULT_TEXT = {  # common.xml's descriptions
    MissionResult.ACCEPTED: "mission accepted OK",
    MissionResult.ERROR: "generic error / not accepting mission commands at all right now",
    MissionResult.UNSUPPORTED_FRAME: "coordinate frame is not supported",
    MissionResult.UNSUPPORTED: "command is not supported",
    MissionResult.NO_SPACE: "mission items exceed storage space",
    MissionResult.INVALID: "one of the parameters has an invalid value",
    MissionResult.INVALID_PARAM1: "param1 has an invalid value",
    MissionResult.INVALID_PARAM2: "param2 has an invalid value",
    MissionResult.INVALID_PARAM3: "param3 has an invalid value",
    MissionResult.INVALID_PARAM4: "param4 has an invalid value",
    MissionResult.INVALID_PARAM5_X: "x / param5 has an invalid value",
    MissionResult.INVALID_PARAM6_Y: "y / param6 has an invalid value",
    MissionResult.INVALID_PARAM7: "z / param7 has an invalid value",
    MissionResult.INVALID_SEQUENCE: "mission item received out of sequence",
    MissionResult.DENIED: "not accepting any mission commands from this communication partner",
    MissionResult.OPERATION_CANCELLED: "current mission operation cancelled",
}

# MAV_CMD names for error messages (common.xml; tests/planner/contract/test_waypoints.py checks them against pymavlink).
COMMAND_NAMES = {
    16: "NAV_WAYPOINT", 17: "NAV_LOITER_UNLIM", 18: "NAV_LOITER_TURNS", 19: "NAV_LOITER_TIME",
    20: "NAV_RETURN_TO_LAUNCH", 21: "NAV_LAND", 22: "NAV_TAKEOFF", 30: "NAV_CONTINUE_AND_CHANGE_ALT",
    31: "NAV_LOITER_TO_ALT", 82: "NAV_SPLINE_WAYPOINT", 93: "NAV_DELAY", 112: "CONDITION_DELAY",
    113: "CONDITION_CHANGE_ALT", 114: "CONDITION_DISTANCE", 115: "CONDITION_YAW", 177: "DO_JUMP",
    178: "DO_CHANGE_SPEED", 179: "DO_SET_HOME", 181: "DO_SET_RELAY", 183: "DO_SET_SERVO", 201: "DO_SET_ROI",
    206: "DO_SET_CAM_TRIGG_DIST", 5000: "NAV_FENCE_RETURN_POINT", 5001: "NAV_FENCE_POLYGON_VERTEX_INCLUSION",
    5002: "NAV_FENCE_POLYGON_VERTEX_EXCLUSION", 5003: "NAV_FENCE_CIRCLE_INCLUSION",
    5004: "NAV_FENCE_CIRCLE_EXCLUSION", 5100: "NAV_RALLY_POINT",
}


class WaypointError(ContractError):
    """A mission item or waypoint file that is not a valid goal list; ``result`` is the MISSION_ACK code to send."""

    def __init__(self, message: str, result: MissionResult = MissionResult.ERROR) -> None:
        super().__init__(message)
        self.result = result


@dataclass(frozen=True)
class MissionItem:
    """One MISSION_ITEM_INT, less the addressing (mavlink.io Mission Protocol, "Mission Items")."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x_lat_e7: int
    y_lon_e7: int
    z: float
    mission_type: int = 0

    @property
    def lat_deg(self) -> float:
        return self.x_lat_e7 / E7

    @property
    def lon_deg(self) -> float:
        return self.y_lon_e7 / E7


def to_e7(deg: float) -> int:
    """Degrees as degE7, rounded to the nearest unit (1e-7 degree, about 1 cm)."""
    return round(deg * E7)


def command_name(command: int) -> str:
    """``22 (NAV_TAKEOFF)``, or the bare number for a command not in the table."""
    name = COMMAND_NAMES.get(command)
    return f"{command} ({name})" if name else str(command)


def frame_name(frame: int) -> str:
    try:
        return f"{frame} ({MavFrame(frame).name})"
    except ValueError:
        return str(frame)


def home_item(lat_deg: float, lon_deg: float) -> MissionItem:
    """Item 0: home, as ArduPilot and QGC expect (MAV_FRAME_GLOBAL, z 0, current 1)."""
    check_position("home", lat_deg, lon_deg)
    return MissionItem(0, int(MavFrame.GLOBAL), MAV_CMD_NAV_WAYPOINT, 1, 1, 0.0, 0.0, 0.0, 0.0,
                       to_e7(lat_deg), to_e7(lon_deg), 0.0)


def check_position(where: str, lat_deg: float, lon_deg: float) -> None:
    if not (math.isfinite(lat_deg) and -90 <= lat_deg <= 90):
        raise WaypointError(f"{where}: latitude {lat_deg!r} deg: expected [-90, 90]")
    if not (math.isfinite(lon_deg) and -180 <= lon_deg <= 180):
        raise WaypointError(f"{where}: longitude {lon_deg!r} deg: expected [-180, 180]")





def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def from_float32(x: float) -> float:
    """A float32 value as the shortest decimal that gives it (12.300000190734863 -> 12.3); others unchanged."""
    try:
        if not math.isfinite(x) or _f32(x) != x:
            return x
        for digits in range(1, 10):
            y = float(f"{x:.{digits}g}")
            if _f32(y) == x:
                return y
    except OverflowError:
        pass
    return x


# QGC WPL 110 (mavlink.io "File Formats", "Mission Plain-Text File Format").


def wpl_frame(frame: int) -> int:
    """The frame written in a WPL file: the float twin of an _INT frame (6 -> 3), as QGC writes."""
    return int(_FLOAT_FRAME.get(frame, frame))


def _num(value: float) -> str:
    """A parameter or altitude: 8 decimals when exact, else the shortest text that reads back the same."""
    text = f"{value:.8f}"
    return text if math.isfinite(value) and float(text) == value else repr(float(value))


def format_wpl(items: Sequence[MissionItem]) -> str:
    """The text of a QGC WPL 110 file: tab-separated, lat/lon in degrees with 8 decimals."""
    lines = [WPL_HEADER]
    for it in items:
        cols = (it.seq, it.current, wpl_frame(it.frame), it.command, _num(it.param1), _num(it.param2),
                _num(it.param3), _num(it.param4), f"{it.x_lat_e7 / E7:.8f}", f"{it.y_lon_e7 / E7:.8f}", _num(it.z),
                it.autocontinue)
        lines.append("\t".join(str(c) for c in cols))
    return "\n".join(lines) + "\n"


def write_wpl(path: str | os.PathLike[str], items: Sequence[MissionItem]) -> Path:
    """Write a QGC WPL 110 file atomically (planner.contract.atomic); returns the path."""
    return write_atomic(path, format_wpl(items).encode("utf-8"))


def read_wpl(path: str | os.PathLike[str]) -> tuple[MissionItem, ...]:
    """Read a QGC WPL 110 file; WaypointError names the file and line. Frames are kept as written."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise WaypointError(f"{p}: no such waypoint file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise WaypointError(f"{p}: cannot read: {exc}") from None
    return parse_wpl(text, source=str(p))


def parse_wpl(text: str, *, source: str = "<text>") -> tuple[MissionItem, ...]:
    """Items from the text of a QGC WPL 110 file; ``#`` lines and blank lines are skipped."""
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise WaypointError(f"{source}:1: header missing; expected {WPL_HEADER!r}")
    if lines[0].strip() != WPL_HEADER:
        raise WaypointError(f"{source}:1: header {lines[0].strip()!r} is not supported; expected {WPL_HEADER!r}")
    items: list[MissionItem] = []
    for lineno, line in enumerate(lines[1:], start=2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        items.append(_parse_line(line, f"{source}:{lineno}", len(items)))
    return tuple(items)


def _parse_line(line: str, where: str, expected_seq: int) -> MissionItem:
    cols = line.split()
    if len(cols) != len(WPL_COLUMNS):
        raise WaypointError(f"{where}: {len(cols)} columns; expected {len(WPL_COLUMNS)} tab-separated: "
                            f"{' '.join(WPL_COLUMNS)}")

    def whole(n: int) -> int:
        try:
            return int(cols[n])
        except ValueError:
            raise WaypointError(f"{where}: {WPL_COLUMNS[n]} {cols[n]!r} is not a whole number") from None

    def number(n: int) -> float:
        try:
            return float(cols[n])
        except ValueError:
            raise WaypointError(f"{where}: {WPL_COLUMNS[n]} {cols[n]!r} is not a number") from None

    def degrees(n: int) -> int:
        value = number(n)
        if not (math.isfinite(value) and abs(value) <= 360):
            raise WaypointError(f"{where}: {WPL_COLUMNS[n]} {cols[n]!r} is not a position in degrees")
        return to_e7(value)

    seq = whole(0)
    if seq != expected_seq:
        raise WaypointError(f"{where}: INDEX {seq} out of sequence; expected {expected_seq}")
    return MissionItem(seq, whole(2), whole(3), whole(1), whole(11), number(4), number(5), number(6), number(7),
                       degrees(8), degrees(9), number(10))
