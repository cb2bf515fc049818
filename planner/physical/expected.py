"""The expected-energy criterion of the physical model, in time near-linear in the state-actions.

A stochastic shortest path, V(s) = min_a (c(s, a) + sum_o P(o | s, a) V(o)) (Bertsekas, "Dynamic
Programming and Optimal Control", vol. 2, ch. 3), solved on the model's per-cell channels
without building per-(state, action) arrays:

1. **Proper states.** Only states from which some policy reaches the goal with probability 1 get
   a value. Repeat: a pair is usable when all its outcomes are alive; a backward search from the
   goal over usable pairs finds the states that stay alive. The last search's order (nearest the
   goal first) and its first-found pairs (each steps nearer the goal) are kept.
2. **Value iteration, Gauss-Seidel**, in that order with a cell's headings together
   (``by_cell``), from the exact value of those first pairs (an upper bound: the values fall
   towards the optimum and never pass it; from below, values would creep up by one cheap
   rotation per sweep). An action's chance of staying in its own state is solved for in the
   update, so a slow action costs no extra sweeps. It stops when a sweep lowers no value by more
   than 1e-4 of itself, or after ``max_iterations`` sweeps.
3. **Policy iteration with exact evaluation.** The greedy policy of those values (where it is
   not proper, the search's pairs) is evaluated exactly: its graph's strongly connected
   components (Tarjan) are solved sinks first, one state by one division, a larger component by
   one dense (or, above ``_DENSE_MAX`` states, sparse) linear solve, so the cost is linear in
   the states when components are small, as they are for a near-optimal policy. An action
   changes only when better by more than ``tolerance_wh``, so ties cannot make it cycle; as
   policy iteration improves the policy strictly at each step it ends, and ``max_iterations``
   bounds it anyway. The values are then those of the final policy to rounding, and no action is
   better than the chosen one by more than ``tolerance_wh`` (``residual_wh``).

The time-to-go is the final policy's mean duration, evaluated the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from planner.contract.errors import PlannerError
from planner.physical.model import PAIR_ACTIONS, PhysicalModel, action_channel, outcome_state

# Shorthands for the kernels' array arguments.
_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_I32 = NDArray[np.int32]
_I8 = NDArray[np.int8]
_Mask = NDArray[np.bool_]

_DENSE_MAX = 400  # components up to this many states are solved densely inside the compiled loop
_SWEEP_REL_TOL = 1e-4  # value iteration only warm-starts policy iteration: it stops at this relative rise


@dataclass(frozen=True, kw_only=True)
class ExpectedResult:
    """Per internal state: value (Wh), time-to-go (s), the chosen action's index into ``PAIR_ACTIONS``
    (-1 where none), and how the solver got there."""

    value_wh: NDArray[np.float64]
    time_s: NDArray[np.float64]
    choice: NDArray[np.int8]
    sweeps: int
    iterations: int
    residual_wh: float


def solve_expected(model: PhysicalModel, is_goal: NDArray[np.bool_]) -> ExpectedResult:
    """Solve the expected criterion on ``model`` for the goal states ``is_goal`` (internal index)."""
    ps = model.settings.physical
    args = _Model.of(model)
    if 8 * model.n_states >= 2**31:
        raise PlannerError(f"expected criterion: {model.n_states:,} states is more than this solver indexes")
    rev_ptr, rev_pair = _reverse(*args.arrays())
    first, alive, order = _proper(*args.arrays(), is_goal, rev_ptr, rev_pair)
    order = by_cell(order, model.water.size)
    usable = _usable(*args.arrays(), alive, is_goal)
    value = _evaluate(args, first, order, energy=True)  # an upper bound: the value of a proper policy
    sweeps = _sweeps(*args.arrays(), usable, order, value, _SWEEP_REL_TOL, ps.max_iterations)
    choice = _greedy(*args.arrays(), usable, order, value, first)
    choice = _make_proper(args, choice, first, order, is_goal)
    iterations = 0
    residual = 0.0
    for iterations in range(1, ps.max_iterations + 1):
        value = _evaluate(args, choice, order, energy=True)
        changed, residual = _improve(*args.arrays(), usable, order, value, choice, ps.tolerance_wh)
        if changed == 0:
            break  # the values are the policy's, and the pass that changed nothing measured its residual
    else:
        raise PlannerError(f"expected criterion: policy iteration did not settle in {ps.max_iterations} iterations "
                           "(physical.max_iterations)")
    time_s = _evaluate(args, choice, order, energy=False)
    value[~alive] = np.inf
    time_s[~alive] = np.inf
    value[is_goal] = 0.0
    time_s[is_goal] = 0.0
    choice[~alive | is_goal] = -1
    return ExpectedResult(value_wh=value, time_s=time_s, choice=choice, sweeps=sweeps, iterations=iterations,
                          residual_wh=residual)


def by_cell(order: NDArray[np.int64], n_cells: int) -> NDArray[np.int64]:
    """The states of ``order`` (internal indices, heading-major) with each cell's headings together, heading
    ascending, at the place of the cell's first state: the cells stay in the search's order.

    Every pass over the states reads a state's channels and their outcome lists, which lie together per
    cell, and its neighbours' values. In the search's order a cell's eight headings come at eight different
    moments, so on a grid larger than the cache each pass fetched a cell's data from memory up to eight
    times: at 4 M states a Gauss-Seidel sweep took 1.05 us a state, grouped 0.54 us (before a state was
    decoded once for all its actions, which made both faster). The sweeps lose a little of their order
    for it: 14 sweeps instead of 13 at 4 M states, 11 instead of 9 on the demo grid (docs/benchmarks.md)."""
    order = np.asarray(order, dtype=np.int64)
    cell = order % n_cells
    first = np.full(n_cells, order.size, dtype=np.int64)
    np.minimum.at(first, cell, np.arange(order.size))
    return order[np.argsort(first[cell] * 8 + order // n_cells, kind="stable")]


@dataclass(frozen=True, eq=False)
class _Model:
    """The model's channel arrays in the order the kernels take them."""

    water: _Mask
    n_ch: int
    n_actions: int
    ok: _Mask
    energy: _F64
    duration: _F64
    ptr: _I64
    slot: NDArray[np.int8]
    prob: _F64
    rot_wh: _F64
    rot_s: float

    @classmethod
    def of(cls, m: PhysicalModel) -> _Model:
        return cls(m.water, m.n_channels, m.n_actions, m.channel_ok, m.channel_energy_wh, m.channel_duration_s,
                   m.channel_ptr, m.slot, m.slot_prob, m.rotate_wh, m.rotate_s)

    def arrays(self) -> tuple[_Mask, int, int, _Mask, _F64, _I64, NDArray[np.int8], _F64, _F64]:
        return (self.water, self.n_ch, self.n_actions, self.ok, self.energy, self.ptr, self.slot, self.prob,
                self.rot_wh)


