"""The durable state written by a thread of its own: a slow or full disk never holds up a decision.

``executive.durable.save`` writes the goals, tables, safety stop and the tide's record (with fsync) at the start,
at every plan swap, when the safety stop fires, when an operator resumes and at every fit of the
tide's timing (every 10 minutes of its record). Each save is a
snapshot of frozen values handed to one worker thread, so saves land in order and the newest
wins; a failure is reported back to the loop (``poll``), which logs and announces it. The
mission goes on either way: a restart resumes from the last state that was saved.
"""

from __future__ import annotations

from collections.abc import Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import wait as wait_for
from pathlib import Path
from typing import Any

from executive import durable
from executive.goal_tables import MissionPlan
from executive.state import Event

CLOSE_TIMEOUT_S = 5.0  # longest wait for the last saves at the end of a run (a dead disk must not hang it)


class StateWriter:
    """Saves of the durable state, in order, on one worker thread."""

    def __init__(self, state_dir: Path) -> None:
        self.state_dir = state_dir
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="lrauv-state")
        self._pending: list[Future[Path]] = []

    def save(self, plan: MissionPlan, blobs: Mapping[int, bytes], *, log_path: Path, mission_path: Path | None,
             safety_stop: str | None, tide: Mapping[str, Any] | None = None) -> None:
        """Queue a save of this snapshot (``blobs`` is copied; the plan is frozen; ``tide`` is the caller's own)."""
        self._pending.append(self._pool.submit(durable.save, self.state_dir, plan, dict(blobs), log_path=log_path,
                                               mission_path=mission_path, safety_stop=safety_stop, tide=tide))

    def poll(self) -> list[Event]:
        """Errors of the saves that have finished since the last call, as events for the log."""
        done = [f for f in self._pending if f.done()]
        self._pending = [f for f in self._pending if not f.done()]
        events = []
        for f in done:
            exc = f.exception()
            if exc is not None:  # the mission goes on; a restart would resume from the last state saved
                reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
                events.append(Event("error", f"cannot save the state to {self.state_dir}: {reason}"))
        return events

    def close(self) -> list[Event]:
        """Wait (at most ``CLOSE_TIMEOUT_S``) for the saves queued; their errors, and one for a save cut short."""
        wait_for(self._pending, timeout=CLOSE_TIMEOUT_S)
        events = self.poll()
        if self._pending:
            events.append(Event("error", f"the state in {self.state_dir} was not saved within {CLOSE_TIMEOUT_S:g} s"
                                         " at the end of the run"))
        self._pool.shutdown(wait=False, cancel_futures=True)
        return events
