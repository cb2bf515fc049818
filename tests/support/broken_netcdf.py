"""Broken netCDF forecasts, each built from a small real one: the cases every reader must refuse with one clear line.

Each builder takes the small synthetic forecast (``SMALL``, written with ``write_synthetic``) and the
path to write, and damages a copy: cut short, garbage, text where numbers belong, axes out of order
or out of range, declared sizes far beyond the file.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path

import netCDF4
import numpy as np
import xarray as xr

from planner.forecast.synthetic.scb import SyntheticSettings

# A 15 x 11-point forecast of the paper's box, 3 hourly steps, layers 0/5/10/15 m (about 44 kB).
SMALL = SyntheticSettings(hours=2, spacing_deg=0.04, n_eddies=1, n_waves=1)
U_STD, V_STD = "eastward_sea_water_velocity", "northward_sea_water_velocity"


def rewrite(base: Path, path: Path, change: Callable[[xr.Dataset], xr.Dataset], **to_netcdf: object) -> None:
    """The forecast ``base`` read whole, changed by ``change``, written to ``path``."""
    with xr.open_dataset(base, decode_times=False) as ds:
        ds = ds.load()
    change(ds).to_netcdf(path, **to_netcdf)  # type: ignore[call-overload]


def cut(fraction: float, fmt: str | None = None) -> Callable[[Path, Path], None]:
    """A builder keeping the first ``fraction`` of the file's bytes (of its copy in format ``fmt`` if given)."""
    def build(base: Path, path: Path) -> None:
        if fmt is None:
            data = base.read_bytes()
        else:
            rewrite(base, path, lambda ds: ds, format=fmt)
            data = path.read_bytes()
        path.write_bytes(data[: int(len(data) * fraction)])
    return build


def coord(name: str, values: Callable[[np.ndarray], np.ndarray], drop: tuple[str, ...] = ()) -> Callable[[Path, Path], None]:
    """Replace coordinate ``name``'s values (keeping its attributes except ``drop``)."""
    def change(ds: xr.Dataset) -> xr.Dataset:
        attrs = {k: v for k, v in ds[name].attrs.items() if k not in drop}
        return ds.assign_coords({name: (name, values(ds[name].values), attrs)})
    return lambda base, path: rewrite(base, path, change)


def _velocity(values: Callable[[np.ndarray], np.ndarray], dims: tuple[str, ...] = ()) -> Callable[[Path, Path], None]:
    """Replace u's values (``dims``: extra trailing dimensions of the new values)."""
    def change(ds: xr.Dataset) -> xr.Dataset:
        u = ds["u"]
        return ds.assign(u=(u.dims + dims, values(u.values), u.attrs))
    return lambda base, path: rewrite(base, path, change)


def _packed(edit: Callable[[netCDF4.Dataset], None]) -> Callable[[Path, Path], None]:
    """u/v packed as int16 with scale_factor 0.001, then edited with netCDF4."""
    def build(base: Path, path: Path) -> None:
        packing = {"dtype": "int16", "scale_factor": 0.001, "_FillValue": np.int16(-32767)}
        rewrite(base, path, lambda ds: ds, encoding={"u": dict(packing), "v": dict(packing)})
        with netCDF4.Dataset(path, "a") as nc:
            edit(nc)
    return build


def _set_scale(value: object) -> Callable[[netCDF4.Dataset], None]:
    def edit(nc: netCDF4.Dataset) -> None:
        nc["u"].scale_factor = value
    return edit


def _all_fill(nc: netCDF4.Dataset) -> None:
    for name in ("u", "v"):
        nc[name].set_auto_maskandscale(False)
        nc[name][:] = np.int16(-32767)


def _all_nan(ds: xr.Dataset) -> xr.Dataset:
    return ds.assign(u=ds["u"] * np.nan, v=ds["v"] * np.nan)


def _text_time(ds: xr.Dataset) -> xr.Dataset:
    return ds.assign_coords(time=("time", np.array(["t0", "t1", "t2"], dtype=object), ds["time"].attrs))


