"""Sampling the physical model's transitions: RK4 through the current, per cell and channel.

docs/physical-model.md gives the model; ``planner.physical.model`` turns the samples into the
transitions the solvers walk. A *channel* is one motion of a cell that does not depend on the
heading unless it says so: DRIFT, UP, DOWN, then FORWARD along each of the eight headings and
(with course offsets) FORWARD_LEFT and FORWARD_RIGHT along each. ROTATE holds station and needs
no sampling. The heading-free channels are therefore sampled once per cell and layer.

Outcomes are stored compactly, per (cell, channel), as a list of the outcome cells that any
sample ended in (a *slot*: the offset within +-2 cells), with the number of samples and their
largest energy (``planner.physical.outcomes``). Cells are sampled in blocks so the dense scratch
of one block is all the memory the sampling needs beyond its result and the currents (on the
fine grid, and per fine cell its four nodes' currents in one row: 64 bytes a fine cell).

Goal entry (a FORWARD or DRIFT sample ends on entering a goal cell) is kept apart: the goal-free
samples of the whole grid are computed once per forecast, and ``enter_goal`` samples again only
the cells from which a sample can reach a goal cell (within two cells of one), so a second goal
on the same forecast costs a small patch, not the grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import GridError
from planner.contract.geodesy import EARTH_RADIUS_M
from planner.contract.headings import N_HEADINGS, courses_deg
from planner.contract.progress import SILENT, Progress
from planner.contract.settings import PhysicalSettings, PlanSettings
from planner.contract.vehicle import power_draw_w
from planner.grid import Grid
from planner.physical.outcomes import SLOTS, compact, merge, splice

# Sample channels per cell: DRIFT, UP, DOWN, then FORWARD along each of the eight headings, then
# (with course offsets) FORWARD_LEFT and FORWARD_RIGHT along each (planner.contract.headings.courses_deg).
N_CHANNELS_BEARINGS = 3 + N_HEADINGS
N_CHANNELS_COURSES = 3 + 3 * N_HEADINGS
GOAL_REACH_CELLS = 2  # a sample ends within 1.5 cells of its cell's centre: goal entry changes cells this near
_CHUNK = 32  # (cell, channel) pairs a parallel task samples with one set of scratch arrays
_BLOCK_CELLS = 8192  # cells sampled per block: the dense scratch is about 5 MB per 1,000 cells


def transition_limit_s(grid: Grid, settings: PlanSettings) -> float:
    """``max_transition_s``, or by default the time for four crossings of the largest cell at cruise
    speed: long enough that a vehicle under way always leaves its cell in still water."""
    given = settings.physical.max_transition_s
    if given is not None:
        return float(given)
    dx_m, dy_m = grid.cell_size_m()
    return 4.0 * max(float(np.max(dx_m)), dy_m) / settings.vehicle.cruise_speed_m_s


def member_offsets_m_s(settings: PhysicalSettings) -> NDArray[np.float64]:
    """(east, north) current offsets of the forecast-error members, the forecast's own (0, 0) first.

    ``error_members`` offsets of radius rho in evenly spaced directions: over the members and the
    forecast, each component's variance is ``M / (M + 1) * rho^2 / 2``, set equal to
    ``current_error_m_s^2``.
    """
    m = settings.error_members
    out = np.zeros((m + 1, 2))
    if m:
        rho = settings.current_error_m_s * math.sqrt(2.0 * (m + 1) / m)
        angle = 2.0 * np.pi * np.arange(m) / m
        out[1:, 0] = rho * np.cos(angle)
        out[1:, 1] = rho * np.sin(angle)
    return out


def start_offsets(settings: PhysicalSettings) -> NDArray[np.float64]:
    """(di, dj) of the start points in cells: an S x S lattice at the centres of equal sub-cells."""
    s = settings.start_points
    a = (np.arange(s) + 0.5) / s - 0.5
    di, dj = np.meshgrid(a, a, indexing="xy")
    return np.column_stack([di.ravel(), dj.ravel()])


@dataclass(frozen=True, eq=False, kw_only=True)
class SampleStats:
    """What the samples of one forecast member (or several, combined) say, per cell and channel.

    Cells are ``(l * ny + j) * nx + i``; a channel ``q = cell * n_channels + channel``. Per
    channel: ``hazard`` (a sample touched land or left the grid: the action is unavailable),
    the sums of the samples' energy ``esum`` (Wh) and duration ``tsum`` (s), and its outcomes
    ``ptr[q]:ptr[q + 1]`` into ``slot`` (int8, ascending), ``count`` and ``emax`` (the largest
    energy of the samples that ended there, Wh). Also the planning-grid currents ``u``/``v``
    (L, ny, nx; NaN = land) and the ROTATE energy ``rot_wh`` (L, ny, nx). Plain arrays: a Dask
    worker returns one per member.
    """

    n_channels: int
    hazard: NDArray[np.bool_]  # (cells, channels)
    esum: NDArray[np.float64]
    tsum: NDArray[np.float64]
    ptr: NDArray[np.int64]  # (cells * channels + 1,)
    slot: NDArray[np.int8]
    count: NDArray[np.int32]
    emax: NDArray[np.float64]
    n_samples: int
    u: NDArray[np.float64]
    v: NDArray[np.float64]
    rot_wh: NDArray[np.float64]
    members: int = 1

    @property
    def n_outcomes(self) -> int:
        return int(self.slot.size)

    def dense(self) -> tuple[NDArray[np.int32], NDArray[np.float64]]:
        """``count`` and ``emax`` as (cells, channels, 25) arrays (for tests and small grids)."""
        cells = self.hazard.shape[0]
        count = np.zeros((cells * self.n_channels, SLOTS), dtype=np.int32)
        emax = np.zeros((cells * self.n_channels, SLOTS))
        q = np.repeat(np.arange(cells * self.n_channels), np.diff(self.ptr))
        count[q, self.slot] = self.count
        emax[q, self.slot] = self.emax
        return count.reshape(cells, self.n_channels, SLOTS), emax.reshape(cells, self.n_channels, SLOTS)


@dataclass(frozen=True, eq=False, kw_only=True)
class _Kernel:
    """The arguments the sampling kernel shares between the whole grid and a goal patch."""

    uf: NDArray[np.float64]
    vf: NDArray[np.float64]
    corners: NDArray[np.float64]  # per fine cell: its four nodes' u, then v (64 bytes a row)
    wet: NDArray[np.bool_]
    water: NDArray[np.bool_]
    refine: int
    lat0: float
    dlat: float
    dlon_rad: float
    dy_m: float
    depth_m: NDArray[np.float64]
    course_rad: NDArray[np.float64]
    offsets: NDArray[np.float64]
    members: NDArray[np.float64]
    speed: float
    glide_rate: float
    t_max: float
    rk4_steps: int
    powers: NDArray[np.float64]
    n_channels: int

    def run(self, cells: NDArray[np.int64], goal: NDArray[np.bool_]) -> tuple[NDArray, ...]:
        """Dense samples of ``cells``: hazard, esum, tsum (n, channels), count and emax (n, channels, 25)."""
        n = cells.size
        count = np.zeros((n, self.n_channels, SLOTS), dtype=np.int32)
        emax = np.zeros((n, self.n_channels, SLOTS))
        esum = np.zeros((n, self.n_channels))
        tsum = np.zeros((n, self.n_channels))
        hazard = np.zeros((n, self.n_channels), dtype=np.bool_)
        # numba compiles (and loads from its cache) one kernel per signature, and a read-only array is another
        # type: a goal mask that arrives read-only would cost a second compile of the kernel, and every plan
        # a second load of it.
        goal = np.require(goal, dtype=np.bool_, requirements=["C", "W"])
        _sample_cells(cells, self.uf, self.vf, self.corners, self.wet, self.water, goal, self.refine, self.lat0,
                      self.dlat, self.dlon_rad, self.dy_m, self.depth_m, self.course_rad, self.offsets, self.members,
                      self.speed, self.glide_rate, self.t_max, self.rk4_steps, self.powers, count, emax, esum, tsum, hazard)
        return hazard, esum, tsum, count, emax


def _kernel(u_fine_m_s: NDArray[np.float64], v_fine_m_s: NDArray[np.float64], grid: Grid, settings: PlanSettings,
            refine: int) -> tuple[_Kernel, NDArray[np.float64], NDArray[np.float64]]:
    L, ny, nx = grid.n_layers, grid.ny, grid.nx
    shape_f = (L, (ny - 1) * refine + 1, (nx - 1) * refine + 1)
    uf = np.ascontiguousarray(u_fine_m_s, dtype=np.float64)
    vf = np.ascontiguousarray(v_fine_m_s, dtype=np.float64)
    if uf.shape != shape_f or vf.shape != shape_f:
        raise GridError(f"currents: expected shape {shape_f} on the refined grid; got {uf.shape} and {vf.shape}")
    u = np.ascontiguousarray(uf[:, ::refine, ::refine])
    v = np.ascontiguousarray(vf[:, ::refine, ::refine])
    finite = np.isfinite(uf) & np.isfinite(vf)
    # A fine cell whose four nodes are all water: interpolation there needs no land check.
    wet = np.ascontiguousarray(finite[:, :-1, :-1] & finite[:, 1:, :-1] & finite[:, :-1, 1:] & finite[:, 1:, 1:])
    ps, vp = settings.physical, settings.vehicle
    _dx_m, dy_m = grid.cell_size_m()
    powers = np.array([
        float(power_draw_w(vp, 0.0, False)),  # DRIFT
        float(power_draw_w(vp, 0.0, True)),  # UP / DOWN: no thrust, buoyancy engine
        float(power_draw_w(vp, vp.cruise_speed_m_s, False)),  # FORWARD
    ])
    kernel = _Kernel(
        uf=uf, vf=vf, corners=_corners(uf, vf), wet=wet, water=np.isfinite(u) & np.isfinite(v), refine=refine,
        lat0=float(grid.lat_deg[0]),
        dlat=grid.dlat_deg, dlon_rad=math.radians(grid.dlon_deg), dy_m=dy_m,
        depth_m=np.asarray(grid.depth_m, dtype=np.float64),
        course_rad=np.ascontiguousarray(np.radians(courses_deg(grid.bearings_deg()))),  # (ny, 8, 3), from north
        offsets=start_offsets(ps), members=member_offsets_m_s(ps), speed=vp.cruise_speed_m_s,
        glide_rate=vp.glide_rate_m_s, t_max=transition_limit_s(grid, settings), rk4_steps=ps.rk4_steps,
        powers=powers, n_channels=N_CHANNELS_COURSES if ps.course_offsets else N_CHANNELS_BEARINGS,
    )
    return kernel, u, v


def _corners(uf: NDArray[np.float64], vf: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per fine cell (layer, row, column, flattened): u at its (0, 0), (0, 1), (1, 0), (1, 1) nodes, then v:
    one 64-byte row where the nodes' values lie in two rows of each of two arrays."""
    parts = [f[:, dy:f.shape[1] - 1 + dy, dx:f.shape[2] - 1 + dx] for f in (uf, vf) for dy in (0, 1) for dx in (0, 1)]
    return np.ascontiguousarray(np.stack(parts, axis=-1).reshape(-1, 8))


