"""How long work reports its progress: a small protocol the library calls and a front end draws.

Library functions (sampling and solving in ``planner.pipeline.make_plan``, evaluation runs, replay
and audit, the demo's closed loop) take an optional ``Progress`` and call ``update`` with counts
that only grow and end at the total. They never draw anything themselves: the command line
(``planner.cli.progress_bar``) draws a bar, and only when stderr is a terminal. This module is
standard library only, so it may sit in the contract without weighing on the executive (which
never reports progress: it runs unattended).
"""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    def update(self, task: str, done: float, total: float, *, unit: str = "", detail: str = "") -> None:
        """``done`` of ``total`` (in ``unit``) of ``task``; a new ``task`` name starts a new bar.
        ``detail`` is a short live status (e.g. the distance to the goal)."""
        ...

    def note(self, text: str) -> None:
        """A one-line announcement (e.g. a slow first compile), printed above any bar."""
        ...


class Silent:
    """Reports nothing: the default, and what a quiet run or a run off a terminal gets."""

    def update(self, task: str, done: float, total: float, *, unit: str = "", detail: str = "") -> None:
        return None

    def note(self, text: str) -> None:
        return None


SILENT: Progress = Silent()
