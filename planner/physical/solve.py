"""Criteria for the physical model: worst case (``robust``) and expected energy (``expected``).

docs/physical-model.md. Both give the cost-to-go in watt-hours and the action of every state.

- ``robust``: V(s) = min over actions of the max over the action's outcomes o of
  (E_max(s, a, o) + V(o)), E_max being the largest energy of the samples that ended in o. Solved
  exactly by Dijkstra generalised to AND-OR graphs (Knuth, "A generalization of Dijkstra's
  algorithm", IPL 6, 1977): an action's value is known once all its outcomes are settled. An
  action that may leave the vehicle in its own state (it had not moved a cell spacing when
  ``max_transition_s`` ran out) may do so for ever in the worst case, so it is never chosen:
  its own state is an outcome that is never settled before the state itself.
- ``expected``: a stochastic shortest path, V = min_a (c(s, a) + sum_o P(o | s, a) V(o)),
  solved by policy iteration on sparse matrices (Bertsekas, "Dynamic Programming and Optimal
  Control", vol. 2, ch. 3). Only states from which some policy reaches the goal with
  probability 1 get a value (found by repeated backward search); the first policy steps to a
  state nearer the goal in that search, so it is proper. Every cost is at least
  ``min_cost_wh`` > 0, so an improper policy costs infinity and policy iteration never picks
  one: a zero-cost cycle cannot trap it. An action changes only when better by more than
  ``tolerance_wh``, so ties cannot make it cycle, and ``max_iterations`` bounds it anyway.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.errors import PlannerError
from planner.physical.model import PhysicalModel
from planner.contract.settings import Goal
from planner.paper.solve import GoalCells, goal_cells_on


@dataclass(frozen=True, kw_only=True)
class PhysicalStep:
    """One state along a nominal path, the action taken and its mean duration."""

    l: int
    j: int
    i: int
    k: int
    action: Action
    duration_s: float = 0.0


@dataclass(frozen=True, eq=False, kw_only=True)
class PhysicalSolution:
    """Cost-to-go (Wh), time-to-go (s) and action of every state, arrays ``(L, ny, nx, 8)``."""

    model: PhysicalModel
    goal: Goal
    goal_cells: GoalCells
    value_wh: NDArray[np.float64]  # inf where unreachable or land
    time_s: NDArray[np.float64]  # time-to-go under the same criterion and policy
    action: NDArray[np.uint8]
    policy_pair: NDArray[np.int64]  # the chosen pair per internal state index, -1 where none
    iterations: int = 0
    residual_wh: float = 0.0
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def reachable(self) -> NDArray[np.bool_]:
        return np.isfinite(self.value_wh)

    @property
    def cost(self) -> NDArray[np.float64]:
        return self.value_wh

    @property
    def steps(self) -> NDArray[np.int64]:
        """Not defined for this model (no unit step); -1 where unreachable, else 0."""
        return np.where(self.reachable, 0, -1)

    def value(self, l: int, j: int, i: int, k: int) -> tuple[float, int]:
        v = float(self.value_wh[l, j, i, k])
        return (v, 0 if np.isfinite(v) else -1)

    def nominal(self, start: tuple[int, int, int, int], *, max_steps: int = 100_000) -> list[PhysicalStep]:
        """Follow the policy from ``start`` taking each action's most likely outcome (ties: the one
        with the lower value), stopping at the goal, where no action is known, or at a repeat."""
        m = self.model
        l, j, i, k = start
        state = (int(l), int(j), int(i), int(k))
        path: list[PhysicalStep] = []
        seen: set[tuple[int, int, int, int]] = set()
        for _ in range(max_steps):
            a = Action(int(self.action[state]))
            p = int(self.policy_pair[m.state_index(*state)])
            if a in (Action.AT_GOAL, Action.UNREACHABLE) or p < 0 or state in seen:
                path.append(PhysicalStep(l=state[0], j=state[1], i=state[2], k=state[3],
                                         action=a if p >= 0 or a is Action.AT_GOAL else Action.UNREACHABLE))
                break
            seen.add(state)
            path.append(PhysicalStep(l=state[0], j=state[1], i=state[2], k=state[3], action=a,
                                     duration_s=float(m.duration_s[p])))
            best = max(m.outcomes(p), key=lambda o: (o[1], -self.value_wh[o[0]]))
            state = best[0]
        return path


def solve_physical(model: PhysicalModel, goal: Goal) -> PhysicalSolution:
    """Solve ``model`` under its settings' criterion (robust or expected)."""
    goal_cells = goal_cells_on(model.grid, model.water, goal)
    L, ny, nx, K = model.grid.shape
    goal_states = np.flatnonzero(np.broadcast_to(goal_cells.mask[None], (K, L, ny, nx)).ravel())
    t0 = time.perf_counter()
    if model.settings.criterion == "robust":
        value, tgo, pair = _robust(model.ptr, model.out_state, model.out_energy_max_wh, model.pair_state,
                                   model.duration_s, goal_states, model.n_states)
        iterations, residual = 0, 0.0
    elif model.settings.criterion == "expected":
        value, tgo, pair, iterations, residual = _expected(model, goal_states)
    else:
        raise PlannerError(f"criterion: the physical model has robust and expected; got {model.settings.criterion!r}")
    solve_s = time.perf_counter() - t0
    action = np.full(model.n_states, int(Action.UNREACHABLE), dtype=np.uint8)
    has = pair >= 0
    action[has] = model.pair_action[pair[has]]
    action[goal_states] = int(Action.AT_GOAL)
    water = np.broadcast_to(model.water[None], (K, L, ny, nx)).ravel()
    value = np.where(water, value, np.inf)

    def to_lijk(flat: NDArray) -> NDArray:  # internal heading-major index -> [l, j, i, k]
        return np.ascontiguousarray(np.moveaxis(flat.reshape(K, L, ny, nx), 0, -1))

    return PhysicalSolution(
        model=model, goal=goal, goal_cells=goal_cells, value_wh=to_lijk(value), time_s=to_lijk(tgo),
        action=to_lijk(action), policy_pair=pair, iterations=iterations, residual_wh=residual,
        timings_s={"solve_s": solve_s},
    )


