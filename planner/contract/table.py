"""The compact policy table: the file uploaded to the vehicle (docs/policy-table.md).

Reading needs only numpy and the standard library, so the executive can use
this module without the planner's solver, xarray or scipy. Writing takes a
``Solution``-like object (anything with ``action``, ``model.water`` and the
grid) and never imports the solver either.
"""

from __future__ import annotations

import json
import lzma
import math
import os
import struct
import zlib
from bisect import bisect_right
from dataclasses import dataclass, field, replace
from dataclasses import fields as dataclass_fields
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import FORWARD_ACTIONS, Action
from planner.contract.atomic import write_atomic
from planner.contract.errors import TableError
from planner.contract.headings import N_HEADINGS, bearings_deg, cell_size_m, courses_deg
from planner.contract.table_header import (CURRENT_IN_PAYLOAD, MAX_CURRENT_PAIRS, MAX_STATES, block_shape, header_fields,
                                           kept_block_cells, slice_unix_s)

MAGIC = b"LRAUVPT\x00"
FORMAT_VERSION = 1  # a stationary plan; its files are what they always were
TIMED_VERSION = 2  # a time-varying plan: one slice of actions per forecast time (docs/policy-table.md)
FLAG_ZLIB = 0x0001
# Version 2 only: the payload is an xz (LZMA2) stream, much smaller than zlib's on the demo's 73
# hourly slices; xz is in Python's standard library, so the vehicle side needs nothing more.
FLAG_XZ = 0x0002
# Version 2 only: the slices' actions are stored whole and cell by cell (a cell's eight actions in
# slice 0, then in slice 1, ...), not slice after slice as changes from the slice before. A cell's
# actions mostly repeat from one hour to the next, which xz codes as a short match four bytes back:
# on the demo's 73 hourly slices the payload is 37 % smaller than with the XOR changes the first
# version 2 files carry, which readers still take (without this flag).
FLAG_BY_CELL = 0x0008
_PREAMBLE = struct.Struct("<8sHHI")  # magic, version, flags, header length
_PAYLOAD = struct.Struct("<II")  # stored payload length, raw payload length
_CRC = struct.Struct("<I")
# A cell is left only once the vehicle is this fraction of a spacing beyond its edge
# (docs/executive.md): the executive's default, and the evaluation's (docs/evaluation.md).
CELL_MARGIN = 0.1

LookupReason = Literal["ok", "at_goal", "unreachable", "outside_grid", "land"]
# Which slice of a time-varying table holds at a time: the nearest slice's time ("in_horizon"); the
# first slice before it, or while the vehicle has no UTC time; the last slice past it.
SliceStatus = Literal["stationary", "in_horizon", "before_start", "past_horizon", "time_unknown"]
# The vehicle figures a physical plan depends on (``VehicleParams``' other fields are the simulator's alone).
PHYSICAL_VEHICLE_KEYS = ("cruise_speed_m_s", "max_speed_m_s", "yaw_rate_deg_s", "glide_rate_m_s", "hotel_w",
                         "propulsion_w", "buoyancy_w", "battery_wh")


@dataclass(frozen=True, slots=True)
class Lookup:
    """The table's answer for one position and heading; the executive never gets a bare None."""

    action: Action
    reason: LookupReason
    state: tuple[int, int, int, int] | None  # (l, j, i, k) as exported, None outside the grid


@dataclass(frozen=True, eq=False, slots=True)
class TimeSlice:
    """The stationary plan that holds at one time: ``table`` is slice ``index`` of a time-varying table
    (or the table itself), ``status`` says why that slice."""

    table: PolicyTable
    index: int
    status: SliceStatus


