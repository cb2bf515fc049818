"""Exact cost-to-go and policy for the paper model (spec sections 6 and 7).

One backward Dijkstra-type search from the goal settles every state once.
Values ``(cost, steps)`` are packed into one int64, ``cost << 32 | steps``, so
that integer order is the lexicographic order of spec section 7. Costs are
small integers, so the queue is a bucket queue (Dial) over cost; inside a
bucket, states are taken in order of steps: those queued from earlier buckets
sorted, merged with a FIFO of zero-cost moves (whose steps only grow).

``robust`` is Knuth's generalisation: an action of a state becomes usable when
the last of its distinct outcomes is settled; that outcome has the largest value.

Predecessors are not stored as a sparse matrix: each state keeps two 64-bit
masks (one ``(n, 2)`` array) saying which neighbouring states reach it by which
action (the displacement between them is at most two tiles), built by one
forward pass. While the search runs, a settled state's value is stored
complemented (``~value``, negative), so no separate settled array is needed.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.errors import GoalError, GridError
from planner.contract.geodesy import swap_hint
from planner.grid import Grid
from planner.contract.headings import DI, DJ, N_HEADINGS
from planner.contract.progress import SILENT, Progress, Silent
from planner.contract.settings import Goal
from planner.contract.table import MAX_STATES
from planner.paper.transitions import TransitionModel, outcomes_of

UNREACHED = np.iinfo(np.int64).max
STEPS_BITS = 32
STEPS_MASK = (1 << STEPS_BITS) - 1
# Horizontal displacements between a state and its successor: index 0 is none,
# 1 + d is one tile along d, 9 + d two tiles along d.
DISP_DI = np.concatenate([[0], DI, 2 * DI]).astype(np.int64)
DISP_DJ = np.concatenate([[0], DJ, 2 * DJ]).astype(np.int64)
MOVE_CODES = np.array([Action.DRIFT, Action.FORWARD, Action.UP, Action.DOWN], dtype=np.int64)


@dataclass(frozen=True, eq=False, kw_only=True)
class GoalCells:
    """The goal's cell and layer and the mask of goal cells in that layer (spec section 6)."""

    i: int
    j: int
    l: int
    mask: NDArray[np.bool_]  # (L, ny, nx)


@dataclass(frozen=True, eq=False, kw_only=True)
class Solution:
    """Value and policy of every state, arrays shaped ``(L, ny, nx, 8)`` indexed ``[l, j, i, k]``."""

    model: TransitionModel
    goal: Goal
    goal_cells: GoalCells
    packed_value: NDArray[np.int64]  # cost << 32 | steps; UNREACHED where unreachable or land
    action: NDArray[np.uint8]  # Action codes (spec sections 5 and 6)

    @property
    def reachable(self) -> NDArray[np.bool_]:
        return self.packed_value != UNREACHED

    @property
    def cost(self) -> NDArray[np.float64]:
        """Cost-to-go, ``inf`` where unreachable or land (spec section 8)."""
        out = (self.packed_value >> STEPS_BITS).astype(np.float64)
        out[~self.reachable] = np.inf
        return out

    @property
    def steps(self) -> NDArray[np.int64]:
        """Actions along the (worst, under robust) branch, ``-1`` where unreachable or land."""
        return np.where(self.reachable, self.packed_value & STEPS_MASK, -1)

    def value(self, l: int, j: int, i: int, k: int) -> tuple[float, int]:
        """``(cost, steps)`` of one state; ``(inf, -1)`` when unreachable."""
        p = int(self.packed_value[l, j, i, k])
        if p == UNREACHED:
            return (float("inf"), -1)
        return (float(p >> STEPS_BITS), p & STEPS_MASK)


@dataclass(frozen=True, kw_only=True)
class PathStep:
    """One state along a nominal path and the action the policy takes there."""

    l: int
    j: int
    i: int
    k: int
    action: Action


