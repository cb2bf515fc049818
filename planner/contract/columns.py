"""Every line the commands print fits in ``WIDTH`` columns: labelled lines wrap under their value.

The commands print ``label      value`` lines (the value at column 11) and tables. A line
longer than ``WIDTH`` is wrapped at spaces, its continuation lines indented to its value's
column, so nothing is lost and the labels still line up. A word is never cut: a path longer
than the line stays whole (on its label's line), the one thing that may pass the width.
"""

from __future__ import annotations

import re
import textwrap

WIDTH = 100  # columns
VALUE_COLUMN = 11  # where the value of a "label      value" line starts
_LABEL = re.compile(r" *\S+(?: \S+)*? {2,}")  # a label of words, then two spaces or more up to its value
_MAX_VALUE_COLUMN = 20  # a value further right is not a label's: continuations indent by two


def fit(text: str, width: int = WIDTH) -> str:
    """``text`` with each of its lines wrapped at spaces to ``width`` columns (see the module's docstring)."""
    return "\n".join(_fit_line(line, width) for line in text.split("\n"))


def _fit_line(line: str, width: int) -> str:
    if len(line) <= width:
        return line
    indent = len(line) - len(line.lstrip(" "))
    label = _LABEL.match(line)
    if label is not None and label.end() <= _MAX_VALUE_COLUMN:
        value = label.end()
    elif line[VALUE_COLUMN - 1:VALUE_COLUMN + 1].startswith(" ") and line[VALUE_COLUMN] != " ":
        value = VALUE_COLUMN  # "resolution value": a ten-letter label and one space
    else:
        value = indent + 2
    rows = textwrap.wrap(line, width, subsequent_indent=" " * value, break_long_words=False, break_on_hyphens=False)
    if len(rows) > 1 and len(rows[0]) <= value:  # a label alone: its value is one word longer than the line
        rows[:2] = [rows[0].ljust(value) + rows[1].lstrip(" ")]
    return "\n".join(rows or [line])


def say(text: str = "", *, flush: bool = False) -> None:
    """Print ``text`` to stdout, fitted to ``WIDTH`` columns."""
    print(fit(text), flush=flush)