def sample_transitions(
    u_fine_m_s: NDArray[np.float64], v_fine_m_s: NDArray[np.float64], grid: Grid, settings: PlanSettings, *, refine: int,
    goal_mask: NDArray[np.bool_] | None = None, meter: Progress = SILENT,
) -> SampleStats:
    """Sample every water cell's channels in one forecast member; currents on ``fine_grid(grid, refine)``.

    ``meter`` hears the water cells sampled, block by block (``planner.contract.progress``).

    ``goal_mask`` (L, ny, nx): a FORWARD or DRIFT sample that enters a goal cell ends there, when
    it enters, as a vehicle arrives on entering the goal cells (not a cell spacing later). Without
    it the samples are goal-free; ``enter_goal`` adds a goal to them.
    """
    kernel, u, v = _kernel(u_fine_m_s, v_fine_m_s, grid, settings, refine)
    no_goal = np.zeros(kernel.water.shape, dtype=np.bool_)
    cells = np.flatnonzero(kernel.water.ravel()).astype(np.int64)
    n_cells = kernel.water.size
    n_ch = kernel.n_channels
    hazard = np.ones((n_cells, n_ch), dtype=np.bool_)  # land: nothing is available
    esum = np.zeros((n_cells, n_ch))
    tsum = np.zeros((n_cells, n_ch))
    n_out = np.zeros(n_cells * n_ch, dtype=np.int64)
    parts: list[tuple[NDArray, NDArray, NDArray]] = []
    meter.update("sampling", 0, cells.size, unit="cells")
    for lo in range(0, cells.size, _BLOCK_CELLS):
        block = cells[lo:lo + _BLOCK_CELLS]
        h, es, ts, count, emax = kernel.run(block, no_goal)
        hazard[block], esum[block], tsum[block] = h, es, ts
        parts.append(compact(block, n_ch, h, count, emax, n_out))
        meter.update("sampling", lo + block.size, cells.size, unit="cells")
    ptr = np.zeros(n_cells * n_ch + 1, dtype=np.int64)
    np.cumsum(n_out, out=ptr[1:])
    slot = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int8)
    count = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0, np.int32)
    emax = np.concatenate([p[2] for p in parts]) if parts else np.zeros(0)
    stats = SampleStats(n_channels=n_ch, hazard=hazard, esum=esum, tsum=tsum, ptr=ptr, slot=slot, count=count,
                        emax=emax, n_samples=kernel.offsets.shape[0] * kernel.members.shape[0], u=u, v=v,
                        rot_wh=_rotate_wh(u, v, settings))
    if goal_mask is not None and np.any(goal_mask):
        stats = _patch(stats, kernel, np.ascontiguousarray(goal_mask, dtype=np.bool_))
    return stats


