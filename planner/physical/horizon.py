"""The physical plan over the forecast's horizon: time in the state (docs/time-varying.md).

A stationary plan assumes the current it was planned on lasts; where it turns within hours (tides,
inertial oscillations) that plan steers into the current it will meet. Here the state gains the
forecast time: slice ``n`` holds the physical model sampled in the current of forecast time
``t_n`` (``planner.physical.sampling``), and an action taken at ``t_n`` that lasts ``d`` (its mean
duration over the samples) ends at ``t_n + d``, where the value of each outcome cell is
interpolated linearly in time between the two slices around it. That is the time-expanded
Bellman equation of a semi-Lagrangian scheme:

    V_n(s) = min_a [ c(s, a) + sum_o P(o | s, a) ((1 - w) V_m(o) + w V_{m+1}(o)) ]    (expected)
    V_n(s) = min_a max_o [ E_max(s, a, o) + (1 - w) V_m(o) + w V_{m+1}(o) ]          (robust)

with ``t_m <= t_n + d < t_{m+1}`` and ``w = (t_n + d - t_m) / (t_{m+1} - t_m)``. Beyond the last
slice the current is taken to last: the **terminal value** is the stationary plan of the last
slice (``planner.physical.solve.solve_physical``, exact for either criterion), and a landing time
past it takes that plan's value.

The slices are solved backward, the last first. Within slice ``n`` an action shorter than the
gap to the next slice lands partly in slice ``n`` itself, so each slice is a small stationary
problem in which every action leaks ``w`` of its weight to later slices whose values are known.
It is solved by Gauss-Seidel value iteration from infinity (a state gets a value once one of its
actions has all its outcomes valued, as in the stationary solvers' search, so values fall from
an upper bound), in the order of the next slice's values, solving an action's chance of staying
in its own state in the update (expected criterion). The robust criterion never takes an action
that may leave the vehicle in its own state within the slice, as the stationary one does not.
It stops when a sweep changes no value by more than ``tolerance_wh`` (or a relative 1e-9 of it),
or after ``max_iterations`` sweeps.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import NDArray

from planner.contract.actions import Action
from planner.contract.errors import PlannerError
from planner.contract.settings import Goal
from planner.physical.model import PhysicalModel
from planner.physical.solve import PhysicalSolution, solve_physical

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_Mask = NDArray[np.bool_]
_REL_TOL = 1e-9


@dataclass(frozen=True, eq=False, kw_only=True)
class HorizonSolution:
    """Per slice ``n`` at ``times_s[n]`` (s after the first): value (Wh), time-to-go (s) and action,
    arrays ``(T, L, ny, nx, 8)``; ``first`` is slice 0 as a stationary solution (its model, for
    pictures and nominal paths), ``last`` the terminal plan."""

    first: PhysicalSolution
    last: PhysicalSolution
    times_s: NDArray[np.float64]
    value_wh: NDArray[np.float64]
    time_s: NDArray[np.float64]
    action: NDArray[np.uint8]
    sweeps: tuple[int, ...]  # Gauss-Seidel sweeps per slice (the last is solved exactly: 0)
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def n_slices(self) -> int:
        return int(self.times_s.size)


def solve_horizon(model_at: Callable[[int], PhysicalModel], times_s: NDArray[np.float64], goal: Goal,
                  *, progress: Callable[[str], None] = lambda _: None) -> HorizonSolution:
    """Solve the slices backward; ``model_at(n)`` builds slice ``n``'s model (asked once each, last first,
    so that only one slice's transitions are held at a time)."""
    times = np.asarray(times_s, dtype=np.float64)
    if times.size < 2 or np.any(np.diff(times) <= 0):
        raise PlannerError(f"time-varying plan: expected two or more increasing slice times; got {times.tolist()[:6]}")
    T = times.size
    t0 = time.perf_counter()
    model = model_at(T - 1)
    timings = {"transitions_s": time.perf_counter() - t0, "solve_s": 0.0}
    t = time.perf_counter()
    last = solve_physical(model, goal)
    timings["solve_s"] += time.perf_counter() - t
    L, ny, nx, K = model.grid.shape
    n = model.n_states
    value = np.full((T, n), np.inf)
    tgo = np.full((T, n), np.inf)
    action = np.empty((T, L, ny, nx, K), dtype=np.uint8)
    value[T - 1] = _internal(last.value_wh)
    tgo[T - 1] = _internal(last.time_s)
    action[T - 1] = last.action
    sweeps = [0] * T
    first = last
    # The goal cells are the same in every slice (land does not move).
    is_goal = np.broadcast_to(last.goal_cells.mask[None], (K, L, ny, nx)).ravel()
    for s in range(T - 2, -1, -1):
        t = time.perf_counter()
        model = model_at(s)
        timings["transitions_s"] += time.perf_counter() - t
        t = time.perf_counter()
        if model.n_states != n:
            raise PlannerError(f"time-varying plan: slice {s} has {model.n_states:,} states, the last {n:,}")
        ps = model.settings.physical
        order = np.argsort(value[s + 1], kind="stable")
        state_ptr = np.searchsorted(model.pair_state, np.arange(n + 1)).astype(np.int64)
        choice = np.full(n, -1, dtype=np.int64)
        robust = model.settings.criterion == "robust"
        rotation = np.isin(model.pair_action, (int(Action.ROTATE_LEFT), int(Action.ROTATE_RIGHT)))
        sweeps[s] = int(_slice(state_ptr, model.ptr, model.out_state, model.out_prob, model.out_energy_max_wh,
                               model.energy_wh, model.duration_s, rotation, is_goal, order, times, s, value, tgo, choice,
                               robust, ps.tolerance_wh, ps.max_iterations))
        if sweeps[s] > ps.max_iterations:
            raise PlannerError(f"time-varying plan: slice {s} did not settle in {ps.max_iterations} sweeps "
                               "(physical.max_iterations)")
        flat = np.full(n, int(Action.UNREACHABLE), dtype=np.uint8)
        has = choice >= 0
        flat[has] = model.pair_action[choice[has]]
        flat[is_goal] = int(Action.AT_GOAL)
        action[s] = _lijk(flat, model)
        timings["solve_s"] += time.perf_counter() - t
        progress(f"slice {s} of {T}: {sweeps[s]} sweeps")
        if s == 0:
            first = PhysicalSolution(model=model, goal=goal, goal_cells=last.goal_cells,
                                     value_wh=_lijk(value[0], model), time_s=_lijk(tgo[0], model), action=action[0],
                                     sweeps=sweeps[0], timings_s={"solve_s": timings["solve_s"]})
    shape = (T, L, ny, nx, K)
    return HorizonSolution(first=first, last=last, times_s=times,
                           value_wh=np.stack([_lijk(v, model) for v in value]).reshape(shape),
                           time_s=np.stack([_lijk(v, model) for v in tgo]).reshape(shape), action=action,
                           sweeps=tuple(sweeps), timings_s=timings)


