"""A logged message's JSON checked against what its topic promises, before replay uses it.

Replay reads files from sea: cut, damaged, or written by another version. Each
payload is checked against its topic's JSON schema (``executive.recorder.Topic.schema``:
types, required keys, items, enums) and a MAVLink record's fields against the
ardupilotmega dialect pymavlink was built from (type, range, array length). What
does not fit raises ``PayloadError`` saying which key, what was expected and what
was found; the caller adds the file and the message. So a wrong type never
reaches the summary, the audit or the re-stream as a crash deep inside them.

MAVLink fields come back decoded as pymavlink would give them on the wire: null
floats are NaN again (the recorder writes NaN as null, JSON has none), and an
extension field a record lacks takes the dialect's default, as MAVLink 2 fills
missing trailing extension bytes with zeros.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
import types
import typing
from collections.abc import Callable, Mapping
from functools import cache
from typing import Any

from executive import mavlink_bridge as bridge
from executive.log_topics import ADDED_LATER
from executive.recorder import Topic

__all__ = ["PayloadError", "check_fields", "check_payload", "mavlink_value"]

mavlink = bridge.mavlink

_INT_RANGES = {f"{sign}int{bits}_t": ((0, 2 ** bits - 1) if sign else (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1))
               for sign in ("u", "") for bits in (8, 16, 32, 64)}
_INT64 = _INT_RANGES["int64_t"]  # replay keeps integers in numpy int64 columns
_MAVLINK_TOPICS = (Topic.MAVLINK_RX, Topic.MAVLINK_TX)
_FLOAT_MAX = 1.7976931348623157e308  # a larger JSON integer does not fit a float


class PayloadError(ValueError):
    """A payload that is not what its topic's schema or the MAVLink dialect says."""


def check_payload(topic: Topic, payload: Any, *, keep_undecodable: bool = False) -> dict[str, Any]:
    """``payload`` checked against ``topic``'s schema; MAVLink fields decoded (see the module's doc).

    ``keep_undecodable``: a MAVLink record whose fields do not fit the dialect comes back as
    logged rather than raising, for a reader that skips such records by name (the re-stream).
    """
    try:
        _compiled(topic)(payload)
    except _Bad as bad:
        where = "".join(k if k.startswith("[") else f".{k}" for k in bad.path).lstrip(".")
        raise PayloadError(f"{where or 'the payload'}: {bad.text}") from None
    if topic in _MAVLINK_TOPICS:
        try:
            return {**payload, "fields": _mavlink_fields(payload)}
        except PayloadError:
            if not keep_undecodable:
                raise
    return dict(payload)


def mavlink_value(name: str, fname: str, value: Any, kind: str, length: int) -> Any:
    """One MAVLink field's logged value as pymavlink takes it (text as bytes); ``PayloadError`` when it does not fit."""
    value = _converter(name, fname, kind, length)(value)
    return value.encode("utf-8") if kind == "char" else value


def check_fields(obj: Any, where: str) -> None:
    """Each field of a dataclass built from logged JSON (``HelmConfig.from_json``) has its annotated type.

    The forms the executive's settings use: float, int, bool, str, Literal, ``X | None``,
    tuples and nested dataclasses; anything else is taken as it is.
    """
    try:
        hints = typing.get_type_hints(type(obj))
    except NameError:
        return
    for f in dataclasses.fields(obj):
        if f.name in hints:
            _check_hint(getattr(obj, f.name), hints[f.name], f"{where}.{f.name}")


# -- internals: MAVLink fields ---------------------------------------------------------------