def enter_goal(stats: SampleStats, u_fine_m_s: NDArray[np.float64], v_fine_m_s: NDArray[np.float64], grid: Grid,
               settings: PlanSettings, *, refine: int, goal_mask: NDArray[np.bool_]) -> SampleStats:
    """Goal-free ``stats`` of one member with the goal ``goal_mask`` entered: the cells within
    ``GOAL_REACH_CELLS`` of a goal cell sampled again with it, the rest kept."""
    if stats.members != 1:
        raise GridError("enter_goal: the goal is entered per forecast member, before members are combined")
    kernel, _u, _v = _kernel(u_fine_m_s, v_fine_m_s, grid, settings, refine)
    if kernel.n_channels != stats.n_channels:
        raise GridError("enter_goal: the samples were taken with other settings")
    return _patch(stats, kernel, np.ascontiguousarray(goal_mask, dtype=np.bool_)) if np.any(goal_mask) else stats


def goal_reach(goal_mask: NDArray[np.bool_], water: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Water cells from which a FORWARD or DRIFT sample can enter a goal cell of its own layer."""
    L, ny, nx = goal_mask.shape
    r = GOAL_REACH_CELLS
    near = np.zeros((L, ny + 2 * r, nx + 2 * r), dtype=bool)
    for dj in range(-r, r + 1):
        for di in range(-r, r + 1):
            near[:, r + dj:r + dj + ny, r + di:r + di + nx] |= goal_mask
    return near[:, r:r + ny, r:r + nx] & water


def _patch(stats: SampleStats, kernel: _Kernel, goal: NDArray[np.bool_]) -> SampleStats:
    cells = np.flatnonzero(goal_reach(goal, kernel.water).ravel()).astype(np.int64)
    n_ch = stats.n_channels
    h, es, ts, count, emax = kernel.run(cells, goal)
    hazard, esum, tsum = stats.hazard.copy(), stats.esum.copy(), stats.tsum.copy()
    hazard[cells], esum[cells], tsum[cells] = h, es, ts
    n_out = np.diff(stats.ptr)
    slot_p, count_p, emax_p = compact(cells, n_ch, h, count, emax, n_out)
    ptr = np.zeros_like(stats.ptr)
    np.cumsum(n_out, out=ptr[1:])
    slot, cnt, em = splice(stats.ptr, stats.slot, stats.count, stats.emax, ptr, cells, n_ch, slot_p, count_p, emax_p)
    return SampleStats(n_channels=n_ch, hazard=hazard, esum=esum, tsum=tsum, ptr=ptr, slot=slot, count=cnt, emax=em,
                       n_samples=stats.n_samples, u=stats.u, v=stats.v, rot_wh=stats.rot_wh, members=stats.members)


def _rotate_wh(u: NDArray[np.float64], v: NDArray[np.float64], settings: PlanSettings) -> NDArray[np.float64]:
    """ROTATE holds station for 45 degrees of turn: water speed = the current's, up to the maximum."""
    vp = settings.vehicle
    rot_s = 45.0 / vp.yaw_rate_deg_s
    speed = np.minimum(np.hypot(np.nan_to_num(u), np.nan_to_num(v)), vp.max_speed_m_s)
    return np.ascontiguousarray(power_draw_w(vp, speed, False) * rot_s / 3600.0, dtype=np.float64)


def combine(stats: list[SampleStats]) -> SampleStats:
    """Forecast members as outcomes: every member's samples together (docs/scale-out.md).

    The worst case is then over all members' samples and the expected cost averages the members
    (each has as many samples). A cell is water only where every member has water. Summed in
    member order, so the result does not depend on where the members were sampled.
    """
    if not stats:
        raise GridError("an ensemble needs at least one member")
    first = stats[0]
    if len(stats) == 1:
        return first
    shapes = {s.hazard.shape for s in stats}
    if len(shapes) != 1 or len({s.n_samples for s in stats}) != 1:
        raise GridError(f"ensemble members sampled on different grids or settings: {sorted(shapes)}")
    out = first
    u, v = first.u.copy(), first.v.copy()
    rot = first.rot_wh.copy()
    for s in stats[1:]:
        ptr, slot, count, emax = merge(out.ptr, out.slot, out.count, out.emax, s.ptr, s.slot, s.count, s.emax)
        land = ~(np.isfinite(s.u) & np.isfinite(s.v))
        u[land] = np.nan
        v[land] = np.nan
        rot = np.maximum(rot, s.rot_wh)
        out = SampleStats(n_channels=out.n_channels, hazard=out.hazard | s.hazard, esum=out.esum + s.esum,
                          tsum=out.tsum + s.tsum, ptr=ptr, slot=slot, count=count, emax=emax,
                          n_samples=out.n_samples + s.n_samples, u=u, v=v, rot_wh=rot,
                          members=out.members + s.members)
    return out


# --------------------------------------------------------------------------- compiled kernels

# Shorthands for the kernels' array arguments.
_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_Mask = NDArray[np.bool_]


@numba.njit(cache=True, nogil=True)
def _interp_slow(f: _F64, l: int, X: float, Y: float) -> float:  # pragma: no cover - compiled
    """Bilinear value of layer ``l`` at fine-grid index point (X, Y), clamped to the grid; NaN when a
    node with non-zero weight is land."""
    nyf, nxf = f.shape[1], f.shape[2]
    X = min(max(X, 0.0), nxf - 1.0)
    Y = min(max(Y, 0.0), nyf - 1.0)
    x0 = min(int(X), nxf - 2)
    y0 = min(int(Y), nyf - 2)
    fx = X - x0
    fy = Y - y0
    total = 0.0
    for dy in range(2):
        wy = fy if dy else 1.0 - fy
        if wy == 0.0:
            continue
        for dx in range(2):
            wx = fx if dx else 1.0 - fx
            if wx == 0.0:
                continue
            total += wx * wy * f[l, y0 + dy, x0 + dx]  # NaN propagates: land
    return total


@numba.njit(cache=True, nogil=True, inline="always")
def _corner_sum(  # pragma: no cover
    corners: _F64, k: int, w00: float, w01: float, w10: float, w11: float,
) -> tuple[float, float]:
    """(u, v) of fine cell ``k`` (its row of ``corners``) with the bilinear weights of its four nodes."""
    cu = w00 * corners[k, 0] + w01 * corners[k, 1] + w10 * corners[k, 2] + w11 * corners[k, 3]
    cv = w00 * corners[k, 4] + w01 * corners[k, 5] + w10 * corners[k, 6] + w11 * corners[k, 7]
    return cu, cv


@numba.njit(cache=True, nogil=True, inline="always")
def _current(  # pragma: no cover
    uf: _F64, vf: _F64, corners: _F64, wet: _Mask, l: int, X: float, Y: float,
) -> tuple[float, float]:
    """(u, v) of layer ``l`` at fine-grid index point (X, Y): inside a fine cell of four water nodes,
    both components with one set of weights (the same sums, in the same order, as ``_interp_slow``);
    elsewhere the clamped, land-checking path; NaN at a NaN point."""
    if X >= 0.0 and Y >= 0.0 and X < wet.shape[2] and Y < wet.shape[1] and wet[l, int(Y), int(X)]:  # NaN fails each test
        x0 = int(X)
        y0 = int(Y)
        fx = X - x0
        fy = Y - y0
        w00 = (1.0 - fx) * (1.0 - fy)
        w01 = fx * (1.0 - fy)
        w10 = (1.0 - fx) * fy
        w11 = fx * fy
        return _corner_sum(corners, (l * wet.shape[1] + y0) * wet.shape[2] + x0, w00, w01, w10, w11)
    if not (math.isfinite(X) and math.isfinite(Y)):
        return math.nan, math.nan  # a point from a stage that touched land
    return _interp_slow(uf, l, X, Y), _interp_slow(vf, l, X, Y)


# Below it, cos d to d^4 and sin d to d^3 leave under 1e-17 (d^6 / 720 and d^5 / 120): three rows of
# the demo's 0.01-degree grid are 5e-4 rad, so the short series is the one that runs.
_SHORT_SERIES_RAD = 1e-3


@numba.njit(cache=True, nogil=True, inline="always")
def _cos_near(cos_a: float, sin_a: float, d: float) -> float:  # pragma: no cover
    """cos(a + d) from cos a and sin a, for |d| up to a few planning rows (0.05 rad on 1-degree rows):
    the series of cos d and sin d to d^8 and d^9 leave less than 1e-19, below double rounding, and
    cost a few multiplications where a libm cos per current evaluation was a third of the sampling.
    ``_stage`` calls it only at or above ``_SHORT_SERIES_RAD``; below, it uses the short series."""
    d2 = d * d
    cos_d = 1.0 - d2 * (1.0 / 2.0) * (1.0 - d2 * (1.0 / 12.0) * (1.0 - d2 * (1.0 / 30.0) * (1.0 - d2 * (1.0 / 56.0))))
    sin_d = d * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0) * (1.0 - d2 * (1.0 / 42.0) * (1.0 - d2 * (1.0 / 72.0)))))
    return cos_a * cos_d - sin_a * sin_d


