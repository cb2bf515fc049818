"""The argument parser shared by every ``lrauv`` subcommand."""

from __future__ import annotations

import argparse
import math
import re
from typing import Any, TypeAlias

# Longitudes west of Greenwich are negative: `--start -118.1,33.45` must read as a value.
# Python 3.13's argparse accepts it; 3.11/3.12 take anything but "-1" or "-1.5" for an option.
_NEGATIVE_NUMBER = re.compile(r"^-\.?\d")


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
