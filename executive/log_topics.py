"""The executive log's topics and their JSON schemas, and how a payload becomes JSON.

Three topics carry Foxglove's well-known schemas, so the Foxglove app draws them without
configuration: the track (Map panel, ``foxglove.LocationFix``), the events (Log panel,
``foxglove.Log``) and the mission's shapes on the map (``foxglove.GeoJSON``: goals, geofence,
the running plan). Their schemas are the official definitions, vendored unchanged from the
npm package ``@foxglove/schemas`` (``executive/foxglove_schemas/*.json``, written by
``tests/node/foxglove_schemas.mjs`` and checked against the package by the tests), loaded here
at import. The ``lrauv.*`` topics have our own schemas, below.

Every payload also carries ``boot_time_s``, the vehicle time since boot it was logged at: the
MCAP log time is UTC (``executive.log_clock``). Foxglove's schemas leave objects open (no
``additionalProperties: false``), so the extra key is valid there too.

Standard library only.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
import re
from collections.abc import Mapping
from enum import Enum, IntEnum
from importlib import resources
from typing import Any, get_args

from executive.log_records import LogError
from executive.state import LogLevelName

__all__ = ["ADDED_LATER", "BOOT_TIME_KEY", "FOXGLOVE_SCHEMAS", "NS_PER_S", "LogLevel", "LogLevelName", "Topic", "boot_time_of",
           "encode", "foxglove_time", "level_code", "time_ns"]

NS_PER_S = 1_000_000_000
BOOT_TIME_KEY = "boot_time_s"  # vehicle time since boot, in every payload of a log with UTC log times


# -- Foxglove's schemas, as the official package defines them -------------------------------------

FOXGLOVE_SCHEMAS = ("LocationFix", "Log", "GeoJSON")  # the files in executive/foxglove_schemas/


def _official(name: str) -> dict[str, Any]:
    text = resources.files("executive").joinpath("foxglove_schemas", f"{name}.json").read_text(encoding="utf-8")
    schema: dict[str, Any] = json.loads(text)
    return schema


_LOCATION_FIX, _LOG, _GEOJSON = (_official(name) for name in FOXGLOVE_SCHEMAS)


# -- our own schemas --------------------------------------------------------------------------

_NUM = {"type": "number"}
_NUM_OR_NULL = {"type": ["number", "null"]}
_INT = {"type": "integer"}
_STR = {"type": "string"}
_STR_OR_NULL = {"type": ["string", "null"]}
_BOOL = {"type": "boolean"}
_OBJ = {"type": "object"}


def _lrauv(name: str, description: str, required: Mapping[str, Any], optional: Mapping[str, Any] | None = None
           ) -> dict[str, Any]:
    """A JSON schema for one of our own topics: ``required`` keys are in every payload.

    Objects stay open (no ``additionalProperties: false``), so a field added to a value
    object later does not make older readers reject the log. ``boot_time_s`` is optional:
    logs written before log times were UTC lack it.
    """
    return {
        "title": name,
        "description": description,
        "type": "object",
        "properties": {**required, **(optional or {}), BOOT_TIME_KEY: _NUM},
        "required": list(required),
    }


_VEHICLE_STATE = _lrauv("lrauv.VehicleState", "The executive's picture of the vehicle; null = not yet known", {
    "time_s": _NUM,  # vehicle time since boot
    "lat_deg": _NUM_OR_NULL,
    "lon_deg": _NUM_OR_NULL,
    "depth_m": _NUM_OR_NULL,  # positive down
    "heading_deg": _NUM_OR_NULL,  # compass, clockwise from north
    "mode": {"type": ["integer", "null"]},  # HEARTBEAT.custom_mode
    "armed": _BOOL,
    "position_ok": _BOOL,
    "battery_pct": _NUM_OR_NULL,
    "energy_used_wh": _NUM_OR_NULL,
}, {"heartbeat_s": _NUM_OR_NULL})

_DECISION = _lrauv("lrauv.Decision", "One helm decision: where the vehicle was and what the policy said", {
    "time_s": _NUM,
    "lat_deg": _NUM_OR_NULL,
    "lon_deg": _NUM_OR_NULL,
    "depth_m": _NUM_OR_NULL,
    "heading_deg": _NUM_OR_NULL,
    # policy-table state index, axis order [l, j, i, k] (docs/policy-table.md)
    "cell": {"type": ["array", "null"], "items": _INT, "minItems": 4, "maxItems": 4},
    "situation": _STR,
    "action": _STR_OR_NULL,
    "mode": _STR,
    "changed": _BOOL,
}, {
    # time-varying plans only (executive.timeline): the slice decided with, and why that slice
    "slice": _INT,
    "slice_status": {"type": "string", "enum": ["in_horizon", "before_start", "past_horizon", "time_unknown"]},
})

_COMMAND = _lrauv("lrauv.Command", "A command the helm sent; the remaining keys are the command's fields", {
    "time_s": _NUM,
    "kind": _STR,  # SetMode, Arm, VelocityYaw, DepthTarget, ...
})

_POLICY = _lrauv("lrauv.Policy", "A policy table the executive loaded, swapped in or refused", {
    "time_s": _NUM,
    "reason": {"type": "string", "enum": ["loaded", "received", "swapped", "refused"]},
}, {
    "table_crc32": {"type": "string", "pattern": "^[0-9a-f]{8}$"},  # absent only when a refused file is no table
    "source": _STR,  # what brought the table: upload PATH, onboard plan (REASON), next goal
    "goal_index": _INT,
    "previous": _OBJ,  # the replaced table's table_crc32, forecast_identity, forecast_time
    "forecast_identity": _STR_OR_NULL,
    "forecast_time": _STR_OR_NULL,
    "latency_s": _NUM,  # onboard plans: from the trigger (a new forecast seen) to the table ready
    "plan_s": _NUM,  # onboard plans: the planner process alone
    "refusal": _STR,
    "forecast": {"type": "object", "properties": {"identity": _STR, "time": _STR_OR_NULL}},
    "grid": _OBJ,
    "goal": _OBJ,
    "model": _STR_OR_NULL,
    "criterion": _STR_OR_NULL,
    # time-varying tables only: how many slices, the first's and the last's UTC time, and (when the table
    # carries its slices' currents) that the tide's timing is fitted onboard
    "slices": {"type": "object", "properties": {"count": _INT, "first_utc": _STR, "last_utc": _STR,
                                                "timing_correction": {"type": "boolean"}}},
})

_MAVLINK = _lrauv("lrauv.MavlinkMessage", "One MAVLink message as received or sent", {
    "msg_id": _INT,
    "name": _STR,
    "src_system": _INT,
    "src_component": _INT,
    "fields": _OBJ,  # field name -> value, MAVLink units (common.xml)
}, {
    "time_s": _NUM,
    "direction": {"type": "string", "enum": ["rx", "tx"]},  # also implied by the topic
    "frame": {"type": "string", "contentEncoding": "base64"},  # the exact wire bytes (lrauv replay --tlog)
})



class Topic(Enum):
    """The log's topics; ``value`` is the MCAP topic name."""

    FIX = "/vehicle/fix"
    LOG = "/log"
    STATE = "/vehicle/state"
    DECISION = "/executive/decision"
    COMMAND = "/executive/command"
    POLICY = "/executive/policy"
    MAVLINK_RX = "/mavlink/rx"
    MAVLINK_TX = "/mavlink/tx"
    # foxglove.GeoJSON, each message the whole layer (the Map panel shows a topic's latest message)
    MAP_GOALS = "/map/goals"  # every goal of the mission, the active one marked
    MAP_GEOFENCE = "/map/geofence"  # the safety section's geofence
    MAP_PLAN = "/map/plan"  # the running plan: its table's grid, land and goal cells, and the active goal

    @property
    def schema_name(self) -> str:
        """``foxglove.*`` for Foxglove's well-known schemas, ``lrauv.*`` for ours (the schema's title)."""
        return str(self.schema["title"])

    @property
    def schema(self) -> Mapping[str, Any]:
        """The JSON schema (a shared dict; do not mutate)."""
        return _SCHEMAS[self]

    @property
    def required(self) -> tuple[str, ...]:
        """Keys every payload on this topic has (the schema's ``required``)."""
        return tuple(self.schema.get("required", ()))

    @property
    def stamped(self) -> bool:
        """Whether the payload has a Foxglove ``timestamp`` (the record's log time, UTC)."""
        return "timestamp" in self.schema.get("properties", {})