@numba.njit(cache=True, nogil=True, inline="always")
def _nearest(x: float) -> int:  # pragma: no cover
    """Nearest index, halves going to the lower one (as ``Grid.nearest_cell``)."""
    return int(math.ceil(x - 0.5))


# Rows of the kernel's per-sample scratch: the step, position, time, through-water velocity, glide
# weight, a stage's point, each stage's (dx/dt, dy/dt), a stage's current, metric and bilinear
# weights, the start point, whether the last step was plain (``_plain_steps``), and from ``_C0`` on
# the eight corner currents of the fine cell the row read last (``kc`` says which; ``_stage``).
_H, _X, _Y, _T, _WE, _WN, _W, _PX, _PY = range(9)
_K1, _K2, _K3, _K4 = 9, 11, 13, 15
_CU, _CV, _DXM, _W00, _W01, _W10, _W11 = 17, 18, 19, 20, 21, 22, 23
_X0, _Y0, _OK = 24, 25, 26
_C0 = 27
_ROWS = _C0 + 8


@numba.njit(cache=True, nogil=True, inline="always")
def _stage(  # pragma: no cover
    work: _F64, kidx: _I64, kc: _I64, na: int, rx: int, ry: int, rk: int, uf: _F64, vf: _F64, corners: _F64,
    wet: _Mask, wet_flat: _Mask, refine: int, la: int, lb: int, j: int, cos_j: float, sin_j: float, dlat_rad: float,
    dlon_rad: float, dy_m: float,
) -> None:
    """(dx/dt, dy/dt) in planning cells per second of the ``na`` running samples at the planning-index
    points in rows ``rx``, ``ry``, into rows ``rk`` and ``rk + 1``; NaN on land.

    Over ground = through water (rows ``_WE``, ``_WN``, m/s, members' offsets included) + the current
    of layer ``la`` blended with ``lb`` by the weight in row ``_W`` (glides); a stage after one on
    land is NaN too. In straight loops that LLVM vectorises: the metric at each point's latitude (spec
    section 1); each point's fine cell (``kidx``: its row of ``corners``, -1 outside the fine grid) and
    bilinear weights; the current; the velocity. A running row keeps the corners of the fine cell it
    read last (rows ``_C0`` on, its cell in ``kc``): a sample takes several stages to cross a fine
    cell, so only a row whose cell changed reads ``corners``, one at a time, and the sums run over
    the rows. A cell with land among its nodes, or a point outside, takes ``_current``'s
    land-checking path, with the same sums; so do glides, which blend two layers (``_blended``).
    ``cos_j``, ``sin_j``: of row ``j``'s latitude, which the points are within a few rows of;
    ``wet_flat``: ``wet`` flattened, indexed like ``corners``."""
    far = 0
    for n in range(na):
        d = (work[ry, n] - j) * dlat_rad
        d2 = d * d
        work[_DXM, n] = EARTH_RADIUS_M * (cos_j * (1.0 - d2 * (0.5 - d2 * (1.0 / 24.0)))
                                          - sin_j * (d * (1.0 - d2 * (1.0 / 6.0)))) * dlon_rad
        far += abs(d) >= _SHORT_SERIES_RAD
    if far:
        for n in range(na):
            d = (work[ry, n] - j) * dlat_rad
            if abs(d) >= _SHORT_SERIES_RAD:
                work[_DXM, n] = EARTH_RADIUS_M * _cos_near(cos_j, sin_j, d) * dlon_rad
    nyw = wet.shape[1]
    nxw = wet.shape[2]
    for n in range(na):
        X = work[rx, n] * refine
        Y = work[ry, n] * refine
        inside = (X >= 0.0) & (Y >= 0.0) & (X < nxw) & (Y < nyw)  # NaN fails each test
        xc = X if inside else 0.0
        yc = Y if inside else 0.0
        x0 = int(xc)
        y0 = int(yc)
        fx = xc - x0
        fy = yc - y0
        work[_W00, n] = (1.0 - fx) * (1.0 - fy)
        work[_W01, n] = fx * (1.0 - fy)
        work[_W10, n] = (1.0 - fx) * fy
        work[_W11, n] = fx * fy
        kidx[n] = (la * nyw + y0) * nxw + x0 if inside else -1
    step_l = (lb - la) * nyw * nxw
    if la == lb:
        slow = 0  # rows whose cell has land among its nodes, or is outside: _current's path
        miss = 0
        for n in range(na):
            miss += kidx[n] != kc[n]
        for n in range(na if miss else 0):  # a row's cell changed: read its corners
            k = kidx[n]
            if k != kc[n]:
                if k >= 0 and wet_flat[k]:
                    for m in range(8):
                        work[_C0 + m, n] = corners[k, m]
                    kc[n] = k
                else:
                    slow += 1
        for n in range(na):
            w00 = work[_W00, n]
            w01 = work[_W01, n]
            w10 = work[_W10, n]
            w11 = work[_W11, n]
            work[_CU, n] = (w00 * work[_C0, n] + w01 * work[_C0 + 1, n] + w10 * work[_C0 + 2, n]
                            + w11 * work[_C0 + 3, n])
            work[_CV, n] = (w00 * work[_C0 + 4, n] + w01 * work[_C0 + 5, n] + w10 * work[_C0 + 6, n]
                            + w11 * work[_C0 + 7, n])
        if slow:
            for n in range(na):
                if kidx[n] != kc[n]:  # kc only ever holds a cell of four water nodes
                    work[_CU, n], work[_CV, n] = _current(uf, vf, corners, wet, la, work[rx, n] * refine,
                                                          work[ry, n] * refine)
    else:
        _blended(work, kidx, na, rx, ry, uf, vf, corners, wet, wet_flat, refine, la, lb, step_l)
    for n in range(na):
        work[rk, n] = (work[_CU, n] + work[_WE, n]) / work[_DXM, n]
        work[rk + 1, n] = (work[_CV, n] + work[_WN, n]) / dy_m


