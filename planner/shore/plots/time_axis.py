"""Time on the dive pictures: UTC time axes, hourly marks along a track, and a heading axis that never hides.

A dive's times are vehicle time since the autopilot booted; with the offset to
UTC (from the autopilot's SYSTEM_TIME) they are drawn as UTC clock times. When
only boot time is known, the axis says so instead of pretending a date.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["HEADING_LIMITS_DEG", "TimeMarks", "draw_time_marks", "heading_axis", "marks_legend", "mark_step_s", "time_axis", "time_marks", "time_values",
           "wrapped"]

# Heading is drawn on -15..375 degrees: a vehicle heading due north (0 or 360) is a line inside the frame.
HEADING_LIMITS_DEG = (-15.0, 375.0)
_MARK_STEPS_S = (300.0, 600.0, 900.0, 1800.0, 3600.0, 7200.0, 10800.0, 21600.0, 43200.0, 86400.0)


def mark_step_s(span_s: float, *, most: int = 10) -> float:
    """The shortest round step (5 min .. 1 day) that puts at most ``most`` steps in ``span_s`` seconds (hourly
    for dives of 5 to 10 h)."""
    for step in _MARK_STEPS_S:
        if span_s / step <= most:
            return step
    return _MARK_STEPS_S[-1] * float(np.ceil(span_s / (_MARK_STEPS_S[-1] * most)))


@dataclass(frozen=True, eq=False, slots=True)
class TimeMarks:
    """Points along a track at round times: position, and a label (``06:00`` UTC, or ``+2 h`` since boot)."""

    lon_deg: NDArray[np.float64]
    lat_deg: NDArray[np.float64]
    labels: tuple[str, ...]
    utc: bool  # labels are UTC clock times (else hours since the autopilot booted)
    step_s: float


def time_marks(time_s: NDArray[np.float64], lon_deg: NDArray[np.float64], lat_deg: NDArray[np.float64],
               unix_offset_s: float | None) -> TimeMarks:
    """Marks at round times within the track (UTC multiples of the step when the offset is known, else whole
    steps of vehicle time), each placed by linear interpolation between the surrounding positions."""
    t = np.asarray(time_s, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(lon_deg) & np.isfinite(lat_deg)
    t, lon, lat = t[ok], np.asarray(lon_deg)[ok], np.asarray(lat_deg)[ok]
    empty = np.zeros(0)
    if t.size < 2 or not t[-1] > t[0]:
        return TimeMarks(empty, empty, (), unix_offset_s is not None, 3600.0)
    order = np.argsort(t, kind="stable")
    t, lon, lat = t[order], lon[order], lat[order]
    step = mark_step_s(float(t[-1] - t[0]))
    shift = 0.0 if unix_offset_s is None else float(unix_offset_s)
    first = np.ceil((t[0] + shift) / step) * step
    count = int(np.floor((t[-1] + shift - first) / step + 1e-6)) + 1  # a mark at the very end counts
    at = first + step * np.arange(max(count, 0)) - shift  # vehicle times of the marks
    if unix_offset_s is None:
        labels = tuple(f"+{x / 3600.0:g} h" for x in at)
    else:
        fmt = "%H:%M" if step < 86400.0 else "%m-%d"
        labels = tuple(_strftime(x + shift, fmt) for x in at)
    return TimeMarks(np.interp(at, t, lon), np.interp(at, t, lat), labels, unix_offset_s is not None, step)


def _strftime(unix_s: float, fmt: str) -> str:
    import datetime as dt

    return dt.datetime.fromtimestamp(round(unix_s), dt.UTC).strftime(fmt)


def time_values(mpl: Any, time_s: NDArray[np.float64], unix_offset_s: float | None) -> NDArray[np.float64]:
    """The x values of vehicle times ``time_s``: matplotlib dates (UTC) with an offset, else hours since boot."""
    t = np.asarray(time_s, dtype=np.float64)
    if unix_offset_s is None:
        return t / 3600.0
    ms = np.round((t + unix_offset_s) * 1000.0)
    stamps = np.where(np.isfinite(ms), ms, 0).astype(np.int64).astype("datetime64[ms]")
    out = np.asarray(mpl.dates.date2num(stamps), dtype=np.float64)
    out[~np.isfinite(ms)] = np.nan
    return out


def time_axis(mpl: Any, ax: Any, unix_offset_s: float | None, first_s: float) -> None:
    """Label ``ax``'s x axis as the values of ``time_values``: UTC clock times with the day of ``first_s``
    (vehicle time), or hours since the autopilot booted with a note that UTC is unknown."""
    if unix_offset_s is None:
        ax.set_xlabel("vehicle time since the autopilot booted (h); UTC unknown: the log has no SYSTEM_TIME with UTC")
        return
    import datetime as dt

    utc = dt.UTC
    locator = mpl.dates.AutoDateLocator(tz=utc, minticks=4, maxticks=10)
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(mpl.dates.ConciseDateFormatter(locator, tz=utc, show_offset=False))
    day = _strftime(first_s + unix_offset_s, "%Y-%m-%d")
    ax.set_xlabel(f"time (UTC), from {day}")


def heading_axis(ax: Any) -> None:
    """Heading on ``HEADING_LIMITS_DEG`` with ticks at the cardinal points: 0 and 360 lie inside the frame."""
    ax.set_ylim(*HEADING_LIMITS_DEG)
    ax.set_yticks([0, 90, 180, 270, 360], ["0 N", "90 E", "180 S", "270 W", "360 N"])


def wrapped(x: NDArray[np.float64], heading_deg: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``x``, ``heading`` with NaN inserted where the heading wraps past north, so no line crosses the plot."""
    h = np.mod(np.asarray(heading_deg, dtype=np.float64), 360.0)
    wraps = np.flatnonzero(np.abs(np.diff(h)) > 180.0) + 1
    return np.insert(np.asarray(x, dtype=np.float64), wraps, np.nan), np.insert(h, wraps, np.nan)