_SCHEMAS: dict[Topic, dict[str, Any]] = {
    Topic.FIX: _LOCATION_FIX,
    Topic.LOG: _LOG,
    Topic.STATE: _VEHICLE_STATE,
    Topic.DECISION: _DECISION,
    Topic.COMMAND: _COMMAND,
    Topic.POLICY: _POLICY,
    Topic.MAVLINK_RX: _MAVLINK,  # both directions share one schema
    Topic.MAVLINK_TX: _MAVLINK,
    Topic.MAP_GOALS: _GEOJSON,
    Topic.MAP_GEOFENCE: _GEOJSON,
    Topic.MAP_PLAN: _GEOJSON,
}


# Keys a schema requires that logs from before it was the official one lack (foxglove.Log's source
# file and line): readers accept a payload without them.
ADDED_LATER: dict[Topic, tuple[str, ...]] = {Topic.LOG: ("file", "line")}


class LogLevel(IntEnum):
    """foxglove.LogLevel (Log.json)."""

    UNKNOWN = 0
    DEBUG = 1
    INFO = 2
    WARNING = 3
    ERROR = 4
    FATAL = 5


_LEVELS: dict[str, int] = {name: int(LogLevel[name.upper()]) for name in get_args(LogLevelName)}


def level_code(level: str) -> int:
    """foxglove.LogLevel of a level name; ``LogError`` for another name."""
    code = _LEVELS.get(level)
    if code is None:
        raise LogError(f"log level: expected one of {list(_LEVELS)}; got {level!r}")
    return code