def _make_proper(args: _Model, choice: _I8, first: _I8, order: _I64, is_goal: _Mask) -> _I8:
    """``choice`` where it reaches the goal with probability 1, else the search's first pairs.

    Repeated until every state of ``order`` reaches the goal: a state that the search's pair takes
    always has an outcome nearer the goal, so the set of such states only grows, and it ends."""
    choice = choice.copy()
    while True:
        comp, _n = _components(*args.arrays(), choice, order, is_goal)
        bad = _improper(*args.arrays(), choice, order, is_goal, comp)
        if not bad.any():
            return choice
        choice[bad] = first[bad]


def _evaluate(args: _Model, choice: _I8, order: _I64, *, energy: bool) -> _F64:
    """The policy's exact expected energy (or duration) to the goal: components sinks first."""
    n = args.water.size * 8
    cost = args.energy if energy else args.duration
    rot = args.rot_wh
    if not energy:
        rot = np.full_like(args.rot_wh, args.rot_s)
        # As read-only as rot_wh: numba compiles (and loads) a kernel once per signature, and a
        # read-only array is another type than a writable one.
        rot.flags.writeable = args.rot_wh.flags.writeable
    is_goal = np.zeros(n, dtype=np.bool_)  # goal states are outside ``order`` and keep 0
    comp, n_comp = _components(*args.arrays(), choice, order, is_goal)
    members, comp_ptr = _group(comp, order, n_comp)
    value = np.zeros(n)
    start = 0
    while start < n_comp:
        stop = _solve_components(args.water, args.n_ch, args.ptr, args.slot, args.prob, cost, rot, choice,
                                 members, comp_ptr, comp, value, start, _DENSE_MAX)
        if stop < n_comp:  # a component too large for the dense solve
            _solve_sparse(args, cost, rot, choice, members[comp_ptr[stop]:comp_ptr[stop + 1]], comp, stop, value)
            stop += 1
        start = stop
    return value