# --------------------------------------------------------------------------- robust

# Shorthands for the kernels' array arguments.
_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]


@numba.njit(cache=True)
def _robust(  # pragma: no cover
    ptr: _I64, out_state: _I64, out_emax: _F64, pair_state: _I64, duration: _F64, goal_states: _I64, n_states: int,
) -> tuple[_F64, _F64, _I64]:
    n_pairs = pair_state.size
    remaining = np.zeros(n_pairs, dtype=np.int64)
    rev_count = np.zeros(n_states + 1, dtype=np.int64)
    for p in range(n_pairs):
        for e in range(ptr[p], ptr[p + 1]):
            remaining[p] += 1
            rev_count[out_state[e] + 1] += 1
    rev_ptr = np.cumsum(rev_count)
    fill = rev_ptr[:-1].copy()
    rev_entry = np.empty(rev_ptr[-1], dtype=np.int64)
    rev_pair = np.empty(rev_ptr[-1], dtype=np.int64)
    for p in range(n_pairs):
        for e in range(ptr[p], ptr[p + 1]):
            o = out_state[e]
            rev_entry[fill[o]] = e
            rev_pair[fill[o]] = p
            fill[o] += 1
    value = np.full(n_states, np.inf)
    tgo = np.full(n_states, np.inf)
    chosen = np.full(n_states, -1, dtype=np.int64)
    settled = np.zeros(n_states, dtype=np.bool_)
    acc = np.zeros(n_pairs)
    acc_t = np.zeros(n_pairs)
    # Binary heap of (key, pair); goal states enter as pair -1 - state.
    cap = n_pairs + goal_states.size + 1
    hk = np.empty(cap)
    hv = np.empty(cap, dtype=np.int64)
    n = 0
    for g in goal_states:
        n = _push(hk, hv, n, 0.0, -1 - g)
    while n > 0:
        key = hk[0]
        item = hv[0]
        n = _pop(hk, hv, n)
        if item < 0:
            s = -1 - item
            t_s = 0.0
        else:
            s = pair_state[item]
            t_s = acc_t[item]
        if settled[s]:
            continue
        settled[s] = True
        value[s] = key
        tgo[s] = t_s
        if item >= 0:
            chosen[s] = item
        for r in range(rev_ptr[s], rev_ptr[s + 1]):
            p = rev_pair[r]
            if settled[pair_state[p]]:
                continue
            e = rev_entry[r]
            cand = out_emax[e] + key
            if cand > acc[p]:
                acc[p] = cand
            if duration[p] + t_s > acc_t[p]:
                acc_t[p] = duration[p] + t_s
            remaining[p] -= 1
            if remaining[p] == 0:
                n = _push(hk, hv, n, acc[p], p)
    return value, tgo, chosen


