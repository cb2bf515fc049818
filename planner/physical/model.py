"""The physical planning model: transitions integrated through the current, costs in watt-hours.

docs/physical-model.md gives the reasoning; in short, for every water cell and action:

- the vehicle starts from ``start_points`` x ``start_points`` points spread over the cell, in
  the forecast current and in each perturbed member of the forecast-error model
  (``PhysicalSettings``);
- its motion, over ground = through-water velocity + current, is integrated with RK4 through
  the current interpolated bilinearly between grid nodes (a node on land makes the point land,
  as ``vehicle_sim.world`` does): FORWARD at the cruise speed along the heading's bearing
  (FORWARD_LEFT/RIGHT along ``planner.contract.headings.courses_deg``'s offset courses), DRIFT
  with no thrust, UP/DOWN with no thrust while gliding at the glide rate to the next layer
  (the current blended between the two layers by depth), ROTATE holding station for
  45 deg / yaw rate (ArduSub GUIDED with zero velocity, as the executive commands it);
- FORWARD and DRIFT last until the vehicle is one cell spacing away from its start point
  east-west or north-south, or ``max_transition_s``. One spacing, not "until the cell's own
  edge": from points spread over the cell the edge is half a cell away on average, which would
  halve every predicted time and make the prediction depend on where in the cell the vehicle is;
- each sample's outcome is the cell it ends in; a sample that touches land or leaves the grid
  makes the action unavailable in that state (it could strand the vehicle);
- energy = ``vehicle_sim.dynamics.power_draw_w`` x duration: the simulator's own energy law.

The currents are sampled on a grid ``refine`` times finer than the planning grid (planning
nodes are every ``refine``-th node), chosen so that the field keeps about the forecast's
resolution whatever the planning resolution: a finer planning grid then changes the model's
discretisation, not the ocean it plans through.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import GridError
from planner.grid import Grid
from planner.contract.headings import N_HEADINGS, courses_deg
from planner.contract.geodesy import EARTH_RADIUS_M
from planner.contract.settings import PhysicalSettings, PlanSettings
from planner.paper.transitions import flow_directions
from planner.contract.vehicle import power_draw_w

# Sample channels per cell: DRIFT, UP, DOWN, then FORWARD along each of the eight headings, then
# (with course offsets) FORWARD_LEFT and FORWARD_RIGHT along each (planner.contract.headings.courses_deg).
N_CHANNELS_BEARINGS = 3 + N_HEADINGS
N_CHANNELS_COURSES = 3 + 3 * N_HEADINGS
_SLOTS = 25  # outcome cells within +-2 cells: slot = (dj + 2) * 5 + (di + 2)
MAX_REFINE = 8


@dataclass(frozen=True, eq=False, kw_only=True)
class PhysicalModel:
    """The sampled transitions as flat arrays the solvers walk.

    A *pair* is one (state, action). States use the paper model's internal heading-major index
    ``((k * L + l) * ny + j) * nx + i``. Pair ``p`` has outcomes ``out_state[ptr[p]:ptr[p+1]]``
    with probabilities ``out_prob`` and, per outcome, the largest energy of the samples that
    ended there (``out_energy_max_wh``, for the worst case); ``energy_wh``/``duration_s`` are the
    pair's mean over all samples (for the expected cost). Only available pairs are listed.
    """

    grid: Grid
    settings: PlanSettings
    water: NDArray[np.bool_]  # (L, ny, nx)
    flow_dir: NDArray[np.int8]  # the paper model's flow directions, for the pictures only
    pair_state: NDArray[np.int64]
    pair_action: NDArray[np.int8]
    ptr: NDArray[np.int64]
    out_state: NDArray[np.int64]
    out_prob: NDArray[np.float64]
    out_energy_max_wh: NDArray[np.float64]
    energy_wh: NDArray[np.float64]
    duration_s: NDArray[np.float64]
    refine: int
    samples_per_action: int
    members: int = 1  # forecast members whose samples make the outcomes

    @property
    def n_states(self) -> int:
        return self.grid.n_states

    @property
    def n_pairs(self) -> int:
        return int(self.pair_state.size)

    def state_index(self, l: int, j: int, i: int, k: int) -> int:
        """Internal state index (``Grid.state_index``)."""
        return self.grid.state_index(l, j, i, k)

    def state_of(self, index: int) -> tuple[int, int, int, int]:
        """``(l, j, i, k)`` of an internal state index."""
        return self.grid.state_of(index)

    def pairs_of(self, l: int, j: int, i: int, k: int) -> range:
        """Pair indices of one state (pairs are sorted by state)."""
        s = self.state_index(l, j, i, k)
        lo = int(np.searchsorted(self.pair_state, s, side="left"))
        hi = int(np.searchsorted(self.pair_state, s, side="right"))
        return range(lo, hi)

    def outcomes(self, pair: int) -> list[tuple[tuple[int, int, int, int], float, float]]:
        """``((l, j, i, k), probability, worst energy Wh)`` of each outcome of a pair."""
        lo, hi = int(self.ptr[pair]), int(self.ptr[pair + 1])
        return [(self.state_of(int(self.out_state[e])), float(self.out_prob[e]), float(self.out_energy_max_wh[e]))
                for e in range(lo, hi)]


def transition_limit_s(grid: Grid, settings: PlanSettings) -> float:
    """``max_transition_s``, or by default the time for four crossings of the largest cell at cruise
    speed: long enough that a vehicle under way always leaves its cell in still water."""
    given = settings.physical.max_transition_s
    if given is not None:
        return float(given)
    dx_m, dy_m = grid.cell_size_m()
    return 4.0 * max(float(np.max(dx_m)), dy_m) / settings.vehicle.cruise_speed_m_s


def refine_factor(grid: Grid, native_spacing_deg: float | None) -> int:
    """How many current nodes per planning cell keep about the forecast's own resolution (1..8)."""
    if native_spacing_deg is None or not native_spacing_deg > 0:
        return 1
    planning = min(grid.dlon_deg, grid.dlat_deg)
    return int(min(MAX_REFINE, max(1, math.ceil(planning / native_spacing_deg - 1e-6))))