def _solve_sparse(args: _Model, cost: _F64, rot: _F64, choice: _I8, states: _I64, comp: _I64, c: int,
                  value: _F64) -> None:
    rows, cols, probs, rhs = _block(args.water, args.n_ch, args.ptr, args.slot, args.prob, cost, rot, choice,
                                    states, comp, c, value)
    m = states.size
    A = sp.identity(m, format="csc") - sp.csr_matrix((probs, (rows, cols)), shape=(m, m)).tocsc()
    with np.errstate(all="ignore"):
        v = spla.spsolve(A, rhs)
    if not np.all(np.isfinite(v)):
        raise PlannerError("expected criterion: the policy's linear system is singular (an improper policy); "
                           "raise physical.min_cost_wh")
    value[states] = v


# --------------------------------------------------------------------------- compiled kernels


@numba.njit(cache=True, inline="always")
def _decode(s: int, L: int, ny: int, nx: int) -> tuple[int, int, int, int, int]:  # pragma: no cover
    """(k, cell, l, j, i) of an internal state index."""
    n_cells = L * ny * nx
    k = s // n_cells
    c = s % n_cells
    return k, c, c // (ny * nx), (c // nx) % ny, c % nx


@numba.njit(cache=True, inline="always")
def _turned(k: int, a: int) -> int:  # pragma: no cover
    """The heading after rotation ``a``: ROTATE_LEFT (2) k + 1, ROTATE_RIGHT k - 1."""
    return (k + 1) % 8 if a == 2 else (k + 7) % 8


@numba.njit(cache=True, inline="always")
def _pair(k: int, c: int, ai: int, n_ch: int, n_cells: int) -> tuple[int, int, int]:  # pragma: no cover
    """Pair ``ai`` of the state with heading ``k`` in cell ``c``: its action code, its channel's row (-1
    for a rotation) and, for a rotation, the one state it ends in (else -1)."""
    a = PAIR_ACTIONS[ai]
    ch = action_channel(a, k)
    if ch < 0:
        return a, -1, _turned(k, a) * n_cells + c
    return a, c * n_ch + ch, -1


@numba.njit(cache=True)
def _reverse(  # pragma: no cover
    water: _Mask, n_ch: int, n_actions: int, ok: _Mask, energy: _F64, ptr: _I64, slot: NDArray[np.int8], prob: _F64,
    rot_wh: _F64,
) -> tuple[_I64, _I32]:
    """For each state, the pairs (``s * 8 + ai``) that have it as an outcome."""
    L, ny, nx = water.shape
    n_cells = L * ny * nx
    n = 8 * n_cells
    count = np.zeros(n + 1, dtype=np.int64)
    fill = np.zeros(0, dtype=np.int64)
    rev = np.empty(0, dtype=np.int32)
    for pass_ in range(2):
        if pass_ == 1:
            for s in range(n):
                count[s + 1] += count[s]
            fill = count[:-1].copy()
            rev = np.empty(count[n], dtype=np.int32)
        for s in range(n):
            k, c, l, j, i = _decode(s, L, ny, nx)
            if not water.flat[c]:
                continue
            for ai in range(n_actions):
                a, q, o = _pair(k, c, ai, n_ch, n_cells)
                if q < 0:
                    if pass_ == 0:
                        count[o + 1] += 1
                    else:
                        rev[fill[o]] = s * 8 + ai
                        fill[o] += 1
                    continue
                if not ok[q]:
                    continue
                for t in range(ptr[q], ptr[q + 1]):
                    o = outcome_state(a, k, l, j, i, slot[t], L, ny, nx)
                    if pass_ == 0:
                        count[o + 1] += 1
                    else:
                        rev[fill[o]] = s * 8 + ai
                        fill[o] += 1
    return count, rev