@numba.njit(cache=True, inline="always")
def _less(hk: _F64, hv: _I64, a: int, b: int) -> bool:  # pragma: no cover
    return hk[a] < hk[b] or (hk[a] == hk[b] and hv[a] < hv[b])


@numba.njit(cache=True)
def _push(hk: _F64, hv: _I64, n: int, key: float, item: int) -> int:  # pragma: no cover
    hk[n] = key
    hv[n] = item
    c = n
    while c > 0:
        parent = (c - 1) // 2
        if _less(hk, hv, c, parent):
            hk[c], hk[parent] = hk[parent], hk[c]
            hv[c], hv[parent] = hv[parent], hv[c]
            c = parent
        else:
            break
    return n + 1


@numba.njit(cache=True)
def _pop(hk: _F64, hv: _I64, n: int) -> int:  # pragma: no cover
    n -= 1
    hk[0] = hk[n]
    hv[0] = hv[n]
    c = 0
    while True:
        a = 2 * c + 1
        b = a + 1
        m = c
        if a < n and _less(hk, hv, a, m):
            m = a
        if b < n and _less(hk, hv, b, m):
            m = b
        if m == c:
            break
        hk[c], hk[m] = hk[m], hk[c]
        hv[c], hv[m] = hv[m], hv[c]
        c = m
    return n


# --------------------------------------------------------------------------- expected


def _expected(model: PhysicalModel, goal_states: NDArray[np.int64]) -> tuple[NDArray, NDArray, NDArray, int, float]:
    ps = model.settings.physical
    n = model.n_states
    is_goal = np.zeros(n, dtype=bool)
    is_goal[goal_states] = True
    policy, alive = _proper_start(model.ptr, model.out_state, model.pair_state, is_goal, n)
    n_pairs = model.n_pairs
    rows = np.repeat(np.arange(n_pairs), np.diff(model.ptr))
    # Q = c + P V over all pairs; outcomes at the goal carry V = 0, so their columns can stay.
    P = sp.csr_matrix((model.out_prob, (rows, model.out_state)), shape=(n_pairs, n))
    pair_ok = np.minimum.reduceat(alive[model.out_state], model.ptr[:-1]) if n_pairs else np.zeros(0, bool)
    pair_ok &= alive[model.pair_state] & ~is_goal[model.pair_state]
    cost = model.energy_wh
    value = np.full(n, np.inf)
    value[is_goal] = 0.0
    solve_states = np.flatnonzero(alive & ~is_goal)
    iterations = 0
    for iterations in range(1, ps.max_iterations + 1):
        value = _evaluate(P, cost, policy, solve_states, value)
        q = np.full(n_pairs, np.inf)
        q[pair_ok] = cost[pair_ok] + P[pair_ok] @ np.where(np.isfinite(value), value, 0.0)
        best = _best_pairs(q, model.pair_state, n)
        current = np.full(n, np.inf)
        current[solve_states] = q[policy[solve_states]]
        better = np.isfinite(q[np.maximum(best, 0)]) & (best >= 0) & (q[np.maximum(best, 0)] < current - ps.tolerance_wh)
        if not better.any():
            break
        policy = np.where(better, best, policy)
    else:
        raise PlannerError(f"expected criterion: policy iteration did not settle in {ps.max_iterations} iterations "
                           "(physical.max_iterations)")
    q = np.full(n_pairs, np.inf)
    q[pair_ok] = cost[pair_ok] + P[pair_ok] @ np.where(np.isfinite(value), value, 0.0)
    best = _best_pairs(q, model.pair_state, n)
    residual = float(np.max(value[solve_states] - q[best[solve_states]])) if solve_states.size else 0.0
    tgo = np.full(n, np.inf)
    tgo[is_goal] = 0.0
    tgo = _evaluate(P, model.duration_s, policy, solve_states, tgo)
    policy = np.where(alive & ~is_goal, policy, -1)
    return value, tgo, policy, iterations, residual


