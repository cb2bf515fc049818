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
masks saying which neighbouring states reach it by which action (the
displacement between them is at most two tiles), built by one forward pass.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from planner.actions import Action
from planner.errors import GoalError
from planner.headings import DI, DJ, N_HEADINGS
from planner.settings import Goal
from planner.transitions import FLOW_LAND, TransitionModel, outcomes_of

UNREACHED = np.iinfo(np.int64).max
STEPS_BITS = 32
STEPS_MASK = (1 << STEPS_BITS) - 1
# Horizontal displacements between a state and its successor: index 0 is none,
# 1 + d is one tile along d, 9 + d two tiles along d.
DISP_DI = np.concatenate([[0], DI, 2 * DI]).astype(np.int64)
DISP_DJ = np.concatenate([[0], DJ, 2 * DJ]).astype(np.int64)
_DISP_INDEX = np.full((5, 5), -1, dtype=np.int64)
for _n in range(17):
    _DISP_INDEX[DISP_DJ[_n] + 2, DISP_DI[_n] + 2] = _n
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


def locate_goal(model: TransitionModel, goal: Goal) -> GoalCells:
    """Goal cell, layer and goal-cell mask, or a GoalError that says why not (spec section 6)."""
    grid = model.grid
    i, j, outside = grid.nearest_cell(goal.lon_deg, goal.lat_deg)
    where = f"goal ({goal.lon_deg:.5f}, {goal.lat_deg:.5f}, {goal.depth_m:g} m)"
    if outside > 0.5:
        b = grid.bbox
        raise GoalError(
            f"{where} lies {outside:.2f} cells outside the planning grid "
            f"(lon {b.west_deg:.5f}..{b.east_deg:.5f}, lat {b.south_deg:.5f}..{b.north_deg:.5f}); "
            "expected at most half a cell outside"
        )
    if goal.depth_m < 0 or goal.depth_m > grid.depth_m[-1] + 0.5 * (
        grid.depth_m[-1] - grid.depth_m[-2] if grid.n_layers > 1 else 0.0
    ):
        raise GoalError(
            f"{where}: depth {goal.depth_m:g} m is outside the layers "
            f"{', '.join(f'{d:g}' for d in grid.depth_m)} m"
        )
    l = grid.nearest_layer(goal.depth_m)
    water = model.water
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


