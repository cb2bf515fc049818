"""Opening forecast and grid files: the file's identity, and the checks made before the netCDF library reads it.

An empty or truncated file is refused from its own header (netCDF-3 or HDF5), so a cut download
says so instead of reading zeros or failing with a bare "HDF error".
"""

from __future__ import annotations

import inspect
import os
import warnings
from pathlib import Path
from typing import Any

import xarray as xr

from planner.contract.errors import ForecastError
from planner.forecast.opendap import fetch_source
from planner.forecast.remote import file_sha256, is_url

# What netCDF4/xarray/pyproj raise on damaged or unexpected files; wrapped into ForecastError.
LIBRARY_ERRORS = (
    OSError, ValueError, KeyError, TypeError, RuntimeError, IndexError, AttributeError, ArithmeticError, MemoryError,
)


def file_identity(path: Path, label: str | None = None) -> str:
    """``sha256:`` + the first 16 hex characters of the SHA-256 of the file's bytes."""
    try:
        return file_sha256(path)
    except OSError as exc:
        raise ForecastError(
            f"{label or path}: cannot read the file ({exc.strerror or exc}); check the path and permissions"
        ) from exc


# Lazily opened: no index is built from a coordinate at open time, so a damaged header that
# claims a huge dimension is refused (MAX_VALUES_PER_VARIABLE) before anything is read.
# Values typed Any: mypy checks an unpacked dict's value type against every keyword parameter of open_dataset.
_LAZY_OPEN: dict[str, Any] = (
    {"create_default_indexes": False}
    if "create_default_indexes" in inspect.signature(xr.open_dataset).parameters
    else {}
)


def open_dataset(path: str | os.PathLike[str], what: str) -> tuple[xr.Dataset, str, Path]:
    """(dataset, label, path) of a forecast or grid file, opened lazily after the completeness check.

    An http(s) URL is read from its copy in the cache (``planner.forecast.remote``; an OPeNDAP dataset's,
    ``planner.forecast.opendap``); the label stays the URL.
    """
    label = os.fspath(path)
    p = fetch_source(label).path if is_url(label) else Path(label)  # an http(s) URL: its copy in the cache
    if not p.exists():
        raise ForecastError(f"{label}: {what} not found; check the path")
    if not p.is_file():
        raise ForecastError(f"{label}: {what} is not a regular file; expected a netCDF file")
    _check_complete(p, label, what)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # xarray's SerializationWarnings about odd encodings
            ds = xr.open_dataset(
                p,
                engine="netcdf4",
                decode_times=False,
                decode_timedelta=False,
                decode_coords=False,
                mask_and_scale=True,  # CF fill -> NaN (land, spec section 1); never fillna(0)
                **_LAZY_OPEN,
            )
    except LIBRARY_ERRORS as exc:
        raise ForecastError(
            f"{label}: cannot open {what} as netCDF ({type(exc).__name__}: {exc}); expected a netCDF-3 or "
            "netCDF-4 file of ocean currents"
        ) from exc
    return ds, label, p


class _CutHeader(Exception):
    """The file ends inside its own header."""


# netCDF-3 external types (NC_BYTE .. NC_UINT64) and their sizes in bytes.
_CDF_TYPE_BYTES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 4, 6: 8, 7: 1, 8: 2, 9: 4, 10: 8, 11: 8}


def _check_complete(p: Path, label: str, what: str) -> None:
    """Refuse an empty or truncated file from its own header, before the netCDF library reads it.

    A cut netCDF-4 (HDF5) file fails to open with a bare "HDF error"; a cut netCDF-3 file opens and
    reads zeros where its data is missing. Both headers say how long the file must be: HDF5's
    superblock stores the end-of-file address, a netCDF-3 header every variable's offset and shape.
    """
    try:
        size = p.stat().st_size
        if size == 0:
            raise ForecastError(f"{label}: {what} is empty (0 bytes); expected a netCDF file")
        with p.open("rb") as fh:
            head = fh.read(8)
            fh.seek(0)
            if head[:3] == b"CDF" and len(head) >= 4 and head[3] in (1, 2, 5):
                kind, need = "netCDF-3", _netcdf3_min_size(fh, head[3], size)
            elif head == b"\x89HDF\r\n\x1a\n":
                kind, need = "netCDF-4/HDF5", _hdf5_min_size(fh.read(96))
            else:
                return
    except _CutHeader:
        raise ForecastError(
            f"{label}: truncated or damaged {what}: its header runs past the end of the file ({size:,} bytes); "
            "copy or download it again"
        ) from None
    except OSError as exc:
        raise ForecastError(f"{label}: cannot read the {what} ({exc.strerror or exc})") from None
    if need is not None and size < need:
        raise ForecastError(
            f"{label}: truncated {what}: its {kind} header says the file holds at least {need:,} bytes, the file has "
            f"{size:,} ({100.0 * size / need:.3g} %); copy or download it again"
        )


