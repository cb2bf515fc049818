"""Which slice of a time-varying plan the helm follows, and what the log says about it.

Pure: ``follow(timeline, table, utc_s)`` gives the slice that holds at the vehicle's UTC
time (``PolicyTable.slice_at``) and the events that announce a change of slice or of
the reason for it. The loop (``executive.loop``) passes the slice to ``helm.step`` and
keeps the new ``Timeline`` and logs the events only when the step made a decision:
what the log announces is the plan decisions were made with. The decision audit
(``planner.shore.replay.audit``) finds the same slice from the same logged inputs.

A stationary table is its own slice: no events, and decision records without slice
keys, byte for byte what they were before time-varying plans existed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from executive.helm import Decision
from executive.state import Event
from planner.contract.table import PolicyTable, SliceStatus, TimeSlice


@dataclass(frozen=True, slots=True)
class Timeline:
    """What the log last said of the plan's time: for which table (its CRC), which slice and why."""

    table_crc32: int | None = None
    index: int | None = None
    status: SliceStatus | None = None
    warned_past: bool = False  # the past-horizon warning went out for this table (once: it is also a STATUSTEXT)


@dataclass(frozen=True, slots=True)
class Followed:
    """The slice to decide with, and the timeline and events to keep if a decision is made with it."""

    current: TimeSlice
    timeline: Timeline
    events: tuple[Event, ...] = ()


def utc_s(now_s: float, unix_offset_s: float | None) -> float | None:
    """The vehicle's UTC (Unix s) at vehicle time ``now_s``, or None while SYSTEM_TIME has given none."""
    return None if unix_offset_s is None else now_s + unix_offset_s


def iso_utc(unix_s: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(unix_s))


def slice_for(table: PolicyTable, unix_s: float | None, shift_s: float = 0.0) -> TimeSlice:
    """The slice of ``table`` at the vehicle's UTC ``unix_s``, looked up ``shift_s`` later (the tide's timing
    fitted onboard, ``executive.tide_watch``; negative: earlier)."""
    return table.slice_at(None if unix_s is None else unix_s + shift_s)


def follow(timeline: Timeline, table: PolicyTable, unix_s: float | None, shift_s: float = 0.0) -> Followed:
    """The slice of ``table`` that holds at ``unix_s`` (``slice_for``), and what to log if it differs from the
    last one used."""
    current = slice_for(table, unix_s, shift_s)
    if not table.time_varying:
        return Followed(current, timeline)
    if timeline.table_crc32 != table.crc32:  # another table: its slice is announced afresh
        timeline = Timeline(table_crc32=table.crc32)
    if (current.index, current.status) == (timeline.index, timeline.status):
        return Followed(current, timeline)
    event = _announce(table, current, unix_s, shift_s, timeline.warned_past)
    warned = timeline.warned_past or current.status == "past_horizon"
    return Followed(current, Timeline(table_crc32=table.crc32, index=current.index, status=current.status,
                                      warned_past=warned), (event,))


def _announce(table: PolicyTable, current: TimeSlice, unix_s: float | None, shift_s: float, warned_past: bool) -> Event:
    times = table.slice_times
    n = current.index
    if current.status == "in_horizon":
        return Event("info", f"time-varying plan: slice {n} of {len(times)} ({times[n]})")
    if current.status == "past_horizon":
        # Once per table as a warning; a clock that steps back into the horizon and out again is only noted.
        if warned_past:
            return Event("info", f"past the plan's horizon again: using the last slice's plan (last slice {times[n]})")
        return Event("warning", f"past the plan's horizon: using the last slice's plan (last slice {times[n]})")
    if current.status == "before_start":
        assert unix_s is not None
        shifted = f", looked up at UTC {shift_s:+.0f} s" if shift_s else ""
        return Event("warning", f"before the plan's first slice: using the first slice's plan (first slice {times[0]},"
                                f" vehicle UTC {iso_utc(unix_s)}{shifted})")
    return Event("warning", f"UTC unknown: using the first slice's plan (no SYSTEM_TIME with UTC yet;"
                            f" first slice {times[0]})")


def decision_record(decision: Decision, current: TimeSlice | None) -> dict[str, Any]:
    """The ``/executive/decision`` payload of ``helm.Decision``: with the slice and why, for a time-varying table."""
    record = decision.to_record()
    if current is not None and current.status != "stationary":
        record["slice"] = current.index
        record["slice_status"] = current.status
    return record


def slices_record(table: PolicyTable) -> dict[str, Any]:
    """A time-varying table's slices in a policy record: how many, the first's and the last's UTC time."""
    record: dict[str, Any] = {"count": table.n_slices, "first_utc": table.slice_times[0],
                              "last_utc": table.slice_times[-1]}
    if table.slice_current_m_s is not None:  # the tide's timing is fitted onboard (executive.tide_watch)
        record["timing_correction"] = True
        if table.current_block_cells is not None:  # its reference current per block of cells, not per layer
            record["timing_block_cells"] = table.current_block_cells
    return record
