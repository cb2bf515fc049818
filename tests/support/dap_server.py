"""A small OPeNDAP (DAP 2.0) server on 127.0.0.1 for the tests: netCDF-C's own DAP client reads from it.

It serves every netCDF file of one folder at ``http://127.0.0.1:PORT/NAME.nc`` with the three
DAP 2.0 responses a client asks for (OPULS, "The Data Access Protocol - DAP 2.0", ESE-RFC-004):

- ``NAME.nc.dds``: the Dataset Descriptor Structure, each variable an Array of its type with
  named dimensions (``Float32 u[time = 73][depth = 4][lat = 41][lon = 57];``);
- ``NAME.nc.das``: the attributes, per variable and ``NC_GLOBAL``;
- ``NAME.nc.dods?CE``: the constrained DDS, ``Data:``, then each projected array in XDR: its
  length twice, then its values big-endian (section 7.3.2). The constraint is a comma-separated
  projection of ``var[start:stride:stop]...`` hyperslabs (or ``[start:stop]``, ``[index]``).

Enough for the files the planner reads (numeric arrays; attributes of text and numbers), not a
general server. Requests are counted by kind so a test can see what the client asked for.
"""

from __future__ import annotations

import re
import threading
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

import netCDF4
import numpy as np

_TYPES = {"f4": "Float32", "f8": "Float64", "i4": "Int32", "u4": "UInt32", "i2": "Int16", "u2": "UInt16",
          "u1": "Byte"}
_XDR = {"f4": ">f4", "f8": ">f8", "i4": ">i4", "u4": ">u4", "i2": ">i4", "u2": ">u4"}  # 16-bit go as 32 (XDR)
_SLAB = re.compile(r"\[(\d+)(?::(\d+))?(?::(\d+))?\]")


