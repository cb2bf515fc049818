"""The executive's own parameters and its side of the MAVLink parameter protocol (pure).

A ground station that loads a vehicle's parameters (PARAM_REQUEST_LIST to the vehicle's
system, component 0, as QGroundControl's ParameterManager does, or to component 191) gets
these from the executive's component beside the autopilot's own. They say what the
executive is doing and which limits it holds; all are read-only: the mission and its
safety section are changed by upload (mission protocol, MAVLink FTP), never by PARAM_SET.

Per https://mavlink.io/en/services/parameter.html: names are at most 16 characters;
every value goes out as MAV_PARAM_TYPE_REAL32, so each is the float32 nearest to the
truth (whole numbers below 2**24 exactly); ``param_count`` and ``param_index`` are those
of this fixed list, the same for the whole run. A PARAM_REQUEST_READ names a parameter by
``param_id`` when ``param_index`` is -1, else by index; one that names none is not answered.
A PARAM_SET that cannot be applied is answered with PARAM_VALUE carrying the current value.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

NAME_MAX = 16  # PARAM_VALUE.param_id: char[16], no terminator when full
MESSAGES = frozenset({"PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"})


def float32(value: float) -> float:
    """``value`` as a MAV_PARAM_TYPE_REAL32 parameter carries it."""
    return float(struct.unpack("<f", struct.pack("<f", value))[0])


@dataclass(frozen=True, slots=True)
class Parameter:
    name: str
    value: float  # the float32 on the wire

    def __post_init__(self) -> None:
        if not 0 < len(self.name) <= NAME_MAX or not self.name.isascii():
            raise ValueError(f"parameter name {self.name!r}: expected 1 to {NAME_MAX} ASCII characters")
        object.__setattr__(self, "value", float32(self.value))


@dataclass(frozen=True, slots=True)
class ParamValue:
    """One PARAM_VALUE to send: the parameter, its index and how many there are."""

    name: str
    value: float
    index: int
    count: int


@dataclass(frozen=True, slots=True)
class Answer:
    """What a parameter message gets: the PARAM_VALUEs to send and the line the log keeps."""

    values: tuple[ParamValue, ...]
    text: str
    refused: bool = False  # a PARAM_SET that changed nothing (announced, not only logged)


@dataclass(frozen=True, slots=True)
class Facts:
    """What the parameters report, read from the executive at the time of the request."""

    goal_index: int  # the active goal (0-based); -1 without a plan
    goal_count: int
    safety_stop: bool
    max_depth_m: float | None  # the mission's safety section; None: no such limit (no parameter)
    min_battery_pct: float | None


def table(facts: Facts) -> tuple[Parameter, ...]:
    """The parameters, in index order. Which limits appear depends only on the configuration, fixed for the run."""
    params = [Parameter("EXEC_GOAL_INDEX", facts.goal_index), Parameter("EXEC_GOAL_COUNT", facts.goal_count),
              Parameter("EXEC_SAFE_STOP", 1.0 if facts.safety_stop else 0.0)]
    if facts.max_depth_m is not None:
        params.append(Parameter("EXEC_MAX_DEPTH_M", facts.max_depth_m))
    if facts.min_battery_pct is not None:
        params.append(Parameter("EXEC_MINBATT_PCT", facts.min_battery_pct))
    return tuple(params)


def _value(params: tuple[Parameter, ...], index: int) -> ParamValue:
    p = params[index]
    return ParamValue(p.name, p.value, index, len(params))


def _index_of(params: tuple[Parameter, ...], name: str) -> int | None:
    return next((n for n, p in enumerate(params) if p.name == name), None)


def param_name(raw: str | bytes) -> str:
    """A received ``param_id``: up to the first NUL (pymavlink gives str or bytes)."""
    text = raw.decode("ascii", "replace") if isinstance(raw, bytes | bytearray) else str(raw)
    return text.split("\x00", 1)[0]


def answer(params: tuple[Parameter, ...], kind: str, *, name: str = "", index: int = -1, value: float = 0.0,
           peer: tuple[int, int] = (0, 0)) -> Answer:
    """The answer to one parameter message of type ``kind`` from ``peer`` (system, component)."""
    who = f"from {peer[0]}/{peer[1]}"
    if kind == "PARAM_REQUEST_LIST":
        return Answer(tuple(_value(params, n) for n in range(len(params))),
                      f"PARAM_REQUEST_LIST {who}: {len(params)} parameters sent")
    if kind == "PARAM_REQUEST_READ":
        found = _index_of(params, name) if index == -1 else (index if 0 <= index < len(params) else None)
        what = repr(name) if index == -1 else f"index {index}"
        if found is None:
            return Answer((), f"PARAM_REQUEST_READ {what} {who}: no such parameter, not answered")
        return Answer((_value(params, found),), f"PARAM_REQUEST_READ {what} {who}: {params[found].name} sent")
    if kind == "PARAM_SET":
        found = _index_of(params, name)
        if found is None:
            return Answer((), f"PARAM_SET {name!r} = {value:g} {who}: no such parameter, not answered")
        current = params[found].value
        return Answer((_value(params, found),),  # the words that matter first: a STATUSTEXT may be cut
                      f"read-only parameter {name}: PARAM_SET {value:g} {who} refused, current value {current:g}"
                      " answered (the mission's upload changes it)", refused=True)
    raise ValueError(f"not a parameter message: {kind}")