@numba.njit(cache=True, nogil=True, inline="always")
def _blended(  # pragma: no cover
    work: _F64, kidx: _I64, na: int, rx: int, ry: int, uf: _F64, vf: _F64, corners: _F64, wet: _Mask,
    wet_flat: _Mask, refine: int, la: int, lb: int, step_l: int,
) -> None:
    """Rows ``_CU``, ``_CV``: the current of layer ``la`` blended with ``lb`` by the weight in row ``_W``
    (a glide), one point at a time from ``corners``, or ``_current``'s land-checking path."""
    for n in range(na):
        k = kidx[n]
        w00 = work[_W00, n]
        w01 = work[_W01, n]
        w10 = work[_W10, n]
        w11 = work[_W11, n]
        if k >= 0 and wet_flat[k]:
            cu, cv = _corner_sum(corners, k, w00, w01, w10, w11)
        else:
            cu, cv = _current(uf, vf, corners, wet, la, work[rx, n] * refine, work[ry, n] * refine)
        wb = work[_W, n]
        if wb > 0.0:
            kb = k + step_l
            if k >= 0 and wet_flat[kb]:
                bu, bv = _corner_sum(corners, kb, w00, w01, w10, w11)
            else:
                bu, bv = _current(uf, vf, corners, wet, lb, work[rx, n] * refine, work[ry, n] * refine)
            cu = (1.0 - wb) * cu + wb * bu
            cv = (1.0 - wb) * cv + wb * bv
        work[_CU, n] = cu
        work[_CV, n] = cv


