"""The command line's progress bars: a ``planner.contract.progress.Progress`` drawn with tqdm on stderr.

Drawn only when stderr is a terminal and ``--quiet`` is not given: a log file, a pipe or a test
capturing stderr gets no bar characters. tqdm is imported here, on first use, so the executive's
import path and ``lrauv exec`` argument parsing never load it.
"""

from __future__ import annotations

import shutil
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import IO, Any

from planner.contract.progress import SILENT, Progress


class TerminalBars:
    """One tqdm bar per task, one after another; a new task name closes the previous bar (left on screen)."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.task: str | None = None
        self.bar: Any = None
        self.drawn_s = 0.0

    # Callers may tick on every message of a log (tens of thousands): the bar is drawn at most this often,
    # and always at a task's start and end.
    REDRAW_S = 0.1

    def update(self, task: str, done: float, total: float, *, unit: str = "", detail: str = "") -> None:
        from tqdm import tqdm

        if task != self.task:
            self.close()
            self.task = task
            # The terminal's size once: one that reports 0 x 0 gets $COLUMNS or 80 x 24 (tqdm would draw nothing).
            size = shutil.get_terminal_size()
            self.bar = tqdm(total=total, desc=task, unit=f" {unit}" if unit else "it", file=self.stream,
                            ncols=min(size.columns, 100), nrows=size.lines, mininterval=0.2)
        elif done < total and time.monotonic() - self.drawn_s < self.REDRAW_S:
            return
        bar = self.bar
        bar.total = total
        bar.n = done
        if detail:
            bar.set_postfix_str(detail, refresh=False)
        bar.refresh()
        self.drawn_s = time.monotonic()

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


def announcer(meter: Progress, *, quiet: bool) -> Callable[[str], None]:
    """Where a command's one-line notes go: above the bars on a terminal, plain lines on stderr off one
    (a log keeps them), nowhere with ``--quiet``."""
    if quiet:
        return lambda _text: None
    if meter is not SILENT:
        return meter.note
    return lambda text: print(f"  {text}", file=sys.stderr, flush=True)