def _swap(i: int, k: int) -> Callable[[np.ndarray], np.ndarray]:
    def change(a: np.ndarray) -> np.ndarray:
        a = a.copy()
        a[[i, k]] = a[[k, i]]
        return a
    return change


def _huge_lon_netcdf4(base: Path, path: Path) -> None:
    """A netCDF-4 file declaring lon of 10^8 points; no chunk is ever written, so the file is 10 kB."""
    with netCDF4.Dataset(path, "w", format="NETCDF4") as nc:
        nc.createDimension("time", 1)
        nc.createDimension("lat", 4)
        nc.createDimension("lon", 10**8)
        _axes(nc, lon_chunks=(1 << 20,))
        for name, std in (("u", U_STD), ("v", V_STD)):
            var = nc.createVariable(name, "f4", ("time", "lat", "lon"), chunksizes=(1, 4, 1 << 16),
                                    fill_value=np.float32(np.nan))
            var.standard_name, var.units = std, "m s-1"


def _huge_time_netcdf4(base: Path, path: Path) -> None:
    """An unlimited time dimension grown to 2^31 - 1 steps by one write at its end (16 kB on disk)."""
    with netCDF4.Dataset(path, "w", format="NETCDF4") as nc:
        nc.createDimension("time", None)
        nc.createDimension("lat", 4)
        nc.createDimension("lon", 5)
        _axes(nc)
        nc["lon"][:] = np.linspace(-118.2, -117.8, 5)
        for name, std in (("u", U_STD), ("v", V_STD)):
            var = nc.createVariable(name, "f4", ("time", "lat", "lon"), fill_value=np.float32(np.nan))
            var.standard_name, var.units = std, "m s-1"
        nc["time"][2**31 - 2] = 1.0


def _huge_lon_netcdf3(base: Path, path: Path) -> None:
    """The forecast as classic netCDF with one header field damaged: lon's length 15 reads 10^8."""
    rewrite(base, path, lambda ds: ds, format="NETCDF3_64BIT")
    data = path.read_bytes()
    entry = b"\x00\x00\x00\x03lon\x00" + struct.pack(">I", 15)  # name length, name padded to 4, dimension length
    assert data.count(entry) == 1
    path.write_bytes(data.replace(entry, entry[:-4] + struct.pack(">I", 10**8)))


def _axes(nc: netCDF4.Dataset, lon_chunks: tuple[int, ...] | None = None) -> None:
    t = nc.createVariable("time", "f8", ("time",))
    t.units = "hours since 2026-01-15 00:00:00"
    lat = nc.createVariable("lat", "f8", ("lat",))
    lat.units = "degrees_north"
    lat[:] = [33.3, 33.4, 33.5, 33.6]
    kw = {"chunksizes": lon_chunks} if lon_chunks else {}
    lon = nc.createVariable("lon", "f8", ("lon",), **kw)
    lon.units = "degrees_east"


def _write(data: bytes) -> Callable[[Path, Path], None]:
    return lambda base, path: path.write_bytes(data)


_HDF5_GARBAGE = b"\x89HDF\r\n\x1a\n" + bytes(range(256)) * 8