class DapServer:
    """Serves ``folder`` until ``close``; ``url(name)`` is a file's dataset URL, ``requests`` counts by kind."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.requests: Counter[str] = Counter()
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                server._answer(self)

            def log_message(self, *args: Any) -> None:
                pass

        self._http = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self._thread = threading.Thread(target=self._http.serve_forever, daemon=True)
        self._thread.start()

    def url(self, name: str) -> str:
        return f"http://127.0.0.1:{self._http.server_address[1]}/{name}"

    def close(self) -> None:
        self._http.shutdown()
        self._http.server_close()
        self._thread.join(timeout=5)

    def _answer(self, handler: BaseHTTPRequestHandler) -> None:
        parts = urlsplit(handler.path)
        path = unquote(parts.path).lstrip("/")
        for kind in ("dds", "das", "dods"):
            if path.endswith("." + kind):
                name = path[: -len(kind) - 1]
                break
        else:
            kind, name = "file", path
        self.requests[kind] += 1
        file = self.folder / name
        if "/" in name or not file.is_file() or kind == "file":
            handler.send_error(404 if kind != "file" else 400, "not a DAP request for a served file")
            return
        with netCDF4.Dataset(file) as ds:
            try:
                body = {"dds": lambda: _dds(ds, name, _all(ds)).encode(), "das": lambda: _das(ds).encode(),
                        "dods": lambda: _dods(ds, name, unquote(parts.query))}[kind]()
            except (KeyError, ValueError, IndexError) as exc:
                handler.send_error(400, f"bad constraint: {exc}")
                return
        handler.send_response(200)
        handler.send_header("Content-Type", "application/octet-stream" if kind == "dods" else "text/plain")
        handler.send_header("Content-Description", f"dods_{'data' if kind == 'dods' else kind}")
        handler.send_header("XDODS-Server", "dods/2.0")
        handler.send_header("Content-Length", str(len(body)))
        handler.end_headers()
        handler.wfile.write(body)


@contextmanager
def dap_server(folder: Path) -> Iterator[DapServer]:
    server = DapServer(folder)
    try:
        yield server
    finally:
        server.close()


def _all(ds: netCDF4.Dataset) -> list[tuple[str, tuple[slice, ...]]]:
    return [(name, tuple(slice(0, n, 1) for n in var.shape)) for name, var in ds.variables.items()]


def _dds(ds: netCDF4.Dataset, name: str, projection: list[tuple[str, tuple[slice, ...]]]) -> str:
    lines = ["Dataset {"]
    for var_name, slabs in projection:
        var = ds.variables[var_name]
        dims = "".join(f"[{d} = {len(range(s.start, s.stop, s.step))}]" for d, s in zip(var.dimensions, slabs, strict=True))
        lines.append(f"    {_TYPES[var.dtype.str[1:]]} {var_name}{dims};")
    lines.append(f"}} {name};")
    return "\n".join(lines) + "\n"


def _das(ds: netCDF4.Dataset) -> str:
    lines = ["Attributes {"]
    for owner, names in [*((v, var.ncattrs()) for v, var in ds.variables.items()), ("NC_GLOBAL", ds.ncattrs())]:
        lines.append(f"    {owner} {{")
        source = ds if owner == "NC_GLOBAL" else ds.variables[owner]
        for attr in names:
            value = source.getncattr(attr)
            if isinstance(value, str):
                text = value.replace("\\", "\\\\").replace('"', '\\"')
                lines.append(f'        String {attr} "{text}";')
            else:
                arr = _dap_values(np.atleast_1d(np.asarray(value)))
                lines.append(f"        {_TYPES[arr.dtype.str[1:]]} {attr} {', '.join(repr(x.item()) for x in arr)};")
        lines.append("    }")
    lines.append("}")
    return "\n".join(lines) + "\n"


def _dap_values(arr: np.ndarray) -> np.ndarray:
    """An attribute's values in a DAP 2.0 type: it has no 64-bit or signed 8-bit integers (as THREDDS,
    Int32 where they fit, else Float64; Int16 for int8)."""
    code = arr.dtype.str[1:]
    if code == "i1":
        return arr.astype(np.int16)
    if code in ("i8", "u8"):
        fits = arr.size and np.all((arr >= -(2**31)) & (arr < 2**31))
        return arr.astype(np.int32 if fits else np.float64)
    return arr


def _dods(ds: netCDF4.Dataset, name: str, constraint: str) -> bytes:
    projection = _all(ds) if not constraint else [_slabs(ds, item) for item in constraint.split(",") if item]
    out = [_dds(ds, name, projection).encode(), b"Data:\n"]
    for var_name, slabs in projection:
        var = ds.variables[var_name]
        var.set_auto_mask(False)  # the stored values; the client applies _FillValue itself
        values = np.asarray(var[slabs] if slabs else var[...])
        code = values.dtype.str[1:]
        n = values.size
        if code == "u1":
            out.append(np.array([n, n], ">u4").tobytes() + values.tobytes() + b"\0" * (-n % 4))
        else:
            out.append(np.array([n, n], ">u4").tobytes() + values.astype(_XDR[code]).tobytes())
    return b"".join(out)


def _slabs(ds: netCDF4.Dataset, item: str) -> tuple[str, tuple[slice, ...]]:
    var_name = item.split("[", 1)[0]
    var = ds.variables[var_name]
    found = _SLAB.findall(item[len(var_name):])
    if not found:
        return var_name, tuple(slice(0, n, 1) for n in var.shape)
    if len(found) != var.ndim:
        raise ValueError(f"{var_name}: {len(found)} hyperslabs for {var.ndim} dimensions")
    slabs = []
    for (a, b, c), n in zip(found, var.shape, strict=True):
        start = int(a)
        stride, stop = (1, start) if not b else (1, int(b)) if not c else (int(b), int(c))
        if not 0 <= start <= stop < n or stride < 1:
            raise IndexError(f"{var_name}: [{a}:{b}:{c}] outside 0..{n - 1}")
        slabs.append(slice(start, stop + 1, stride))
    return var_name, tuple(slabs)
