"""Maps of the planning grid: lon/lat axes, cell edges, land with its coastline, cell outlines, arrow thinning.

Shared by the plan pictures, the track picture and the dive report. A grid's
cell centres lie on its bbox edges (spec section 1), so a map spans half a cell
beyond them; its axes keep the metric aspect 1/cos(latitude).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.shore.plots.style import LAND_COLOR

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.grid import Grid

__all__ = [
    "COAST_COLOR",
    "MAX_ARROWS_PER_AXIS",
    "arrow_stride",
    "cell_edges",
    "cell_points",
    "cos_lat",
    "draw_land",
    "draw_outline",
    "geo_axes",
    "panel_height",
]

MAX_ARROWS_PER_AXIS = 40  # thin out arrows on big grids so they stay readable
COAST_COLOR = "#8c7a55"


def cos_lat(grid: Grid) -> float:
    """Cosine of the grid's middle latitude: a degree of longitude is this many degrees of latitude long."""
    return float(np.cos(np.radians(0.5 * (grid.lat_deg[0] + grid.lat_deg[-1]))))


def panel_height(grid: Grid, width_in: float) -> float:
    """Axes height that keeps the map's metric aspect for an axes ``width_in`` wide."""
    ratio = grid.ny * grid.dlat_deg / (grid.nx * grid.dlon_deg * cos_lat(grid))
    return float(np.clip(width_in * ratio, 2.4, 9.0))


def cell_points(grid: Grid, width_in: float) -> float:
    """Approximate displayed size of one cell, in points, on a map axes ``width_in`` wide."""
    ratio = grid.ny * grid.dlat_deg / (grid.nx * grid.dlon_deg * cos_lat(grid))  # map height / width
    map_w = min(width_in, panel_height(grid, width_in) / ratio)
    return 72.0 * min(map_w / grid.nx, map_w * ratio / grid.ny)


def arrow_stride(grid: Grid, max_per_axis: int) -> int:
    """Draw every n-th cell so that at most ``max_per_axis`` symbols lie along either axis."""
    return max(1, math.ceil(max(grid.nx, grid.ny) / max_per_axis))


def cell_edges(grid: Grid) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Cell edges: centres lie on the bbox edges, so edges extend half a cell beyond (spec section 1)."""
    lon_e = np.concatenate([grid.lon_deg - 0.5 * grid.dlon_deg, [grid.lon_deg[-1] + 0.5 * grid.dlon_deg]])
    lat_e = np.concatenate([grid.lat_deg - 0.5 * grid.dlat_deg, [grid.lat_deg[-1] + 0.5 * grid.dlat_deg]])
    return lon_e, lat_e


def draw_land(mpl: Any, ax: Any, grid: Grid, land: NDArray[np.bool_]) -> None:
    """Fill the land where ``land`` (a cell mask) is true, bounded by a smooth coastline.

    The coastline is the 0.5 contour of the mask between cell centres (matplotlib's
    ``contour``, linear between centres): it separates every land centre from every water
    centre as the cells do, but cuts the cells' corners instead of drawing their staircase.
    The mask is carried to the map's frame, so land that reaches the grid's edge fills to it.
    The filled land has gid ``land``, the line gid ``coastline``.
    """
    if not land.any():
        return
    lon_e, lat_e = cell_edges(grid)
    x = np.concatenate([[lon_e[0]], grid.lon_deg, [lon_e[-1]]])
    y = np.concatenate([[lat_e[0]], grid.lat_deg, [lat_e[-1]]])
    z = np.pad(np.asarray(land, dtype=np.float64), 1, mode="edge")
    fill = ax.contourf(x, y, z, levels=[0.5, 1.5], colors=[LAND_COLOR], zorder=2)
    fill.set_gid("land")
    coast = ax.contour(x, y, z, levels=[0.5], colors=[COAST_COLOR], linewidths=0.9, zorder=3.5)
    coast.set_gid("coastline")


def draw_outline(mpl: Any, ax: Any, grid: Grid, mask: NDArray[np.bool_], *, color: str, linewidth: float) -> None:
    """Outline the union of the cells where ``mask`` is true (edges between in and out)."""
    if not mask.any():
        return
    lon_e, lat_e = cell_edges(grid)
    padded = np.pad(mask, 1)
    segs = []
    # Vertical edges: between columns i-1 and i (padded index shift).
    vert = padded[1:-1, 1:] != padded[1:-1, :-1]  # (ny, nx + 1)
    for j, i in zip(*np.nonzero(vert)):
        segs.append([(lon_e[i], lat_e[j]), (lon_e[i], lat_e[j + 1])])
    horiz = padded[1:, 1:-1] != padded[:-1, 1:-1]  # (ny + 1, nx)
    for j, i in zip(*np.nonzero(horiz)):
        segs.append([(lon_e[i], lat_e[j]), (lon_e[i + 1], lat_e[j])])
    ax.add_collection(mpl.collections.LineCollection(segs, colors=color, linewidths=linewidth, zorder=3.5,
                                                     capstyle="projecting"))


def geo_axes(mpl: Any, ax: Any, grid: Grid, *, xlabel: bool = True, ylabel: bool = True) -> None:
    """Lon/lat axes in degrees with hemisphere letters and aspect 1/cos(lat) (spec section 1)."""
    lon_e, lat_e = cell_edges(grid)
    ax.set_xlim(lon_e[0], lon_e[-1])
    ax.set_ylim(lat_e[0], lat_e[-1])
    ax.set_aspect(1.0 / cos_lat(grid))
    ax.xaxis.set_major_locator(mpl.ticker.MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]))
    ax.yaxis.set_major_locator(mpl.ticker.MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]))
    ax.xaxis.set_major_formatter(_degree_formatter(mpl, "E", "W"))
    ax.yaxis.set_major_formatter(_degree_formatter(mpl, "N", "S"))
    ax.tick_params(labelsize=8.5)
    if xlabel:
        ax.set_xlabel("longitude")
    if ylabel:
        ax.set_ylabel("latitude")


def _degree_formatter(mpl: Any, pos_letter: str, neg_letter: str) -> Any:
    """Tick labels like ``118.15°W`` with as few decimals as the tick spacing needs."""

    class DegreeFormatter(mpl.ticker.Formatter):
        decimals = 2

        def format_ticks(self, values: Any) -> list[str]:
            locs = np.asarray(values, dtype=np.float64)
            self.decimals = 0
            while self.decimals < 5 and np.any(np.abs(np.round(locs, self.decimals) - locs) > 1e-9):
                self.decimals += 1
            return [self(x, n) for n, x in enumerate(locs)]

        def __call__(self, x: float, pos: int | None = None) -> str:
            letter = pos_letter if x > 0 else neg_letter if x < 0 else ""
            return f"{abs(x):.{self.decimals}f}\u00b0{letter}"

    return DegreeFormatter()