def _mavlink_fields(payload: Mapping[str, Any]) -> dict[str, Any]:
    """The fields of a logged MAVLink message, decoded; unchanged for a message the dialect lacks."""
    name, fields = payload["name"], payload["fields"]
    cls = mavlink.mavlink_map.get(payload["msg_id"])
    if cls is None:
        return dict(fields)  # not this dialect's: counted and skipped where it would be used
    if cls.msgname != name:
        raise PayloadError(f"msg_id {payload['msg_id']} is {cls.msgname}, not {name}")
    out = dict(fields)
    for fname, convert, default in _layout(cls):
        value = fields.get(fname, _ABSENT)
        if value is not _ABSENT:
            out[fname] = convert(value)
        elif default is inspect.Parameter.empty:
            raise PayloadError(f"{name}: field {fname!r} is missing")
        else:
            out[fname] = (default.decode("utf-8") if isinstance(default, bytes)
                          else list(default) if isinstance(default, tuple) else default)  # as JSON gives them
    return out


@cache
def _layout(cls: Any) -> tuple[tuple[str, Callable[[Any], Any], Any], ...]:
    """Each field of a dialect message: its converter and its default (extension fields only)."""
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    params = inspect.signature(cls.__init__).parameters
    return tuple((f, _converter(cls.msgname, f, kind, lengths[f]), params[f].default)
                 for f, kind in zip(cls.fieldnames, cls.fieldtypes, strict=True))


@cache
def _converter(name: str, fname: str, kind: str, length: int) -> Callable[[Any], Any]:
    """The logged value of one field, checked against its MAVLink type; text stays text."""
    def bad(value: Any, expected: str) -> PayloadError:
        return PayloadError(f"{name}.{fname}: expected {expected}; got {_brief(value)}")

    if kind == "char":  # char[n] is text (bytes on the wire); the log holds it decoded
        def text(value: Any) -> Any:
            if type(value) is str:
                return value
            raise bad(value, "text")
        return text
    if kind in ("float", "double"):
        def real(value: Any) -> Any:
            if type(value) is float:
                return value
            if value is None:
                return math.nan  # the recorder writes NaN as null
            if type(value) is int and -_FLOAT_MAX <= value <= _FLOAT_MAX:
                return float(value)
            raise bad(value, kind)
        scalar = real
    else:
        lo, hi = _INT_RANGES[kind]

        def integer(value: Any) -> Any:
            if type(value) is int and lo <= value <= hi:
                return value
            raise bad(value, f"{kind} ({lo} to {hi})")
        scalar = integer
    if not length:
        return scalar

    def array(value: Any) -> Any:
        if type(value) is not list or len(value) != length:
            raise bad(value, f"a list of {length} {kind}")
        return [scalar(v) for v in value]
    return array


# -- internals: the topics' JSON schemas -----------------------------------------------------


class _Bad(Exception):
    """A value that does not fit its schema; ``path`` grows as it leaves each level."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text
        self.path: list[str] = []


_ABSENT = object()
_PLAIN = {"string": str, "boolean": bool, "null": type(None), "object": dict, "array": list}


@cache
def _compiled(topic: Topic) -> Callable[[Any], None]:
    later = ADDED_LATER.get(topic, ())  # required now, absent from older logs
    return _compile({**topic.schema, "required": [k for k in topic.required if k not in later]})


def _compile(schema: Mapping[str, Any]) -> Callable[[Any], None]:
    """A check of the part of JSON Schema the recorder's schemas use: type, properties, required, items, enum."""
    kinds = schema.get("type")
    kinds = None if kinds is None else ((kinds,) if isinstance(kinds, str) else tuple(kinds))
    fits = _any if kinds is None else _type_test(kinds)
    expected = "" if kinds is None else " or ".join(kinds)
    choices = schema.get("enum")
    if choices is None and "oneOf" in schema and all("const" in s for s in schema["oneOf"]):
        choices = [s["const"] for s in schema["oneOf"]]
    pattern = re.compile(schema["pattern"]) if "pattern" in schema else None
    required = tuple(schema.get("required", ()))
    properties = tuple((k, _compile(sub)) for k, sub in schema.get("properties", {}).items())
    low, high = schema.get("minItems", 0), schema.get("maxItems", math.inf)
    items = _compile(schema["items"]) if "items" in schema else None
    if choices is None and pattern is None and not (required or properties or items) and "minItems" not in schema:
        def leaf(value: Any) -> None:  # most keys: a type alone
            if not fits(value):
                raise _Bad(f"expected {expected}; got {_brief(value)}")
        return leaf

    def check(value: Any) -> None:
        if not fits(value):
            raise _Bad(f"expected {expected}; got {_brief(value)}")
        if choices is not None and (type(value) is bool or value not in choices):
            raise _Bad(f"expected one of {', '.join(map(str, choices))}; got {_brief(value)}")
        if pattern is not None and type(value) is str and pattern.search(value) is None:
            raise _Bad(f"expected text matching {pattern.pattern}; got {_brief(value)}")
        if type(value) is dict:
            for key in required:
                if key not in value:
                    bad = _Bad("missing")
                    bad.path.append(key)
                    raise bad
            for key, sub in properties:
                v = value.get(key, _ABSENT)
                if v is not _ABSENT:
                    try:
                        sub(v)
                    except _Bad as bad:
                        bad.path.insert(0, key)
                        raise
        elif type(value) is list:
            if not low <= len(value) <= high:
                raise _Bad(f"expected {low if low == high else f'{low} to {high}'} items; got {len(value)}")
            if items is not None:
                for i, v in enumerate(value):
                    try:
                        items(v)
                    except _Bad as bad:
                        bad.path.insert(0, f"[{i}]")
                        raise
    return check