@numba.njit(cache=True, nogil=True, inline="always")
def _next_point(work: _F64, na: int, rk: int, frac: float, glide_s: float) -> None:  # pragma: no cover
    """The next RK4 stage's points (rows ``_PX``, ``_PY``): ``frac`` of the step along the slope in
    rows ``rk``, ``rk + 1``; with a glide (``glide_s`` > 0), the layers' weight at that time too."""
    for n in range(na):
        hh = work[_H, n]
        work[_PX, n] = work[_X, n] + frac * hh * work[rk, n]
        work[_PY, n] = work[_Y, n] + frac * hh * work[rk + 1, n]
    if glide_s > 0.0:
        for n in range(na):
            work[_W, n] = (work[_T, n] + frac * work[_H, n]) / glide_s


@numba.njit(cache=True, nogil=True, inline="always")
def _plain_steps(  # pragma: no cover
    work: _F64, na: int, gliding: bool, seeking: bool, end: float, nx: int, ny: int,
) -> None:
    """Row ``_OK``: 1 where the RK4 step just taken (to rows ``_PX``, ``_PY``) leaves the sample running
    with nothing for ``_finish`` to decide (no land, still within one spacing of its start, within the
    grid and the time limit, no goal to enter), else 0; in a straight loop, so it vectorises."""
    if seeking:
        for n in range(na):
            work[_OK, n] = 0.0
        return
    for n in range(na):
        xn = work[_PX, n]
        yn = work[_PY, n]
        ok = ((xn >= -0.5) & (xn <= nx - 0.5) & (yn >= -0.5) & (yn <= ny - 0.5)  # NaN (land) fails each test
              & (work[_T, n] + work[_H, n] < end - 1e-9))
        if not gliding:
            ok = ok & (abs(xn - work[_X0, n]) < 1.0) & (abs(yn - work[_Y0, n]) < 1.0)
        work[_OK, n] = 1.0 if ok else 0.0


# A sample's state between RK4 steps.
_RUNNING, _DONE, _FAILED = 0, 1, 2