def nominal_path(solution: Solution, start: tuple[int, int, int, int], *, max_steps: int = 100_000) -> list[PathStep]:
    """Follow the policy from ``start`` (``(l, j, i, k)``) taking each action's nominal outcome.

    The nominal outcome is the move along the action's own direction (spec
    section 5, without the lateral deviations). The last step carries AT_GOAL
    or UNREACHABLE. Under ``robust`` the value falls along every outcome, so the
    path ends at the goal; under ``optimistic`` it may not, and then it stops
    where the value stops falling.
    """
    model = solution.model
    out = np.empty(3, dtype=np.int64)
    path: list[PathStep] = []
    l, j, i, k = start
    state = (int(l), int(j), int(i), int(k))
    for _ in range(max_steps):
        a = Action(int(solution.action[state]))
        path.append(PathStep(l=state[0], j=state[1], i=state[2], k=state[3], action=a))
        if a in (Action.AT_GOAL, Action.UNREACHABLE):
            break
        outcomes_of(model.flow_dir, model.reach, model.lateral, *state, int(a), out)
        nxt = model.state_of(int(out[0]))
        if solution.packed_value[nxt] >= solution.packed_value[state]:
            break  # optimistic plans promise only the best outcome
        state = nxt
    return path


def locate_goal(model: TransitionModel, goal: Goal) -> GoalCells:
    """Goal cell, layer and goal-cell mask, or a GoalError that says why not (spec section 6)."""
    return goal_cells_on(model.grid, model.water, goal)


def goal_cells_on(grid: Grid, water: NDArray[np.bool_], goal: Goal) -> GoalCells:
    """``locate_goal`` for a grid and its water mask ``(L, ny, nx)``."""
    i, j, outside = grid.nearest_cell(goal.lon_deg, goal.lat_deg)
    where = f"goal ({goal.lon_deg:.5f}, {goal.lat_deg:.5f}, {goal.depth_m:g} m)"
    if outside > 0.5:
        b = grid.bbox
        raise GoalError(
            f"{where} lies {outside:.2f} cells outside the planning grid "
            f"(lon {b.west_deg:.5f}..{b.east_deg:.5f}, lat {b.south_deg:.5f}..{b.north_deg:.5f}); "
            "expected at most half a cell outside"
            + swap_hint(goal.lon_deg, goal.lat_deg, fits=lambda lon, lat: grid.nearest_cell(lon, lat)[2] <= 0.5)
        )
    if goal.depth_m < 0 or goal.depth_m > grid.depth_m[-1] + 0.5 * (
        grid.depth_m[-1] - grid.depth_m[-2] if grid.n_layers > 1 else 0.0
    ):
        raise GoalError(
            f"{where}: depth {goal.depth_m:g} m is outside the layers "
            f"{', '.join(f'{d:g}' for d in grid.depth_m)} m"
        )
    l = grid.nearest_layer(goal.depth_m)
    if not water[l, j, i]:
        wl = np.argwhere(water[l])
        hint = ""
        if wl.size:
            jj, ii = wl[np.argmin((wl[:, 0] - j) ** 2 + (wl[:, 1] - i) ** 2)]
            hint = f"; the nearest water cell in that layer is at ({grid.lon_deg[ii]:.5f}, {grid.lat_deg[jj]:.5f})"
        raise GoalError(
            f"{where} is on land: cell i={i}, j={j} in layer {l} ({grid.depth_m[l]:g} m) has no current{hint}"
        )
    r = int(goal.radius_cells)
    mask = np.zeros(water.shape, dtype=bool)
    j0, j1 = max(0, j - r), min(grid.ny, j + r + 1)
    i0, i1 = max(0, i - r), min(grid.nx, i + r + 1)
    mask[l, j0:j1, i0:i1] = water[l, j0:j1, i0:i1]
    mask.setflags(write=False)
    return GoalCells(i=i, j=j, l=l, mask=mask)


