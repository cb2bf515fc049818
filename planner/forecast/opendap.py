"""Forecasts on OPeNDAP servers: the part a plan needs, read over DAP 2.0 into a netCDF file in the cache.

An OPeNDAP dataset URL (a THREDDS ``dodsC`` URL, a Hyrax or ERDDAP ``griddap`` dataset, any DAP 2.0
server) names a dataset, not a file: ``URL.dds`` answers with its structure (OPULS, "The Data Access
Protocol - DAP 2.0", section 7.2.1), which is how it is told from a plain netCDF download. netCDF-C
reads it (its DAP client, in the netCDF4 wheels) and asks the server for hyperslabs only, so:

- every variable is copied with its attributes and fill values, as the server describes them;
- with a ``bbox`` and 1-D ascending longitude and latitude coordinates, only the columns and rows
  that resampling a grid inside it uses, with the reader's own margin
  (``planner.forecast.regular.regular_window``): the copy then plans exactly as the whole dataset;
- variables are read one first-axis index at a time (a time step), so memory stays at one step.

The copy goes to the cache (``planner.forecast.cache``) under a name made from the URL, the window and
the server's DDS and DAS and 1-D coordinate values: asking again while those are unchanged reuses it
(a server that changes values under the same structure and axes is not noticed: clear the cache).
From there on the forecast is a local file like any other (``planner.forecast.files``).
"""

from __future__ import annotations

import hashlib
import os
import re
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import netCDF4
import numpy as np

from planner import __version__
from planner.contract.atomic import atomic_target
from planner.contract.errors import ForecastError
from planner.contract.geodesy import BBox
from planner.forecast.cache import forecasts_dir
from planner.forecast.regular import regular_window
from planner.forecast.remote import TIMEOUT_S, Fetched, file_sha256, is_url

__all__ = ["fetch_opendap", "fetch_source", "is_opendap"]

_LON = ("lon", "longitude", "nav_lon", "x_lon")
_LAT = ("lat", "latitude", "nav_lat", "y_lat")


def is_opendap(url: str, *, timeout_s: float = TIMEOUT_S) -> bool:
    """True when ``url`` names a DAP 2.0 dataset: ``URL.dds`` answers 200 with a ``Dataset {`` structure."""
    return _dds(url, timeout_s) is not None


def fetch_source(url: str, cache: str | os.PathLike[str] | None = None, *, bbox: BBox | None = None) -> Fetched:
    """An http(s) forecast URL as a file in the cache: an OPeNDAP dataset's part (``fetch_opendap``), else the file."""
    from planner.forecast.remote import fetch

    return fetch_opendap(url, cache, bbox=bbox) if is_opendap(url) else fetch(url, cache)


def fetch_opendap(url: str, cache: str | os.PathLike[str] | None = None, *, bbox: BBox | None = None,
                  timeout_s: float = TIMEOUT_S) -> Fetched:
    """The dataset at ``url`` (the part around ``bbox``, when given) as a netCDF-4 file in the cache.

    Every failure is a ``ForecastError`` naming the URL.
    """
    url = _dataset_url(url)
    dds = _dds(url, timeout_s)
    if dds is None:
        raise ForecastError(f"{url}: not an OPeNDAP dataset: {url}.dds does not describe one")
    try:
        with netCDF4.Dataset(url) as remote:
            coords = {name: np.asarray(var[:]) for name, var in remote.variables.items()
                      if var.ndim == 1 and var.dimensions == (name,)}
            window = _window(remote, coords, bbox, url)
            key = hashlib.sha256()
            for part in (url, repr(sorted(window.items())), dds, _text(url + ".das", timeout_s) or ""):
                key.update(part.encode())
            for name in sorted(coords):
                key.update(name.encode() + coords[name].tobytes())
            name = re.sub(r"[^A-Za-z0-9._-]", "_", urlsplit(url).path.rstrip("/").rsplit("/", 1)[-1])[-60:]
            path = forecasts_dir(cache) / f"{key.hexdigest()[:16]}-{name or 'opendap'}.dap.nc"
            downloaded = not path.is_file()
            if downloaded:
                path.parent.mkdir(parents=True, exist_ok=True)
                with atomic_target(path) as tmp:
                    _copy(remote, window, tmp, url)
    except ForecastError:
        raise
    except (OSError, RuntimeError, ValueError, KeyError, IndexError) as exc:
        raise ForecastError(f"{url}: cannot read the OPeNDAP dataset ({type(exc).__name__}: {exc}); check the URL "
                            "and the server") from None
    return Fetched(url=url, path=path, identity=file_sha256(path), size_bytes=path.stat().st_size,
                   downloaded=downloaded)