@dataclass(frozen=True, eq=False, kw_only=True)
class PolicyTable:
    """Actions for every state ``[l, j, i, k]`` plus the water mask ``[l, j, i]`` and provenance.

    Geometry follows spec section 1: cell centres ``lon0 + i * dlon``, ``lat0 + j * dlat``.
    """

    lon0_deg: float
    lat0_deg: float
    dlon_deg: float
    dlat_deg: float
    nx: int
    ny: int
    depth_m: tuple[float, ...]
    goal_lon_deg: float
    goal_lat_deg: float
    goal_depth_m: float
    goal_radius_cells: int
    criterion: str
    uncertainty: str
    model: str
    costs: dict[str, int]
    forecast_source: str
    forecast_identity: str
    forecast_time: str | None
    planner_version: str
    actions: NDArray[np.uint8] = field(repr=False)  # (L, ny, nx, 8)
    water: NDArray[np.bool_] = field(repr=False)  # (L, ny, nx)
    # Physical plans: {"vehicle": {...}, "sampling": {...}} (docs/policy-table.md); None for the paper model.
    physical: dict[str, dict[str, float | int | bool | None]] | None = None
    # Time-varying plans: the UTC time of each slice, and its actions (T, L, ny, nx, 8); ``actions``
    # is the first slice. Empty and None for a stationary plan.
    slice_times: tuple[str, ...] = ()
    slices: NDArray[np.uint8] | None = field(default=None, repr=False)
    # Optional, time-varying plans: each slice's forecast current per region, the mean over the region's
    # water cells (T, R, 2: east, north, m/s, to the cm/s), from which the executive fits the tide's timing
    # (``planner.contract.tide_timing``). A region is a layer, or with ``current_block_cells`` a block of
    # that many cells a side within a layer (``current_region``). None: looked up at the vehicle's own UTC.
    slice_current_m_s: NDArray[np.float64] | None = field(default=None, repr=False)
    current_block_cells: int | None = None
    # Where the plan expects the vehicle to go from the start it was planned with (``lrauv plan
    # --start``): (lon, lat) vertices, the real start first (spec section 5's nominal outcomes; for
    # a physical plan the most likely ones). Shown on the vehicle's map; empty when not planned.
    nominal_path: tuple[tuple[float, float], ...] = ()
    # Derived from the geometry in __post_init__, for the per-message lookups.
    _bearings: NDArray[np.float64] = field(init=False, repr=False, compare=False)
    _bearing_rows: tuple[tuple[float, ...], ...] = field(init=False, repr=False, compare=False)
    _course_rows: list[list[list[float]]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        shape = (len(self.depth_m), self.ny, self.nx)
        if self.actions.shape != shape + (N_HEADINGS,) or self.water.shape != shape:
            raise TableError(f"table arrays: expected {shape + (N_HEADINGS,)} and {shape}; got {self.actions.shape} and {self.water.shape}")
        for arr in (self.actions, self.water):
            arr.setflags(write=False)
        if self.slices is not None:
            n = self.slices.shape[0]
            if self.slices.shape[1:] != self.actions.shape or len(self.slice_times) != n or n < 2:
                raise TableError(f"table slices: expected (T >= 2,) + {self.actions.shape} and T times; got "
                                 f"{self.slices.shape} and {len(self.slice_times)} times")
            self.slices.setflags(write=False)
        elif self.slice_times:
            raise TableError("table slices: slice times without slices")
        if self.current_block_cells is not None and (self.slice_current_m_s is None or self.current_block_cells < 1):
            raise TableError(f"table slice currents: a block of {self.current_block_cells} cells needs slice currents"
                             " and at least one cell")
        if self.slice_current_m_s is not None:
            expected = (self.n_slices, self.n_current_regions, 2)
            if self.slices is None or self.slice_current_m_s.shape != expected:
                raise TableError(f"table slice currents: expected {expected} for a time-varying table; got "
                                 f"{self.slice_current_m_s.shape}{'' if self.slices is not None else ' on a stationary one'}")
            out_of_range = _current_out_of_range(self.slice_current_m_s)
            if out_of_range:
                raise TableError(f"table slice currents: {out_of_range}")
            if self.slice_current_m_s.size > 2 * MAX_CURRENT_PAIRS:
                raise TableError(f"table slice currents: {self.n_slices} slices x {self.n_current_regions:,} regions"
                                 f" exceed the limit of {MAX_CURRENT_PAIRS:,} pairs; a larger timing block makes fewer")
            self.slice_current_m_s.setflags(write=False)
        dx_m, dy_m = cell_size_m(self.lat_deg, self.dlon_deg, self.dlat_deg)
        bearings = bearings_deg(dx_m, dy_m)
        bearings.setflags(write=False)
        object.__setattr__(self, "_bearings", bearings)
        # Plain floats for the per-message lookup: numpy's per-call overhead dominates on 8 values.
        object.__setattr__(self, "_bearing_rows", tuple(tuple(float(b) for b in row) for row in bearings))
        object.__setattr__(self, "_course_rows", courses_deg(bearings).tolist())

    @classmethod
    def from_solution(
        cls,
        solution: Any,
        *,
        forecast_source: str,
        forecast_identity: str,
        forecast_time: str | None,
    ) -> PolicyTable:
        """Pack a solved plan (``planner.paper.solve.Solution``) with its provenance."""
        from planner import __version__

        model = solution.model
        grid = model.grid
        settings = model.settings
        goal = solution.goal
        physical = None
        costs = {"drift": settings.costs.drift, "forward": settings.costs.forward,
                 "rotate": settings.costs.rotate, "glide": settings.costs.glide}
        if settings.model == "physical":  # costs are watt-hours from the vehicle figures, not the paper's
            costs = {}
            physical = {
                "vehicle": {key: getattr(settings.vehicle, key) for key in PHYSICAL_VEHICLE_KEYS},
                "sampling": {f.name: getattr(settings.physical, f.name) for f in dataclass_fields(settings.physical)},
            }
        return cls(
            lon0_deg=float(grid.lon_deg[0]),
            lat0_deg=float(grid.lat_deg[0]),
            dlon_deg=grid.dlon_deg,
            dlat_deg=grid.dlat_deg,
            nx=grid.nx,
            ny=grid.ny,
            depth_m=tuple(float(d) for d in grid.depth_m),
            goal_lon_deg=float(goal.lon_deg),
            goal_lat_deg=float(goal.lat_deg),
            goal_depth_m=float(goal.depth_m),
            goal_radius_cells=int(goal.radius_cells),
            criterion=settings.criterion,
            uncertainty=settings.uncertainty,
            model=settings.model,
            costs=costs,
            forecast_source=forecast_source,
            forecast_identity=forecast_identity,
            forecast_time=forecast_time,
            planner_version=__version__,
            actions=np.ascontiguousarray(solution.action, dtype=np.uint8),
            water=np.ascontiguousarray(model.water),
            physical=physical,
        )

    # -- time -----------------------------------------------------------------------
    def with_slices(self, times_utc: tuple[str, ...], actions: NDArray[np.uint8],
                    current_m_s: NDArray[np.float64] | None = None, *, block_cells: int | None = None) -> PolicyTable:
        """This table made time-varying: slice ``n`` (actions ``(L, ny, nx, 8)``) holds around ``times_utc[n]``;
        ``current_m_s`` (T, R, 2), each slice's mean current per region (a layer, or a block of ``block_cells``
        cells a side: ``current_region``), lets the vehicle fit the tide's timing."""
        stack = np.ascontiguousarray(actions, dtype=np.uint8)
        slice_unix_s(times_utc, "slice times")  # ISO 8601 UTC, increasing
        current = None if current_m_s is None else np.round(np.asarray(current_m_s, dtype=np.float64) * 100.0) / 100.0
        return replace(self, actions=np.ascontiguousarray(stack[0]), slices=stack, slice_times=tuple(times_utc),
                       slice_current_m_s=current,
                       current_block_cells=None if current is None else kept_block_cells(self.ny, self.nx, block_cells))

    def current_blocks(self) -> tuple[int, int]:
        """(rows, columns) of current regions in a layer: blocks of ``current_block_cells``, or the whole layer."""
        return block_shape(self.ny, self.nx, self.current_block_cells)

    @property
    def n_current_regions(self) -> int:
        rows, cols = self.current_blocks()
        return len(self.depth_m) * rows * cols

    def current_region(self, cell: tuple[int, int, int]) -> int:
        """The index into ``slice_current_m_s``'s regions of cell (layer, row, column)."""
        l, j, i = cell
        k = self.current_block_cells
        if k is None:
            return l
        rows, cols = self.current_blocks()
        return (l * rows + j // k) * cols + i // k

    @property
    def time_varying(self) -> bool:
        return self.slices is not None

    @property
    def n_slices(self) -> int:
        return 1 if self.slices is None else int(self.slices.shape[0])

    @cached_property
    def slice_unix_s(self) -> tuple[float, ...]:
        """Each slice's time, Unix seconds (empty for a stationary table)."""
        return slice_unix_s(self.slice_times, "slice times") if self.slice_times else ()

    @cached_property
    def _views(self) -> list[PolicyTable | None]:
        return [None] * self.n_slices

    def slice_table(self, index: int) -> PolicyTable:
        """Slice ``index`` as a stationary table, with this file's identity (``crc32``): made once."""
        if self.slices is None:
            return self
        view = self._views[index]
        if view is None:
            view = replace(self, actions=self.slices[index], slices=None, slice_times=(), slice_current_m_s=None,
                           current_block_cells=None)
            view.__dict__["crc32"] = self.crc32
            self._views[index] = view
        return view

    def slice_at(self, unix_s: float | None) -> TimeSlice:
        """The slice that holds at a UTC time: the one whose time is nearest (a slice is the plan for
        the vehicle at its time, and the actions change midway between two slices); the first one
        before the first slice or while the time is unknown; the last one past the last (the plan's
        horizon), whose values assume its currents last (docs/time-varying.md)."""
        if self.slices is None:
            return TimeSlice(self, 0, "stationary")
        times = self.slice_unix_s
        if unix_s is None or not math.isfinite(unix_s):
            return TimeSlice(self.slice_table(0), 0, "time_unknown")
        if unix_s < times[0]:
            return TimeSlice(self.slice_table(0), 0, "before_start")
        if unix_s > times[-1]:
            return TimeSlice(self.slice_table(len(times) - 1), len(times) - 1, "past_horizon")
        n = bisect_right(times, unix_s) - 1
        if n + 1 < len(times) and times[n + 1] - unix_s < unix_s - times[n]:
            n += 1
        return TimeSlice(self.slice_table(n), n, "in_horizon")

    # -- geometry -------------------------------------------------------------------
    @property
    def lon_deg(self) -> NDArray[np.float64]:
        return self.lon0_deg + self.dlon_deg * np.arange(self.nx, dtype=np.float64)

    @property
    def lat_deg(self) -> NDArray[np.float64]:
        return self.lat0_deg + self.dlat_deg * np.arange(self.ny, dtype=np.float64)

    @property
    def n_layers(self) -> int:
        return len(self.depth_m)

    @property
    def n_states(self) -> int:
        return self.n_layers * self.ny * self.nx * N_HEADINGS

    def bearing_deg(self, j: int, k: int) -> float:
        """True compass bearing of grid direction ``k`` in row ``j`` (spec section 2)."""
        return float(self._bearings[j, k])

    def course_deg(self, j: int, k: int, action: Action) -> float:
        """Compass course of a FORWARD action in heading ``k`` of row ``j``: ``bearing_k(j)`` for FORWARD,
        a third of the way to the neighbouring heading's bearing for FORWARD_LEFT/RIGHT."""
        return self._course_rows[j][k][FORWARD_ACTIONS.index(action)]

    def cell_centre(self, j: int, i: int) -> tuple[float, float]:
        """``(lat_deg, lon_deg)`` of a cell centre."""
        return (self.lat0_deg + j * self.dlat_deg, self.lon0_deg + i * self.dlon_deg)

    def locate(self, lat_deg: float, lon_deg: float, depth_m: float) -> tuple[int, int, int] | None:
        """Cell ``(l, j, i)`` containing a position, or None outside the planned volume.

        A cell spans half a spacing either side of its centre; the layer is the
        nearest one (lower index at a midpoint, as for the goal in spec section 6),
        and a depth more than half a layer spacing below the deepest layer is outside.
        """
        if not (math.isfinite(lat_deg) and math.isfinite(lon_deg) and math.isfinite(depth_m)):
            return None
        fi = (lon_deg - self.lon0_deg) / self.dlon_deg
        fj = (lat_deg - self.lat0_deg) / self.dlat_deg
        if not (-0.5 <= fi <= self.nx - 0.5 and -0.5 <= fj <= self.ny - 0.5):
            return None
        i = min(max(math.ceil(fi - 0.5), 0), self.nx - 1)
        j = min(max(math.ceil(fj - 0.5), 0), self.ny - 1)
        depths = self.depth_m
        below = 0.5 * (depths[-1] - depths[-2]) if len(depths) > 1 else 2.5
        if depth_m > depths[-1] + below:
            return None
        l, best = 0, abs(depths[0] - depth_m)
        for n in range(1, len(depths)):
            d = abs(depths[n] - depth_m)
            if d < best:  # strict: a midpoint keeps the lower layer
                l, best = n, d
        return (l, j, i)

    def heading_index(self, j: int, heading_deg: float) -> int:
        """Grid direction nearest to a compass heading in row ``j``; ties to the lower ``k`` (spec 2)."""
        h = float(heading_deg)
        best_k, best = 0, math.inf
        for k, b in enumerate(self._bearing_rows[j]):
            diff = abs((h - b + 180.0) % 360.0 - 180.0)
            if diff < best:  # strict: ties keep the lower k
                best_k, best = k, diff
        return best_k

    def lookup(self, lat_deg: float, lon_deg: float, depth_m: float, heading_deg: float) -> Lookup:
        """The action for a position and compass heading, in constant time."""
        cell = self.locate(lat_deg, lon_deg, depth_m)
        if cell is None:
            return Lookup(Action.UNREACHABLE, "outside_grid", None)
        return self.lookup_cell(cell, heading_deg)

    def near_cell(self, lat_deg: float, lon_deg: float, j: int, i: int, margin_cells: float) -> bool:
        """Whether a position lies within ``margin_cells`` of a spacing beyond cell ``(j, i)``'s edges."""
        reach = 0.5 + margin_cells
        return (abs((lon_deg - self.lon0_deg) / self.dlon_deg - i) <= reach
                and abs((lat_deg - self.lat0_deg) / self.dlat_deg - j) <= reach)

    def lookup_held(self, lat_deg: float, lon_deg: float, depth_m: float, heading_deg: float,
                    held: tuple[int, int] | None, margin_cells: float = CELL_MARGIN) -> Lookup:
        """``lookup`` with hysteresis: keep water cell ``held = (j, i)`` while within ``margin_cells`` of it.

        Without it a vehicle on a boundary, pushed back by the current after each crossing,
        makes the decision chatter between two cells' actions (docs/executive.md). Arrival and
        leaving the grid are never delayed; the layer and heading are always the measured ones.
        """
        look = self.lookup(lat_deg, lon_deg, depth_m, heading_deg)
        if margin_cells <= 0.0 or held is None or look.state is None or look.reason not in ("ok", "unreachable", "land"):
            return look
        l, j, i, _k = look.state
        hj, hi = held
        if (j, i) == (hj, hi) or not self.near_cell(lat_deg, lon_deg, hj, hi, margin_cells) or not self.water[l, hj, hi]:
            return look
        return self.lookup_cell((l, hj, hi), heading_deg)

    def lookup_cell(self, cell: tuple[int, int, int], heading_deg: float) -> Lookup:
        """The action for cell ``(l, j, i)`` of the grid and a compass heading."""
        l, j, i = cell
        k = self.heading_index(j, heading_deg) if math.isfinite(heading_deg) else 0
        state = (l, j, i, k)
        if not self.water[l, j, i]:
            return Lookup(Action.UNREACHABLE, "land", state)
        action = Action(int(self.actions[state]))
        if action == Action.AT_GOAL:
            return Lookup(action, "at_goal", state)
        if action == Action.UNREACHABLE:
            return Lookup(action, "unreachable", state)
        return Lookup(action, "ok", state)

    # -- identity -------------------------------------------------------------------
    def header(self) -> dict[str, Any]:
        """The JSON header, as documented in docs/policy-table.md."""
        out = {
            "grid": {
                "lon0_deg": self.lon0_deg,
                "lat0_deg": self.lat0_deg,
                "dlon_deg": self.dlon_deg,
                "dlat_deg": self.dlat_deg,
                "nx": self.nx,
                "ny": self.ny,
                "depth_m": list(self.depth_m),
            },
            "headings": {"count": N_HEADINGS, "convention": "grid-k-ccw-from-east"},
            "goal": {
                "lon_deg": self.goal_lon_deg,
                "lat_deg": self.goal_lat_deg,
                "depth_m": self.goal_depth_m,
                "radius_cells": self.goal_radius_cells,
            },
            "model": self.model,
            "criterion": self.criterion,
            "uncertainty": self.uncertainty,
            "costs": dict(self.costs),
            "forecast": {
                "source": self.forecast_source,
                "identity": self.forecast_identity,
                "time": self.forecast_time,
            },
            "planner_version": self.planner_version,
        }
        if self.physical is not None:  # optional: paper tables keep the bytes they always had
            out["physical"] = {part: dict(values) for part, values in self.physical.items()}
        if self.slices is not None:  # version 2 only
            time_part: dict[str, Any] = {"slices_utc": list(self.slice_times), "lookup": "nearest"}
            out["time"] = time_part
            if self.slice_current_m_s is not None:  # optional; older readers never saw it
                time_part["current_cm_s"] = CURRENT_IN_PAYLOAD
                if self.current_block_cells is not None:  # optional: without it, a region is a layer
                    time_part["current_block_cells"] = self.current_block_cells
        if self.nominal_path:  # optional: a table planned without a start keeps the bytes it always had
            out["nominal_path"] = {"lon_lat_deg": [list(point) for point in self.nominal_path]}
        return out

    # -- bytes ----------------------------------------------------------------------
    def to_bytes(self, *, compress: bool = True) -> bytes:
        """Serialise: preamble, JSON header, 1-bit water mask + 4-bit actions, CRC32."""
        header = json.dumps(self.header(), sort_keys=True, separators=(",", ":")).encode("utf-8")
        raw = _pack_payload(self.water, self.actions if self.slices is None else _cell_major(self.slices))
        if self.slice_current_m_s is not None:
            raw += _pack_current(self.slice_current_m_s)
        if self.slices is None:
            version, flags = FORMAT_VERSION, FLAG_ZLIB if compress else 0
            stored = zlib.compress(raw, 9) if compress else raw
        else:
            version, flags = TIMED_VERSION, FLAG_BY_CELL | (FLAG_XZ if compress else 0)
            stored = (lzma.compress(raw, format=lzma.FORMAT_XZ, check=lzma.CHECK_CRC32, preset=9 | lzma.PRESET_EXTREME)
                      if compress else raw)
        body = b"".join([_PREAMBLE.pack(MAGIC, version, flags, len(header)), header, _PAYLOAD.pack(len(stored), len(raw)),
                         stored])
        return body + _CRC.pack(zlib.crc32(body))

    @classmethod
    def from_bytes(cls, data: bytes, *, name: str = "table") -> PolicyTable:
        """Parse and check a table; raise TableError saying what is wrong and where."""
        data = bytes(data)
        if len(data) < _PREAMBLE.size + _PAYLOAD.size + _CRC.size:
            raise TableError(f"{name}: truncated: {len(data)} bytes is shorter than the smallest table")
        magic, version, flags, header_len = _PREAMBLE.unpack_from(data, 0)
        if magic != MAGIC:
            raise TableError(f"{name}: not a policy table: magic {magic!r}, expected {MAGIC!r}")
        if version not in (FORMAT_VERSION, TIMED_VERSION):
            raise TableError(f"{name}: format version {version} is not supported; this reader reads versions "
                             f"{FORMAT_VERSION} and {TIMED_VERSION}")
        if flags & ~(FLAG_ZLIB | FLAG_XZ | FLAG_BY_CELL):
            raise TableError(f"{name}: unknown flags 0x{flags:04x}")
        if flags & FLAG_XZ and (flags & FLAG_ZLIB or version != TIMED_VERSION):
            raise TableError(f"{name}: flags 0x{flags:04x}: an xz payload (0x0002) is version 2's alone, and never with zlib (0x0001)")
        if flags & FLAG_BY_CELL and version != TIMED_VERSION:
            raise TableError(f"{name}: flags 0x{flags:04x}: actions by cell (0x0008) are version 2's alone")
        pos = _PREAMBLE.size + header_len
        if pos + _PAYLOAD.size + _CRC.size > len(data):
            raise TableError(f"{name}: truncated: the header says {header_len} header bytes but the file has {len(data)} bytes")
        stored_len, raw_len = _PAYLOAD.unpack_from(data, pos)
        end = pos + _PAYLOAD.size + stored_len
        if end + _CRC.size != len(data):
            what = "truncated" if end + _CRC.size > len(data) else "has trailing bytes"
            raise TableError(f"{name}: {what}: expected {end + _CRC.size} bytes from its lengths, got {len(data)}")
        (crc,) = _CRC.unpack_from(data, end)
        actual = zlib.crc32(data[:end])
        if crc != actual:
            raise TableError(f"{name}: CRC32 mismatch: stored 0x{crc:08x}, computed 0x{actual:08x}; the file is corrupt")
        try:
            header = json.loads(data[_PREAMBLE.size : pos].decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise TableError(f"{name}: header is not valid JSON: {exc}") from None
        except RecursionError:
            raise TableError(f"{name}: header is not valid JSON: nested too deeply") from None
        try:
            fields = header_fields(header)
        except TableError as exc:
            raise TableError(f"{name}: header {exc}") from None
        times = fields.get("slice_times", ())
        if (version == TIMED_VERSION) != bool(times):
            raise TableError(f"{name}: format version {version} " + ("needs the header's time.slices_utc" if version == TIMED_VERSION
                             else "has no time slices; the header's time.slices_utc needs version 2"))
        n_slices = max(len(times), 1)
        n_states = len(fields["depth_m"]) * fields["ny"] * fields["nx"] * N_HEADINGS
        if n_states * n_slices > MAX_STATES:
            raise TableError(f"{name}: {n_slices} slices of {n_states:,} states exceed the limit of {MAX_STATES:,} actions")
        shape = (len(fields["depth_m"]), fields["ny"], fields["nx"])
        regions = fields.pop("payload_current_regions", 0)
        expected = _payload_len(shape[0] * shape[1] * shape[2], n_slices, regions)
        if raw_len != expected:
            raise TableError(
                f"{name}: payload declared as {raw_len:,} bytes but the grid {shape[0]} x {shape[1]} x {shape[2]} x "
                f"{N_HEADINGS}{f' and {regions} regions of slice currents' if regions else ''} needs {expected:,}"
            )
        stored = data[pos + _PAYLOAD.size : end]
        if flags & FLAG_ZLIB:
            # At most the bytes the grid needs are inflated: a corrupt or hostile stream cannot
            # make the reader allocate more than the table it claims to be.
            inflate = zlib.decompressobj()
            try:
                raw = inflate.decompress(stored, expected + 1)
            except zlib.error as exc:
                raise TableError(f"{name}: compressed payload is corrupt: {exc}") from None
            if len(raw) > expected or inflate.unconsumed_tail:
                raise TableError(f"{name}: compressed payload inflates to more than the {expected:,} bytes the grid needs")
            if not inflate.eof:
                raise TableError(f"{name}: compressed payload is corrupt: the zlib stream ends early ({len(raw):,} of {expected:,} bytes)")
        elif flags & FLAG_XZ:
            unpack = lzma.LZMADecompressor(format=lzma.FORMAT_XZ)  # at most what the grid needs, as for zlib
            try:
                raw = unpack.decompress(stored, expected + 1)
            except lzma.LZMAError as exc:
                raise TableError(f"{name}: compressed payload is corrupt: {exc}") from None
            if len(raw) > expected:
                raise TableError(f"{name}: compressed payload inflates to more than the {expected:,} bytes the grid needs")
            if not unpack.eof:
                raise TableError(f"{name}: compressed payload is corrupt: the xz stream ends early ({len(raw):,} of {expected:,} bytes)")
        else:
            raw = stored
        if len(raw) != expected:
            raise TableError(
                f"{name}: payload is {len(raw):,} bytes but the grid {shape[0]} x {shape[1]} x {shape[2]} x "
                f"{N_HEADINGS} needs {expected:,}"
            )
        if regions:
            current_bytes = n_slices * regions * _CURRENT_BYTES
            fields["slice_current_m_s"] = _unpack_current(memoryview(raw)[len(raw) - current_bytes:], n_slices, regions)
        out_of_range = _current_out_of_range(fields["slice_current_m_s"]) if "slice_current_m_s" in fields else ""
        if out_of_range:
            raise TableError(f"{name}: slice currents: {out_of_range}")
        water, actions = _unpack_payload(raw, shape, n_slices)
        if n_slices > 1 and flags & FLAG_BY_CELL:  # the same nibbles, in the order cell, slice, heading
            actions = np.ascontiguousarray(np.moveaxis(actions.reshape(shape + (n_slices, N_HEADINGS)), -2, 0))
        elif n_slices > 1:
            actions = np.bitwise_xor.accumulate(actions, axis=0)  # each slice was stored as its change from the one before
        if np.any(actions > max(Action)):
            raise TableError(f"{name}: action codes above {int(max(Action))} in the payload")
        if np.any(actions > Action.UNREACHABLE):
            if fields["model"] != "physical":
                raise TableError(f"{name}: action codes above {int(Action.UNREACHABLE)} (course offsets) in a "
                                 f"{fields['model']}-model table; only physical plans have them")
            if (fields.get("physical") or {}).get("sampling", {}).get("course_offsets") is False:
                raise TableError(f"{name}: action codes above {int(Action.UNREACHABLE)} (course offsets) in a table "
                                 "whose header says physical.sampling.course_offsets false")
        if np.any(actions[..., ~water, :] != Action.UNREACHABLE):
            raise TableError(f"{name}: land cells must carry UNREACHABLE (spec section 6)")
        if n_slices > 1:
            table = cls(actions=np.ascontiguousarray(actions[0]), water=water, slices=actions, **fields)
        else:
            table = cls(actions=actions, water=water, **fields)
        if flags & (FLAG_ZLIB | FLAG_XZ):
            # A compressed file is the serialisation ``crc32`` names: keep its checked CRC rather
            # than compress the whole table again (12 ms at 320,000 states, on the executive's loop).
            table.__dict__["crc32"] = crc
        return table

    def save(self, path: str | os.PathLike[str], *, compress: bool = True) -> Path:
        """Write atomically: a temporary file in the same folder, then rename."""
        return write_atomic(path, self.to_bytes(compress=compress))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> PolicyTable:
        """Read and check a table file."""
        return cls.from_bytes(read_table_file(path), name=str(path))

    @cached_property
    def crc32(self) -> int:
        """CRC32 of the compressed serialisation: the table's identity in logs (computed once)."""
        return int.from_bytes(self.to_bytes()[-4:], "little")

    def matches(self, other: PolicyTable) -> list[str]:
        """Fields that differ from another table's grid or goal (empty when compatible)."""
        mine, theirs = self.header(), other.header()
        return [key for key in ("grid", "goal") if mine[key] != theirs[key]]


def read_table_file(path: str | os.PathLike[str]) -> bytes:
    """A table file's bytes, unchecked (``PolicyTable.from_bytes`` checks them); TableError naming it."""
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise TableError(f"{path}: cannot read the policy table: {exc.strerror or exc}") from None


def _payload_len(n_cells: int, n_slices: int = 1, current_regions: int = 0) -> int:
    return (n_cells + 7) // 8 + n_slices * ((n_cells * N_HEADINGS + 1) // 2 + current_regions * _CURRENT_BYTES)


# Slice currents in the payload: per slice, region and component (east, north) a little-endian int16 of cm/s.
_CURRENT_BYTES = 4  # per slice and region
_CURRENT_LIMIT_M_S = 327.67


def _current_out_of_range(current_m_s: NDArray[np.float64]) -> str:
    """Empty, or what is wrong with the first slice current beyond 16 bits of cm/s (or not finite)."""
    bad = ~(np.abs(current_m_s) <= _CURRENT_LIMIT_M_S)  # NaN is bad too
    if not bad.any():
        return ""
    n, r, c = (int(x) for x in np.argwhere(bad)[0])
    return (f"slice {n}, region {r}, {('east', 'north')[c]}: {float(current_m_s[n, r, c])!r} m/s; expected a finite current"
            f" within +-{_CURRENT_LIMIT_M_S} m/s (whole cm/s in 16 bits)")


def _pack_current(current_m_s: NDArray[np.float64]) -> bytes:
    """(T, R, 2) currents as whole cm/s: the first slice, then each slice less the one before, in int16
    arithmetic that wraps (a reader's running sum wraps back): hourly means change by a few cm/s, so
    most of these bytes are alike and compress with the actions."""
    cm_s = np.round(np.asarray(current_m_s) * 100.0).astype(np.int64)
    step = cm_s.copy()
    step[1:] -= cm_s[:-1]
    return step.astype("<i2").tobytes()  # int64 to int16 keeps the low 16 bits: the wrapped difference


def _unpack_current(raw: bytes | memoryview, n_slices: int, n_regions: int) -> NDArray[np.float64]:
    """Inverse of ``_pack_current``: (T, R, 2) in m/s."""
    step = np.frombuffer(raw, dtype="<i2").reshape(n_slices, n_regions, 2)
    with np.errstate(over="ignore"):
        cm_s = np.cumsum(step, axis=0, dtype=np.int16)  # wraps as the writer's differences did
    return cm_s.astype(np.float64) / 100.0


def _pack_payload(water: NDArray[np.bool_], actions: NDArray[np.uint8]) -> bytes:
    """Water bits (little bit order, [l, j, i]) then actions, two per byte, low nibble first; a
    time-varying table's slices one after another, each padded to whole bytes."""
    mask = np.packbits(np.ascontiguousarray(water).ravel(), bitorder="little")
    per_slice = int(np.prod(water.shape)) * N_HEADINGS
    flat = np.ascontiguousarray(actions).astype(np.uint8).reshape(-1, per_slice)
    if per_slice % 2:
        flat = np.concatenate([flat, np.zeros((flat.shape[0], 1), dtype=np.uint8)], axis=1)
    nibbles = (flat[:, 0::2] & 0x0F) | ((flat[:, 1::2] & 0x0F) << 4)
    return mask.tobytes() + nibbles.astype(np.uint8).tobytes()


def _cell_major(slices: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """(T, L, ny, nx, 8) slices in the order of flag bit 3: (L, ny, nx, T, 8). Each cell's block of T x 8
    nibbles is whole bytes, so ``_pack_payload`` adds no padding and the file's length is unchanged."""
    return np.ascontiguousarray(np.moveaxis(slices, 0, -2))


def _unpack_payload(raw: bytes | memoryview, cell_shape: tuple[int, int, int], n_slices: int = 1) -> tuple[NDArray[np.bool_], NDArray[np.uint8]]:
    """Inverse of ``_pack_payload``: actions ``cell_shape + (8,)``, or ``(n_slices,) + ...`` when sliced."""
    n_cells = int(np.prod(cell_shape))
    n_mask = (n_cells + 7) // 8
    buf = np.frombuffer(raw, dtype=np.uint8)
    water = np.unpackbits(buf[:n_mask], bitorder="little")[:n_cells].astype(bool).reshape(cell_shape)
    packed = buf[n_mask:_payload_len(n_cells, n_slices)].reshape(n_slices, -1)  # slice currents may follow
    actions = np.empty((n_slices, packed.shape[1] * 2), dtype=np.uint8)
    actions[:, 0::2] = packed & 0x0F
    actions[:, 1::2] = packed >> 4
    out = actions[:, : n_cells * N_HEADINGS].reshape((n_slices,) + cell_shape + (N_HEADINGS,))
    return water, (out[0] if n_slices == 1 else out)
