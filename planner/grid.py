"""The planning grid: regular lon/lat cells with depth layers (spec section 1)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import GridError
from planner.contract.geodesy import BBox
from planner.contract.headings import N_HEADINGS, bearings_deg, cell_size_m


@dataclass(frozen=True, eq=False, kw_only=True)
class Grid:
    """Cell centres ``lon_deg[i]`` (nx,), ``lat_deg[j]`` (ny,) and layer depths ``depth_m[l]`` (L,).

    State arrays are indexed ``[l, j, i, k]`` (spec section 2).
    """

    lon_deg: NDArray[np.float64]
    lat_deg: NDArray[np.float64]
    depth_m: NDArray[np.float64]

    def __post_init__(self) -> None:
        for name in ("lon_deg", "lat_deg", "depth_m"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.lon_deg.size < 2 or self.lat_deg.size < 2:
            raise GridError(f"grid: expected nx >= 2 and ny >= 2; got nx={self.lon_deg.size}, ny={self.lat_deg.size}")
        if self.depth_m.size < 1:
            raise GridError("grid: expected at least one depth layer; got none")
        if np.any(np.diff(self.depth_m) <= 0) or np.any(self.depth_m < 0):
            raise GridError(
                f"depths: expected non-negative depths in metres, strictly increasing; got {self.depth_m.tolist()}"
            )

    @classmethod
    def from_bbox(cls, bbox: BBox, *, nx: int, ny: int, depths_m: NDArray[np.float64] | list[float]) -> Grid:
        """Cell centres on the box edges: ``linspace(west, east, nx)`` (spec section 1)."""
        if int(nx) < 2 or int(ny) < 2:
            raise GridError(f"grid: expected nx >= 2 and ny >= 2; got nx={nx}, ny={ny}")
        return cls(
            lon_deg=np.linspace(bbox.west_deg, bbox.east_deg, int(nx)),
            lat_deg=np.linspace(bbox.south_deg, bbox.north_deg, int(ny)),
            depth_m=np.asarray(depths_m, dtype=np.float64),
        )

    @property
    def nx(self) -> int:
        return int(self.lon_deg.size)

    @property
    def ny(self) -> int:
        return int(self.lat_deg.size)

    @property
    def n_layers(self) -> int:
        return int(self.depth_m.size)

    @property
    def shape(self) -> tuple[int, int, int, int]:
        """State array shape ``(L, ny, nx, 8)``."""
        return (self.n_layers, self.ny, self.nx, N_HEADINGS)

    @property
    def n_states(self) -> int:
        return int(np.prod(self.shape))

    @property
    def dlon_deg(self) -> float:
        return float((self.lon_deg[-1] - self.lon_deg[0]) / (self.nx - 1))

    @property
    def dlat_deg(self) -> float:
        return float((self.lat_deg[-1] - self.lat_deg[0]) / (self.ny - 1))

    @property
    def bbox(self) -> BBox:
        return BBox(
            west_deg=float(self.lon_deg[0]),
            south_deg=float(self.lat_deg[0]),
            east_deg=float(self.lon_deg[-1]),
            north_deg=float(self.lat_deg[-1]),
        )

    def cell_size_m(self) -> tuple[NDArray[np.float64], float]:
        """``(dx_m (ny,), dy_m)`` (spec section 1)."""
        return cell_size_m(self.lat_deg, self.dlon_deg, self.dlat_deg)

    def bearings_deg(self) -> NDArray[np.float64]:
        """Compass bearing of each grid direction per row, ``(ny, 8)`` (spec section 2)."""
        dx_m, dy_m = self.cell_size_m()
        return bearings_deg(dx_m, dy_m)

    def nearest_cell(self, lon_deg: float, lat_deg: float) -> tuple[int, int, float]:
        """Nearest cell centre ``(i, j)`` and how far outside the grid the point is, in cells.

        At an exact midpoint the lower index wins (spec section 6).
        """
        fi = (lon_deg - self.lon_deg[0]) / self.dlon_deg
        fj = (lat_deg - self.lat_deg[0]) / self.dlat_deg
        i = int(np.clip(_round_half_down(fi), 0, self.nx - 1))
        j = int(np.clip(_round_half_down(fj), 0, self.ny - 1))
        outside = max(0.0, -fi, fi - (self.nx - 1), -fj, fj - (self.ny - 1))
        return i, j, float(outside)

    def state_index(self, l: int, j: int, i: int, k: int) -> int:
        """Internal state index of the solvers: heading-major, ``((k * L + l) * ny + j) * nx + i``,
        so that the moves of one heading stay in one contiguous slab."""
        return ((k * self.n_layers + l) * self.ny + j) * self.nx + i

    def state_of(self, index: int) -> tuple[int, int, int, int]:
        """``(l, j, i, k)`` of an internal state index."""
        k, l, j, i = np.unravel_index(index, (N_HEADINGS, self.n_layers, self.ny, self.nx))
        return (int(l), int(j), int(i), int(k))

    def nearest_layer(self, depth_m: float) -> int:
        """Nearest layer; at an exact midpoint the lower index (spec section 6)."""
        d = np.abs(self.depth_m - depth_m)
        return int(np.argmin(d))


def vehicle_longitudes(bbox: BBox) -> BBox:
    """``bbox`` on -180..180: a box wholly east of 180 deg (0..360 longitudes, as HYCOM's regional files
    use) is turned by -360 deg, exactly (Sterbenz); any other box is kept as given."""
    if bbox.west_deg < 180.0 or bbox.east_deg > 540.0:
        return bbox
    return replace(bbox, west_deg=bbox.west_deg - 360.0, east_deg=bbox.east_deg - 360.0)


def _round_half_down(x: float) -> int:
    """Nearest integer, halves going to the lower one."""
    return int(np.ceil(x - 0.5))