@numba.njit(cache=True, nogil=True, inline="always")
def _finish(  # pragma: no cover
    goal: _Mask, seeks: bool, la: int, gliding: bool, x0: float, y0: float, x: float, y: float, t: float, hh: float,
    xn: float, yn: float, end: float, nx: int, ny: int,
) -> tuple[int, float, float, float]:
    """End one RK4 step of a sample from (x, y) at time t to (xn, yn) over ``hh``: (state, x, y, t);
    ``seeks``: whether there is a goal to enter (goal-free samples skip the test).

    A glide lasts exactly ``end``; a move until one cell spacing from the start (x0, y0) along
    either axis, entering a goal cell of layer ``la`` (``goal``), or ``end``. Crossings are
    placed on the RK4 step's chord. The sample fails where a stage touched land or it leaves the grid.
    """
    if not (math.isfinite(xn) and math.isfinite(yn)):
        return _FAILED, x, y, t  # a stage touched land
    tau = 1.0  # the step's fraction at which the one-spacing box is left
    if not gliding and (abs(xn - x0) >= 1.0 or abs(yn - y0) >= 1.0):
        if abs(xn - x0) >= 1.0:
            tau = min(tau, (x0 + math.copysign(1.0, xn - x0) - x) / (xn - x))
        if abs(yn - y0) >= 1.0:
            tau = min(tau, (y0 + math.copysign(1.0, yn - y0) - y) / (yn - y))
        xn = x + tau * (xn - x)
        yn = y + tau * (yn - y)
    if seeks and not gliding:
        gi = _nearest(xn)
        gj = _nearest(yn)
        if 0 <= gi < nx and 0 <= gj < ny and goal[la, gj, gi] and not goal[la, _nearest(y), _nearest(x)]:
            enter = 0.0  # the chord's fraction at which it enters that goal cell
            if abs(x - gi) > 0.5:
                edge = gi - 0.5 if xn > x else gi + 0.5
                enter = max(enter, (edge - x) / (xn - x))
            if abs(y - gj) > 0.5:
                edge = gj - 0.5 if yn > y else gj + 0.5
                enter = max(enter, (edge - y) / (yn - y))
            enter = min(enter + 1e-6, 1.0)  # just inside: a point on the edge belongs to the lower cell
            return _DONE, x + enter * (xn - x), y + enter * (yn - y), t + enter * tau * hh
    if tau < 1.0:
        t = t + tau * hh
        state = _DONE
    else:
        t += hh
        state = _RUNNING if t < end - 1e-9 else _DONE
    if xn < -0.5 or xn > nx - 0.5 or yn < -0.5 or yn > ny - 0.5:
        return _FAILED, xn, yn, t  # left the grid
    return state, xn, yn, t