def _evaluate(P: sp.csr_matrix, cost: NDArray, policy: NDArray, states: NDArray, base: NDArray) -> NDArray:
    """Solve V(s) = c(s, pi(s)) + sum P V for ``states``; other states keep ``base`` (goal: 0)."""
    out = base.copy()
    if states.size == 0:
        return out
    Pp = P[policy[states]]  # rows of the chosen pairs, columns all states
    index = np.full(P.shape[1], -1, dtype=np.int64)
    index[states] = np.arange(states.size)
    Pc = Pp.tocoo()
    inside = index[Pc.col] >= 0
    A = sp.csr_matrix((Pc.data[inside], (Pc.row[inside], index[Pc.col[inside]])), shape=(states.size, states.size))
    known = np.where(np.isfinite(base), base, 0.0)
    rhs = cost[policy[states]] + sp.csr_matrix((Pc.data[~inside], (Pc.row[~inside], Pc.col[~inside])),
                                               shape=Pp.shape) @ known
    M = (sp.identity(states.size, format="csc") - A.tocsc())
    with np.errstate(all="ignore"):
        v = spla.spsolve(M, rhs)
    if not np.all(np.isfinite(v)):
        raise PlannerError("expected criterion: the policy's linear system is singular (an improper policy); "
                           "raise physical.min_cost_wh")
    out[states] = v
    return out


def _best_pairs(q: NDArray, pair_state: NDArray, n: int) -> NDArray[np.int64]:
    """The pair of least Q per state (ties: the lower pair, i.e. the lower action code); -1 where none."""
    order = np.lexsort((np.arange(q.size), q, pair_state))  # by state, then Q, then pair
    first = np.ones(order.size, dtype=bool)
    first[1:] = pair_state[order[1:]] != pair_state[order[:-1]]
    best = np.full(n, -1, dtype=np.int64)
    sel = order[first]
    sel = sel[np.isfinite(q[sel])]
    best[pair_state[sel]] = sel
    return best


@numba.njit(cache=True)
def _proper_start(  # pragma: no cover
    ptr: _I64, out_state: _I64, pair_state: _I64, is_goal: NDArray[np.bool_], n_states: int,
) -> tuple[_I64, NDArray[np.bool_]]:
    """States that reach the goal with probability 1 under some policy, and a proper policy there.

    Repeat: a pair is usable when all its outcomes are alive; a backward search from the goal over
    usable pairs ranks the states; those it does not reach die. At the fixed point each alive
    state's first-found pair has an outcome of lower rank, so the goal is reached w.p. 1.
    """
    n_pairs = pair_state.size
    rev_count = np.zeros(n_states + 1, dtype=np.int64)
    for p in range(n_pairs):
        for e in range(ptr[p], ptr[p + 1]):
            rev_count[out_state[e] + 1] += 1
    rev_ptr = np.cumsum(rev_count)
    fill = rev_ptr[:-1].copy()
    rev_pair = np.empty(rev_ptr[-1], dtype=np.int64)
    for p in range(n_pairs):
        for e in range(ptr[p], ptr[p + 1]):
            o = out_state[e]
            rev_pair[fill[o]] = p
            fill[o] += 1
    alive = np.ones(n_states, dtype=np.bool_)
    policy = np.full(n_states, -1, dtype=np.int64)
    queue = np.empty(n_states, dtype=np.int64)
    while True:
        usable = np.zeros(n_pairs, dtype=np.bool_)
        for p in range(n_pairs):
            ok = not is_goal[pair_state[p]]
            for e in range(ptr[p], ptr[p + 1]):
                if not alive[out_state[e]]:
                    ok = False
                    break
            usable[p] = ok
        found = np.zeros(n_states, dtype=np.bool_)
        policy[:] = -1
        head = 0
        tail = 0
        for s in range(n_states):
            if is_goal[s]:
                found[s] = True
                queue[tail] = s
                tail += 1
        while head < tail:
            o = queue[head]
            head += 1
            for r in range(rev_ptr[o], rev_ptr[o + 1]):
                p = rev_pair[r]
                s = pair_state[p]
                if usable[p] and not found[s]:
                    found[s] = True
                    policy[s] = p
                    queue[tail] = s
                    tail += 1
        changed = False
        for s in range(n_states):
            if alive[s] and not found[s]:
                alive[s] = False
                changed = True
        if not changed:
            return policy, alive