def _hdf5_min_size(sb: bytes) -> int | None:
    """End-of-file address from an HDF5 superblock at offset 0 (versions 0 to 3), or None when not stated."""
    if len(sb) < 16:
        raise _CutHeader
    version = sb[8]
    if version in (0, 1):
        n_off = sb[13]
        at = 24 + (4 if version == 1 else 0)
        fields = (at, at + 2 * n_off)  # base address, end-of-file address
    elif version in (2, 3):
        n_off = sb[9]
        fields = (12, 12 + 2 * n_off)
    else:
        return None
    if n_off not in (2, 4, 8):
        return None
    if len(sb) < fields[1] + n_off:
        raise _CutHeader
    base, eof = (int.from_bytes(sb[f : f + n_off], "little") for f in fields)
    undefined = (1 << (8 * n_off)) - 1
    if eof == undefined:
        return None
    return (0 if base == undefined else base) + eof


def _netcdf3_min_size(fh: Any, version: int, size: int) -> int | None:
    """Bytes a classic (1), 64-bit offset (2) or CDF-5 (5) netCDF file needs, from its header.

    Layout: the NetCDF Classic and 64-bit Offset Format specification (Unidata, NetCDF User's Guide,
    "File Format Specifications"), and CDF-5 for 8-byte counts.
    """
    count_bytes = 8 if version == 5 else 4
    offset_bytes = 4 if version == 1 else 8

    def take(n: int) -> bytes:
        if n > size - fh.tell():  # also keeps a garbage length from allocating gigabytes
            raise _CutHeader
        return fh.read(n)

    def number(n: int) -> int:
        return int.from_bytes(take(n), "big")

    def items(min_bytes: int) -> int:
        tag, n = number(4), number(count_bytes)
        if tag == 0 and n == 0:  # ABSENT
            return 0
        if n * min_bytes > size - fh.tell():
            raise _CutHeader
        return n

    def name() -> None:
        take((number(count_bytes) + 3) // 4 * 4)

    def attributes() -> None:
        for _ in range(items(12)):
            name()
            nc_type, n = number(4), number(count_bytes)
            take((n * _CDF_TYPE_BYTES.get(nc_type, 1) + 3) // 4 * 4)

    take(4)  # magic
    numrecs = number(count_bytes)
    dims = []
    for _ in range(items(8)):
        name()
        dims.append(number(count_bytes))
    attributes()
    need = fh.tell()
    records: list[tuple[int, int]] = []  # (begin, bytes per record) of record variables
    for _ in range(items(16)):
        name()
        n_dims = number(count_bytes)
        if n_dims * count_bytes > size - fh.tell():
            raise _CutHeader
        dim_ids = [number(count_bytes) for _ in range(n_dims)]
        attributes()
        nc_type = number(4)
        number(count_bytes)  # vsize: clipped for large variables; recomputed from the shape
        begin = number(offset_bytes)
        shape = [dims[d] if 0 <= d < len(dims) else 0 for d in dim_ids]
        per_value = _CDF_TYPE_BYTES.get(nc_type, 1)
        if shape and dim_ids[0] < len(dims) and dims[dim_ids[0]] == 0:
            n = per_value
            for length in shape[1:]:
                n *= length
            records.append((begin, n))
        else:
            n = per_value
            for length in shape:
                n *= length
            need = max(need, begin + n)
    if records and numrecs not in (0, (1 << (8 * count_bytes)) - 1):
        # One record holds every record variable, each padded to 4 bytes unless it is the only one.
        record_size = records[0][1] if len(records) == 1 else sum((n + 3) // 4 * 4 for _, n in records)
        need = max(need, *(begin + (numrecs - 1) * record_size + n for begin, n in records))
    return need