def _type_test(kinds: tuple[str, ...]) -> Callable[[Any], bool]:
    """Whether a decoded JSON value is one of ``kinds`` (JSON's types: a bool is no number)."""
    plain = tuple(_PLAIN[k] for k in kinds if k in _PLAIN)
    integer, number = "integer" in kinds, "number" in kinds

    def test(value: Any) -> bool:
        t = type(value)
        if t in plain or (number and t is float):
            return True
        if t is int:  # an integer replay can hold: as a float, or in an int64 column
            return (number and -_FLOAT_MAX <= value <= _FLOAT_MAX) or (integer and _INT64[0] <= value <= _INT64[1])
        return False
    return test


def _any(value: Any) -> bool:
    return True


# -- internals: settings dataclasses ---------------------------------------------------------


def _check_hint(value: Any, hint: Any, where: str) -> None:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if not any(_fits(value, a) for a in args):
            raise PayloadError(f"{where}: expected {' or '.join(_hint_name(a) for a in args)}; got {_brief(value)}")
        for a in args:  # the one it fits, checked all the way down
            if _fits(value, a):
                _check_hint(value, a, where)
                return
    if not _fits(value, hint):
        raise PayloadError(f"{where}: expected {_hint_name(hint)}; got {_brief(value)}")
    if origin is tuple:
        each = [args[0]] * len(value) if len(args) == 2 and args[1] is Ellipsis else list(args)
        if len(each) != len(value):
            raise PayloadError(f"{where}: expected {len(each)} items; got {len(value)}")
        for i, (v, a) in enumerate(zip(value, each, strict=True)):
            _check_hint(v, a, f"{where}[{i}]")
    elif dataclasses.is_dataclass(hint):
        check_fields(value, where)


def _fits(value: Any, hint: Any) -> bool:
    """Whether ``value`` has the outer type of ``hint`` (anything not understood fits)."""
    origin = typing.get_origin(hint)
    if hint is type(None):
        return value is None
    if hint is float:
        return _is_number(value)
    if hint is int:
        return _is_int(value)
    if hint in (bool, str):
        return isinstance(value, hint)
    if origin is typing.Literal:
        return any(value == a and type(value) is type(a) for a in typing.get_args(hint))
    if origin is tuple:
        return isinstance(value, tuple)
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return isinstance(value, hint)
    return True


def _hint_name(hint: Any) -> str:
    if typing.get_origin(hint) is typing.Literal:
        return "one of " + ", ".join(map(repr, typing.get_args(hint)))
    return "null" if hint is type(None) else getattr(hint, "__name__", str(hint))


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    """A JSON number replay can hold as a float (NaN and infinities included, as the decoder gives them)."""
    if isinstance(value, float):
        return True
    return _is_int(value) and abs(value) <= _FLOAT_MAX


def _brief(value: Any) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"
