"""Ocean current forecasts: reading netCDF files into ``Forecast`` values (spec section 1).

``open_forecast`` turns a file into a ``Forecast`` whose velocities are eastward/northward m/s
with NaN for land ("Products that store grid-relative components ... are rotated to east/north
when they are read"); ``planner.forecast.resample`` puts a time step onto a planning ``Grid``.
Regular lon/lat, projected or curvilinear, and ROMS/CROCO C-grid files are read
(``planner.forecast.layout``); with ``bbox=``, ``time_index=`` or ``member=`` only that part of
the file is read (docs/forecasts-large.md). ``forecast_times`` reads just the time axis,
``ensemble_size`` the number of members.

This package is the only part of the project that reads netCDF (xarray and netCDF4; pyproj only
for projected grids).
"""

from planner.forecast.describe import describe
from planner.forecast.files import file_identity
from planner.forecast.lazy import MAX_AXIS_POINTS, MAX_VALUES_PER_VARIABLE
from planner.forecast.model import (
    Forecast,
    ForecastTimes,
    ForecastWindow,
    is_periodic_lon,
    lon_shifts,
    nearest_time_index,
)
from planner.forecast.reader import ensemble_size, forecast_times, open_forecast
from planner.forecast.regular import WINDOW_MARGIN_NODES

__all__ = [
    "MAX_AXIS_POINTS",
    "MAX_VALUES_PER_VARIABLE",
    "WINDOW_MARGIN_NODES",
    "Forecast",
    "ForecastTimes",
    "ForecastWindow",
    "describe",
    "ensemble_size",
    "file_identity",
    "forecast_times",
    "is_periodic_lon",
    "lon_shifts",
    "nearest_time_index",
    "open_forecast",
]
