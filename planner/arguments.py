"""The argument parser shared by every ``lrauv`` subcommand."""

from __future__ import annotations

import argparse
import re

# Longitudes west of Greenwich are negative: `--start -118.1,33.45` must read as a value.
# Python 3.13's argparse accepts it; 3.11/3.12 take anything but "-1" or "-1.5" for an option.
_NEGATIVE_NUMBER = re.compile(r"^-\.?\d")


class CommandParser(argparse.ArgumentParser):
    """``ArgumentParser`` that takes ``-118.1,33.45`` as a value; subparsers inherit the class."""

    def __init__(self, *args, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER
