"""The argument parser shared by every ``lrauv`` subcommand."""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from typing import Any, TypeAlias, TypeVar

# Longitudes west of Greenwich are negative: `--start -118.1,33.45` must read as a value.
# Python 3.13's argparse accepts it; 3.11/3.12 take anything but "-1" or "-1.5" for an option.
_NEGATIVE_NUMBER = re.compile(r"^-\.?\d")
_Number = TypeVar("_Number", int, float)


class CommandParser(argparse.ArgumentParser):
    """``ArgumentParser`` that takes ``-118.1,33.45`` as a value; subparsers inherit the class."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER


# What ``CommandParser.add_subparsers`` returns; each subcommand's module registers its parsers on it.
# A string: argparse's class is generic only in its stubs.
Subcommands: TypeAlias = "argparse._SubParsersAction[CommandParser]"


def floats(text: str, n: int | None, what: str) -> list[float]:
    """``n`` (any number when None) finite comma-separated numbers, e.g. ``-118.1,33.45``; an argparse type."""
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what}: expected comma-separated numbers; got {text!r}") from None
    if n is not None and len(values) != n:
        raise argparse.ArgumentTypeError(f"{what}: expected {n} comma-separated numbers; got {len(values)} in {text!r}")
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{what}: expected finite numbers; got {text!r}")
    return values


def count(text: str) -> int:
    """A whole number >= 1 (workers); an argparse type."""
    return _checked(text, int, lambda v: v >= 1, "a whole number >= 1")


def mavlink_id(text: str) -> int:
    """A MAVLink system or component id, 0..255 (one byte on the wire); an argparse type."""
    return _checked(text, int, lambda v: 0 <= v <= 255, "a MAVLink id 0..255")


def seconds(text: str) -> float:
    """A finite number of seconds > 0 (a timeout, an interval); an argparse type."""
    return _checked(text, float, lambda v: math.isfinite(v) and v > 0, "a number of seconds > 0")


def _checked(text: str, parse: Callable[[str], _Number], ok: Callable[[_Number], bool], expected: str) -> _Number:
    try:
        value = parse(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}; got {text!r}") from None
    if not ok(value):
        raise argparse.ArgumentTypeError(f"expected {expected}; got {text}")
    return value
