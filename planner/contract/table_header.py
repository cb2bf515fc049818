"""A policy table's JSON header read back: every value checked, and refused with its key path named
(docs/policy-table.md). ``planner.contract.table`` turns the fields into a ``PolicyTable``.

numpy and the standard library only, as the rest of the table's reading: the executive imports it.
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import TableError
from planner.contract.headings import N_HEADINGS

MAX_SLICES = 10_000
MAX_STATES = 1 << 31
# ``time.current_cm_s`` of a table whose slice currents follow the actions in the payload (docs/policy-table.md):
# compressed with them, they take a fifth of the header's JSON lists.
CURRENT_IN_PAYLOAD = "payload"
# Slice currents a table may carry (slices x regions): 64 MB in the payload, 256 MB read as numbers. A
# block of 4 cells on a grid of 4 M states and 73 slices is 2.3 M pairs.
MAX_CURRENT_PAIRS = 1 << 24


def block_shape(ny: int, nx: int, block_cells: int | None) -> tuple[int, int]:
    """(rows, columns) of the current's regions in a layer of ``ny`` x ``nx`` cells: blocks of ``block_cells``
    cells a side from cell (0, 0), the last ones smaller where it does not divide the grid; None: the whole layer."""
    return (1, 1) if block_cells is None else (-(-ny // block_cells), -(-nx // block_cells))


def kept_block_cells(ny: int, nx: int, block_cells: int | None) -> int | None:
    """``block_cells`` as a table keeps it: None where one block covers a whole layer, whose region is then
    the layer itself, so such a table is written, read and fitted as one of a mean per layer."""
    return None if block_cells is None or block_shape(ny, nx, block_cells) == (1, 1) else block_cells


def header_fields(header: Any) -> dict[str, Any]:
    """The PolicyTable fields of a parsed JSON header; TableError naming the key path and the value.

    One key is not a field: ``payload_current_regions``, the regions whose slice currents the payload
    carries (``time.current_cm_s`` is ``CURRENT_IN_PAYLOAD``)."""
    top = _section(header, "")
    g = _section(_key(top, "grid", ""), "grid")
    nx, ny = _int(_key(g, "nx", "grid"), "grid.nx"), _int(_key(g, "ny", "grid"), "grid.ny")
    for key, n in (("grid.nx", nx), ("grid.ny", ny)):
        if n < 2:
            raise TableError(f"{key}: expected at least 2 cells; got {n}")
    depth_raw = _key(g, "depth_m", "grid")
    if not isinstance(depth_raw, list) or not depth_raw:
        raise TableError(f"grid.depth_m: expected a non-empty list of layer depths in metres; got {depth_raw!r}"[:200])
    depths = tuple(_float(d, f"grid.depth_m[{n}]") for n, d in enumerate(depth_raw))
    if depths[0] < 0 or any(b <= a for a, b in zip(depths, depths[1:])):
        raise TableError(f"grid.depth_m: expected depths >= 0, strictly increasing; got {list(depths)[:12]}")
    n_states = len(depths) * ny * nx * N_HEADINGS
    if n_states > MAX_STATES:
        raise TableError(
            f"grid: {len(depths)} x {ny} x {nx} x {N_HEADINGS} = {n_states:,} states exceeds the limit of {MAX_STATES:,}"
        )
    fields: dict[str, Any] = {"nx": nx, "ny": ny, "depth_m": depths}
    for key in ("lon0_deg", "lat0_deg", "dlon_deg", "dlat_deg"):
        fields[key] = _float(_key(g, key, "grid"), f"grid.{key}")
    for key in ("dlon_deg", "dlat_deg"):
        if fields[key] <= 0:
            raise TableError(f"grid.{key}: expected a positive spacing in degrees; got {fields[key]!r}")
    lat_n = fields["lat0_deg"] + (ny - 1) * fields["dlat_deg"]
    if fields["lat0_deg"] < -90 or lat_n > 90:
        raise TableError(f"grid: rows span latitudes {fields['lat0_deg']:g}..{lat_n:g}; expected them within [-90, 90]")
    headings = _section(_key(top, "headings", ""), "headings")
    if _key(headings, "count", "headings") != N_HEADINGS:
        raise TableError(f"headings.count: expected {N_HEADINGS}; got {headings['count']!r}")
    goal = _section(_key(top, "goal", ""), "goal")
    fields.update(
        goal_lon_deg=_float(_key(goal, "lon_deg", "goal"), "goal.lon_deg"),
        goal_lat_deg=_float(_key(goal, "lat_deg", "goal"), "goal.lat_deg"),
        goal_depth_m=_float(_key(goal, "depth_m", "goal"), "goal.depth_m"),
        goal_radius_cells=_int(_key(goal, "radius_cells", "goal"), "goal.radius_cells"),
    )
    for key in ("criterion", "uncertainty", "model", "planner_version"):
        fields[key] = _text(_key(top, key, ""), key)
    costs = _section(_key(top, "costs", ""), "costs")
    fields["costs"] = {str(k): _int(v, f"costs.{k}") for k, v in costs.items()}
    forecast = _section(_key(top, "forecast", ""), "forecast")
    fields["forecast_source"] = _text(_key(forecast, "source", "forecast"), "forecast.source")
    fields["forecast_identity"] = _text(_key(forecast, "identity", "forecast"), "forecast.identity")
    when = _key(forecast, "time", "forecast")
    fields["forecast_time"] = None if when is None else _text(when, "forecast.time")
    if "time" in top:  # version 2: a time-varying plan
        time_part = _section(top["time"], "time")
        times = _key(time_part, "slices_utc", "time")
        if not isinstance(times, list):
            raise TableError(f"time.slices_utc: expected a list of ISO 8601 UTC times; got {times!r}"[:200])
        slice_unix_s(times, "time.slices_utc")
        if _key(time_part, "lookup", "time") != "nearest":
            raise TableError(f"time.lookup: expected \"nearest\"; got {time_part['lookup']!r}"[:200])
        fields["slice_times"] = tuple(times)
        if "current_block_cells" in time_part:  # optional: without it, a region is a layer
            k = _int(time_part["current_block_cells"], "time.current_block_cells")
            if k < 1 or "current_cm_s" not in time_part:  # a block larger than the grid is one block a layer
                raise TableError(f"time.current_block_cells: expected a whole number of cells >= 1, with"
                                 f" time.current_cm_s; got {k}")
            fields["current_block_cells"] = kept_block_cells(ny, nx, k)
        if "current_cm_s" in time_part:  # optional; older readers never saw it
            rows, cols = block_shape(ny, nx, fields.get("current_block_cells"))
            regions = len(depths) * rows * cols
            if len(times) * regions > MAX_CURRENT_PAIRS:  # checked before the payload is read
                raise TableError(f"time.current_cm_s: {len(times)} slices x {regions:,} regions exceed the limit of"
                                 f" {MAX_CURRENT_PAIRS:,} pairs")
            if time_part["current_cm_s"] == CURRENT_IN_PAYLOAD:  # the reader takes them from the payload
                fields["payload_current_regions"] = regions
            else:  # JSON lists, as the first tables with currents were written
                fields["slice_current_m_s"] = _slice_current(time_part["current_cm_s"], len(times), regions)
    if "nominal_path" in top:  # optional; older readers never saw it
        fields["nominal_path"] = _lon_lat_points(_key(_section(top["nominal_path"], "nominal_path"), "lon_lat_deg",
                                                      "nominal_path"), "nominal_path.lon_lat_deg")
    if "physical" in top:  # optional (physical plans); older readers never saw it
        physical = _section(top["physical"], "physical")
        fields["physical"] = {}
        for part in ("vehicle", "sampling"):
            values = _section(_key(physical, part, "physical"), f"physical.{part}")
            # null: a sampling setting left to the model (max_transition_s); true/false: the switch course_offsets
            fields["physical"][part] = {str(k): _switch(v, f"physical.{part}.{k}") if (part, k) == ("sampling", "course_offsets")
                                        else None if v is None and part == "sampling" else
                                        _number(v, f"physical.{part}.{k}") for k, v in values.items()}
    return fields


MAX_PATH_POINTS = 10_000


def _slice_current(value: Any, n_slices: int, n_regions: int) -> NDArray[np.float64]:
    """``time.current_cm_s``: per slice, per region (a layer, or a block of one), [east, north] as whole cm/s."""
    key = "time.current_cm_s"
    if not isinstance(value, list) or len(value) != n_slices:
        raise TableError(f"{key}: expected \"{CURRENT_IN_PAYLOAD}\" or one entry per slice ({n_slices});"
                         f" got {repr(value)[:80]}")
    out = np.empty((n_slices, n_regions, 2))
    for n, when in enumerate(value):
        if not isinstance(when, list) or len(when) != n_regions:
            raise TableError(f"{key}[{n}]: expected one [east, north] per region ({n_regions}: per layer, or per block"
                             f" of time.current_block_cells in each layer); got {repr(when)[:80]}")
        for l, pair in enumerate(when):
            if not isinstance(pair, list) or len(pair) != 2:
                raise TableError(f"{key}[{n}][{l}]: expected [east, north] in cm/s; got {repr(pair)[:80]}")
            for c in range(2):
                cm_s = _int(pair[c], f"{key}[{n}][{l}][{c}]")
                if abs(cm_s) > 32767:  # what the payload's 16 bits hold, and what a table may carry
                    raise TableError(f"{key}[{n}][{l}][{c}]: expected whole cm/s within +-32767; got {cm_s}"[:200])
                out[n, l, c] = cm_s
    return out / 100.0


def _lon_lat_points(value: Any, key: str) -> tuple[tuple[float, float], ...]:
    """A list of [lon, lat] pairs in degrees (at most MAX_PATH_POINTS), each within range."""
    if not isinstance(value, list) or len(value) > MAX_PATH_POINTS:
        raise TableError(f"{key}: expected a list of at most {MAX_PATH_POINTS:,} [lon, lat] pairs; got {value!r}"[:200])
    points = []
    for n, point in enumerate(value):
        if not isinstance(point, list) or len(point) != 2:
            raise TableError(f"{key}[{n}]: expected [lon, lat] in degrees; got {point!r}"[:200])
        lon, lat = _float(point[0], f"{key}[{n}][0]"), _float(point[1], f"{key}[{n}][1]")
        if not (-180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0):
            raise TableError(f"{key}[{n}]: ({lon:g}, {lat:g}) is not a longitude in [-180, 180] and a latitude in [-90, 90]")
        points.append((lon, lat))
    return tuple(points)


def _section(value: Any, key: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        what = f"{key}: expected a JSON object" if key else "is not a JSON object"
        raise TableError(f"{what}; got {type(value).__name__} {repr(value)[:60]}")
    return value


def _key(section: dict[str, Any], key: str, parent: str) -> Any:
    if key not in section:
        raise TableError(f"lacks the key {f'{parent}.{key}' if parent else key!r}")
    return section[key]


def _text(value: Any, key: str) -> str:
    if not isinstance(value, str):
        raise TableError(f"{key}: expected text; got {repr(value)[:60]}")
    return value


def _float(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise TableError(f"{key}: expected a finite number; got {value!r}")
    return float(value)


def _number(value: Any, key: str) -> float | int:
    """A finite number, kept an int when it is one (whole-number settings stay whole)."""
    return value if isinstance(value, int) and not isinstance(value, bool) else _float(value, key)


def _switch(value: Any, key: str) -> bool:
    if not isinstance(value, bool):
        raise TableError(f"{key}: expected true or false; got {value!r}")
    return value


def _int(value: Any, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TableError(f"{key}: expected an integer; got {value!r}")
    return value


def slice_unix_s(times_utc: tuple[str, ...] | list[Any], key: str) -> tuple[float, ...]:
    """Unix seconds of ISO 8601 UTC times (``2026-01-15T03:00:00Z``), strictly increasing; TableError naming ``key``."""
    if not 2 <= len(times_utc) <= MAX_SLICES:
        raise TableError(f"{key}: expected 2 to {MAX_SLICES:,} slice times; got {len(times_utc)}")
    out: list[float] = []
    for n, text in enumerate(times_utc):
        if not isinstance(text, str) or not text.endswith("Z"):
            raise TableError(f"{key}[{n}]: expected an ISO 8601 UTC time like 2026-01-15T03:00:00Z; got {text!r}"[:200])
        try:
            when = dt.datetime.fromisoformat(text[:-1]).replace(tzinfo=dt.UTC)
        except ValueError:
            raise TableError(f"{key}[{n}]: expected an ISO 8601 UTC time like 2026-01-15T03:00:00Z; got {text!r}"[:200]) from None
        out.append(when.timestamp())
        if n and out[-1] <= out[-2]:
            raise TableError(f"{key}[{n}]: {text} is not after the slice before it ({times_utc[n - 1]})")
    return tuple(out)
