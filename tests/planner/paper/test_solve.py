"""The solver against a literal second implementation, hand-derived cases and invariants."""

from __future__ import annotations

import numpy as np
import pytest

from planner.contract.actions import Action
from planner.contract.errors import GoalError, GridError
from planner.grid import Grid
from planner.contract.geodesy import BBox
from planner.contract.settings import Costs, Goal, PlanSettings
from planner.paper.solve import solve
from planner.paper.transitions import build_transitions
from tests.support.paper_reference import INF, PaperModel, algorithm1_optimistic, value_iteration


def random_case(seed: int, *, nx=6, ny=5, layers=2, land=0.2, lateral=True):
    rng = np.random.default_rng(seed)
    grid = Grid.from_bbox(BBox(west_deg=-118.2, south_deg=33.3, east_deg=-118.1, north_deg=33.4), nx=nx, ny=ny,
                          depths_m=[5.0 * l for l in range(layers)])
    u = rng.normal(0, 0.2, (layers, ny, nx))
    v = rng.normal(0, 0.2, (layers, ny, nx))
    u[rng.random(u.shape) < 0.1] = 0.0  # some calm cells
    v[u == 0.0] = 0.0
    is_land = rng.random(u.shape) < land
    u[is_land] = np.nan
    v[is_land] = np.nan
    water = np.argwhere(~is_land[0])
    gj, gi = water[rng.integers(len(water))]
    goal = Goal(lon_deg=grid.lon_deg[gi], lat_deg=grid.lat_deg[gj], depth_m=0.0, radius_cells=int(rng.integers(0, 2)))
    return grid, u, v, goal


def reference(grid, u, v, goal, settings):
    ref = PaperModel(u.tolist(), v.tolist(), grid.lat_deg.tolist(), grid.dlon_deg, grid.dlat_deg,
                     settings.costs.as_list(), lateral=settings.uncertainty == "lateral",
                     calm=settings.calm_speed_m_s)
    gi, gj, _ = grid.nearest_cell(goal.lon_deg, goal.lat_deg)
    goals = ref.goal_states(grid.nearest_layer(goal.depth_m), gj, gi, goal.radius_cells)
    return ref, goals


def assert_same(sol, V, pol):
    for (l, j, i, k), val in V.items():
        got = sol.value(l, j, i, k)
        want = (float("inf"), -1) if val == INF else (float(val[0]), int(val[1]))
        assert got == want, f"value at {(l, j, i, k)}: solver {got}, reference {want}"
        assert sol.action[l, j, i, k] == pol[(l, j, i, k)], f"action at {(l, j, i, k)}"
    # land carries UNREACHABLE (spec section 6)
    assert np.all(sol.action[~sol.model.water] == Action.UNREACHABLE)


@pytest.mark.parametrize("seed", range(12))
def test_optimistic_matches_literal_algorithm1(seed):
    grid, u, v, goal = random_case(seed)
    settings = PlanSettings(criterion="optimistic")
    sol = solve(build_transitions(u, v, grid, settings), goal)
    ref, goals = reference(grid, u, v, goal, settings)
    V, pol = algorithm1_optimistic(ref, goals)
    assert_same(sol, V, pol)


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("uncertainty", ["lateral", "none"])
def test_robust_matches_value_iteration(seed, uncertainty):
    grid, u, v, goal = random_case(100 + seed, layers=3)
    settings = PlanSettings(criterion="robust", uncertainty=uncertainty)
    sol = solve(build_transitions(u, v, grid, settings), goal)
    ref, goals = reference(grid, u, v, goal, settings)
    V, pol = value_iteration(ref, goals, "robust")
    assert_same(sol, V, pol)
    if goal.radius_cells >= 1:
        assert sol.reachable.sum() > len(goals)  # the case is not trivial


@pytest.mark.parametrize("seed", range(6))
def test_optimistic_with_other_costs_matches(seed):
    grid, u, v, goal = random_case(200 + seed, layers=2, lateral=False)
    settings = PlanSettings(criterion="optimistic", costs=Costs(drift=1, forward=3, rotate=2, glide=0))
    sol = solve(build_transitions(u, v, grid, settings), goal)
    ref, goals = reference(grid, u, v, goal, settings)
    V, pol = value_iteration(ref, goals, "optimistic")
    assert_same(sol, V, pol)


def still_water(nx=8, ny=3, layers=1):
    grid = Grid.from_bbox(BBox(west_deg=0.0, south_deg=0.0, east_deg=0.07, north_deg=0.02), nx=nx, ny=ny,
                          depths_m=[5.0 * l for l in range(layers)])
    zeros = np.zeros((layers, ny, nx))
    return grid, zeros, zeros.copy()


