"""One read of a forecast file: the open files, what part of them to read, and what a layout's reader returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from planner.contract.errors import ForecastError

if TYPE_CHECKING:
    from planner.contract.geodesy import BBox


@dataclass(frozen=True, kw_only=True)
class Want:
    """What part of the file to read: every field None reads the whole file (the default)."""

    bbox: BBox | None = None
    time_index: int | None = None
    member: int | None = None

    @property
    def partial(self) -> bool:
        return self.bbox is not None or self.time_index is not None or self.member is not None

    @classmethod
    def checked(cls, label: str, *, bbox: Any, time_index: Any, member: Any) -> Want:
        from planner.contract.geodesy import BBox

        if bbox is not None and not isinstance(bbox, BBox):
            raise ForecastError(f"{label}: bbox: expected a planner.grid.BBox; got {type(bbox).__name__}")
        for name, value in (("time_index", time_index), ("member", member)):
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ForecastError(f"{label}: {name}: expected an integer >= 0; got {value!r}")
        return cls(
            bbox=bbox,
            time_index=None if time_index is None else int(time_index),
            member=None if member is None else int(member),
        )


@dataclass(frozen=True, kw_only=True)
class Context:
    """The open file (and optional grid file) plus a label for error messages."""

    ds: xr.Dataset
    label: str
    grid_ds: xr.Dataset | None
    grid_label: str | None
    # Selections (member, time step) applied to every variable found that has the dimension.
    select: dict[str, int | slice] = field(default_factory=dict)

    def find(
        self, names: tuple[str, ...], shape: tuple[int, ...] | None = None
    ) -> tuple[str, xr.DataArray, str] | None:
        """First variable among ``names`` (main file, then grid file) with the given shape: (name, var, where)."""
        for dset, where in ((self.ds, self.label), (self.grid_ds, self.grid_label)):
            if dset is None:
                continue
            for name in names:
                if name in dset.variables:
                    var = dset[name]
                    chosen = {d: s for d, s in self.select.items() if d in var.dims}
                    if chosen:
                        var = var.isel(chosen)
                    if shape is None or tuple(var.shape) == tuple(shape):
                        return name, var, str(where)
        return None

    def grid_hint(self) -> str:
        return "" if self.grid_ds is not None else "; pass --grid-file GRID.nc (grid_file=) with the model grid"


@dataclass(frozen=True, eq=False, kw_only=True)
class Fields:
    """What a layout's reader (regular, projected, C-grid) read: east/north m/s on the Forecast's axes.

    ``u``/``v`` are ``(T, Z, Y, X)``; ``time_s`` holds the steps kept (one with ``time_index=``),
    ``file_n_times`` the file's count. ``part`` says what part of the file was read ("" for all
    of it). ``lon_index``/``lat_index`` and ``file_lon``/``file_lat`` are set only for a lon/lat
    window of a regular grid (``ForecastWindow``).
    """

    u: NDArray[np.float64]
    v: NDArray[np.float64]
    lon: NDArray[np.float64]
    lat: NDArray[np.float64]
    depth: NDArray[np.float64] | None
    time_s: NDArray[np.float64]
    time_origin: str | None
    file_n_times: int
    part: str = ""
    covers_surface: bool = True
    lon_index: tuple[int, int] | None = None
    lat_index: tuple[int, int] | None = None
    file_lon: NDArray[np.float64] | None = None
    file_lat: NDArray[np.float64] | None = None
