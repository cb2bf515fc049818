"""The paper model's transitions: flow direction, alignment, step length and outcomes.

Spec sections 3 to 5. The arrays built here are what the solver walks; the
per-state outcome rule lives in one numba function, ``outcomes_of``, used by the
policy paths, the pictures and the tests alike. The solver's forward pass
(``solve._preds_heading``) writes the same rule out inline, for speed: numba
counts references of the arrays passed on every call. The tests compare the
solver with an independent reference implementation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.errors import GridError
from planner.grid import Grid
from planner.contract.headings import DI, DJ, N_HEADINGS
from planner.contract.settings import PlanSettings

FLOW_CALM = -1  # spec section 8
FLOW_LAND = -2

# (di, dj) -> k, for the eight neighbours (spec section 2).
_STEP_TO_K = {(int(DI[k]), int(DJ[k])): k for k in range(N_HEADINGS)}


def flow_directions(
    u_m_s: NDArray[np.float64], v_m_s: NDArray[np.float64], grid: Grid, *, calm_speed_m_s: float
) -> NDArray[np.int8]:
    """Flow direction ``w`` per cell, shape ``(L, ny, nx)``: 0..7, ``FLOW_CALM`` or ``FLOW_LAND``.

    Spec section 3: the Euler step to the nearest grid point, computed exactly
    in grid-index space without forming ``dt``.
    """
    u = np.asarray(u_m_s, dtype=np.float64)
    v = np.asarray(v_m_s, dtype=np.float64)
    if u.shape != (grid.n_layers, grid.ny, grid.nx) or v.shape != u.shape:
        raise GridError(f"currents: expected shape {(grid.n_layers, grid.ny, grid.nx)}; got {u.shape} and {v.shape}")
    dx_m, dy_m = grid.cell_size_m()
    water = np.isfinite(u) & np.isfinite(v)
    with np.errstate(invalid="ignore"):
        a = u / dx_m[None, :, None]  # cells per second, one division each (spec 3.1)
        b = v / dy_m
        calm = (np.hypot(u, v) <= calm_speed_m_s) | ((a == 0) & (b == 0))
        A = np.abs(a)
        B = np.abs(b)
        sa = np.sign(a).astype(np.int64)
        sb = np.sign(b).astype(np.int64)
        a_major = A >= B
        di = np.where(a_major, sa, np.where(2 * A >= B, sa, 0))
        dj = np.where(a_major, np.where(2 * B >= A, sb, 0), sb)
    lut = np.full((3, 3), FLOW_LAND, dtype=np.int8)
    for (si, sj), k in _STEP_TO_K.items():
        lut[si + 1, sj + 1] = k
    flow = np.full(u.shape, FLOW_LAND, dtype=np.int8)
    moving = water & ~calm
    flow[moving] = lut[di[moving] + 1, dj[moving] + 1]
    flow[water & calm] = FLOW_CALM
    return flow


def step_length(k: int | NDArray[np.int64], w: int | NDArray[np.int64]) -> NDArray[np.int8]:
    """Tiles moved for heading ``k`` in flow direction ``w`` (spec section 4): 2, 1 or 0."""
    diff = np.abs(np.asarray(k) - np.asarray(w))
    steps45 = np.minimum(diff, 8 - diff)  # rho / 45
    return np.where(steps45 == 0, 2, np.where(steps45 <= 2, 1, 0)).astype(np.int8)


def reach_table(water: NDArray[np.bool_]) -> NDArray[np.int8]:
    """How many tiles (0..2) can be stepped from ``(i, j)`` along each direction in each layer.

    Shape ``(L, ny, nx, 8)``. Only the tiles stepped onto are checked, and the
    start tile need not be water (spec section 5, "moving along a direction").
    """
    L, ny, nx = water.shape
    padded = np.zeros((L, ny + 4, nx + 4), dtype=bool)
    padded[:, 2:-2, 2:-2] = water
    reach = np.zeros((L, ny, nx, N_HEADINGS), dtype=np.int8)
    for k in range(N_HEADINGS):
        one = padded[:, 2 + DJ[k] : 2 + DJ[k] + ny, 2 + DI[k] : 2 + DI[k] + nx]
        two = padded[:, 2 + 2 * DJ[k] : 2 + 2 * DJ[k] + ny, 2 + 2 * DI[k] : 2 + 2 * DI[k] + nx]
        reach[..., k] = one.astype(np.int8) + (one & two).astype(np.int8)
    return reach


@dataclass(frozen=True, eq=False, kw_only=True)
class TransitionModel:
    """Everything the solver needs about the graph, as arrays indexed ``[l, j, i(, k)]``.

    ``flow_dir`` (L, ny, nx) int8, ``reach`` (L, ny, nx, 8) int8, ``costs`` (6,) int64
    by action code, ``lateral`` for the three-outcome uncertainty (spec section 5).
    """

    grid: Grid
    settings: PlanSettings
    flow_dir: NDArray[np.int8]
    reach: NDArray[np.int8]
    costs: NDArray[np.int64]

    @property
    def water(self) -> NDArray[np.bool_]:
        return self.flow_dir != FLOW_LAND

    @property
    def lateral(self) -> bool:
        return self.settings.uncertainty == "lateral"

    def outcomes(self, l: int, j: int, i: int, k: int, action: Action) -> list[tuple[int, int, int, int]]:
        """Distinct outcome states ``(l, j, i, k)`` of an action; empty when it is unavailable."""
        out = np.empty(3, dtype=np.int64)
        n = outcomes_of(
            self.flow_dir, self.reach, self.lateral, l, j, i, k, int(action), out
        )
        return [self.state_of(int(out[m])) for m in range(n)]

    def state_index(self, l: int, j: int, i: int, k: int) -> int:
        """Internal state index (``Grid.state_index``)."""
        return self.grid.state_index(l, j, i, k)

    def state_of(self, index: int) -> tuple[int, int, int, int]:
        """``(l, j, i, k)`` of an internal state index."""
        return self.grid.state_of(index)


def build_transitions(
    u_m_s: NDArray[np.float64], v_m_s: NDArray[np.float64], grid: Grid, settings: PlanSettings
) -> TransitionModel:
    """Flow directions and reach tables for currents on the planning grid (spec sections 1, 3, 5)."""
    flow = flow_directions(u_m_s, v_m_s, grid, calm_speed_m_s=settings.calm_speed_m_s)
    water = flow != FLOW_LAND
    for l in range(grid.n_layers):
        if not water[l].any():
            raise GridError(
                f"layer {l} at {grid.depth_m[l]:g} m is all land on this grid; "
                "choose shallower --depths or a bbox with water at that depth"
            )
    flow.setflags(write=False)
    reach = reach_table(water)
    reach.setflags(write=False)
    costs = np.array(settings.costs.as_list(), dtype=np.int64)
    costs.setflags(write=False)
    return TransitionModel(grid=grid, settings=settings, flow_dir=flow, reach=reach, costs=costs)


@numba.njit(cache=True, nogil=True)
def outcomes_of(  # pragma: no cover - compiled
    flow_dir: NDArray[np.int8], reach: NDArray[np.int8], lateral: bool, l: int, j: int, i: int, k: int, action: int,
    out: NDArray[np.int64],
) -> int:
    """Write the distinct outcome state indices of ``action`` at ``(l, j, i, k)`` into ``out``.

    State indices are internal and heading-major, ``((k * L + l) * ny + j) * nx + i``,
    so that the moves of one heading stay in one contiguous slab (see ``state_index``).

    Returns how many (0 when the action is unavailable). Spec section 5:
    ``n`` and ``w`` are those of the state's own cell; a move steps tile by tile
    and stops before land or the grid edge; lateral uncertainty adds ``d +- 1``.
    """
    L, ny, nx = flow_dir.shape
    w = flow_dir[l, j, i]
    if w == -2:
        return 0
    if action == 2 or action == 3:  # rotations: one outcome, same cell
        k2 = (k + 1) % 8 if action == 2 else (k + 7) % 8
        out[0] = ((k2 * L + l) * ny + j) * nx + i
        return 1
    lt = l
    if action == 4:
        if l == 0 or flow_dir[l - 1, j, i] == -2:
            return 0
        lt = l - 1
    elif action == 5:
        if l == L - 1 or flow_dir[l + 1, j, i] == -2:
            return 0
        lt = l + 1
    if w == -1:  # calm: FORWARD moves one tile, the others none (spec section 4)
        n = np.int64(1) if action == 1 else np.int64(0)
        d = k
    else:
        diff = abs(k - w)
        s45 = min(diff, 8 - diff)
        n = np.int64(2) if s45 == 0 else (np.int64(1) if s45 <= 2 else np.int64(0))
        d = k if action == 1 else w
    if n == 0:
        out[0] = ((k * L + lt) * ny + j) * nx + i
        return 1
    count = 0
    n_dirs = 3 if lateral else 1
    for m in range(n_dirs):
        dd = d if m == 0 else ((d + 1) % 8 if m == 1 else (d + 7) % 8)
        r = np.int64(reach[lt, j, i, dd])
        steps = n if n < r else r
        jj = j + steps * _DJ[dd]
        ii = i + steps * _DI[dd]
        s = ((k * L + lt) * ny + jj) * nx + ii
        dup = False
        for q in range(count):
            if out[q] == s:
                dup = True
        if not dup:
            out[count] = s
            count += 1
    return count


_DI = DI.copy()
_DJ = DJ.copy()