def solve(model: TransitionModel, goal: Goal, *, progress: bool = False) -> Solution:
    """Cost-to-go and policy for every state (spec section 7), exactly.

    With ``progress``, long solves print their progress to stderr.
    """
    goal_cells = locate_goal(model, goal)
    grid = model.grid
    robust = model.settings.criterion == "robust"
    n_states = grid.n_states
    mask_h = np.zeros(n_states, dtype=np.uint64)
    mask_v = np.zeros(n_states, dtype=np.uint64)
    remaining = np.zeros((n_states, 4) if robust else (1, 4), dtype=np.uint8)
    t0 = time.perf_counter()
    _build_predecessors(model.flow_dir, model.reach, model.lateral, robust, mask_h, mask_v, remaining)
    if progress:
        print(f"  transitions: {time.perf_counter() - t0:.2f} s", file=sys.stderr, flush=True)

    packed = np.full(n_states, UNREACHED, dtype=np.int64)
    action = np.full(n_states, Action.UNREACHABLE, dtype=np.uint8)
    settled = np.zeros(n_states, dtype=np.uint8)
    goal_states = (np.flatnonzero(goal_cells.mask.ravel())[:, None] * N_HEADINGS + np.arange(N_HEADINGS)).ravel()
    packed[goal_states] = 0
    action[goal_states] = Action.AT_GOAL
    n_water = int(model.water.sum()) * N_HEADINGS
    queue = _new_queue(goal_states, int(model.costs.max()) + 1)
    budget = max(n_water // 20, 200_000) if progress else n_states + 1
    done = 0
    t1 = time.perf_counter()
    while True:
        queue, n = _dijkstra(
            grid.n_layers, grid.ny, grid.nx, mask_h, mask_v, remaining, model.costs, robust,
            packed, action, settled, queue, budget,
        )
        done += n
        if progress:
            print(f"  solving: {done / n_water:6.1%} of water states settled", file=sys.stderr, flush=True)
        if queue[-1][0] == 0:  # no entries left
            break
    if progress:
        print(f"  search: {time.perf_counter() - t1:.2f} s", file=sys.stderr, flush=True)
    shape = grid.shape
    return Solution(
        model=model,
        goal=goal,
        goal_cells=goal_cells,
        packed_value=packed.reshape(shape),
        action=action.reshape(shape),
    )


def _new_queue(goal_states: NDArray[np.int64], n_buckets: int) -> tuple:
    cap = max(1024, 2 * goal_states.size)
    pool_state = np.empty(cap, dtype=np.int64)
    pool_key = np.empty(cap, dtype=np.int64)
    pool_next = np.empty(cap, dtype=np.int64)
    head = np.full(n_buckets, -1, dtype=np.int64)
    n = goal_states.size
    pool_state[:n] = goal_states
    pool_key[:n] = 0
    pool_next[:n] = np.arange(1, n + 1)
    if n:
        pool_next[n - 1] = -1
        head[0] = 0
    # counters: live entries, used slots, free-list head, current cost
    counters = np.array([n, n, -1, 0], dtype=np.int64)
    return (pool_state, pool_key, pool_next, head, counters)


@numba.njit(cache=True, nogil=True, parallel=True)
def _build_predecessors(flow_dir, reach, lateral, robust, mask_h, mask_v, remaining):  # pragma: no cover
    """One forward pass: predecessor masks of every state and, for robust, outcome counts.

    ``mask_h`` bit ``b`` (b < 16: DRIFT, else FORWARD) and ``mask_v`` bit ``b``
    (b < 17: UP from the layer below, else DOWN from the layer above) name the
    predecessor by its displacement (``DISP_DI``/``DISP_DJ``). Targets keep the
    source's heading, so the headings are independent and run in parallel.
    """
    L, ny, nx = flow_dir.shape
    one = np.uint64(1)
    for kk in numba.prange(8):
        k = np.int64(kk)
        out = np.empty(3, dtype=np.int64)
        for l in range(L):
            for j in range(ny):
                for i in range(nx):
                    if flow_dir[l, j, i] == -2:
                        continue
                    s = ((l * ny + j) * nx + i) * 8 + k
                    for ai in range(4):
                        a = _MOVE_CODES[ai]
                        n = outcomes_of(flow_dir, reach, lateral, l, j, i, k, a, out)
                        if robust:
                            remaining[s, ai] = n
                        for q in range(n):
                            t = out[q]
                            if t == s:
                                continue
                            tc = t // 8
                            ti = tc % nx
                            tj = (tc // nx) % ny
                            disp = _DISP_INDEX_NB[tj - j + 2, ti - i + 2]
                            if a == 0:
                                mask_h[t] |= one << np.uint64(disp - 1)
                            elif a == 1:
                                mask_h[t] |= one << np.uint64(disp + 15)
                            elif a == 4:
                                mask_v[t] |= one << np.uint64(disp)
                            else:
                                mask_v[t] |= one << np.uint64(disp + 17)


@numba.njit(cache=True, nogil=True)
def _dijkstra(L, ny, nx, mask_h, mask_v, remaining, costs, robust, packed, action, settled, queue, budget):  # pragma: no cover
    """Settle states bucket by bucket until ``budget`` states are settled or the queue is empty."""
    pool_state, pool_key, pool_next, head, counters = queue
    live, used, free, c = counters[0], counters[1], counters[2], counters[3]
    n_buckets = head.size
    n_settled = 0
    fifo_state = np.empty(1024, dtype=np.int64)
    fifo_key = np.empty(1024, dtype=np.int64)
    one = np.uint64(1)
    while live > 0 and n_settled < budget:
        b = c % n_buckets
        # Gather this bucket's entries (all have cost c) and free their nodes.
        count = 0
        node = head[b]
        while node != -1:
            count += 1
            node = pool_next[node]
        cand_state = np.empty(count, dtype=np.int64)
        cand_key = np.empty(count, dtype=np.int64)
        m = 0
        node = head[b]
        while node != -1:
            nxt = pool_next[node]
            st = pool_state[node]
            if settled[st] == 0 and packed[st] == pool_key[node]:
                cand_state[m] = st
                cand_key[m] = pool_key[node]
                m += 1
            pool_next[node] = free
            free = node
            node = nxt
        live -= count
        head[b] = -1
        order = np.argsort(cand_key[:m], kind="mergesort")
        p = 0
        f_head = 0
        f_tail = 0
        while p < m or f_head < f_tail:
            if f_head < f_tail and (p >= m or fifo_key[f_head] < cand_key[order[p]]):
                s = fifo_state[f_head]
                key = fifo_key[f_head]
                f_head += 1
            else:
                s = cand_state[order[p]]
                key = cand_key[order[p]]
                p += 1
            if settled[s] != 0 or packed[s] != key:
                continue
            settled[s] = 1
            n_settled += 1
            k = s % 8
            tc = s // 8
            i = tc % nx
            j = (tc // nx) % ny
            l = tc // (nx * ny)
            base = s - k
            # Predecessors by rotation: ROTATE_LEFT from k-1, ROTATE_RIGHT from k+1.
            for r in range(2):
                src = base + ((k + 7) % 8 if r == 0 else (k + 1) % 8)
                a = 2 + r
                pushed = _relax(src, a, key, costs, packed, action, settled)
                if pushed:
                    if costs[a] == 0:
                        if f_tail == fifo_state.size:
                            fifo_state, fifo_key = _grow_fifo(fifo_state, fifo_key, f_head, f_tail)
                            f_tail -= f_head
                            f_head = 0
                        fifo_state[f_tail] = src
                        fifo_key[f_tail] = packed[src]
                        f_tail += 1
                    else:
                        if free == -1 and used == pool_state.size:
                            pool_state, pool_key, pool_next = _grow_pool(pool_state, pool_key, pool_next)
                        if free != -1:
                            node = free
                            free = pool_next[node]
                        else:
                            node = used
                            used += 1
                        bb = (c + costs[a]) % n_buckets
                        pool_state[node] = src
                        pool_key[node] = packed[src]
                        pool_next[node] = head[bb]
                        head[bb] = node
                        live += 1
            # Predecessors by drift/forward (same layer) and up/down (other layers).
            for which in range(2):
                mask = mask_h[s] if which == 0 else mask_v[s]
                bit = 0
                while mask != 0:
                    if mask & one:
                        if which == 0:
                            a = 0 if bit < 16 else 1
                            disp = bit + 1 if bit < 16 else bit - 15
                            ai = a
                            ls = l
                        else:
                            a = 4 if bit < 17 else 5
                            disp = bit if bit < 17 else bit - 17
                            ai = 2 if bit < 17 else 3
                            ls = l + 1 if bit < 17 else l - 1
                        js = j - _DISP_DJ_NB[disp]
                        is_ = i - _DISP_DI_NB[disp]
                        src = ((ls * ny + js) * nx + is_) * 8 + k
                        usable = settled[src] == 0
                        if usable and robust:
                            remaining[src, ai] -= 1
                            usable = remaining[src, ai] == 0
                        if usable and _relax(src, a, key, costs, packed, action, settled):
                            if costs[a] == 0:
                                if f_tail == fifo_state.size:
                                    fifo_state, fifo_key = _grow_fifo(fifo_state, fifo_key, f_head, f_tail)
                                    f_tail -= f_head
                                    f_head = 0
                                fifo_state[f_tail] = src
                                fifo_key[f_tail] = packed[src]
                                f_tail += 1
                            else:
                                if free == -1 and used == pool_state.size:
                                    pool_state, pool_key, pool_next = _grow_pool(pool_state, pool_key, pool_next)
                                if free != -1:
                                    node = free
                                    free = pool_next[node]
                                else:
                                    node = used
                                    used += 1
                                bb = (c + costs[a]) % n_buckets
                                pool_state[node] = src
                                pool_key[node] = packed[src]
                                pool_next[node] = head[bb]
                                head[bb] = node
                                live += 1
                    mask = mask >> one
                    bit += 1
        c += 1
    counters[0] = live
    counters[1] = used
    counters[2] = free
    counters[3] = c
    return (pool_state, pool_key, pool_next, head, counters), n_settled


@numba.njit(cache=True, nogil=True, inline="always")
def _relax(src, a, key, costs, packed, action, settled):  # pragma: no cover
    """Offer ``(c_a, 1) + value`` to ``src``; ties go to the lower cost, then code (spec 7).

    Returns True when the value improved (the state must be queued again).
    """
    if settled[src] != 0:
        return False
    cand = key + (costs[a] << 32) + 1
    cur = packed[src]
    if cand < cur:
        packed[src] = cand
        action[src] = a
        return True
    if cand == cur:
        b = action[src]
        if costs[a] < costs[b] or (costs[a] == costs[b] and a < b):
            action[src] = a
    return False


@numba.njit(cache=True, nogil=True)
def _grow_pool(pool_state, pool_key, pool_next):  # pragma: no cover
    n = pool_state.size
    s2 = np.empty(2 * n, dtype=np.int64)
    k2 = np.empty(2 * n, dtype=np.int64)
    n2 = np.empty(2 * n, dtype=np.int64)
    s2[:n] = pool_state
    k2[:n] = pool_key
    n2[:n] = pool_next
    return s2, k2, n2


@numba.njit(cache=True, nogil=True)
def _grow_fifo(fifo_state, fifo_key, f_head, f_tail):  # pragma: no cover
    n = f_tail - f_head
    size = max(2 * n, 1024)
    s2 = np.empty(size, dtype=np.int64)
    k2 = np.empty(size, dtype=np.int64)
    s2[:n] = fifo_state[f_head:f_tail]
    k2[:n] = fifo_key[f_head:f_tail]
    return s2, k2


_MOVE_CODES = MOVE_CODES
_DISP_INDEX_NB = _DISP_INDEX
_DISP_DI_NB = DISP_DI
_DISP_DJ_NB = DISP_DJ