def _internal(lijk: NDArray) -> NDArray:
    """``[l, j, i, k]`` -> the models' heading-major internal index ``((k * L + l) * ny + j) * nx + i``."""
    return np.ascontiguousarray(np.moveaxis(lijk, -1, 0)).ravel()


def _lijk(flat: NDArray, model: PhysicalModel) -> NDArray:
    L, ny, nx, K = model.grid.shape
    return np.ascontiguousarray(np.moveaxis(flat.reshape(K, L, ny, nx), 0, -1))


@numba.njit(cache=True)
def _landing(times: _F64, n: int, d: float) -> tuple[int, float]:  # pragma: no cover
    """The slice ``m`` at or before ``t_n + d`` and the weight ``w`` of slice ``m + 1`` (0 past the last)."""
    tau = times[n] + d
    m = n
    while m + 1 < times.size and times[m + 1] <= tau:
        m += 1
    if m + 1 >= times.size:
        return m, 0.0
    return m, (tau - times[m]) / (times[m + 1] - times[m])


@numba.njit(cache=True)
def _slice(  # pragma: no cover
    state_ptr: _I64, ptr: _I64, out_state: _I64, out_prob: _F64, out_emax: _F64, energy: _F64, duration: _F64,
    is_rotation: _Mask, is_goal: _Mask, order: _I64, times: _F64, n: int, value: _F64, tgo: _F64, choice: _I64,
    robust: bool, tol: float, max_sweeps: int,
) -> int:
    """Gauss-Seidel sweeps over slice ``n`` (rows ``value[n]``, ``tgo[n]``); returns the sweeps taken."""
    n_pairs = energy.size
    land_m = np.empty(n_pairs, dtype=np.int64)
    land_w = np.empty(n_pairs)
    for p in range(n_pairs):
        land_m[p], land_w[p] = _landing(times, n, duration[p])
    V = value[n]
    Tg = tgo[n]
    for s in range(V.size):
        if is_goal[s]:
            V[s] = 0.0
            Tg[s] = 0.0
    sweeps = 0
    while sweeps <= max_sweeps:
        sweeps += 1
        changed = False
        for s in order:
            if is_goal[s]:
                continue
            best = np.inf
            best_t = np.inf
            best_p = -1
            for p in range(state_ptr[s], state_ptr[s + 1]):
                m = land_m[p]
                w = land_w[p]
                here = 1.0 - w  # the weight of slice m, the rest on m + 1
                q = 0.0 if robust else energy[p]
                qt = duration[p]
                stay = 0.0  # expected: the chance, in slice n, of staying in s
                ok = True
                for e in range(ptr[p], ptr[p + 1]):
                    o = out_state[e]
                    pr = out_prob[e]
                    if m == n and o == s and here > 0.0:
                        if robust:
                            ok = False
                            break
                        stay += pr * here
                        vo = value[m + 1, o] * w if w > 0.0 else 0.0
                        to = tgo[m + 1, o] * w if w > 0.0 else 0.0
                    else:
                        vo = 0.0
                        to = 0.0
                        if here > 0.0:
                            vo += here * value[m, o]
                            to += here * tgo[m, o]
                        if w > 0.0:
                            vo += w * value[m + 1, o]
                            to += w * tgo[m + 1, o]
                    if not vo < np.inf:
                        ok = False
                        break
                    if robust:
                        if out_emax[e] + vo > q:
                            q = out_emax[e] + vo
                        if duration[p] + to > qt:
                            qt = duration[p] + to
                    else:
                        q += pr * vo
                        qt += pr * to
                if not ok:
                    q = np.inf
                elif stay > 0.0:
                    q /= 1.0 - stay
                    qt /= 1.0 - stay
                if is_rotation[p] and m == n and w > 0.0:
                    # Turning back and forth holds the vehicle where it is until the current changes: a
                    # cycle of two rotations whose value is solved for here, not crept to one rotation's
                    # worth of time per sweep (w is a few seconds over the gap between slices).
                    o = out_state[ptr[p]]
                    c = choice[o]
                    if c >= 0 and is_rotation[c] and out_state[ptr[c]] == s:
                        e_p = out_emax[ptr[p]] if robust else energy[p]
                        e_c = out_emax[ptr[c]] if robust else energy[c]
                        keep = (1.0 - w) * (1.0 - w)
                        qc = (e_p + w * value[m + 1, o] + (1.0 - w) * (e_c + w * value[m + 1, s])) / (1.0 - keep)
                        tc = (duration[p] + w * tgo[m + 1, o] + (1.0 - w) * (duration[c] + w * tgo[m + 1, s])) / (1.0 - keep)
                        if qc < q:
                            q = qc
                            qt = tc
                if q < best:
                    best = q
                    best_t = qt
                    best_p = p
            old = V[s]
            if best < np.inf and not (old - best <= max(tol, _REL_TOL * best) and best - old <= max(tol, _REL_TOL * best)):
                changed = True
            V[s] = best
            Tg[s] = best_t
            choice[s] = best_p
        if not changed:
            break
    return sweeps
