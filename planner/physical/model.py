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
from functools import cached_property

import numba
import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import GridError
from planner.contract.settings import PlanSettings
from planner.grid import Grid
from planner.paper.transitions import flow_directions
from planner.physical.sampling import (
    N_CHANNELS_BEARINGS,
    N_CHANNELS_COURSES,
    SampleStats,
    combine,
    enter_goal,
    member_offsets_m_s,
    sample_transitions,
    start_offsets,
    transition_limit_s,
)

__all__ = [
    "MAX_REFINE", "N_CHANNELS_BEARINGS", "N_CHANNELS_COURSES", "PhysicalModel", "SampleStats", "assemble",
    "build_physical", "combine", "enter_goal", "fine_grid", "member_offsets_m_s", "refine_factor",
    "sample_transitions", "start_offsets", "transition_limit_s",
]

MAX_REFINE = 8


@dataclass(frozen=True, eq=False, kw_only=True)
class PhysicalModel:
    """The sampled transitions, per cell and channel (``planner.physical.sampling``), as the solvers walk them.

    Channel ``q = cell * n_channels + channel`` of cell ``(l * ny + j) * nx + i``: available where
    ``channel_ok``, with the mean energy ``channel_energy_wh`` and duration ``channel_duration_s``
    over all samples, and outcomes ``channel_ptr[q]:channel_ptr[q + 1]`` into ``slot`` (the
    outcome cell's offset, ``(dj + 2) * 5 + (di + 2)``), ``slot_prob`` and ``slot_energy_max_wh``
    (the largest energy of the samples that ended there, for the worst case). A state's actions
    map onto channels as ``action_channel`` says; ROTATE is ``rotate_wh`` for ``rotate_s``.

    The same transitions per (state, action) *pair*, as flat arrays (``pair_state``, ``ptr``,
    ``out_state``, ...), are built on first use: for tests, pictures and the robust solver. States
    use the paper model's internal heading-major index ``((k * L + l) * ny + j) * nx + i``.
    """

    grid: Grid
    settings: PlanSettings
    water: NDArray[np.bool_]  # (L, ny, nx)
    flow_dir: NDArray[np.int8]  # the paper model's flow directions, for the pictures only
    n_channels: int
    channel_ok: NDArray[np.bool_]
    channel_energy_wh: NDArray[np.float64]
    channel_duration_s: NDArray[np.float64]
    channel_ptr: NDArray[np.int64]
    slot: NDArray[np.int8]
    slot_prob: NDArray[np.float64]
    slot_energy_max_wh: NDArray[np.float64]
    rotate_wh: NDArray[np.float64]  # (L * ny * nx,)
    rotate_s: float
    refine: int
    samples_per_action: int
    members: int = 1  # forecast members whose samples make the outcomes

    @property
    def n_states(self) -> int:
        return self.grid.n_states

    @property
    def n_actions(self) -> int:
        """Actions per state: DRIFT, FORWARD, ROTATE_LEFT/RIGHT, UP, DOWN, and FORWARD_LEFT/RIGHT with courses."""
        return 8 if self.n_channels > N_CHANNELS_BEARINGS else 6

    def state_index(self, l: int, j: int, i: int, k: int) -> int:
        """Internal state index (``Grid.state_index``)."""
        return self.grid.state_index(l, j, i, k)

    def state_of(self, index: int) -> tuple[int, int, int, int]:
        """``(l, j, i, k)`` of an internal state index."""
        return self.grid.state_of(index)

    @cached_property
    def _pairs(self) -> tuple[NDArray, ...]:
        arrays = _pairs(self.water, self.n_channels, self.channel_ok, self.channel_energy_wh, self.channel_duration_s,
                        self.channel_ptr, self.slot, self.slot_prob, self.slot_energy_max_wh, self.rotate_wh,
                        self.rotate_s)
        for arr in arrays:
            arr.setflags(write=False)
        return arrays

    @property
    def pair_state(self) -> NDArray[np.int64]:
        return self._pairs[0]

    @property
    def pair_action(self) -> NDArray[np.int8]:
        return self._pairs[1]

    @property
    def ptr(self) -> NDArray[np.int64]:
        return self._pairs[2]

    @property
    def out_state(self) -> NDArray[np.int64]:
        return self._pairs[3]

    @property
    def out_prob(self) -> NDArray[np.float64]:
        return self._pairs[4]

    @property
    def out_energy_max_wh(self) -> NDArray[np.float64]:
        return self._pairs[5]

    @property
    def energy_wh(self) -> NDArray[np.float64]:
        """Each pair's mean energy over all its samples (Wh)."""
        return self._pairs[6]

    @property
    def duration_s(self) -> NDArray[np.float64]:
        """Each pair's mean duration over all its samples (s)."""
        return self._pairs[7]

    @property
    def n_pairs(self) -> int:
        """Available (state, action) pairs, counted without building them."""
        return int(_count_pairs(self.water, self.n_channels, self.channel_ok))

    def pair_of(self, state: int, action: int) -> int:
        """The pair index of (internal state, action code); -1 where the action is unavailable there."""
        lo = int(np.searchsorted(self.pair_state, state, side="left"))
        hi = int(np.searchsorted(self.pair_state, state, side="right"))
        for p in range(lo, hi):
            if int(self.pair_action[p]) == action:
                return p
        return -1

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