@numba.njit(cache=True, inline="always")
def _mark_usable(  # pragma: no cover
    s: int, water: _Mask, n_ch: int, n_actions: int, ok: _Mask, ptr: _I64, slot: NDArray[np.int8], alive: _Mask,
    usable: _Mask,
) -> None:
    """``usable[s * 8 + ai]`` for the actions of an alive, non-goal state ``s``: the action is available (a
    rotation, or a channel without hazard) and all its outcomes are alive. ``s`` is decoded once."""
    L, ny, nx = water.shape
    k, c, l, j, i = _decode(s, L, ny, nx)  # alive: a water state
    for ai in range(n_actions):
        a, q, o = _pair(k, c, ai, n_ch, L * ny * nx)
        if q < 0:
            usable[s * 8 + ai] = alive[o]
            continue
        live = ok[q]
        if live:
            for t in range(ptr[q], ptr[q + 1]):
                if not alive[outcome_state(a, k, l, j, i, slot[t], L, ny, nx)]:
                    live = False
                    break
        usable[s * 8 + ai] = live


@numba.njit(cache=True)
def _proper(  # pragma: no cover
    water: _Mask, n_ch: int, n_actions: int, ok: _Mask, energy: _F64, ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, rot_wh: _F64, is_goal: _Mask, rev_ptr: _I64, rev: _I32,
) -> tuple[_I8, _Mask, _I64]:
    """States that reach the goal with probability 1 under some policy; the last backward search's
    first-found pair per state and its order (non-goal states, nearest the goal first)."""
    n = is_goal.size
    alive = np.empty(n, dtype=np.bool_)
    n_cells = water.size
    for s in range(n):
        alive[s] = water.flat[s % n_cells]
    first = np.full(n, -1, dtype=np.int8)
    queue = np.empty(n, dtype=np.int64)
    usable = np.zeros(n * 8, dtype=np.bool_)
    while True:
        usable[:] = False
        for s in range(n):
            if alive[s] and not is_goal[s]:
                _mark_usable(s, water, n_ch, n_actions, ok, ptr, slot, alive, usable)
        found = np.zeros(n, dtype=np.bool_)
        first[:] = -1
        head = 0
        tail = 0
        for s in range(n):
            if is_goal[s] and alive[s]:
                found[s] = True
                queue[tail] = s
                tail += 1
        n_goal = tail
        while head < tail:
            o = queue[head]
            head += 1
            for r in range(rev_ptr[o], rev_ptr[o + 1]):
                pid = rev[r]
                s = pid // 8
                if usable[pid] and not found[s]:
                    found[s] = True
                    first[s] = pid % 8
                    queue[tail] = s
                    tail += 1
        changed = False
        for s in range(n):
            if alive[s] and not found[s]:
                alive[s] = False
                changed = True
        if not changed:
            return first, alive, queue[n_goal:tail].copy()


@numba.njit(cache=True)
def _usable(  # pragma: no cover
    water: _Mask, n_ch: int, n_actions: int, ok: _Mask, energy: _F64, ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, rot_wh: _F64, alive: _Mask, is_goal: _Mask,
) -> _Mask:
    n = alive.size
    usable = np.zeros(n * 8, dtype=np.bool_)
    for s in range(n):
        if alive[s] and not is_goal[s]:
            _mark_usable(s, water, n_ch, n_actions, ok, ptr, slot, alive, usable)
    return usable


@numba.njit(cache=True, inline="always")
def _q(  # pragma: no cover
    s: int, ai: int, water: _Mask, n_ch: int, cost: _F64, ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, rot: _F64, value: _F64,
) -> tuple[float, float]:
    """(c + sum over the other outcomes of P V, P(own state)) of pair (s, ai)."""
    L, ny, nx = water.shape
    k, c, l, j, i = _decode(s, L, ny, nx)
    return _q_at(s, k, c, l, j, i, ai, L, ny, nx, n_ch, cost, ptr, slot, prob, rot, value)


@numba.njit(cache=True, inline="always")
def _q_at(  # pragma: no cover
    s: int, k: int, c: int, l: int, j: int, i: int, ai: int, L: int, ny: int, nx: int, n_ch: int, cost: _F64,
    ptr: _I64, slot: NDArray[np.int8], prob: _F64, rot: _F64, value: _F64,
) -> tuple[float, float]:
    """``_q`` of a state already decoded: the loops over a state's actions decode it once, not once
    an action (its divisions by the grid's sizes cost more than the action's sum)."""
    a, q, o = _pair(k, c, ai, n_ch, L * ny * nx)
    if q < 0:
        return rot[c] + value[o], 0.0
    total = cost[q]
    p_self = 0.0
    for t in range(ptr[q], ptr[q + 1]):
        o = outcome_state(a, k, l, j, i, slot[t], L, ny, nx)
        if o == s:
            p_self += prob[t]
        else:
            total += prob[t] * value[o]
    return total, p_self