# (case, builder(base, path), texts the error line must hold besides the file name)
NETCDF_CASES: list[tuple[str, Callable[[Path, Path], None], tuple[str, ...]]] = [
    ("cut at 10%", cut(0.10), ("truncated forecast file", "HDF5 header says the file holds at least", "(10 %)")),
    ("cut at 50%", cut(0.50), ("truncated forecast file", "(50 %)")),
    ("cut at 99%", cut(0.99), ("truncated forecast file", "(99 %)")),
    ("netCDF-3 cut in its header", cut(0.05, "NETCDF3_64BIT"),
     ("truncated or damaged forecast file", "header runs past the end of the file")),
    ("netCDF-3 cut at 50%", cut(0.50, "NETCDF3_64BIT"), ("truncated forecast file", "netCDF-3 header says")),
    ("netCDF-3 cut at 99%", cut(0.99, "NETCDF3_64BIT"), ("truncated forecast file", "netCDF-3 header says")),
    ("zero bytes", _write(b""), ("empty (0 bytes)",)),
    ("text", _write(b"u,v\n0.1,0.2\n"), ("cannot open forecast file as netCDF", "Unknown file format")),
    ("HDF5 garbage", _write(_HDF5_GARBAGE), ("cannot open forecast file as netCDF",)),
    ("CDF magic then garbage", _write(b"CDF\x01" + b"\xff" * 200), ("header runs past the end of the file",)),
    ("u as strings", _velocity(lambda u: np.full(u.shape, "fast", dtype=object)), ("variable u holds text values",)),
    ("u as chars", _velocity(lambda u: np.full(u.shape + (4,), b"x", dtype="S1"), ("nchar",)),
     ("variable u holds text values", "nchar")),
    ("u packed, scale_factor text", _packed(_set_scale("lots")), ("variable u: scale_factor 'lots'", "not a finite number")),
    ("u packed, scale_factor 0", _packed(_set_scale(0.0)), ("variable u: scale_factor is 0",)),
    ("u packed, all fill", _packed(_all_fill), ("hold no finite current values",)),
    ("only NaN", lambda b, p: rewrite(b, p, _all_nan), ("variables u/v hold no finite current values",)),
    ("time as strings", lambda b, p: rewrite(b, p, _text_time), ("time variable time holds text values",)),
    ("time duplicated", coord("time", lambda t: np.array([0.0, 1.0, 1.0])),
     ("time variable time: expected strictly increasing", "[0.0, 1.0, 1.0]")),
    ("time not monotonic", coord("time", lambda t: np.array([0.0, 2.0, 1.0])), ("strictly increasing",)),
    ("time beyond datetime range", coord("time", lambda t: t * 1e300), ("time_s", "check the time units")),
    ("lon not monotonic", coord("lon", _swap(3, 7)), ("coordinate lon: expected strictly monotonic",)),
    ("lat not monotonic", coord("lat", _swap(2, 5)), ("coordinate lat: expected strictly monotonic",)),
    ("depth not monotonic", coord("depth", lambda d: np.array([0.0, 10.0, 5.0, 15.0])),
     ("depth levels of u: expected strictly monotonic", "[0.0, 10.0, 5.0, 15.0]")),
    ("lat out of range", coord("lat", lambda a: a + 80.0), ("coordinate lat: values 113.3..113.7", "[-90, 90]")),
    ("lon out of range", coord("lon", lambda a: a + 1000.0), ("coordinate lon: values 881.74..882.3", "[-360, 360]")),
    ("lat as strings", coord("lat", lambda a: np.array([f"{x:.2f}N" for x in a], dtype=object)),
     ("coordinate lat holds text values",)),
    ("no lat/lon", lambda b, p: rewrite(b, p, lambda ds: ds.drop_vars(["lat", "lon"])),
     ("no longitude/latitude for u",)),
    ("negative depths, positive down", coord("depth", lambda d: -d),
     ("depth variable depth: levels above the sea surface", "-5, -10, -15", "positive = 'down'")),
    ("depths of both signs", coord("depth", lambda d: d - 5.0, drop=("positive", "axis", "standard_name")),
     ("depth variable depth: levels above the sea surface", "-5 m", "no 'positive' attribute")),
    ("lon of 10^8 points (netCDF-4, empty)", _huge_lon_netcdf4, ("variable u declares 400,000,000 values", "lon 100,000,000")),
    ("time of 2^31 steps (netCDF-4, sparse)", _huge_time_netcdf4, ("variable u declares 42,949,672,940 values",)),
    ("lon of 10^8 points (netCDF-3 header)", _huge_lon_netcdf3, ("truncated forecast file", "netCDF-3 header says")),
]