# -- JSON encoding (pure) ------------------------------------------------------------------


def _json_default(obj: Any) -> Any:
    """What the C encoder cannot do itself; called only for such objects, so it costs nothing otherwise."""
    if isinstance(obj, Enum):
        return obj.value
    if isinstance(obj, bytes | bytearray | memoryview):
        return base64.b64encode(obj).decode("ascii")  # Foxglove's JSON convention for bytes
    if isinstance(obj, set | frozenset):
        return list(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if hasattr(obj, "dtype") and hasattr(obj, "item"):  # a numpy scalar, without importing numpy
        return obj.item()
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serialisable")


def _sanitise(obj: Any) -> Any:
    """A copy with non-finite floats as null and every key a string; the slow path only."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, str | int | bool) or obj is None:
        return obj
    if isinstance(obj, Mapping):
        return {_key(k): _sanitise(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_sanitise(v) for v in obj]
    return _sanitise(_json_default(obj))


def _key(key: Any) -> str:
    key = key.value if isinstance(key, Enum) else key
    if isinstance(key, str):
        return key
    return json.dumps(key) if isinstance(key, bool | int | float) else str(key)  # as json spells such keys


# Compact and strict: allow_nan=False makes NaN/inf raise, and the slow path writes null
# (bare NaN is not JSON; Foxglove and json.loads in other languages reject it).
_ENCODE = json.JSONEncoder(separators=(",", ":"), allow_nan=False, default=_json_default).encode


def encode(payload: Mapping[str, Any]) -> bytes:
    """``payload`` as compact JSON: NaN/inf as null, Enums as their value, tuples as arrays, keys as text.

    Raises ``TypeError`` or ``ValueError`` for what JSON cannot hold (an object, a cycle).
    """
    try:
        return _ENCODE(payload).encode()
    except (ValueError, TypeError):  # NaN/inf, or keys/values the fast path cannot take
        try:
            return _ENCODE(_sanitise(payload)).encode()
        except RecursionError as exc:  # a cycle
            raise ValueError(str(exc)) from None


def time_ns(t_s: float, what: str) -> int:
    """Unix seconds -> int ns, exact to the float: a Unix time times 1e9 would lose ~100 ns to rounding."""
    try:
        sec = math.floor(t_s)
        ns = sec * NS_PER_S + round((t_s - sec) * NS_PER_S)
    except (ValueError, OverflowError, TypeError):
        raise LogError(f"{what}: expected a finite time in seconds; got {t_s!r}") from None
    return max(ns, 0)  # MCAP times are unsigned


def foxglove_time(ns: int) -> dict[str, int]:
    """foxglove.Time of Unix nanoseconds: ``{sec, nsec}``."""
    sec, nsec = divmod(max(ns, 0), NS_PER_S)
    return {"sec": sec, "nsec": nsec}


_BOOT_TAIL = re.compile(rb'"%s":(-?[0-9][0-9.eE+-]*)\}\s*$' % BOOT_TIME_KEY.encode())


def boot_time_of(data: bytes) -> float | None:
    """The ``boot_time_s`` of a logged message's JSON, or None (a log from before UTC log times).

    The recorder writes it as the last key, so its value is read off the end without decoding
    the rest; anything else is decoded whole.
    """
    found = _BOOT_TAIL.search(data[-48:])
    if found is not None:
        return float(found.group(1))
    if BOOT_TIME_KEY.encode() not in data:
        return None
    try:
        value = json.loads(data).get(BOOT_TIME_KEY)
    except (ValueError, AttributeError):
        return None
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None