# Fused multiply-adds and reciprocals where LLVM likes (about a fifth faster; energies move by
# 1e-13 Wh), but never the flags that assume no NaN or infinity: NaN is how land shows.
@numba.njit(cache=True, parallel=True, fastmath={"contract", "arcp", "nsz", "afn"})
def _sample_cells(  # pragma: no cover
    cells: _I64, uf: _F64, vf: _F64, corners: _F64, wet: _Mask, water: _Mask, goal: _Mask, refine: int, lat0: float,
    dlat: float, dlon_rad: float, dy_m: float, depth_m: _F64, course_rad: _F64, offsets: _F64, members: _F64,
    speed: float, glide_rate: float, t_max: float, rk4_steps: int, powers: _F64,
    count: NDArray[np.int32], emax: _F64, esum: _F64, tsum: _F64, hazard: _Mask,
) -> None:
    """Sample every channel of ``cells`` (water cells); row ``r`` of the outputs is ``cells[r]``."""
    L, ny, nx = water.shape
    n_off = offsets.shape[0]
    n_mem = members.shape[0]
    n_ch = count.shape[1]
    n_q = n_off * n_mem
    n_rc = cells.size * n_ch
    n_chunks = (n_rc + _CHUNK - 1) // _CHUNK
    wet_flat = wet.reshape(wet.size)
    seeks = bool(goal.any())  # goal-free samples (the whole grid's) skip the goal test
    # Parallel over chunks of _CHUNK (cell, channel) pairs, not over cells: a goal's patch of a few
    # cells still gives every core work; each chunk allocates its scratch once.
    for chunk in numba.prange(n_chunks):
        xs = np.empty(n_q)
        ys = np.empty(n_q)
        ts = np.empty(n_q)
        act = np.empty(n_q, dtype=np.int64)
        kidx = np.empty(n_q, dtype=np.int64)
        kc = np.full(n_q, -2, dtype=np.int64)  # no cell's corners in the rows yet (-1 is outside)
        work = np.empty((_ROWS, n_q))  # per running sample, a row each (the _H ... names)
        for rc in range(chunk * _CHUNK, min(n_rc, (chunk + 1) * _CHUNK)):
            r = rc // n_ch
            ch = rc % n_ch
            c = cells[r]
            l = c // (ny * nx)
            j = (c // nx) % ny
            i = c % nx
            lat = lat0 + j * dlat
            dlat_rad = math.radians(dlat)
            cos_j = math.cos(math.radians(lat))
            sin_j = math.sin(math.radians(lat))
            dx_m = EARTH_RADIUS_M * cos_j * dlon_rad
            cell_m = min(dx_m, dy_m)
            cu, cv = _current(uf, vf, corners, wet, l, i * refine, j * refine)
            cur = math.hypot(cu, cv)
            lb = l
            glide_s = 0.0
            we = 0.0
            wn = 0.0
            if ch == 1 or ch == 2:
                lb = l - 1 if ch == 1 else l + 1
                if lb < 0 or lb >= L or not water[lb, j, i]:
                    hazard[r, ch] = True
                    continue
                glide_s = abs(depth_m[lb] - depth_m[l]) / glide_rate
                power = powers[1]
                h = glide_s / rk4_steps
            else:
                power = powers[0]
                v_water = 0.0
                if ch >= 3:
                    b = course_rad[j, (ch - 3) % 8, (ch - 3) // 8]
                    we = speed * math.sin(b)
                    wn = speed * math.cos(b)
                    power = powers[2]
                    v_water = speed
                h = min(t_max, cell_m / max(v_water + cur, 1e-3)) / rk4_steps
            # All samples of the channel advance together, one RK4 stage of every running sample at a
            # time: the samples are independent, so the core overlaps them instead of waiting on one
            # sample's chain of stages (each needs the one before).
            gliding = glide_s > 0.0
            end = glide_s if gliding else t_max
            # The running samples' state lives in rows 0 .. na - 1 of ``work`` (``act`` says whose), so each
            # stage's arithmetic is straight loops over contiguous rows (vectorised); only a new fine cell's
            # corners are read one by one. A sample that ends leaves its row to the last running one. The
            # four stages run in a loop, not four inlined copies: as fast, and compiled in a third of the time.
            for q in range(n_q):
                x = i + offsets[q // n_mem, 0]
                y = j + offsets[q // n_mem, 1]
                xs[q] = x
                ys[q] = y
                ts[q] = 0.0
                act[q] = q
                work[_X, q] = x
                work[_Y, q] = y
                work[_T, q] = 0.0
                work[_X0, q] = x
                work[_Y0, q] = y
                work[_WE, q] = we + members[q % n_mem, 0]
                work[_WN, q] = wn + members[q % n_mem, 1]
            na = n_q if 0.0 < end - 1e-9 else 0
            while na > 0:
                for n in range(na):
                    work[_H, n] = min(h, end - work[_T, n])
                    work[_W, n] = work[_T, n] / glide_s if gliding else 0.0
                for st in range(4):  # RK4's stages: k1 at the point, k2 and k3 half a step on, k4 a step on
                    rk = _K1 + 2 * st
                    _stage(work, kidx, kc, na, _X if st == 0 else _PX, _Y if st == 0 else _PY, rk, uf, vf, corners,
                           wet, wet_flat, refine, l, lb, j, cos_j, sin_j, dlat_rad, dlon_rad, dy_m)
                    if st < 3:
                        _next_point(work, na, rk, 1.0 if st == 2 else 0.5, glide_s)
                for n in range(na):
                    hh = work[_H, n]
                    work[_PX, n] = work[_X, n] + hh / 6.0 * (work[_K1, n] + 2.0 * work[_K2, n] + 2.0 * work[_K3, n]
                                                             + work[_K4, n])
                    work[_PY, n] = work[_Y, n] + hh / 6.0 * (work[_K1 + 1, n] + 2.0 * work[_K2 + 1, n]
                                                             + 2.0 * work[_K3 + 1, n] + work[_K4 + 1, n])
                _plain_steps(work, na, gliding, seeks and not gliding, end, nx, ny)
                plain = 0
                for n in range(na):
                    ok = work[_OK, n] != 0.0
                    plain += ok
                    work[_X, n] = work[_PX, n] if ok else work[_X, n]
                    work[_Y, n] = work[_PY, n] if ok else work[_Y, n]
                    work[_T, n] = work[_T, n] + work[_H, n] if ok else work[_T, n]
                if plain == na:
                    continue
                ended = 0
                for n in range(na):
                    if work[_OK, n] != 0.0:
                        continue
                    st, work[_X, n], work[_Y, n], work[_T, n] = _finish(
                        goal, seeks, l, gliding, work[_X0, n], work[_Y0, n], work[_X, n], work[_Y, n], work[_T, n],
                        work[_H, n], work[_PX, n], work[_PY, n], end, nx, ny)
                    if st == _FAILED:
                        hazard[r, ch] = True  # one stranded sample makes the action unavailable
                        break
                    if st == _DONE:
                        work[_OK, n] = -1.0
                        ended += 1
                if hazard[r, ch]:
                    break
                n = 0
                while ended > 0 and n < na:
                    if work[_OK, n] != -1.0:
                        n += 1
                        continue
                    q = act[n]
                    xs[q] = work[_X, n]
                    ys[q] = work[_Y, n]
                    ts[q] = work[_T, n]
                    ended -= 1
                    na -= 1
                    act[n] = act[na]
                    for row in (_X, _Y, _T, _X0, _Y0, _WE, _WN, _OK):
                        work[row, n] = work[row, na]
            if hazard[r, ch]:
                continue
            for q in range(n_q):
                ii = _nearest(xs[q])
                jj = _nearest(ys[q])
                di = ii - i
                dj = jj - j
                if ii < 0 or ii >= nx or jj < 0 or jj >= ny or abs(di) > 2 or abs(dj) > 2 or not water[lb, jj, ii]:
                    hazard[r, ch] = True
                    break
                e = power * ts[q] / 3600.0
                slot = (dj + 2) * 5 + (di + 2)
                count[r, ch, slot] += 1
                if e > emax[r, ch, slot]:
                    emax[r, ch, slot] = e
                esum[r, ch] += e
                tsum[r, ch] += ts[q]


ENTRY_KERNEL = _sample_cells  # the kernel every physical plan runs: its first compile is the slow one