def solve(model: TransitionModel, goal: Goal, *, progress: bool = False, meter: Progress = SILENT) -> Solution:
    """Cost-to-go and policy for every state (spec section 7), exactly.

    With ``progress``, long solves print their progress to stderr; ``meter`` hears the water states
    settled (``planner.contract.progress``), in pieces of about a twentieth.
    """
    goal_cells = locate_goal(model, goal)
    grid = model.grid
    if grid.n_states >= MAX_STATES:
        raise GridError(f"grid: {grid.n_states:,} states; the solver and the table hold at most {MAX_STATES - 1:,}")
    robust = model.settings.criterion == "robust"
    n_states = grid.n_states
    masks = np.zeros((n_states, 2), dtype=np.uint64)  # both masks of a state in one cache line
    remaining = np.zeros((n_states, 4) if robust else (1, 4), dtype=np.uint8)
    t0 = time.perf_counter()
    _build_predecessors(model.flow_dir, model.reach, model.lateral, robust, masks, remaining)
    if progress:
        print(f"  transitions: {time.perf_counter() - t0:.2f} s", file=sys.stderr, flush=True)

    packed = np.full(n_states, UNREACHED, dtype=np.int64)
    action = np.full(n_states, Action.UNREACHABLE, dtype=np.uint8)
    slab = grid.n_layers * grid.ny * grid.nx  # internal states are heading-major (transitions.state_index)
    goal_states = (np.arange(N_HEADINGS)[:, None] * slab + np.flatnonzero(goal_cells.mask.ravel())[None, :]).ravel()
    packed[goal_states] = 0
    action[goal_states] = Action.AT_GOAL
    n_water = int(model.water.sum()) * N_HEADINGS
    queue = _BucketQueue.start(goal_states, n_buckets=int(model.costs.max()) + 1)
    chunked = progress or not isinstance(meter, Silent)  # the search resumes where its budget ran out: same result
    budget = max(n_water // 20, 200_000) if chunked else n_states + 1
    meter.update("solving", 0, n_water, unit="states")
    t1 = time.perf_counter()
    while True:
        status = _search(
            grid.n_layers, grid.ny, grid.nx, masks, remaining, model.costs, robust,
            packed, action, *queue.arrays(), budget,
        )
        if status == _DONE:
            break
        if status == _BUDGET:
            meter.update("solving", min(int(queue.ctr[_SETTLED]), n_water), n_water, unit="states")
        if status == _BUDGET and progress:
            done = int(queue.ctr[_SETTLED])
            print(f"  solving: {done / n_water:6.1%} of water states settled", file=sys.stderr, flush=True)
        queue.grow(status)
    _unmark_settled(packed)
    meter.update("solving", n_water, n_water, unit="states")
    if progress:
        print(f"  search: {time.perf_counter() - t1:.2f} s", file=sys.stderr, flush=True)
    internal = (N_HEADINGS, grid.n_layers, grid.ny, grid.nx)
    return Solution(
        model=model,
        goal=goal,
        goal_cells=goal_cells,
        packed_value=np.moveaxis(packed.reshape(internal), 0, -1),  # views indexed [l, j, i, k]
        action=np.moveaxis(action.reshape(internal), 0, -1),
    )


PARALLEL_FROM_STATES = 2_000_000  # below this, starting threads costs more than it saves


def _build_predecessors(
    flow_dir: NDArray[np.int8], reach: NDArray[np.int8], lateral: bool, robust: bool, masks: NDArray[np.uint64],
    remaining: NDArray[np.uint8],
) -> None:
    """One forward pass: predecessor masks of every state and, for robust, outcome counts.

    ``masks[t, 0]`` (mask_h) bit ``b`` (b < 16: DRIFT, else FORWARD) and ``masks[t, 1]`` (mask_v) bit ``b``
    (b < 17: UP from the layer below, else DOWN from the layer above) name the
    predecessor by its displacement (``DISP_DI``/``DISP_DJ``). Targets keep the
    source's heading, so headings are independent and large grids do them in parallel.
    """
    driver = _preds_parallel if masks.shape[0] >= PARALLEL_FROM_STATES else _preds_serial
    driver(flow_dir, reach, lateral, robust, masks, remaining)


@numba.njit(cache=True, nogil=True, parallel=True)
def _preds_parallel(  # pragma: no cover
    flow_dir: NDArray[np.int8], reach: NDArray[np.int8], lateral: bool, robust: bool, masks: NDArray[np.uint64],
    remaining: NDArray[np.uint8],
) -> None:
    for k in numba.prange(8):
        _preds_heading(np.int64(k), flow_dir, reach, lateral, robust, masks, remaining)


@numba.njit(cache=True, nogil=True)
def _preds_serial(  # pragma: no cover
    flow_dir: NDArray[np.int8], reach: NDArray[np.int8], lateral: bool, robust: bool, masks: NDArray[np.uint64],
    remaining: NDArray[np.uint8],
) -> None:
    for k in range(8):
        _preds_heading(k, flow_dir, reach, lateral, robust, masks, remaining)


@numba.njit(cache=True, nogil=True)
def _preds_heading(  # pragma: no cover
    k: int | np.int64, flow_dir: NDArray[np.int8], reach: NDArray[np.int8], lateral: bool, robust: bool,
    masks: NDArray[np.uint64], remaining: NDArray[np.uint8],
) -> None:
    """The forward pass for the states of one heading (all their outcomes keep it).

    The outcome rule of ``transitions.outcomes_of`` (spec section 5) written out
    here, not called: numba counts references of the arrays passed to a function
    on every call (atomic operations, shared by the threads of the parallel pass).
    The tests compare both against the reference implementation.
    """
    L, ny, nx = flow_dir.shape
    one = np.uint64(1)
    disp_of = np.zeros(3, dtype=np.int64)  # distinct outcome displacements (DISP_DI/DISP_DJ index)
    for l in range(L):
        for j in range(ny):
            for i in range(nx):
                w = flow_dir[l, j, i]
                if w == -2:
                    continue
                s = ((k * L + l) * ny + j) * nx + i
                for ai in range(4):
                    a = MOVE_CODES[ai]
                    lt = l
                    if a == 4:
                        if l == 0 or flow_dir[l - 1, j, i] == -2:
                            if robust:
                                remaining[s, ai] = 0
                            continue
                        lt = l - 1
                    elif a == 5:
                        if l == L - 1 or flow_dir[l + 1, j, i] == -2:
                            if robust:
                                remaining[s, ai] = 0
                            continue
                        lt = l + 1
                    if w == -1:  # calm: FORWARD moves one tile, the others none (spec section 4)
                        n = 1 if a == 1 else 0
                        d = k
                    else:
                        diff = abs(k - w)
                        s45 = min(diff, 8 - diff)
                        n = 2 if s45 == 0 else (1 if s45 <= 2 else 0)
                        d = k if a == 1 else w
                    count = 0
                    if n == 0:
                        disp_of[0] = 0
                        count = 1
                    else:
                        n_dirs = 3 if lateral else 1
                        for m in range(n_dirs):
                            dd = d if m == 0 else ((d + 1) % 8 if m == 1 else (d + 7) % 8)
                            r = reach[lt, j, i, dd]
                            steps = min(n, r)
                            disp = 0 if steps == 0 else (1 + dd if steps == 1 else 9 + dd)
                            dup = False
                            for q in range(count):
                                if disp_of[q] == disp:
                                    dup = True
                            if not dup:
                                disp_of[count] = disp
                                count += 1
                    if robust:
                        remaining[s, ai] = count
                    dl = lt - l
                    for q in range(count):
                        disp = disp_of[q]
                        t = s + (dl * ny + DISP_DJ[disp]) * nx + DISP_DI[disp]
                        if t == s:
                            continue
                        if a == 0:
                            masks[t, 0] |= one << np.uint64(disp - 1)
                        elif a == 1:
                            masks[t, 0] |= one << np.uint64(disp + 15)
                        elif a == 4:
                            masks[t, 1] |= one << np.uint64(disp)
                        else:
                            masks[t, 1] |= one << np.uint64(disp + 17)


# Status codes of ``_search`` and the slots of the queue's counter array.
_DONE, _BUDGET, _BUCKETS_FULL, _FIFO_FULL, _BUCKET_TOO_BIG = 0, 1, 2, 3, 4
_LIVE, _COST, _P, _M, _FHEAD, _FTAIL, _IN_BUCKET, _SETTLED, _NEED = range(9)
_ROOM = 40  # queue slots one settled state may need: 2 rotations + 34 mask bits


@dataclass(eq=False)
class _BucketQueue:
    """Dial's bucket queue over cost: one contiguous array per cost modulo ``n_buckets``.

    ``bucket_state`` is ``(n_buckets, capacity)`` with ``count`` entries
    used per row; appends and the gather of a bucket are sequential in memory. The
    open bucket's entries, sorted, sit in ``cand_*``; zero-cost moves go to the FIFO.
    Arrays grow here, between calls of ``_search``, never inside it: rebinding
    arrays inside a numba loop costs a reference count per access.
    """

    bucket_state: NDArray[np.int32]
    count: NDArray[np.int64]
    cand_state: NDArray[np.int64]
    cand_key: NDArray[np.int64]
    fifo_state: NDArray[np.int64]
    fifo_key: NDArray[np.int64]
    ctr: NDArray[np.int64]

    @classmethod
    def start(cls, goal_states: NDArray[np.int64], *, n_buckets: int) -> _BucketQueue:
        n = goal_states.size
        cap = max(4096, 2 * n)
        bucket_state = np.zeros((n_buckets, cap), dtype=np.int32)  # state indices < 2**31 (table.MAX_STATES)
        bucket_state[0, :n] = goal_states
        count = np.zeros(n_buckets, dtype=np.int64)
        count[0] = n
        ctr = np.zeros(9, dtype=np.int64)
        ctr[_LIVE] = n
        empty = np.zeros(4096, dtype=np.int64)
        return cls(bucket_state, count,
                   np.zeros(cap, dtype=np.int64), np.zeros(cap, dtype=np.int64), empty.copy(), empty.copy(), ctr)

    def arrays(self) -> tuple[NDArray[np.int32], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
                              NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        """The arrays ``_search`` takes, in its order."""
        return (self.bucket_state, self.count, self.cand_state, self.cand_key,
                self.fifo_state, self.fifo_key, self.ctr)

    def grow(self, status: int) -> None:
        if status == _BUCKETS_FULL:
            self.bucket_state = np.concatenate([self.bucket_state, np.zeros_like(self.bucket_state)], axis=1)
        elif status == _FIFO_FULL:
            self.fifo_state, self.fifo_key = (np.concatenate([a, np.zeros_like(a)]) for a in (self.fifo_state, self.fifo_key))
        elif status == _BUCKET_TOO_BIG:
            size = int(self.ctr[_NEED])
            self.cand_state, self.cand_key = np.zeros(2 * size, np.int64), np.zeros(2 * size, np.int64)


@numba.njit(cache=True, nogil=True)
def _search(  # pragma: no cover
    L: int, ny: int, nx: int, masks: NDArray[np.uint64], remaining: NDArray[np.uint8], costs: NDArray[np.int64],
    robust: bool, packed: NDArray[np.int64], action: NDArray[np.uint8], bucket_state: NDArray[np.int32],
    count: NDArray[np.int64], cand_state: NDArray[np.int64], cand_key: NDArray[np.int64], fifo_state: NDArray[np.int64],
    fifo_key: NDArray[np.int64], ctr: NDArray[np.int64], budget: int,
) -> int:
    """Settle states in value order until done, ``budget`` more are settled, or a buffer is full.

    Inside the open bucket (cost ``c``), states are taken in order of steps from
    two sorted sources: ``cand`` (queued from earlier buckets, sorted on opening)
    and the FIFO of zero-cost moves made in this bucket.
    """
    n_buckets = count.size
    cap = bucket_state.shape[1]
    slab = L * ny * nx
    one = np.uint64(1)
    stop_at = ctr[_SETTLED] + budget
    # Predecessor of ``s`` named by mask bit ``e`` (mask_h bits 0..31, mask_v bits 32..65):
    # ``s + pred_offset[e]`` by action ``pred_action[e]`` (slot ``pred_slot[e]`` of ``remaining``).
    pred_offset = np.empty(66, dtype=np.int64)
    pred_action = np.empty(66, dtype=np.int64)
    pred_slot = np.empty(66, dtype=np.int64)
    for e in range(66):
        if e < 32:
            disp = e + 1 if e < 16 else e - 15
            pred_action[e] = 0 if e < 16 else 1
            pred_slot[e] = pred_action[e]
            dl = 0
        else:
            bit = e - 32
            disp = bit if bit < 17 else bit - 17
            pred_action[e] = 4 if bit < 17 else 5
            pred_slot[e] = 2 if bit < 17 else 3
            dl = 1 if bit < 17 else -1  # UP comes from the layer below, DOWN from above
        pred_offset[e] = dl * ny * nx - DISP_DJ[disp] * nx - DISP_DI[disp]
    # The bucket each action's moves go to from the open bucket (no division per state).
    target = np.empty(6, dtype=np.int64)
    while True:
        if ctr[_IN_BUCKET] == 0:
            if ctr[_LIVE] == 0:
                return _DONE
            if ctr[_SETTLED] >= stop_at:
                return _BUDGET
            b = ctr[_COST] % n_buckets
            size = count[b]
            if size > cand_state.size:
                ctr[_NEED] = size
                return _BUCKET_TOO_BIG
            m = 0
            for n in range(size):
                st = bucket_state[b, n]
                v = packed[st]
                if v >= 0 and (v >> 32) == ctr[_COST]:  # not settled (duplicates are skipped when taken)
                    cand_state[m] = st
                    cand_key[m] = v
                    m += 1
            ctr[_LIVE] -= size
            count[b] = 0
            if m > 1:
                _sort_by_key(cand_state, cand_key, m)
            ctr[_P] = 0
            ctr[_M] = m
            ctr[_FHEAD] = 0
            ctr[_FTAIL] = 0
            ctr[_IN_BUCKET] = 1
        c = ctr[_COST]
        for a in range(6):
            target[a] = (c + costs[a]) % n_buckets
        p = ctr[_P]
        m = ctr[_M]
        fh = ctr[_FHEAD]
        ft = ctr[_FTAIL]
        live = ctr[_LIVE]
        n_settled = ctr[_SETTLED]
        fifo_size = fifo_state.size
        while p < m or fh < ft:
            # Room for every push this state may make, or return to grow the buffers.
            full = False
            for a in range(6):
                if costs[a] > 0 and count[target[a]] + _ROOM > cap:
                    full = True
            if full:
                ctr[_P], ctr[_FHEAD], ctr[_FTAIL], ctr[_LIVE], ctr[_SETTLED] = p, fh, ft, live, n_settled
                return _BUCKETS_FULL
            if fifo_size - ft < _ROOM:
                if fh > 0:
                    n_live = ft - fh
                    fifo_state[:n_live] = fifo_state[fh:ft].copy()
                    fifo_key[:n_live] = fifo_key[fh:ft].copy()
                    fh, ft = 0, n_live
                if fifo_size - ft < _ROOM:
                    ctr[_P], ctr[_FHEAD], ctr[_FTAIL], ctr[_LIVE], ctr[_SETTLED] = p, fh, ft, live, n_settled
                    return _FIFO_FULL
            if fh < ft and (p >= m or fifo_key[fh] < cand_key[p]):
                s = fifo_state[fh]
                key = fifo_key[fh]
                fh += 1
            else:
                s = cand_state[p]
                key = cand_key[p]
                p += 1
            if packed[s] != key:  # settled (negative) or improved since queued
                continue
            packed[s] = ~key
            n_settled += 1
            k = s // slab
            # Rotations (ROTATE_LEFT from k-1, ROTATE_RIGHT from k+1), then the mask bits:
            # mask_h bit < 16 DRIFT, else FORWARD; mask_v bit < 17 UP from below, else DOWN from above.
            for which in range(4):
                if which < 2:
                    mask = one
                else:
                    mask = masks[s, which - 2]
                while mask != 0:
                    low = mask & (~mask + one)
                    bit = _CTZ_TABLE[((low * _DEBRUIJN) >> np.uint64(58))]
                    mask = mask ^ low
                    if which == 0:
                        a = 2
                        src = s - slab if k > 0 else s + 7 * slab
                    elif which == 1:
                        a = 3
                        src = s + slab if k < 7 else s - 7 * slab
                    else:
                        e = bit if which == 2 else bit + 32
                        src = s + pred_offset[e]
                        a = pred_action[e]
                        if packed[src] < 0:
                            continue
                        if robust:
                            ai = pred_slot[e]
                            remaining[src, ai] -= 1
                            if remaining[src, ai] != 0:
                                continue
                    # Offer (c_a, 1) + value to src; ties go to the lower cost, then code (spec 7).
                    # Written out here, not called: numba counts references of the arrays
                    # passed to a function, even an inlined one (atomic operations; the
                    # search at 4 M states took 0.84 s with them, 0.34 s without).
                    # A settled src holds ~value (negative): never beaten or tied.
                    cand = key + (costs[a] << 32) + 1
                    old = packed[src]
                    if cand >= old:
                        if cand == old:
                            b = action[src]
                            if costs[a] < costs[b] or (costs[a] == costs[b] and a < b):
                                action[src] = a
                        continue
                    packed[src] = cand
                    action[src] = a
                    if costs[a] == 0:
                        fifo_state[ft] = src
                        fifo_key[ft] = cand
                        ft += 1
                    elif (old >> 32) != (cand >> 32):
                        # A state already queued at this cost needs no second entry: a bucket's
                        # entries take their keys from ``packed`` when it opens.
                        bb = target[a]
                        n = count[bb]
                        bucket_state[bb, n] = src
                        count[bb] = n + 1
                        live += 1
        ctr[_LIVE], ctr[_SETTLED] = live, n_settled
        ctr[_IN_BUCKET] = 0
        ctr[_COST] += 1


@numba.njit(cache=True, nogil=True)
def _sort_by_key(states: NDArray[np.int64], keys: NDArray[np.int64], m: int) -> None:  # pragma: no cover
    """Sort the first ``m`` entries by key: a counting sort when the keys span little, else argsort."""
    lo = keys[0]
    hi = keys[0]
    for n in range(1, m):
        if keys[n] < lo:
            lo = keys[n]
        elif keys[n] > hi:
            hi = keys[n]
    span = hi - lo + 1
    if span > 4 * m + 64:
        order = np.argsort(keys[:m])
        states[:m] = states[:m][order]
        keys[:m] = keys[:m][order]
        return
    counts = np.zeros(span + 1, dtype=np.int64)
    for n in range(m):
        counts[keys[n] - lo + 1] += 1
    for n in range(span):
        counts[n + 1] += counts[n]
    out_s = np.empty(m, dtype=np.int64)
    out_k = np.empty(m, dtype=np.int64)
    for n in range(m):
        slot = counts[keys[n] - lo]
        counts[keys[n] - lo] = slot + 1
        out_s[slot] = states[n]
        out_k[slot] = keys[n]
    states[:m] = out_s
    keys[:m] = out_k


@numba.njit(cache=True, nogil=True)
def _unmark_settled(packed: NDArray[np.int64]) -> None:  # pragma: no cover
    """Settled states hold ``~value`` during the search; restore their values."""
    for n in range(packed.size):
        if packed[n] < 0:
            packed[n] = ~packed[n]


# Trailing-zero count of a 64-bit power of two by a de Bruijn multiply.
_DEBRUIJN = np.uint64(0x03F79D71B4CA8B09)
_CTZ_TABLE = np.zeros(64, dtype=np.int64)
for _b in range(64):
    _CTZ_TABLE[((1 << _b) * 0x03F79D71B4CA8B09 & 0xFFFFFFFFFFFFFFFF) >> 58] = _b


ENTRY_KERNEL = _search  # the kernel every paper plan runs: its first compile is the slow one