@numba.njit(cache=True)
def _sweeps(  # pragma: no cover
    water: _Mask, n_ch: int, n_actions: int, ok: _Mask, energy: _F64, ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, rot_wh: _F64, usable: _Mask, order: _I64, value: _F64, rel_tol: float, max_sweeps: int,
) -> int:
    """Gauss-Seidel value iteration in ``order``, in place; returns the sweeps made."""
    L, ny, nx = water.shape
    for sweep in range(1, max_sweeps + 1):
        worst = 0.0
        for s in order:
            k, c, l, j, i = _decode(s, L, ny, nx)
            best = np.inf
            for ai in range(n_actions):
                if not usable[s * 8 + ai]:
                    continue
                total, p_self = _q_at(s, k, c, l, j, i, ai, L, ny, nx, n_ch, energy, ptr, slot, prob, rot_wh, value)
                if p_self < 1.0:
                    v = total / (1.0 - p_self)
                    if v < best:
                        best = v
            if best < value[s]:
                fall = (value[s] - best) / best
                if fall > worst:
                    worst = fall
                value[s] = best
        if worst <= rel_tol:
            return sweep
    return max_sweeps


@numba.njit(cache=True, inline="always")
def _best(  # pragma: no cover
    s: int, water: _Mask, n_ch: int, n_actions: int, energy: _F64, ptr: _I64, slot: NDArray[np.int8], prob: _F64,
    rot_wh: _F64, usable: _Mask, value: _F64,
) -> tuple[float, int]:
    """The least Q over the usable pairs of ``s`` and its action index (ties: the lower code); -1 where none."""
    L, ny, nx = water.shape
    k, c, l, j, i = _decode(s, L, ny, nx)
    best = np.inf
    best_ai = -1
    for ai in range(n_actions):
        if usable[s * 8 + ai]:
            total, p_self = _q_at(s, k, c, l, j, i, ai, L, ny, nx, n_ch, energy, ptr, slot, prob, rot_wh, value)
            qv = total + p_self * value[s]
            if qv < best:
                best = qv
                best_ai = ai
    return best, best_ai


@numba.njit(cache=True)
def _greedy(  # pragma: no cover
    water: _Mask, n_ch: int, n_actions: int, ok: _Mask, energy: _F64, ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, rot_wh: _F64, usable: _Mask, order: _I64, value: _F64, fallback: _I8,
) -> _I8:
    choice = fallback.copy()
    for s in order:
        _best_q, best_ai = _best(s, water, n_ch, n_actions, energy, ptr, slot, prob, rot_wh, usable, value)
        if best_ai >= 0:
            choice[s] = best_ai
    return choice


@numba.njit(cache=True)
def _improve(  # pragma: no cover
    water: _Mask, n_ch: int, n_actions: int, ok: _Mask, energy: _F64, ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, rot_wh: _F64, usable: _Mask, order: _I64, value: _F64, choice: _I8, tolerance: float,
) -> tuple[int, float]:
    """Policy improvement in place: the best pair where better than the current one by more than
    ``tolerance``. Returns how many states changed, and the residual: the largest amount by which
    some action beats ``value`` (Wh; the summary's, once nothing changes)."""
    changed = 0
    worst = 0.0
    for s in order:
        total, p_self = _q(s, choice[s], water, n_ch, energy, ptr, slot, prob, rot_wh, value)
        current = total + p_self * value[s]
        best, best_ai = _best(s, water, n_ch, n_actions, energy, ptr, slot, prob, rot_wh, usable, value)
        if value[s] - best > worst:
            worst = value[s] - best
        if best_ai >= 0 and best < current - tolerance:
            choice[s] = best_ai
            changed += 1
    return changed, worst