def draw_time_marks(mpl: Any, ax: Any, marks: TimeMarks, *, label_gap_deg: float = 0.0, zorder: float = 8.0) -> Any:
    """The marks as small white-rimmed dots with their labels beside; returns the dots (gid ``time marks``), or
    None when there is none. A label closer than ``label_gap_deg`` (longitude degrees) to the last one drawn
    is left out, so that a slow stretch does not pile labels on each other; its dot stays."""
    if not marks.labels:
        return None
    dots, = ax.plot(marks.lon_deg, marks.lat_deg, linestyle="none", marker="o", markersize=4.5,
                    markerfacecolor="black", markeredgecolor="white", markeredgewidth=0.9, zorder=zorder)
    dots.set_gid("time marks")
    halo = [mpl.patheffects.withStroke(linewidth=2.2, foreground="white")]
    last: tuple[float, float] | None = None
    for x, y, text in zip(marks.lon_deg, marks.lat_deg, marks.labels):
        # Distance in longitude degrees: a degree of latitude is 1/cos(latitude) of them.
        if last is not None and math.hypot(x - last[0], (y - last[1]) / math.cos(math.radians(y))) < label_gap_deg:
            continue
        last = (float(x), float(y))
        ax.annotate(text, (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7, color="black",
                    zorder=zorder, path_effects=halo, annotation_clip=True)
    return dots


def marks_legend(marks: TimeMarks) -> str:
    """The legend's words for the marks, e.g. ``time marks every 1 h (UTC)``."""
    step = f"{marks.step_s / 3600.0:g} h" if marks.step_s >= 3600.0 else f"{marks.step_s / 60.0:g} min"
    return f"time marks every {step} ({'UTC' if marks.utc else 'since the autopilot booted; UTC unknown'})"