def test_still_water_forward_value_is_4d_d():
    """Calm everywhere, no uncertainty: FORWARD moves one tile (spec 4), so a vehicle
    heading east d tiles west of a radius-0 goal needs d forward moves: value (4d, d)."""
    grid, u, v = still_water()
    settings = PlanSettings(criterion="robust", uncertainty="none")
    goal = Goal(lon_deg=grid.lon_deg[7], lat_deg=grid.lat_deg[1], depth_m=0.0, radius_cells=0)
    sol = solve(build_transitions(u, v, grid, settings), goal)
    for d in range(1, 8):
        assert sol.value(0, 1, 7 - d, 0) == (4.0 * d, d)
        assert sol.action[0, 1, 7 - d, 0] == Action.FORWARD
    # heading north-east one tile west: rotate right once to east (10), then forward (4)
    assert sol.value(0, 1, 6, 1) == (14.0, 2)
    assert sol.action[0, 1, 6, 1] == Action.ROTATE_RIGHT
    # heading north: two rotations right, then forward
    assert sol.value(0, 1, 6, 2) == (24.0, 3)


def test_drift_with_an_aligned_current_is_free():
    """A uniform eastward current: heading east is aligned (rho = 0), so DRIFT moves
    two tiles along the flow at cost 0 (spec sections 4 and 5)."""
    grid, u, v = still_water(nx=9)
    u[:] = 0.3
    settings = PlanSettings(criterion="robust", uncertainty="none")
    goal = Goal(lon_deg=grid.lon_deg[8], lat_deg=grid.lat_deg[1], depth_m=0.0, radius_cells=0)
    sol = solve(build_transitions(u, v, grid, settings), goal)
    assert sol.value(0, 1, 6, 0) == (0.0, 1)
    assert sol.value(0, 1, 4, 0) == (0.0, 2)
    assert sol.action[0, 1, 4, 0] == Action.DRIFT
    # from 7 the 2-tile drift stops at the edge, 8, the goal: one drift
    assert sol.value(0, 1, 7, 0) == (0.0, 1)


def test_glide_down_reaches_goal_below():
    """Calm water, goal one layer below: DOWN (2) is the whole plan."""
    grid, u, v = still_water(layers=2)
    goal = Goal(lon_deg=grid.lon_deg[3], lat_deg=grid.lat_deg[1], depth_m=5.0, radius_cells=0)
    sol = solve(build_transitions(u, v, grid, PlanSettings()), goal)
    assert sol.value(0, 1, 3, 5) == (2.0, 1)
    assert sol.action[0, 1, 3, 5] == Action.DOWN


def test_goal_on_land_and_outside_are_refused():
    grid, u, v = still_water()
    u[0, 1, 3] = np.nan
    model = build_transitions(u, v, grid, PlanSettings())
    with pytest.raises(GoalError, match="on land"):
        solve(model, Goal(lon_deg=grid.lon_deg[3], lat_deg=grid.lat_deg[1], depth_m=0.0))
    with pytest.raises(GoalError, match="outside the planning grid"):
        solve(model, Goal(lon_deg=5.0, lat_deg=grid.lat_deg[1], depth_m=0.0))


def test_all_land_layer_is_refused():
    grid, u, v = still_water(layers=2)
    u[1] = np.nan
    with pytest.raises(GridError, match="layer 1 at 5 m is all land"):
        build_transitions(u, v, grid, PlanSettings())


def follow(sol, z, pick, limit=10_000):
    """Follow the policy from z choosing among outcomes with ``pick``; returns total (cost, steps)."""
    model = sol.model
    cost, steps = 0, 0
    while sol.action[z] != Action.AT_GOAL:
        a = Action(int(sol.action[z]))
        assert a != Action.UNREACHABLE
        outs = model.outcomes(*z, a)
        cost += int(model.costs[a])
        steps += 1
        z = pick(outs)
        assert steps < limit
    return cost, steps


@pytest.mark.parametrize("seed", range(5))
def test_robust_policy_reaches_goal_under_any_outcomes(seed):
    grid, u, v, goal = random_case(300 + seed, nx=10, ny=9, layers=3)
    sol = solve(build_transitions(u, v, grid, PlanSettings()), goal)
    rng = np.random.default_rng(seed)
    starts = np.argwhere(sol.reachable)
    for z in starts[rng.permutation(len(starts))[:60]]:
        z = tuple(int(x) for x in z)
        c, s = follow(sol, z, lambda outs: outs[rng.integers(len(outs))])
        assert c <= sol.value(*z)[0]
        assert s <= sol.value(*z)[1] or c < sol.value(*z)[0]
        # the adversary that always takes the worst outcome pays exactly V
        worst = follow(sol, z, lambda outs: max(outs, key=lambda o: sol.packed_value[o]))
        assert worst == sol.value(*z)


@pytest.mark.parametrize("seed", range(5))
def test_optimistic_policy_along_best_outcome_costs_exactly_v(seed):
    grid, u, v, goal = random_case(400 + seed, nx=10, ny=9, layers=3)
    sol = solve(build_transitions(u, v, grid, PlanSettings(criterion="optimistic")), goal)
    for z in np.argwhere(sol.reachable)[:200]:
        z = tuple(int(x) for x in z)
        best = follow(sol, z, lambda outs: min(outs, key=lambda o: sol.packed_value[o]))
        assert best == sol.value(*z)