@numba.njit(cache=True)
def _successors(  # pragma: no cover
    s: int, ai: int, water: _Mask, n_ch: int, ptr: _I64, slot: NDArray[np.int8], out: _I64,
) -> int:
    """The outcome states of pair (s, ai) into ``out``; returns how many."""
    L, ny, nx = water.shape
    k, c, l, j, i = _decode(s, L, ny, nx)
    a, q, o = _pair(k, c, ai, n_ch, L * ny * nx)
    if q < 0:
        out[0] = o
        return 1
    m = 0
    for t in range(ptr[q], ptr[q + 1]):
        out[m] = outcome_state(a, k, l, j, i, slot[t], L, ny, nx)
        m += 1
    return m


@numba.njit(cache=True)
def _components(  # pragma: no cover
    water: _Mask, n_ch: int, n_actions: int, ok: _Mask, energy: _F64, ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, rot_wh: _F64, choice: _I8, order: _I64, is_goal: _Mask,
) -> tuple[_I64, int]:
    """Strongly connected components of the policy's graph over ``order`` (Tarjan, iterative).

    Returns each state's component (-1 outside ``order``), numbered in the order Tarjan closes
    them: every edge leads to a component of lower or equal number, so ascending numbers are
    sinks first."""
    n = choice.size
    inside = np.zeros(n, dtype=np.bool_)
    for s in order:
        inside[s] = not is_goal[s]
    index = np.full(n, -1, dtype=np.int64)
    low = np.zeros(n, dtype=np.int64)
    comp = np.full(n, -1, dtype=np.int64)
    on_stack = np.zeros(n, dtype=np.bool_)
    stack = np.empty(order.size, dtype=np.int64)
    call = np.empty(order.size, dtype=np.int64)  # the DFS path
    edge = np.empty(order.size, dtype=np.int64)  # next successor to visit, per path entry
    succ = np.empty(32, dtype=np.int64)
    sp_ = 0
    counter = 0
    n_comp = 0
    for root in order:
        if not inside[root] or index[root] >= 0:
            continue
        depth = 0
        call[0] = root
        edge[0] = 0
        index[root] = counter
        low[root] = counter
        counter += 1
        stack[sp_] = root
        sp_ += 1
        on_stack[root] = True
        while depth >= 0:
            v = call[depth]
            m = _successors(v, choice[v], water, n_ch, ptr, slot, succ)
            descended = False
            while edge[depth] < m:
                w = succ[edge[depth]]
                edge[depth] += 1
                if not inside[w]:
                    continue
                if index[w] < 0:
                    index[w] = counter
                    low[w] = counter
                    counter += 1
                    stack[sp_] = w
                    sp_ += 1
                    on_stack[w] = True
                    depth += 1
                    call[depth] = w
                    edge[depth] = 0
                    descended = True
                    break
                if on_stack[w] and index[w] < low[v]:
                    low[v] = index[w]
            if descended:
                continue
            if low[v] == index[v]:
                while True:
                    sp_ -= 1
                    w = stack[sp_]
                    on_stack[w] = False
                    comp[w] = n_comp
                    if w == v:
                        break
                n_comp += 1
            depth -= 1
            if depth >= 0:
                u = call[depth]
                if low[v] < low[u]:
                    low[u] = low[v]
    return comp, n_comp


@numba.njit(cache=True)
def _improper(  # pragma: no cover
    water: _Mask, n_ch: int, n_actions: int, ok: _Mask, energy: _F64, ptr: _I64, slot: NDArray[np.int8],
    prob: _F64, rot_wh: _F64, choice: _I8, order: _I64, is_goal: _Mask, comp: _I64,
) -> _Mask:
    """States that may never reach the goal under ``choice``: those in, or leading into, a component
    that no edge leaves (components ascend sinks first, so one pass in that order decides)."""
    n = choice.size
    n_comp = 0
    for s in order:
        if comp[s] + 1 > n_comp:
            n_comp = comp[s] + 1
    exits = np.zeros(n_comp, dtype=np.bool_)
    bad = np.zeros(n_comp, dtype=np.bool_)
    members, cptr = _group(comp, order, n_comp)
    succ = np.empty(32, dtype=np.int64)
    for c in range(n_comp):
        for t in range(cptr[c], cptr[c + 1]):
            s = members[t]
            m = _successors(s, choice[s], water, n_ch, ptr, slot, succ)
            for e in range(m):
                w = succ[e]
                if comp[w] == c:
                    continue
                if comp[w] >= 0 and bad[comp[w]]:
                    bad[c] = True
                exits[c] = True  # to the goal or a lower component
        if not exits[c]:
            bad[c] = True
    out = np.zeros(n, dtype=np.bool_)
    for s in order:
        if comp[s] >= 0 and bad[comp[s]]:
            out[s] = True
    return out


