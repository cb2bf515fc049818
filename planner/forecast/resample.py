"""Resampling a forecast onto the planning grid, exactly as spec section 1 says.

Pure numpy (and scipy's Delaunay triangulation for curvilinear grids): the
netCDF reading stays in ``planner.forecast``. Regular lon/lat forecasts use
separable linear interpolation with exact snapping to source nodes;
curvilinear forecasts use per-column vertical interpolation, then barycentric
interpolation on a Delaunay triangulation. Any non-zero weight on a land
(NaN) node makes the result land; zero-weight nodes are never touched.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import ForecastError, GridError
from planner.forecast.model import Forecast, is_periodic_lon
from planner.grid import Grid

# Barycentric weights below this are exactly zero (brief for spec section 1, curvilinear grids).
_BARY_SNAP = 1e-9
# Coordinates within this many float32 ulps (at the axis' largest magnitude) of a source node
# are that node (spec section 1: "coordinates stored as float32 count as equal"). Real products
# store float32 axes computed as start + i * step in float32 (HYCOM lon is off by up to 6.7 ulps
# of 125.9 deg, Copernicus lon by 1e-5 deg near 0 deg), so the ulp is taken at the axis' scale,
# never more than a thousandth of the axis spacing.
_SNAP_ULPS = 8.0
_SNAP_MAX_FRACTION_OF_SPACING = 1e-3


def resample(forecast: Forecast, grid: Grid, *, time_index: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """u, v on the planning grid, each shape (L, ny, nx) float64, NaN = land, exactly per spec section 1.

    Regular forecasts: separable linear interpolation in lon, lat and depth; curvilinear
    forecasts: per-column vertical interpolation, then barycentric interpolation on a Delaunay
    triangulation in a locally scaled lon/lat plane. A value that gives non-zero weight to a NaN
    node is NaN; zero-weight nodes are not touched; coordinates within 4 float32 ulps of a
    source node snap to it. Outside the lon/lat range: NaN; shallower than the first level: that
    level (unless ``covers_surface`` is False); deeper than the last level: NaN.
    """
    if not isinstance(forecast, Forecast):
        raise ForecastError(f"resample: expected a Forecast; got {type(forecast).__name__}")
    if not isinstance(grid, Grid):
        raise GridError(f"resample: expected a planning Grid; got {type(grid).__name__}")
    t = _check_time_index(forecast, time_index)
    if forecast.is_regular:
        return _resample_regular(forecast, grid, t)
    return _resample_curvilinear(forecast, grid, t)


def _check_time_index(forecast: Forecast, time_index: int) -> int:
    if isinstance(time_index, bool) or not isinstance(time_index, (int, np.integer)):
        raise ForecastError(
            f"{forecast.source}: time index: expected an integer in 0..{forecast.n_times - 1}; got {time_index!r}"
        )
    t = int(time_index)
    if not 0 <= t < forecast.n_times:
        raise ForecastError(
            f"{forecast.source}: time index {t} out of range: the forecast has {forecast.n_times} time steps, "
            f"valid indices 0..{forecast.n_times - 1}"
        )
    return t


def axis_snap_tol(src: NDArray[np.float64]) -> float:
    """Snap tolerance of a 1-D axis: a few float32 ulps at its largest magnitude (spec section 1)."""
    scale = np.float32(np.max(np.abs(src)))
    tol = _SNAP_ULPS * float(np.spacing(scale))
    if src.size > 1:
        tol = min(tol, _SNAP_MAX_FRACTION_OF_SPACING * float(np.min(np.diff(src))))
    return tol


def _elementwise_snap_tol(src: NDArray[np.float64]) -> NDArray[np.float64]:
    """Snap tolerance per value (per-column s-level depths, computed in float64)."""
    return _SNAP_ULPS * np.spacing(np.abs(src).astype(np.float32)).astype(np.float64)


@dataclass(frozen=True)
class _AxisWeights:
    """Linear weights along one axis: value = w0 * f[i0] + w1 * f[i1]; invalid targets are land."""

    i0: NDArray[np.intp]
    i1: NDArray[np.intp]
    w0: NDArray[np.float64]
    w1: NDArray[np.float64]
    valid: NDArray[np.bool_]


def _axis_weights(
    src: NDArray[np.float64], x: NDArray[np.float64], *, below: str, tol: float | None = None
) -> _AxisWeights:
    """Weights of targets ``x`` on the ascending axis ``src``.

    ``below`` says what a target before ``src[0]`` gets: 'land' or 'first' (the first node,
    spec section 1's rule for layers shallower than the first level). After ``src[-1]``: land.
    ``tol``: the snapping tolerance (default: ``src``'s own; a window of a file passes the file's).
    """
    x = np.asarray(x, dtype=np.float64)
    n = src.size
    if tol is None:
        tol = axis_snap_tol(src)
    k = np.searchsorted(src, x, side="left")  # src[k-1] < x <= src[k]
    lo = np.clip(k - 1, 0, n - 1)
    hi = np.clip(k, 0, n - 1)
    near_hi = np.abs(x - src[hi]) <= tol
    near_lo = np.abs(x - src[lo]) <= tol
    snapped = near_hi | near_lo
    snap_idx = np.where(near_hi, hi, lo)
    inside = (x > src[0]) & (x < src[-1]) & ~snapped
    i0 = np.where(snapped, snap_idx, np.where(inside, lo, 0))
    i1 = np.where(inside, hi, i0)
    span = src[i1] - src[i0]
    with np.errstate(invalid="ignore", divide="ignore"):
        w1 = np.where(inside, (x - src[i0]) / np.where(span > 0, span, 1.0), 0.0)
    w0 = np.where(inside, 1.0 - w1, 1.0)
    valid = snapped | inside
    if below == "first":
        before = (x < src[0]) & ~snapped
        i0 = np.where(before, 0, i0)
        i1 = np.where(before, 0, i1)
        w0 = np.where(before, 1.0, w0)
        w1 = np.where(before, 0.0, w1)
        valid = valid | before
    w0 = np.where(valid, w0, 0.0)
    w1 = np.where(valid, w1, 0.0)
    return _AxisWeights(i0.astype(np.intp), i1.astype(np.intp), w0, w1, valid)


def _accumulate(terms: list[tuple[NDArray[np.float64], NDArray[np.float64]]]) -> NDArray[np.float64]:
    """Sum of ``w * value`` over the terms with w > 0; NaN where such a term's value is not finite.

    Nodes with zero weight are not touched, so ``NaN * 0`` never poisons a value (spec section 1).
    """
    acc: NDArray[np.float64] | None = None
    bad: NDArray[np.bool_] | None = None
    with np.errstate(invalid="ignore"):
        for w, val in terms:
            used = w > 0.0
            term = np.where(used, w * val, 0.0)
            this_bad = used & ~np.isfinite(val)
            acc = term if acc is None else acc + term
            bad = this_bad if bad is None else bad | this_bad
    assert acc is not None and bad is not None
    return np.where(bad, np.nan, acc)


def _vertical(
    values: NDArray[np.float64],
    depth: NDArray[np.float64] | None,
    layers: NDArray[np.float64],
    covers_surface: bool,
) -> NDArray[np.float64]:
    """Values (Z, P) at levels ``depth`` ((Z,) or (Z, P); None = no depth axis) -> (L, P) at the layer depths."""
    n_z, n_p = values.shape
    if depth is None:
        return np.broadcast_to(values[0], (layers.size, n_p)).copy()
    below = "first" if covers_surface else "land"
    out = np.empty((layers.size, n_p))
    if depth.ndim == 1:
        aw = _axis_weights(depth, layers, below=below)
        for l in range(layers.size):
            if not aw.valid[l]:
                out[l] = np.nan
                continue
            out[l] = _accumulate(
                [(np.full(n_p, aw.w0[l]), values[aw.i0[l]]), (np.full(n_p, aw.w1[l]), values[aw.i1[l]])]
            )
        return out
    # Per-column depths (s-levels): the same rules column by column.
    cols = np.arange(n_p)
    good_col = np.all(np.isfinite(depth), axis=0)
    d = np.where(good_col[None, :], depth, 0.0)
    tol = _elementwise_snap_tol(d)
    for l, target in enumerate(layers):
        near = np.abs(d - target) <= tol
        snapped = near.any(axis=0)
        snap_idx = np.argmax(near, axis=0)
        k = np.sum(d <= target, axis=0) - 1  # last level at or above the target
        before = (k < 0) & ~snapped
        after = (k >= n_z - 1) & ~snapped
        inside = ~before & ~after & ~snapped
        k0 = np.where(snapped, snap_idx, np.where(inside, k, 0))
        k1 = np.where(inside, np.minimum(k + 1, n_z - 1), k0)
        span = d[k1, cols] - d[k0, cols]
        with np.errstate(invalid="ignore", divide="ignore"):
            w1 = np.where(inside, (target - d[k0, cols]) / np.where(span > 0, span, 1.0), 0.0)
        w0 = np.where(inside, 1.0 - w1, 1.0)
        valid = good_col & (snapped | inside | (before & covers_surface))
        w0 = np.where(valid, w0, 0.0)
        w1 = np.where(valid, w1, 0.0)
        res = _accumulate([(w0, values[k0, cols]), (w1, values[k1, cols])])
        out[l] = np.where(valid, res, np.nan)
    return out


def _shift_lon(x: NDArray[np.float64], lo: float, hi: float) -> NDArray[np.float64]:
    """Move target longitudes by a multiple of 360 deg into [lo, hi] when they fall outside it."""
    x = np.asarray(x, dtype=np.float64)
    out = x.copy()
    outside = (x < lo) | (x > hi)
    if np.any(outside):
        shifted = lo + np.mod(x - lo, 360.0)
        ok = outside & (shifted <= hi)
        out = np.where(ok, shifted, out)
    return out


def _lon_axis(lon: NDArray[np.float64]) -> NDArray[np.float64]:
    """The longitude axis interpolation runs on: a periodic axis gets its closing node (first + 360 deg)."""
    return np.append(lon, lon[0] + 360.0) if is_periodic_lon(lon) else lon


def _resample_regular(forecast: Forecast, grid: Grid, t: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    lon_src, lat_src = forecast.lon_deg, forecast.lat_deg
    n_x = lon_src.size
    lon_axis = _lon_axis(lon_src)
    # A lon/lat window of a file (open_forecast(bbox=)) snaps and wraps as the whole file does:
    # tolerances and the longitude shift come from the file's axes, the weights from the window's
    # nodes, which are the file's nodes around the bbox.
    file_lon, file_lat = forecast.file_lon_lat
    file_lon_axis = _lon_axis(file_lon)
    tol = axis_snap_tol(file_lon_axis)
    tx = _shift_lon(grid.lon_deg, file_lon_axis[0] - tol, file_lon_axis[-1] + tol)
    turns = np.unique(np.round((tx - grid.lon_deg) / 360.0))
    if turns.size == 1 and turns[0] != 0:
        # Every target is a whole turn off (a box in -180..180 on a file on 0..360): turn the file's axes
        # instead, exactly (x - 360 is exact for x in 180..720, Sterbenz), so the weights are bit for bit
        # those of the same field on -180..180 and the plan is the same.
        lon_axis, file_lon_axis = lon_axis - 360.0 * turns[0], file_lon_axis - 360.0 * turns[0]
        tol, tx = axis_snap_tol(file_lon_axis), grid.lon_deg
    ax = _axis_weights(lon_axis, tx, below="land", tol=tol)
    ay = _axis_weights(lat_src, grid.lat_deg, below="land", tol=axis_snap_tol(file_lat))
    ix0, ix1 = ax.i0 % n_x, ax.i1 % n_x

    rows = np.unique(np.concatenate([ay.i0[ay.valid], ay.i1[ay.valid]]))
    cols = np.unique(np.concatenate([ix0[ax.valid], ix1[ax.valid]]))
    layers = grid.depth_m
    shape = (layers.size, grid.ny, grid.nx)
    if rows.size == 0 or cols.size == 0:
        return np.full(shape, np.nan), np.full(shape, np.nan)

    def column_depth() -> NDArray[np.float64] | None:
        if forecast.depth_m is None or forecast.depth_m.ndim == 1:
            return forecast.depth_m
        d = forecast.depth_m[t][:, rows][:, :, cols]
        return d.reshape(d.shape[0], -1)

    depth = column_depth()
    # Positions of the needed source rows/cols in the cropped block.
    ry0, ry1 = np.searchsorted(rows, ay.i0), np.searchsorted(rows, ay.i1)
    cx0, cx1 = np.searchsorted(cols, ix0), np.searchsorted(cols, ix1)
    ry0, ry1 = np.clip(ry0, 0, rows.size - 1), np.clip(ry1, 0, rows.size - 1)
    cx0, cx1 = np.clip(cx0, 0, cols.size - 1), np.clip(cx1, 0, cols.size - 1)
    wy0, wy1 = ay.w0[:, None], ay.w1[:, None]
    wx0, wx1 = ax.w0[None, :], ax.w1[None, :]
    valid = ay.valid[:, None] & ax.valid[None, :]

    results = []
    for field in (forecast.u_east_m_s, forecast.v_north_m_s):
        block = field[t][:, rows][:, :, cols]  # (Z, nr, nc)
        nz = block.shape[0]
        vert = _vertical(block.reshape(nz, -1), depth, layers, forecast.covers_surface)
        vert = vert.reshape(layers.size, rows.size, cols.size)
        corners = [
            (wy0 * wx0, vert[:, ry0[:, None], cx0[None, :]]),
            (wy0 * wx1, vert[:, ry0[:, None], cx1[None, :]]),
            (wy1 * wx0, vert[:, ry1[:, None], cx0[None, :]]),
            (wy1 * wx1, vert[:, ry1[:, None], cx1[None, :]]),
        ]
        terms = [(np.broadcast_to(w, shape), val) for w, val in corners]
        out = _accumulate(terms)
        out[:, ~valid] = np.nan
        results.append(out)
    return results[0], results[1]


def _resample_curvilinear(forecast: Forecast, grid: Grid, t: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-column vertical interpolation, then barycentric weights on a Delaunay triangulation (spec section 1)."""
    lon = forecast.lon_deg
    _, n_z, _, _ = forecast.shape
    layers = grid.depth_m
    shape = (layers.size, grid.ny, grid.nx)
    lon_lo, lon_hi = float(np.nanmin(lon)), float(np.nanmax(lon))
    glon, glat = np.meshgrid(_shift_lon(grid.lon_deg, lon_lo, lon_hi), grid.lat_deg)
    nodes, weights, inside = _triangulation_weights(forecast, glon.ravel(), glat.ravel())

    if forecast.depth_m is None or forecast.depth_m.ndim == 1:
        depth = forecast.depth_m
    else:
        depth = forecast.depth_m[t].reshape(n_z, -1)
    results = []
    for field in (forecast.u_east_m_s, forecast.v_north_m_s):
        vert = _vertical(field[t].reshape(n_z, -1), depth, layers, forecast.covers_surface)  # (L, P)
        terms = [
            (np.broadcast_to(weights[:, c], (layers.size, weights.shape[0])), vert[:, nodes[:, c]]) for c in range(3)
        ]
        out = _accumulate(terms)
        out[:, ~inside] = np.nan
        results.append(out.reshape(shape))
    return results[0], results[1]


def _triangulation_weights(
    forecast: Forecast, qlon: NDArray[np.float64], qlat: NDArray[np.float64]
) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.bool_]]:
    """(flat source node indices (Q, 3), barycentric weights (Q, 3), inside hull (Q,)) for target points.

    The plane is lon * cos(mean lat), lat. Weights below 1e-9 are snapped to 0 and the rest
    renormalised, so a target on a source node or edge uses only that node or edge.
    """
    from scipy.spatial import ConvexHull, Delaunay, QhullError

    lon, lat = forecast.lon_deg, forecast.lat_deg
    ok = (np.isfinite(lon) & np.isfinite(lat)).ravel()
    index = np.flatnonzero(ok)
    scale = float(np.cos(np.radians(np.nanmean(lat))))
    points = np.column_stack([lon.ravel()[ok] * scale, lat.ravel()[ok]])
    q = np.column_stack([qlon * scale, qlat])
    try:
        tri = Delaunay(points)
        hull = ConvexHull(points)
    except QhullError as exc:
        raise ForecastError(
            f"{forecast.source}: cannot triangulate the forecast's 2-D lon/lat points ({exc}); expected a "
            "non-degenerate grid"
        ) from exc
    # Targets clearly outside the hull never reach Delaunay.find_simplex (its fallback there is a
    # brute-force search over every triangle).
    eq = hull.equations
    slack = 1e-9 * (1.0 + float(np.max(np.abs(points))))
    candidate = np.all(q @ eq[:, :2].T + eq[:, 2] <= slack, axis=1)
    simplex = np.full(q.shape[0], -1, dtype=np.intp)
    if np.any(candidate):
        simplex[candidate] = tri.find_simplex(q[candidate])
    inside = simplex >= 0
    verts = tri.simplices[np.where(inside, simplex, 0)]  # (Q, 3) into points
    a, b, c = points[verts[:, 0]], points[verts[:, 1]], points[verts[:, 2]]
    v0, v1, v2 = b - a, c - a, q - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        w1 = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
        w2 = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    w = np.column_stack([1.0 - w1 - w2, w1, w2])
    w = np.where(np.isfinite(w) & (w >= _BARY_SNAP), w, 0.0)
    total = w.sum(axis=1, keepdims=True)
    inside &= total[:, 0] > 0
    w = np.where(inside[:, None], w / np.where(total > 0, total, 1.0), 0.0)
    return index[verts], w, inside


# --------------------------------------------------------------------------------------
# Time lookup and description
# --------------------------------------------------------------------------------------