def assemble(stats: SampleStats, grid: Grid, settings: PlanSettings, *, refine: int) -> PhysicalModel:
    """The model the solvers walk, from (combined) samples: probabilities, mean costs, the cost floor."""
    L = grid.n_layers
    water = np.isfinite(stats.u) & np.isfinite(stats.v)
    for l in range(L):
        if not water[l].any():
            raise GridError(f"layer {l} at {grid.depth_m[l]:g} m is all land on this grid; "
                            "choose shallower --depths or a bbox with water at that depth")
    floor = settings.physical.min_cost_wh
    n = stats.n_samples
    ok = (~stats.hazard & water.reshape(-1, 1)).ravel()
    energy = np.maximum(stats.esum.ravel() / n, floor)
    duration = stats.tsum.ravel() / n
    prob = stats.count / n
    emax = np.maximum(stats.emax, floor)
    rotate = np.maximum(stats.rot_wh.ravel(), floor)
    flow = flow_directions(stats.u, stats.v, grid, calm_speed_m_s=settings.calm_speed_m_s)
    for arr in (water, flow, ok, energy, duration, stats.ptr, stats.slot, prob, emax, rotate):
        arr.setflags(write=False)
    return PhysicalModel(
        grid=grid, settings=settings, water=water, flow_dir=flow, n_channels=stats.n_channels, channel_ok=ok,
        channel_energy_wh=energy, channel_duration_s=duration, channel_ptr=stats.ptr, slot=stats.slot,
        slot_prob=prob, slot_energy_max_wh=emax, rotate_wh=rotate, rotate_s=45.0 / settings.vehicle.yaw_rate_deg_s,
        refine=refine, samples_per_action=n, members=stats.members,
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
_I64 = NDArray[np.int64]
_Mask = NDArray[np.bool_]

# Pair actions per state, in code order (ties go to the first): DRIFT, FORWARD, ROTATE_LEFT,
# ROTATE_RIGHT, UP, DOWN, then FORWARD_LEFT, FORWARD_RIGHT where sampled.
PAIR_ACTIONS = np.array([0, 1, 2, 3, 4, 5, 8, 9], dtype=np.int64)


@numba.njit(cache=True, inline="always")
def action_channel(a: int, k: int) -> int:  # pragma: no cover
    """The sample channel of a move action: DRIFT 0, UP 1, DOWN 2, FORWARD 3 + heading,
    FORWARD_LEFT 11 + heading, FORWARD_RIGHT 19 + heading; -1 for the rotations."""
    if a == 0:
        return 0
    if a == 1:
        return 3 + k
    if a == 4:
        return 1
    if a == 5:
        return 2
    if a == 2 or a == 3:
        return -1
    return 11 + k if a == 8 else 19 + k


@numba.njit(cache=True, inline="always")
def outcome_state(a: int, k: int, l: int, j: int, i: int, slot: int, L: int, ny: int, nx: int) -> int:  # pragma: no cover
    """The internal state a move action's outcome ``slot`` lands in (UP and DOWN change the layer)."""
    lt = l - 1 if a == 4 else (l + 1 if a == 5 else l)
    return ((k * L + lt) * ny + j + slot // 5 - 2) * nx + i + slot % 5 - 2


@numba.njit(cache=True)
def _count_pairs(water: _Mask, n_ch: int, ok: _Mask) -> int:  # pragma: no cover
    L, ny, nx = water.shape
    n_actions = 8 if n_ch > N_CHANNELS_BEARINGS else 6
    n = 0
    for c in range(L * ny * nx):
        if not water.flat[c]:
            continue
        for k in range(8):
            for a in PAIR_ACTIONS[:n_actions]:
                ch = action_channel(a, k)
                if ch < 0 or ok[c * n_ch + ch]:
                    n += 1
    return n


@numba.njit(cache=True)
def _pairs(  # pragma: no cover
    water: _Mask, n_ch: int, ok: _Mask, energy_ch: _F64, duration_ch: _F64, ch_ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, emax: _F64, rot_wh: _F64, rot_s: float,
) -> tuple[_I64, NDArray[np.int8], _I64, _I64, _F64, _F64, _F64, _F64]:
    """The channels as per-(state, action) outcome lists, states in index order, actions in code order."""
    L, ny, nx = water.shape
    n_cells = L * ny * nx
    n_actions = 8 if n_ch > N_CHANNELS_BEARINGS else 6
    n_pairs = 0
    n_out = 0
    for s in range(8 * n_cells):  # pass 1: sizes
        k = s // n_cells
        c = s % n_cells
        if not water.flat[c]:
            continue
        for a in PAIR_ACTIONS[:n_actions]:
            ch = action_channel(a, k)
            if ch < 0:
                n_pairs += 1
                n_out += 1
            elif ok[c * n_ch + ch]:
                n_pairs += 1
                n_out += ch_ptr[c * n_ch + ch + 1] - ch_ptr[c * n_ch + ch]
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
    for s in range(8 * n_cells):  # pass 2: fill
        k = s // n_cells
        c = s % n_cells
        if not water.flat[c]:
            continue
        l = c // (ny * nx)
        j = (c // nx) % ny
        i = c % nx
        for a in PAIR_ACTIONS[:n_actions]:
            ch = action_channel(a, k)
            if ch < 0:
                k2 = (k + 1) % 8 if a == 2 else (k + 7) % 8
                out_state[e] = k2 * n_cells + c
                out_prob[e] = 1.0
                out_emax[e] = rot_wh[c]
                e += 1
                energy[p] = rot_wh[c]
                duration[p] = rot_s
            else:
                q = c * n_ch + ch
                if not ok[q]:
                    continue
                for t in range(ch_ptr[q], ch_ptr[q + 1]):
                    out_state[e] = outcome_state(a, k, l, j, i, slot[t], L, ny, nx)
                    out_prob[e] = prob[t]
                    out_emax[e] = emax[t]
                    e += 1
                energy[p] = energy_ch[q]
                duration[p] = duration_ch[q]
            pair_state[p] = s
            pair_action[p] = a
            p += 1
            ptr[p] = e
    return pair_state, pair_action, ptr, out_state, out_prob, out_emax, energy, duration