@numba.njit(cache=True)
def _group(comp: _I64, order: _I64, n_comp: int) -> tuple[_I64, _I64]:  # pragma: no cover
    """The states of each component, contiguous, components ascending."""
    cptr = np.zeros(n_comp + 1, dtype=np.int64)
    for s in order:
        if comp[s] >= 0:
            cptr[comp[s] + 1] += 1
    for c in range(n_comp):
        cptr[c + 1] += cptr[c]
    fill = cptr[:-1].copy()
    members = np.empty(cptr[n_comp], dtype=np.int64)
    for s in order:
        if comp[s] >= 0:
            members[fill[comp[s]]] = s
            fill[comp[s]] += 1
    return members, cptr


@numba.njit(cache=True)
def _solve_components(  # pragma: no cover
    water: _Mask, n_ch: int, ptr: _I64, slot: NDArray[np.int8], prob: _F64, cost: _F64, rot: _F64, choice: _I8,
    members: _I64, cptr: _I64, comp: _I64, value: _F64, start: int, dense_max: int,
) -> int:
    """Solve components from ``start`` on, sinks first; stop at one larger than ``dense_max`` and
    return its number (or the count when all are done)."""
    n_comp = cptr.size - 1
    L, ny, nx = water.shape
    for c in range(start, n_comp):
        lo = cptr[c]
        m = cptr[c + 1] - lo
        if m > dense_max:
            return c
        if m == 1:
            s = members[lo]
            total, p_self = _q(s, choice[s], water, n_ch, cost, ptr, slot, prob, rot, value)
            value[s] = total / (1.0 - p_self) if p_self < 1.0 else np.inf
            continue
        rows, cols, probs, rhs = _block(water, n_ch, ptr, slot, prob, cost, rot, choice, members[lo:lo + m], comp,
                                        c, value)
        A = np.eye(m)
        for e in range(rows.size):
            A[rows[e], cols[e]] -= probs[e]
        x = np.linalg.solve(A, rhs)
        for r in range(m):
            value[members[lo + r]] = x[r]
    return n_comp


@numba.njit(cache=True)
def _block(  # pragma: no cover
    water: _Mask, n_ch: int, ptr: _I64, slot: NDArray[np.int8], prob: _F64, cost: _F64, rot: _F64, choice: _I8,
    states: _I64, comp: _I64, c: int, value: _F64,
) -> tuple[_I64, _I64, _F64, _F64]:
    """One component's equations V = c + P_inside V + P_outside V_known, as (row, col, P) and the
    right-hand side."""
    L, ny, nx = water.shape
    m = states.size
    local = numba.typed.Dict.empty(key_type=numba.types.int64, value_type=numba.types.int64)
    for r in range(m):
        local[states[r]] = r
    cap = 32 * m
    rows = np.empty(cap, dtype=np.int64)
    cols = np.empty(cap, dtype=np.int64)
    probs = np.empty(cap)
    rhs = np.empty(m)
    e = 0
    for r in range(m):
        s = states[r]
        ai = choice[s]
        k, cc, l, j, i = _decode(s, L, ny, nx)
        a, q, o = _pair(k, cc, ai, n_ch, L * ny * nx)
        if q < 0:
            rhs[r] = rot[cc]
            if comp[o] == c:
                rows[e], cols[e], probs[e] = r, local[o], 1.0
                e += 1
            else:
                rhs[r] += value[o]
            continue
        rhs[r] = cost[q]
        for t in range(ptr[q], ptr[q + 1]):
            o = outcome_state(a, k, l, j, i, slot[t], L, ny, nx)
            if comp[o] == c:
                rows[e], cols[e], probs[e] = r, local[o], prob[t]
                e += 1
            else:
                rhs[r] += prob[t] * value[o]
    return rows[:e], cols[:e], probs[:e], rhs
