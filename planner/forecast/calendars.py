"""CF calendars other than the proleptic Gregorian one, decoded exactly by cftime (CF-1.8 section 4.4.1).

A model that runs a ``noleap``/``365_day``, ``all_leap``/``366_day`` or ``360_day`` calendar
counts its time in days of that calendar; its dates are still the dates the forecast is issued
for, so a step labelled 2001-03-01 12:00 is read as 2001-03-01 12:00 UTC, and the seconds between
steps are the real ones (a noleap model's 28 Feb -> 1 Mar is two real days in a leap year). A
``julian`` date, and a ``standard``/``gregorian`` date before 1582-10-15 (the mixed calendar),
names a real day of the Julian calendar and is converted to the Gregorian date of that day.
A model date that no real calendar has (30 February of a ``360_day`` calendar, 29 February of
an ``all_leap`` year that is not a leap year) is refused: there is no UTC time to plan on.
"""

from __future__ import annotations

import datetime as dt
import re

import cftime
import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import ForecastError

# Calendars whose dates are real days (cftime converts them to the proleptic Gregorian date of the same day).
_REAL_WORLD = {"standard", "gregorian", "julian", "proleptic_gregorian"}
# Model calendars (CF-1.8 4.4.1): the date is taken as the same UTC date.
_MODEL = {"noleap", "365_day", "all_leap", "366_day", "360_day"}
CF_CALENDARS = tuple(sorted(_REAL_WORLD | _MODEL))
# The mixed Julian/Gregorian calendar switches on this date; a 'standard' time axis that starts
# later is proleptic Gregorian and needs no cftime.
GREGORIAN_START = np.datetime64("1582-10-15T00:00:00", "ms")


def needs_cftime(calendar: str, origin_utc: np.datetime64 | None) -> bool:
    """True when ``calendar`` (lower case, '' = standard) cannot be decoded as proleptic Gregorian seconds."""
    if calendar in ("", "standard", "gregorian"):
        return origin_utc is not None and bool(origin_utc < GREGORIAN_START)
    return calendar != "proleptic_gregorian"


def decode_calendar_times(
    values: NDArray[np.float64], factor_s: float, units: str, calendar: str, label: str, name: str
) -> tuple[NDArray[np.float64], str, str]:
    """(seconds since the origin, the origin as ISO UTC, a note) of a time axis in a CF ``calendar``.

    ``values * factor_s`` are seconds since the reference date of ``units`` counted in ``calendar``;
    cftime turns them into that calendar's dates, which are then read as UTC (see the module).
    """
    where = f"{label}: time variable {name} (calendar {calendar!r})"
    if calendar not in _REAL_WORLD and calendar not in _MODEL:
        raise ForecastError(f"{where}: calendar not understood; expected one of CF's: {', '.join(CF_CALENDARS)}")
    m = re.match(r"^\s*[A-Za-z]+\s+since\s+(.+?)\s*$", units, re.IGNORECASE)
    if m is None:  # the caller decodes only units with a reference date
        raise ForecastError(f"{where}: units {units!r} give no reference date")
    seconds_units = f"seconds since {m.group(1)}"
    try:
        reference = cftime.num2date(0.0, seconds_units, calendar=calendar, only_use_cftime_datetimes=True)
        dates = cftime.num2date(np.asarray(values, dtype=np.float64) * factor_s, seconds_units, calendar=calendar,
                                only_use_cftime_datetimes=True)
    except (ValueError, TypeError, OverflowError) as exc:
        raise ForecastError(f"{where}: cftime cannot decode {units!r}: {exc}") from exc
    utc = np.array([_utc(d, where) for d in np.ravel(dates)], dtype="datetime64[us]")
    try:
        origin = _utc(reference, where)
    except ForecastError:  # a reference date no real calendar has: count from the first step instead
        origin = utc[0]
    time_s = (utc - origin).astype(np.int64) / 1e6
    iso = np.datetime_as_string(origin, unit="s" if origin == origin.astype("datetime64[s]") else "ms") + "Z"
    first, last = (np.datetime_as_string(t, unit="s") + "Z" for t in (utc[0], utc[-1]))
    how = {"julian": "Julian dates converted to Gregorian", "standard": "mixed Julian/Gregorian, reference date before "
           "1582-10-15", "gregorian": "mixed Julian/Gregorian, reference date before 1582-10-15"}.get(
        calendar, "its dates read as UTC dates")
    return time_s, iso, f"time calendar {calendar!r} decoded by cftime ({how}): {first} .. {last}"


def _utc(date: cftime.datetime, where: str) -> np.datetime64:
    """A cftime date as ``datetime64[us]`` of the same UTC instant (real-world calendars) or the same date (models)."""
    if date.calendar in _REAL_WORLD:
        date = date.change_calendar("proleptic_gregorian")
    try:
        real = dt.datetime(date.year, date.month, date.day, date.hour, date.minute, date.second, date.microsecond)
    except ValueError:
        raise ForecastError(
            f"{where}: the model date {date.year:04d}-{date.month:02d}-{date.day:02d} {date.hour:02d}:"
            f"{date.minute:02d} is no real date, so it has no UTC time; expected times on real dates "
            "(plan on the steps that have them)"
        ) from None
    return np.datetime64(real, "us")
