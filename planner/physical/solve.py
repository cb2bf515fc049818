"""Criteria for the physical model: worst case (``robust``) and expected energy (``expected``).

docs/physical-model.md. Both give the cost-to-go in watt-hours and the action of every state.

- ``robust``: V(s) = min over actions of the max over the action's outcomes o of
  (E_max(s, a, o) + V(o)), E_max being the largest energy of the samples that ended in o. Solved
  exactly by Dijkstra generalised to AND-OR graphs (Knuth, "A generalization of Dijkstra's
  algorithm", IPL 6, 1977): an action's value is known once all its outcomes are settled. An
  action that may leave the vehicle in its own state (it had not moved a cell spacing when
  ``max_transition_s`` ran out) may do so for ever in the worst case, so it is never chosen:
  its own state is an outcome that is never settled before the state itself.
- ``expected``: a stochastic shortest path, V = min_a (c(s, a) + sum_o P(o | s, a) V(o)), solved
  by ``planner.physical.expected``: value iteration in Gauss-Seidel sweeps ordered by a backward
  search from the goal, then policy iteration whose evaluations are exact and linear in the
  states (strongly connected components of the policy, sinks first). Only states from which some
  policy reaches the goal with probability 1 get a value. An action changes only when better by
  more than ``tolerance_wh``, and ``max_iterations`` bounds policy iteration.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property

import numba
import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.errors import PlannerError
from planner.contract.progress import SILENT, Progress
from planner.physical.expected import solve_expected
from planner.physical.model import PAIR_ACTIONS, PhysicalModel
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
    iterations: int = 0  # policy iterations (expected criterion)
    sweeps: int = 0  # value-iteration sweeps before them (expected criterion)
    residual_wh: float = 0.0
    timings_s: dict[str, float] = field(default_factory=dict)

    @cached_property
    def policy_pair(self) -> NDArray[np.int64]:
        """The chosen pair per internal state index (``PhysicalModel.pair_state``), -1 where none."""
        m = self.model
        flat = np.moveaxis(self.action, -1, 0).ravel()
        return _pair_index(m.pair_state, m.pair_action, flat.astype(np.int64))

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


def solve_physical(model: PhysicalModel, goal: Goal, *, meter: Progress = SILENT) -> PhysicalSolution:
    """Solve ``model`` under its settings' criterion (robust or expected).

    ``meter`` hears the start and the end (the compiled solver runs in one call)."""
    goal_cells = goal_cells_on(model.grid, model.water, goal)
    L, ny, nx, K = model.grid.shape
    goal_states = np.flatnonzero(np.broadcast_to(goal_cells.mask[None], (K, L, ny, nx)).ravel())
    t0 = time.perf_counter()
    meter.update("solving", 0, model.n_states, unit="states")
    iterations, sweeps, residual = 0, 0, 0.0
    if model.settings.criterion == "robust":
        value, tgo, pair = _robust(model.ptr, model.out_state, model.out_energy_max_wh, model.pair_state,
                                   model.duration_s, goal_states, model.n_states)
        action = np.full(model.n_states, int(Action.UNREACHABLE), dtype=np.uint8)
        has = pair >= 0
        action[has] = model.pair_action[pair[has]]
    elif model.settings.criterion == "expected":
        is_goal = np.zeros(model.n_states, dtype=bool)
        is_goal[goal_states] = True
        result = solve_expected(model, is_goal)
        value, tgo = result.value_wh, result.time_s
        iterations, sweeps, residual = result.iterations, result.sweeps, result.residual_wh
        action = np.full(model.n_states, int(Action.UNREACHABLE), dtype=np.uint8)
        has = result.choice >= 0
        action[has] = PAIR_ACTIONS[result.choice[has]]
    else:
        raise PlannerError(f"criterion: the physical model has robust and expected; got {model.settings.criterion!r}")
    solve_s = time.perf_counter() - t0
    meter.update("solving", model.n_states, model.n_states, unit="states")
    action[goal_states] = int(Action.AT_GOAL)
    water = np.broadcast_to(model.water[None], (K, L, ny, nx)).ravel()
    value = np.where(water, value, np.inf)

    def to_lijk(flat: NDArray) -> NDArray:  # internal heading-major index -> [l, j, i, k]
        return np.ascontiguousarray(np.moveaxis(flat.reshape(K, L, ny, nx), 0, -1))

    return PhysicalSolution(
        model=model, goal=goal, goal_cells=goal_cells, value_wh=to_lijk(value), time_s=to_lijk(tgo),
        action=to_lijk(action), iterations=iterations, sweeps=sweeps, residual_wh=residual,
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


# --------------------------------------------------------------------------- policy pairs


@numba.njit(cache=True)
def _pair_index(pair_state: _I64, pair_action: NDArray[np.int8], action: _I64) -> _I64:  # pragma: no cover
    """The pair of each state's action (pairs sorted by state), -1 where the state has none."""
    out = np.full(action.size, -1, dtype=np.int64)
    for p in range(pair_state.size):
        s = pair_state[p]
        if pair_action[p] == action[s]:
            out[s] = p
    return out