def _dataset_url(url: str) -> str:
    """The dataset's URL without a query, a fragment, or a DAP response suffix given by mistake."""
    parts = urlsplit(url.strip())
    path = re.sub(r"\.(dds|das|dods|html|ascii)$", "", parts.path)
    return urlunsplit((parts.scheme, parts.netloc, path, "", ""))


def _dds(url: str, timeout_s: float) -> str | None:
    text = _text(_dataset_url(url) + ".dds", timeout_s) if is_url(url) else None
    return text if text is not None and text.lstrip().startswith("Dataset") else None


def _text(url: str, timeout_s: float) -> str | None:
    """A small DAP text response, or None when the server does not give one."""
    request = urllib.request.Request(url, headers={"User-Agent": f"lrauv-feedback/{__version__}"})
    try:
        with urllib.request.urlopen(request, timeout=timeout_s) as response:
            return response.read(1 << 22).decode("utf-8", errors="replace")
    except (urllib.error.URLError, OSError, ValueError):
        return None


def _coordinate(coords: dict[str, np.ndarray], remote: netCDF4.Dataset, names: tuple[str, ...], units: str) -> str | None:
    """The 1-D coordinate variable that is the longitude (or latitude): by CF units or standard name, else by name."""
    for name in coords:
        var = remote.variables[name]
        if str(getattr(var, "units", "")).lower() == units or str(getattr(var, "standard_name", "")) in names:
            return name
    return next((n for n in coords if n.lower() in names), None)


def _window(remote: netCDF4.Dataset, coords: dict[str, np.ndarray], bbox: BBox | None, url: str) -> dict[str, slice]:
    """Per dimension, the slice to copy: the bbox's columns and rows (with the reader's margin), else all."""
    if bbox is None:
        return {}
    lon_name = _coordinate(coords, remote, _LON, "degrees_east")
    lat_name = _coordinate(coords, remote, _LAT, "degrees_north")
    if lon_name is None or lat_name is None:
        return {}  # curvilinear or unnamed axes: the reader keeps the whole horizontal grid anyway
    lon, lat = coords[lon_name].astype(np.float64), coords[lat_name].astype(np.float64)
    if lon.size < 2 or lat.size < 2 or np.any(np.diff(lon) <= 0) or np.any(np.diff(lat) <= 0):
        return {}  # the reader's window needs ascending axes; a descending one is copied whole
    x0, x1, y0, y1 = regular_window(lon, lat, bbox, url)
    return {lon_name: slice(x0, x1), lat_name: slice(y0, y1)}


def _copy(remote: netCDF4.Dataset, window: dict[str, slice], path: Path, url: str) -> None:
    """Every variable of ``remote`` into a new netCDF-4 file, sliced by ``window`` along its dimensions."""
    with netCDF4.Dataset(path, "w", format="NETCDF4") as out:
        for name, dim in remote.dimensions.items():
            part = window.get(name, slice(0, len(dim)))
            out.createDimension(name, len(range(*part.indices(len(dim)))))
        out.setncatts({a: remote.getncattr(a) for a in remote.ncattrs()} | {"source_url": url})
        for name, var in remote.variables.items():
            var.set_auto_maskandscale(False)  # the stored values and their encoding, as served
            attrs = {a: var.getncattr(a) for a in var.ncattrs()}
            fill = attrs.pop("_FillValue", None)
            made = out.createVariable(name, var.dtype, var.dimensions, fill_value=fill, zlib=True, complevel=1)
            made.set_auto_maskandscale(False)
            made.setncatts(attrs)
            index: list[Any] = [window.get(d, slice(None)) for d in var.dimensions]
            if var.ndim == 0:
                made.assignValue(var.getValue())
            elif var.ndim == 1 or var.shape[0] == 0:
                made[:] = var[tuple(index)]
            else:  # one first-axis index (a time step) at a time
                first = range(*index[0].indices(var.shape[0]))
                for k, n in enumerate(first):
                    made[(k, *[slice(None)] * (var.ndim - 1))] = var[(n, *index[1:])]
