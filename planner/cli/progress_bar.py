"""The command line's progress bars: a ``planner.contract.progress.Progress`` drawn with tqdm on stderr.

Drawn only when stderr is a terminal and ``--quiet`` is not given: a log file, a pipe or a test
capturing stderr gets no bar characters. tqdm is imported here, on first use, so the executive's
import path and ``lrauv exec`` argument parsing never load it.
"""

from __future__ import annotations

import shutil
import sys
from contextlib import contextmanager
from typing import IO, Any, Iterator

from planner.contract.progress import SILENT, Progress


class TerminalBars:
    """One tqdm bar per task, one after another; a new task name closes the previous bar (left on screen)."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.task: str | None = None
        self.bar: Any = None

    def update(self, task: str, done: float, total: float, *, unit: str = "", detail: str = "") -> None:
        from tqdm import tqdm

        if task != self.task:
            self.close()
            self.task = task
            # The terminal's size once: one that reports 0 x 0 gets $COLUMNS or 80 x 24 (tqdm would draw nothing).
            size = shutil.get_terminal_size()
            self.bar = tqdm(total=total, desc=task, unit=f" {unit}" if unit else "it", file=self.stream,
                            ncols=min(size.columns, 100), nrows=size.lines, mininterval=0.2)
        bar = self.bar
        bar.total = total
        bar.n = done
        if detail:
            bar.set_postfix_str(detail, refresh=False)
        bar.refresh()

    def note(self, text: str) -> None:
        from tqdm import tqdm

        tqdm.write(f"  {text}", file=self.stream)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        self.bar, self.task = None, None


@contextmanager
def bars(*, quiet: bool, stream: IO[str] | None = None) -> Iterator[Progress]:
    """Bars on ``stream`` (stderr) when it is a terminal and not ``quiet``; else a silent meter."""
    out = sys.stderr if stream is None else stream
    if quiet or not out.isatty():
        yield SILENT
        return
    meter = TerminalBars(out)
    try:
        yield meter
    finally:
        meter.close()
