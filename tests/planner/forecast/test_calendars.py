"""CF calendars (CF-1.8 section 4.4.1) decoded exactly by cftime: real netCDF files in each calendar.

Expected UTC times are written out by hand from the calendars' rules, not computed with cftime.
"""

from __future__ import annotations

from pathlib import Path

import netCDF4
import numpy as np
import pytest

from planner.contract.errors import ForecastError
from planner.forecast import forecast_times, open_forecast
from planner.cli import main


def _write(path: Path, times: list[float], units: str, calendar: str | None) -> Path:
    """A small regular forecast (2 x 3 lon/lat, one level) whose time axis is ``times`` in ``units``/``calendar``."""
    with netCDF4.Dataset(path, "w") as nc:
        nc.createDimension("time", len(times))
        nc.createDimension("lat", 2)
        nc.createDimension("lon", 3)
        t = nc.createVariable("time", "f8", ("time",))
        t.units, t.standard_name = units, "time"
        if calendar is not None:
            t.calendar = calendar
        t[:] = times
        lat = nc.createVariable("lat", "f8", ("lat",))
        lat.units = "degrees_north"
        lat[:] = [33.0, 33.1]
        lon = nc.createVariable("lon", "f8", ("lon",))
        lon.units = "degrees_east"
        lon[:] = [-118.0, -117.9, -117.8]
        for name, std in (("u", "eastward_sea_water_velocity"), ("v", "northward_sea_water_velocity")):
            var = nc.createVariable(name, "f4", ("time", "lat", "lon"))
            var.units, var.standard_name = "m s-1", std
            var[:] = np.full((len(times), 2, 3), 0.1, dtype=np.float32)
    return path


def _utc(values: list[str]) -> np.ndarray:
    return np.array(values, dtype="datetime64[ms]")


CASES = [
    # noleap: day 59 after 2000-01-01 is 1 March (no 29 February); the standard calendar would say 29 February.
    ("noleap", "days since 2000-01-01", [58.0, 59.0, 59.5], ["2000-02-28", "2000-03-01", "2000-03-01T12:00"]),
    ("365_day", "hours since 2000-02-28 00:00:00", [0.0, 24.0, 48.0], ["2000-02-28", "2000-03-01", "2000-03-02"]),
    # all_leap: every year has 29 February, so day 365 after 2000-01-01 is 31 December 2000 as in 2000 itself,
    # and 2004-02-29 exists.
    ("all_leap", "days since 2004-02-28", [0.0, 1.0, 2.0], ["2004-02-28", "2004-02-29", "2004-03-01"]),
    ("366_day", "days since 2003-12-31", [0.0, 1.0], ["2003-12-31", "2004-01-01"]),
    # 360_day: 30-day months, so 30 days after 1 January is 1 February, and 2 February 12:00 after 31.5.
    ("360_day", "days since 2001-01-01", [0.0, 30.0, 31.5], ["2001-01-01", "2001-02-01", "2001-02-02T12:00"]),
    # julian: 2000-01-01 of the Julian calendar is 2000-01-14 of the Gregorian one (13 days apart since 1900).
    ("julian", "hours since 2000-01-01 00:00:00", [0.0, 6.0], ["2000-01-14T00:00", "2000-01-14T06:00"]),
    # The mixed calendar of 'standard' before 1582-10-15: 0001-01-01 is Julian, two days before the proleptic
    # Gregorian 0001-01-01, so 730,119 days later is 1999-12-30 (proleptic counting would give 2000-01-01).
    ("standard", "days since 0001-01-01 00:00:00", [730119.0, 730120.0], ["1999-12-30", "1999-12-31"]),
    # Time zone in the reference date, in a model calendar: 00:00 at +01:00 is 23:00 UTC the day before.
    ("noleap", "hours since 2001-03-01 00:00:00 +01:00", [0.0, 1.0], ["2001-02-28T23:00", "2001-03-01T00:00"]),
]


@pytest.mark.parametrize(("calendar", "units", "values", "expected"), CASES,
                         ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_calendar_times_decode_to_exact_utc(tmp_path, calendar, units, values, expected):
    path = _write(tmp_path / f"{calendar}.nc", values, units, calendar)
    want = _utc(expected)
    times = forecast_times(path)
    assert times.times is not None
    assert np.array_equal(times.times, want), (times.times, want)
    fc = open_forecast(path)
    assert np.array_equal(fc.times, want)
    assert any("decoded by cftime" in n for n in fc.notes)
    # The seconds between steps are the real ones.
    assert np.array_equal(fc.time_s - fc.time_s[0], (want - want[0]) / np.timedelta64(1, "s"))


def test_standard_calendars_keep_their_plain_decoding(tmp_path):
    for calendar in (None, "standard", "gregorian", "proleptic_gregorian"):
        path = _write(tmp_path / f"{calendar}.nc", [58.0, 59.0], "days since 2000-01-01", calendar)
        fc = open_forecast(path)
        assert np.array_equal(fc.times, _utc(["2000-02-28", "2000-02-29"]))
        assert fc.time_origin == "2000-01-01T00:00:00Z"
        assert not any("cftime" in n for n in fc.notes)


def test_a_model_date_without_a_real_day_is_refused_by_name(tmp_path):
    # 360_day: 29 and 30 February exist in the model, in no real calendar.
    path = _write(tmp_path / "feb30.nc", [58.0, 59.0], "days since 2001-01-01", "360_day")
    with pytest.raises(ForecastError, match=r"feb30.nc: time variable time \(calendar '360_day'\): the model date "
                                            r"2001-02-29 00:00 is no real date"):
        open_forecast(path)


def test_an_unknown_calendar_is_refused_on_the_command_line(tmp_path, capsys):
    path = _write(tmp_path / "odd.nc", [0.0, 1.0], "days since 2001-01-01", "martian_sols")
    assert main(["forecast", "info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "odd.nc: time variable time (calendar 'martian_sols'): calendar not understood; expected one of CF's" in err