def fine_grid(grid: Grid, refine: int) -> Grid:
    """The grid the currents are sampled on: every ``refine``-th node is a planning node."""
    return Grid.from_bbox(grid.bbox, nx=(grid.nx - 1) * refine + 1, ny=(grid.ny - 1) * refine + 1,
                          depths_m=grid.depth_m)


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

    ``count``/``emax`` (cells, channels, 25 outcome slots), ``esum``/``tsum``/``hazard`` (cells,
    channels), the planning-grid currents ``u``/``v`` (L, ny, nx; NaN = land) and the ROTATE
    energy ``rot_wh`` (L, ny, nx). Plain arrays: a Dask worker returns one per member.
    """

    count: NDArray[np.int32]
    emax: NDArray[np.float64]
    esum: NDArray[np.float64]
    tsum: NDArray[np.float64]
    hazard: NDArray[np.bool_]
    n_samples: int
    u: NDArray[np.float64]
    v: NDArray[np.float64]
    rot_wh: NDArray[np.float64]
    members: int = 1


def sample_transitions(
    u_fine_m_s: NDArray[np.float64], v_fine_m_s: NDArray[np.float64], grid: Grid, settings: PlanSettings, *, refine: int,
    goal_mask: NDArray[np.bool_] | None = None,
) -> SampleStats:
    """Sample every water cell's actions in one forecast member; currents on ``fine_grid(grid, refine)``.

    ``goal_mask`` (L, ny, nx): a FORWARD or DRIFT sample that enters a goal cell ends there, when
    it enters, as a vehicle arrives on entering the goal cells (not a cell spacing later).
    """
    L, ny, nx = grid.n_layers, grid.ny, grid.nx
    shape_f = (L, (ny - 1) * refine + 1, (nx - 1) * refine + 1)
    uf = np.ascontiguousarray(u_fine_m_s, dtype=np.float64)
    vf = np.ascontiguousarray(v_fine_m_s, dtype=np.float64)
    if uf.shape != shape_f or vf.shape != shape_f:
        raise GridError(f"currents: expected shape {shape_f} on the refined grid; got {uf.shape} and {vf.shape}")
    u = np.ascontiguousarray(uf[:, ::refine, ::refine])
    v = np.ascontiguousarray(vf[:, ::refine, ::refine])
    water = np.isfinite(u) & np.isfinite(v)
    ps, vp = settings.physical, settings.vehicle
    _dx_m, dy_m = grid.cell_size_m()
    t_max = transition_limit_s(grid, settings)
    course_rad = np.ascontiguousarray(np.radians(courses_deg(grid.bearings_deg())))  # (ny, 8, 3), clockwise from north
    offsets = start_offsets(ps)
    members = member_offsets_m_s(ps)
    n_ch = N_CHANNELS_COURSES if ps.course_offsets else N_CHANNELS_BEARINGS
    count = np.zeros((L * ny * nx, n_ch, _SLOTS), dtype=np.int32)
    emax = np.zeros((L * ny * nx, n_ch, _SLOTS), dtype=np.float64)
    esum = np.zeros((L * ny * nx, n_ch), dtype=np.float64)
    tsum = np.zeros((L * ny * nx, n_ch), dtype=np.float64)
    hazard = np.zeros((L * ny * nx, n_ch), dtype=np.bool_)
    powers = np.array([
        float(power_draw_w(vp, 0.0, False)),  # DRIFT
        float(power_draw_w(vp, 0.0, True)),  # UP / DOWN: no thrust, buoyancy engine
        float(power_draw_w(vp, vp.cruise_speed_m_s, False)),  # FORWARD
    ])
    goal = np.zeros((L, ny, nx), dtype=np.bool_) if goal_mask is None else np.ascontiguousarray(goal_mask, dtype=np.bool_)
    _sample_cells(
        uf, vf, water, goal, refine, float(grid.lat_deg[0]), grid.dlat_deg, math.radians(grid.dlon_deg), dy_m,
        np.asarray(grid.depth_m, dtype=np.float64), course_rad, offsets, members,
        vp.cruise_speed_m_s, vp.glide_rate_m_s, t_max, ps.rk4_steps, powers,
        count, emax, esum, tsum, hazard,
    )
    # ROTATE holds station for 45 degrees of turn: water speed = the current's, up to the maximum.
    rot_s = 45.0 / vp.yaw_rate_deg_s
    speed = np.minimum(np.hypot(np.nan_to_num(u), np.nan_to_num(v)), vp.max_speed_m_s)
    rot_wh = np.ascontiguousarray(power_draw_w(vp, speed, False) * rot_s / 3600.0, dtype=np.float64)
    return SampleStats(count=count, emax=emax, esum=esum, tsum=tsum, hazard=hazard,
                       n_samples=offsets.shape[0] * members.shape[0], u=u, v=v, rot_wh=rot_wh)


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
    shapes = {s.count.shape for s in stats}
    if len(shapes) != 1 or len({s.n_samples for s in stats}) != 1:
        raise GridError(f"ensemble members sampled on different grids or settings: {sorted(shapes)}")
    count = first.count.copy()
    emax = first.emax.copy()
    esum = first.esum.copy()
    tsum = first.tsum.copy()
    hazard = first.hazard.copy()
    u, v = first.u.copy(), first.v.copy()
    rot = first.rot_wh.copy()
    for s in stats[1:]:
        count += s.count
        np.maximum(emax, s.emax, out=emax)
        esum += s.esum
        tsum += s.tsum
        hazard |= s.hazard
        land = ~(np.isfinite(s.u) & np.isfinite(s.v))
        u[land] = np.nan
        v[land] = np.nan
        rot = np.maximum(rot, s.rot_wh)
    return SampleStats(count=count, emax=emax, esum=esum, tsum=tsum, hazard=hazard,
                       n_samples=first.n_samples * len(stats), u=u, v=v, rot_wh=rot,
                       members=sum(s.members for s in stats))


def assemble(stats: SampleStats, grid: Grid, settings: PlanSettings, *, refine: int) -> PhysicalModel:
    """The model the solvers walk, from (combined) samples."""
    L = grid.n_layers
    water = np.isfinite(stats.u) & np.isfinite(stats.v)
    for l in range(L):
        if not water[l].any():
            raise GridError(f"layer {l} at {grid.depth_m[l]:g} m is all land on this grid; "
                            "choose shallower --depths or a bbox with water at that depth")
    rot_s = 45.0 / settings.vehicle.yaw_rate_deg_s
    arrays = _pairs(stats.count, stats.emax, stats.esum, stats.tsum, stats.hazard, water, stats.rot_wh, rot_s,
                    stats.n_samples)
    pair_state, pair_action, ptr, out_state, out_prob, out_emax, energy, duration = arrays
    floor = settings.physical.min_cost_wh
    energy = np.maximum(energy, floor)
    out_emax = np.maximum(out_emax, floor)
    flow = flow_directions(stats.u, stats.v, grid, calm_speed_m_s=settings.calm_speed_m_s)
    for arr in (water, flow, pair_state, pair_action, ptr, out_state, out_prob, out_emax, energy, duration):
        arr.setflags(write=False)
    return PhysicalModel(
        grid=grid, settings=settings, water=water, flow_dir=flow, pair_state=pair_state, pair_action=pair_action,
        ptr=ptr, out_state=out_state, out_prob=out_prob, out_energy_max_wh=out_emax, energy_wh=energy,
        duration_s=duration, refine=refine, samples_per_action=stats.n_samples, members=stats.members,
    )


def build_physical(
    u_fine_m_s: NDArray[np.float64], v_fine_m_s: NDArray[np.float64], grid: Grid, settings: PlanSettings, *, refine: int,
    goal_mask: NDArray[np.bool_] | None = None,
) -> PhysicalModel:
    """Sample and assemble the model of one forecast (see ``sample_transitions``)."""
    return assemble(sample_transitions(u_fine_m_s, v_fine_m_s, grid, settings, refine=refine, goal_mask=goal_mask),
                    grid, settings, refine=refine)


# --------------------------------------------------------------------------- compiled kernels

# Shorthands for the kernels' array arguments.
_F64 = NDArray[np.float64]
_Mask = NDArray[np.bool_]


@numba.njit(cache=True, nogil=True)
def _interp(f: _F64, l: int, X: float, Y: float) -> float:  # pragma: no cover - compiled
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


@numba.njit(cache=True, nogil=True)
def _velocity(  # pragma: no cover
    uf: _F64, vf: _F64, refine: int, la: int, lb: int, wb: float, x: float, y: float,
    lat0: float, dlat: float, dlon_rad: float, dy_m: float, we: float, wn: float,
) -> tuple[float, float]:
    """(dx/dt, dy/dt) in planning cells per second at planning-index point (x, y); NaN on land.

    Over ground = through water (``we``, ``wn``, m/s, members' offsets included) + the current of
    layer ``la`` blended with ``lb`` by weight ``wb`` (glides)."""
    X = x * refine
    Y = y * refine
    cu = _interp(uf, la, X, Y)
    cv = _interp(vf, la, X, Y)
    if wb > 0.0:
        cu = (1.0 - wb) * cu + wb * _interp(uf, lb, X, Y)
        cv = (1.0 - wb) * cv + wb * _interp(vf, lb, X, Y)
    lat = lat0 + y * dlat
    dx_m = EARTH_RADIUS_M * math.cos(math.radians(lat)) * dlon_rad  # spec section 1, at the point's latitude
    return (cu + we) / dx_m, (cv + wn) / dy_m


@numba.njit(cache=True, nogil=True)
def _run(  # pragma: no cover
    uf: _F64, vf: _F64, goal: _Mask, refine: int, la: int, lb: int, glide_s: float, x0: float, y0: float,
    we: float, wn: float, t_max: float, h: float, lat0: float, dlat: float, dlon_rad: float, dy_m: float,
    nx: int, ny: int,
) -> tuple[bool, float, float, float]:
    """Integrate one sample with RK4. Returns (ok, x, y, t).

    ``glide_s`` > 0: a glide from layer ``la`` to ``lb`` lasting exactly ``glide_s``; else a move
    until one cell spacing from the start along either axis, entering a goal cell of layer ``la``
    (``goal``), or ``t_max``. Crossings are placed on the RK4 step's chord.
    """
    x = x0
    y = y0
    t = 0.0
    end = glide_s if glide_s > 0.0 else t_max
    while t < end - 1e-9:
        hh = min(h, end - t)
        w1 = t / glide_s if glide_s > 0.0 else 0.0
        w2 = (t + 0.5 * hh) / glide_s if glide_s > 0.0 else 0.0
        w3 = (t + hh) / glide_s if glide_s > 0.0 else 0.0
        k1x, k1y = _velocity(uf, vf, refine, la, lb, w1, x, y, lat0, dlat, dlon_rad, dy_m, we, wn)
        k2x, k2y = _velocity(uf, vf, refine, la, lb, w2, x + 0.5 * hh * k1x, y + 0.5 * hh * k1y, lat0, dlat, dlon_rad, dy_m, we, wn)
        k3x, k3y = _velocity(uf, vf, refine, la, lb, w2, x + 0.5 * hh * k2x, y + 0.5 * hh * k2y, lat0, dlat, dlon_rad, dy_m, we, wn)
        k4x, k4y = _velocity(uf, vf, refine, la, lb, w3, x + hh * k3x, y + hh * k3y, lat0, dlat, dlon_rad, dy_m, we, wn)
        xn = x + hh / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        yn = y + hh / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
        if not (math.isfinite(xn) and math.isfinite(yn)):
            return False, x, y, t  # a stage touched land
        tau = 1.0  # the step's fraction at which the one-spacing box is left
        if glide_s <= 0.0 and (abs(xn - x0) >= 1.0 or abs(yn - y0) >= 1.0):
            if abs(xn - x0) >= 1.0:
                tau = min(tau, (x0 + math.copysign(1.0, xn - x0) - x) / (xn - x))
            if abs(yn - y0) >= 1.0:
                tau = min(tau, (y0 + math.copysign(1.0, yn - y0) - y) / (yn - y))
            xn = x + tau * (xn - x)
            yn = y + tau * (yn - y)
        if glide_s <= 0.0:
            gi = _nearest(xn)
            gj = _nearest(yn)
            if 0 <= gi < nx and 0 <= gj < ny and goal[la, gj, gi] and not goal[la, _nearest(y), _nearest(x)]:
                enter = 0.0  # the chord's fraction at which it enters that goal cell
                for a, an, c in ((x, xn, gi), (y, yn, gj)):
                    if abs(a - c) > 0.5:
                        edge = c - 0.5 if an > a else c + 0.5
                        enter = max(enter, (edge - a) / (an - a))
                enter = min(enter + 1e-6, 1.0)  # just inside: a point on the edge belongs to the lower cell
                return True, x + enter * (xn - x), y + enter * (yn - y), t + enter * tau * hh
        if tau < 1.0:
            x = xn
            y = yn
            t = t + tau * hh
            break
        x = xn
        y = yn
        t += hh
        if x < -0.5 or x > nx - 0.5 or y < -0.5 or y > ny - 0.5:
            return False, x, y, t  # left the grid
    if x < -0.5 or x > nx - 0.5 or y < -0.5 or y > ny - 0.5:
        return False, x, y, t
    return True, x, y, t


@numba.njit(cache=True, nogil=True)
def _nearest(x: float) -> int:  # pragma: no cover
    """Nearest index, halves going to the lower one (as ``Grid.nearest_cell``)."""
    return int(math.ceil(x - 0.5))


@numba.njit(cache=True, parallel=True)
def _sample_cells(  # pragma: no cover
    uf: _F64, vf: _F64, water: _Mask, goal: _Mask, refine: int, lat0: float, dlat: float, dlon_rad: float,
    dy_m: float, depth_m: _F64, course_rad: _F64, offsets: _F64, members: _F64, speed: float, glide_rate: float,
    t_max: float, rk4_steps: int, powers: _F64,
    count: NDArray[np.int32], emax: _F64, esum: _F64, tsum: _F64, hazard: _Mask,
) -> None:
    L, ny, nx = water.shape
    n_off = offsets.shape[0]
    n_mem = members.shape[0]
    for c in numba.prange(L * ny * nx):
        l = c // (ny * nx)
        j = (c // nx) % ny
        i = c % nx
        if not water[l, j, i]:
            continue
        lat = lat0 + j * dlat
        dx_m = EARTH_RADIUS_M * math.cos(math.radians(lat)) * dlon_rad
        cell_m = min(dx_m, dy_m)
        cu = _interp(uf, l, i * refine, j * refine)
        cv = _interp(vf, l, i * refine, j * refine)
        cur = math.hypot(cu, cv)
        for ch in range(count.shape[1]):
            lb = l
            glide_s = 0.0
            we = 0.0
            wn = 0.0
            if ch == 1 or ch == 2:
                lb = l - 1 if ch == 1 else l + 1
                if lb < 0 or lb >= L or not water[lb, j, i]:
                    hazard[c, ch] = True
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
            for q in range(n_off * n_mem):
                if hazard[c, ch]:
                    break  # one stranded sample makes the action unavailable: stop sampling it
                o = q // n_mem
                m = q % n_mem
                ok, x, y, t = _run(uf, vf, goal, refine, l, lb, glide_s, i + offsets[o, 0], j + offsets[o, 1],
                                   we + members[m, 0], wn + members[m, 1], t_max, h,
                                   lat0, dlat, dlon_rad, dy_m, nx, ny)
                ii = _nearest(x)
                jj = _nearest(y)
                di = ii - i
                dj = jj - j
                if (not ok or ii < 0 or ii >= nx or jj < 0 or jj >= ny or abs(di) > 2 or abs(dj) > 2
                        or not water[lb, jj, ii]):
                    hazard[c, ch] = True
                    continue
                e = power * t / 3600.0
                slot = (dj + 2) * 5 + (di + 2)
                count[c, ch, slot] += 1
                if e > emax[c, ch, slot]:
                    emax[c, ch, slot] = e
                esum[c, ch] += e
                tsum[c, ch] += t


@numba.njit(cache=True, inline="always")
def _decode(s: int, L: int, ny: int, nx: int) -> tuple[int, int, int, int, int]:  # pragma: no cover
    """(k, cell, l, j, i) of an internal state index (heading-major, as ``PhysicalModel.state_index``)."""
    k = s // (L * ny * nx)
    c = s % (L * ny * nx)
    return k, c, c // (ny * nx), (c // nx) % ny, c % nx


@numba.njit(cache=True, inline="always")
def _channel(a: int, k: int) -> int:  # pragma: no cover
    """The sample channel of a move action: DRIFT 0, UP 1, DOWN 2, FORWARD 3 + heading,
    FORWARD_LEFT 11 + heading, FORWARD_RIGHT 19 + heading."""
    if a == 0:
        return 0
    if a == 1:
        return 3 + k
    if a == 4:
        return 1
    if a == 5:
        return 2
    return 11 + k if a == 8 else 19 + k


# Pair actions per state, in code order (ties go to the first): DRIFT, FORWARD, ROTATE_LEFT,
# ROTATE_RIGHT, UP, DOWN, then FORWARD_LEFT, FORWARD_RIGHT where sampled.
_PAIR_ACTIONS = np.array([0, 1, 2, 3, 4, 5, 8, 9], dtype=np.int64)


@numba.njit(cache=True)
def _pairs(  # pragma: no cover
    count: NDArray[np.int32], emax: _F64, esum: _F64, tsum: _F64, hazard: _Mask, water: _Mask, rot_wh: _F64,
    rot_s: float, n_samples: int,
) -> tuple[NDArray[np.int64], NDArray[np.int8], NDArray[np.int64], NDArray[np.int64], _F64, _F64, _F64, _F64]:
    """Flatten the per-cell samples into per-(state, action) outcome lists, states in index order."""
    L, ny, nx = water.shape
    n_states = 8 * L * ny * nx
    n_actions = 8 if count.shape[1] > N_CHANNELS_BEARINGS else 6  # with course offsets: FORWARD_LEFT/RIGHT too
    n_pairs = 0
    n_out = 0
    for s in range(n_states):  # pass 1: sizes
        k, c, l, j, i = _decode(s, L, ny, nx)
        if not water[l, j, i]:
            continue
        for a in _PAIR_ACTIONS[:n_actions]:
            if a == 2 or a == 3:
                n_pairs += 1
                n_out += 1
                continue
            ch = _channel(a, k)
            if hazard[c, ch]:
                continue
            n_pairs += 1
            for slot in range(25):
                if count[c, ch, slot] > 0:
                    n_out += 1
    pair_state = np.empty(n_pairs, dtype=np.int64)
    pair_action = np.empty(n_pairs, dtype=np.int8)
    ptr = np.empty(n_pairs + 1, dtype=np.int64)
    out_state = np.empty(n_out, dtype=np.int64)
    out_prob = np.empty(n_out, dtype=np.float64)
    out_emax = np.empty(n_out, dtype=np.float64)
    energy = np.empty(n_pairs, dtype=np.float64)
    duration = np.empty(n_pairs, dtype=np.float64)
    p = 0
    e = 0
    ptr[0] = 0
    for s in range(n_states):  # pass 2: fill
        k, c, l, j, i = _decode(s, L, ny, nx)
        if not water[l, j, i]:
            continue
        for a in _PAIR_ACTIONS[:n_actions]:
            if a == 2 or a == 3:
                k2 = (k + 1) % 8 if a == 2 else (k + 7) % 8
                out_state[e] = ((k2 * L + l) * ny + j) * nx + i
                out_prob[e] = 1.0
                out_emax[e] = rot_wh[l, j, i]
                e += 1
                energy[p] = rot_wh[l, j, i]
                duration[p] = rot_s
            else:
                ch = _channel(a, k)
                if hazard[c, ch]:
                    continue
                lt = l - 1 if a == 4 else (l + 1 if a == 5 else l)
                for slot in range(25):
                    n = count[c, ch, slot]
                    if n > 0:
                        jj = j + slot // 5 - 2
                        ii = i + slot % 5 - 2
                        out_state[e] = ((k * L + lt) * ny + jj) * nx + ii
                        out_prob[e] = n / n_samples
                        out_emax[e] = emax[c, ch, slot]
                        e += 1
                energy[p] = esum[c, ch] / n_samples
                duration[p] = tsum[c, ch] / n_samples
            pair_state[p] = s
            pair_action[p] = a
            p += 1
            ptr[p] = e
    return pair_state, pair_action, ptr, out_state, out_prob, out_emax, energy, duration

