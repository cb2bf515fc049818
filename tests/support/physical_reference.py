"""A slow, literal reference of the physical model (docs/physical-model.md), for small grids only.

Plain Python loops over every state, action, start point and forecast-error member, one sample
at a time, in the order the text describes; then plain value iteration (Jacobi, from zero) over
the states from which some policy reaches the goal with probability 1. Nothing here is shared
with ``planner.physical`` but the settings, the grid and the energy law, so the fast code can be
held against it state by state.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import scipy.sparse as sp

from planner.contract.geodesy import EARTH_RADIUS_M
from planner.contract.headings import courses_deg
from planner.contract.settings import PlanSettings
from planner.contract.vehicle import power_draw_w
from planner.grid import Grid

DRIFT, FORWARD, ROTATE_LEFT, ROTATE_RIGHT, UP, DOWN, FORWARD_LEFT, FORWARD_RIGHT = 0, 1, 2, 3, 4, 5, 8, 9

# (outcome (l, j, i, k), probability, worst energy Wh) per (state, action); mean energy Wh per (state, action).
Outcomes = dict[tuple[tuple[int, int, int, int], int], list[tuple[tuple[int, int, int, int], float, float]]]


def _bilinear(f: np.ndarray, l: int, X: float, Y: float) -> float:
    """The current at fine-grid point (X, Y), clamped; NaN when a node with a non-zero weight is land."""
    nyf, nxf = f.shape[1], f.shape[2]
    X = min(max(X, 0.0), nxf - 1.0)
    Y = min(max(Y, 0.0), nyf - 1.0)
    x0, y0 = min(int(X), nxf - 2), min(int(Y), nyf - 2)
    fx, fy = X - x0, Y - y0
    total = 0.0
    for dy, wy in ((0, 1.0 - fy), (1, fy)):
        for dx, wx in ((0, 1.0 - fx), (1, fx)):
            if wx * wy != 0.0:
                total += wx * wy * float(f[l, y0 + dy, x0 + dx])
    return total


def _nearest(x: float) -> int:
    return int(math.ceil(x - 0.5))


def sample(uf: np.ndarray, vf: np.ndarray, grid: Grid, settings: PlanSettings, refine: int,
           goal: np.ndarray) -> tuple[Outcomes, dict, dict]:
    """Every available (state, action): outcomes, mean energy (Wh) and mean duration (s)."""
    ps, vp = settings.physical, settings.vehicle
    L, ny, nx = grid.n_layers, grid.ny, grid.nx
    u, v = uf[:, ::refine, ::refine], vf[:, ::refine, ::refine]
    water = np.isfinite(u) & np.isfinite(v)
    _dx, dy_m = grid.cell_size_m()
    dlon_rad = math.radians(grid.dlon_deg)
    given = ps.max_transition_s
    t_max = float(given) if given is not None else 4.0 * max(float(np.max(_dx)), dy_m) / vp.cruise_speed_m_s
    a = [(s + 0.5) / ps.start_points - 0.5 for s in range(ps.start_points)]
    starts = [(di, dj) for dj in a for di in a]
    m = ps.error_members
    members = [(0.0, 0.0)]
    if m:
        rho = ps.current_error_m_s * math.sqrt(2.0 * (m + 1) / m)
        members += [(rho * math.cos(2 * math.pi * q / m), rho * math.sin(2 * math.pi * q / m)) for q in range(m)]
    courses = courses_deg(grid.bearings_deg())  # (ny, 8, 3)

    def velocity(la, lb, wb, x, y, we, wn):
        if not (math.isfinite(x) and math.isfinite(y)):
            return math.nan, math.nan  # a stage after one on land
        X, Y = x * refine, y * refine
        cu, cv = _bilinear(uf, la, X, Y), _bilinear(vf, la, X, Y)
        if wb > 0.0:
            cu = (1 - wb) * cu + wb * _bilinear(uf, lb, X, Y)
            cv = (1 - wb) * cv + wb * _bilinear(vf, lb, X, Y)
        dx_m = EARTH_RADIUS_M * math.cos(math.radians(grid.lat_deg[0] + y * grid.dlat_deg)) * dlon_rad
        return (cu + we) / dx_m, (cv + wn) / dy_m

    def run(la, lb, glide_s, x0, y0, we, wn, h):
        """One sample: (ok, x, y, t)."""
        x, y, t = x0, y0, 0.0
        end = glide_s if glide_s > 0 else t_max
        while t < end - 1e-9:
            hh = min(h, end - t)
            w = [(t + f * hh) / glide_s if glide_s > 0 else 0.0 for f in (0.0, 0.5, 1.0)]
            k1 = velocity(la, lb, w[0], x, y, we, wn)
            k2 = velocity(la, lb, w[1], x + 0.5 * hh * k1[0], y + 0.5 * hh * k1[1], we, wn)
            k3 = velocity(la, lb, w[1], x + 0.5 * hh * k2[0], y + 0.5 * hh * k2[1], we, wn)
            k4 = velocity(la, lb, w[2], x + hh * k3[0], y + hh * k3[1], we, wn)
            xn = x + hh / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            yn = y + hh / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            if not (math.isfinite(xn) and math.isfinite(yn)):
                return False, x, y, t
            tau = 1.0
            if glide_s <= 0 and (abs(xn - x0) >= 1.0 or abs(yn - y0) >= 1.0):
                if abs(xn - x0) >= 1.0:
                    tau = min(tau, (x0 + math.copysign(1.0, xn - x0) - x) / (xn - x))
                if abs(yn - y0) >= 1.0:
                    tau = min(tau, (y0 + math.copysign(1.0, yn - y0) - y) / (yn - y))
                xn, yn = x + tau * (xn - x), y + tau * (yn - y)
            if glide_s <= 0:
                gi, gj = _nearest(xn), _nearest(yn)
                if 0 <= gi < nx and 0 <= gj < ny and goal[la, gj, gi] and not goal[la, _nearest(y), _nearest(x)]:
                    enter = 0.0
                    for p, pn, c in ((x, xn, gi), (y, yn, gj)):
                        if abs(p - c) > 0.5:
                            edge = c - 0.5 if pn > p else c + 0.5
                            enter = max(enter, (edge - p) / (pn - p))
                    enter = min(enter + 1e-6, 1.0)
                    return True, x + enter * (xn - x), y + enter * (yn - y), t + enter * tau * hh
            if tau < 1.0:
                x, y, t = xn, yn, t + tau * hh
                break
            x, y, t = xn, yn, t + hh
            if x < -0.5 or x > nx - 0.5 or y < -0.5 or y > ny - 0.5:
                return False, x, y, t
        inside = -0.5 <= x <= nx - 0.5 and -0.5 <= y <= ny - 0.5
        return inside, x, y, t

    outcomes: Outcomes = {}
    energy: dict = {}
    duration: dict = {}
    rot_s = 45.0 / vp.yaw_rate_deg_s
    floor = ps.min_cost_wh
    actions = [DRIFT, FORWARD, ROTATE_LEFT, ROTATE_RIGHT, UP, DOWN] + ([FORWARD_LEFT, FORWARD_RIGHT]
                                                                       if ps.course_offsets else [])
    for l in range(L):
        for j in range(ny):
            dx_m = EARTH_RADIUS_M * math.cos(math.radians(grid.lat_deg[0] + j * grid.dlat_deg)) * dlon_rad
            for i in range(nx):
                if not water[l, j, i]:
                    continue
                cur = math.hypot(_bilinear(uf, l, i * refine, j * refine), _bilinear(vf, l, i * refine, j * refine))
                rot_wh = max(float(power_draw_w(vp, min(math.hypot(u[l, j, i], v[l, j, i]), vp.max_speed_m_s),
                                                False)) * rot_s / 3600.0, floor)
                for k in range(8):
                    for act in actions:
                        if act in (ROTATE_LEFT, ROTATE_RIGHT):
                            k2 = (k + 1) % 8 if act == ROTATE_LEFT else (k + 7) % 8
                            outcomes[(l, j, i, k), act] = [((l, j, i, k2), 1.0, rot_wh)]
                            energy[(l, j, i, k), act] = rot_wh
                            duration[(l, j, i, k), act] = rot_s
                            continue
                        lb, glide_s, we, wn = l, 0.0, 0.0, 0.0
                        if act in (UP, DOWN):
                            lb = l - 1 if act == UP else l + 1
                            if not (0 <= lb < L and water[lb, j, i]):
                                continue
                            glide_s = abs(grid.depth_m[lb] - grid.depth_m[l]) / vp.glide_rate_m_s
                            power = float(power_draw_w(vp, 0.0, True))
                            h = glide_s / ps.rk4_steps
                        else:
                            power = float(power_draw_w(vp, 0.0, False))
                            v_water = 0.0
                            if act != DRIFT:
                                offset = {FORWARD: 0, FORWARD_LEFT: 1, FORWARD_RIGHT: 2}[act]
                                b = math.radians(float(courses[j, k, offset]))
                                we, wn = vp.cruise_speed_m_s * math.sin(b), vp.cruise_speed_m_s * math.cos(b)
                                power = float(power_draw_w(vp, vp.cruise_speed_m_s, False))
                                v_water = vp.cruise_speed_m_s
                            h = min(t_max, min(dx_m, dy_m) / max(v_water + cur, 1e-3)) / ps.rk4_steps
                        ends = []
                        for di, dj in starts:
                            for me, mn in members:
                                ok, x, y, t = run(l, lb, glide_s, i + di, j + dj, we + me, wn + mn, h)
                                ii, jj = _nearest(x), _nearest(y)
                                if (not ok or not (0 <= ii < nx and 0 <= jj < ny) or abs(ii - i) > 2
                                        or abs(jj - j) > 2 or not water[lb, jj, ii]):
                                    ends = None
                                    break
                                ends.append(((lb, jj, ii, k), power * t / 3600.0, t))
                            if ends is None:
                                break
                        if ends is None:
                            continue  # a stranded sample: the action is unavailable here
                        n = len(ends)
                        by: dict = defaultdict(list)
                        for o, e, _t in ends:
                            by[o].append(e)
                        outcomes[(l, j, i, k), act] = sorted((o, len(es) / n, max(max(es), floor)) for o, es in by.items())
                        energy[(l, j, i, k), act] = max(sum(e for _o, e, _t in ends) / n, floor)
                        duration[(l, j, i, k), act] = sum(t for _o, _e, t in ends) / n
    return outcomes, energy, duration


def value_iteration(outcomes: Outcomes, energy: dict, goal_states: set, *, tol: float = 1e-12,
                    max_sweeps: int = 200_000) -> dict:
    """Expected energy to the goal by Jacobi value iteration from zero, over the proper states only
    (inf elsewhere); each sweep updates every state from the previous sweep's values."""
    states = {s for s, _a in outcomes} | goal_states
    alive = set(states)
    while True:  # the states from which some policy reaches the goal with probability 1
        usable = {(s, a) for (s, a), outs in outcomes.items()
                  if s in alive and s not in goal_states and all(o in alive for o, _p, _e in outs)}
        reach = set(goal_states)
        grew = True
        while grew:
            grew = False
            for s, a in usable:
                if s not in reach and any(o in reach for o, _p, _e in outcomes[s, a]):
                    reach.add(s)
                    grew = True
        if reach == alive:
            break
        alive = reach
    # Plain Jacobi sweeps, as sparse matrix products: V <- min over usable actions of (c + P V).
    index = {st: n for n, st in enumerate(sorted(alive))}
    pairs = sorted(usable)
    rows, cols, probs = [], [], []
    for r, (st, a) in enumerate(pairs):
        for o, p, _e in outcomes[st, a]:
            rows.append(r)
            cols.append(index[o])
            probs.append(p)
    P = sp.csr_matrix((probs, (rows, cols)), shape=(len(pairs), len(index)))
    cost = np.array([energy[pair] for pair in pairs])
    owner = np.array([index[st] for st, _a in pairs])
    is_goal = np.array([st in goal_states for st in sorted(alive)])
    value = np.zeros(len(index))
    for _ in range(max_sweeps):
        new = np.full(len(index), np.inf)
        np.minimum.at(new, owner, cost + P @ value)
        new[is_goal] = 0.0
        change = float(np.max(np.abs(new - value)))
        value = new
        if change < tol:
            return {st: float(value[index[st]]) if st in index else math.inf for st in states}
    raise AssertionError("value iteration did not converge")
