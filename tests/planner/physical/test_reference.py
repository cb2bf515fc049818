"""The fast physical model against a slow literal reference (tests/support/physical_reference.py).

On a few small grids: every (state, action)'s outcomes, probabilities, worst and mean energies
and mean duration equal the reference's; the expected criterion's values equal plain value
iteration's within the stated tolerance; and every chosen action is within that tolerance of
the best, so the actions are the reference's wherever the two best differ by more. A second
goal on the same goal-free samples gives the model that sampling with that goal from scratch does.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.contract.geodesy import BBox
from planner.contract.settings import Goal, PhysicalSettings, PlanSettings
from planner.grid import Grid
from planner.paper.solve import goal_cells_on
from planner.physical.model import assemble, enter_goal, fine_grid, sample_transitions
from planner.physical.solve import solve_physical
from tests.planner.physical.test_physical import goal_at, small_grid, swirl
from tests.support.physical_reference import sample, value_iteration

# Few samples and RK4 steps, so the reference stays quick: 2 x 2 start points x (forecast + 3 members), 4 steps a crossing.
SETTINGS = PhysicalSettings(start_points=2, error_members=3, current_error_m_s=0.05, rk4_steps=4)
TOLERANCE_WH = 1e-9  # PhysicalSettings.tolerance_wh's default: actions within it of the best are ties


def swirl_with_land() -> tuple[Grid, int, np.ndarray, np.ndarray, Goal]:
    grid = small_grid()
    u, v = swirl(grid, 2)
    u[0, 4, 4] = v[0, 4, 4] = np.nan  # land at planning cell (l=0, j=2, i=2)
    return grid, 2, u, v, goal_at(grid, 0, 3, 4)


def strong_current() -> tuple[Grid, int, np.ndarray, np.ndarray, Goal]:
    """Stronger than the vehicle east of x = 3: unreachable states, and actions that may stay put."""
    grid = small_grid(nx=7, ny=4, depths=(0.0,))
    shape = (1, grid.ny, grid.nx)
    u, v = np.full(shape, 0.3), np.full(shape, -0.1)
    u[:, :, 4:] = 1.3
    return grid, 1, u, v, goal_at(grid, 0, 1, 2)


def double_gyre() -> tuple[Grid, int, np.ndarray, np.ndarray, Goal]:
    """The analytic double gyre (Shadden et al. 2005) at t = 0 over the box, 0.5 m/s, two layers."""
    grid = small_grid(nx=6, ny=4)
    fg = fine_grid(grid, 2)
    x = np.linspace(0.0, 2.0, fg.nx)[None, :]
    y = np.linspace(0.0, 1.0, fg.ny)[:, None]
    u = -0.5 * math.pi * np.sin(math.pi * x) * np.cos(math.pi * y) / math.pi
    v = 0.5 * math.pi * np.cos(math.pi * x) * np.sin(math.pi * y) / math.pi
    return grid, 2, np.stack([u, 0.6 * u]), np.stack([v, 0.6 * v]), goal_at(grid, 0, 1, 4)


def coarse_rows() -> tuple[Grid, int, np.ndarray, np.ndarray, Goal]:
    """Quarter-degree rows at 60 deg N: a sample strays more than 1e-3 rad from its row's latitude, so
    the kernel's metric takes the long series there (the short one serves the fine grids above)."""
    grid = small_grid(nx=6, ny=5, depths=(0.0,), bbox=BBox(west_deg=4.0, south_deg=60.0, east_deg=5.5, north_deg=61.0))
    u, v = swirl(grid, 2, amplitude=0.6)
    u[0, 5, 6] = v[0, 5, 6] = np.nan  # land beside a fine node of planning cell (i=3, j=2)
    return grid, 2, u, v, goal_at(grid, 0, 3, 4)


CASES = {"swirl with land": swirl_with_land, "strong current": strong_current, "double gyre": double_gyre,
         "coarse rows": coarse_rows}


def plan_settings() -> PlanSettings:
    return PlanSettings(model="physical", criterion="expected", physical=SETTINGS)


def goal_mask(grid: Grid, u: np.ndarray, v: np.ndarray, refine: int, goal: Goal) -> np.ndarray:
    water = np.isfinite(u[:, ::refine, ::refine]) & np.isfinite(v[:, ::refine, ::refine])
    return goal_cells_on(grid, water, goal).mask


@pytest.fixture(scope="module", params=list(CASES))
def case(request):
    grid, refine, u, v, goal = CASES[request.param]()
    settings = plan_settings()
    mask = goal_mask(grid, u, v, refine, goal)
    model = assemble(sample_transitions(u, v, grid, settings, refine=refine, goal_mask=mask), grid, settings,
                     refine=refine)
    outcomes, energy, duration = sample(u, v, grid, settings, refine, mask)
    return grid, refine, u, v, goal, model, outcomes, energy, duration


def test_every_state_action_has_the_reference_outcomes_and_costs(case):
    grid, _refine, _u, _v, _goal, model, outcomes, energy, duration = case
    got = {}
    for p in range(model.n_pairs):
        state = model.state_of(int(model.pair_state[p]))
        got[state, int(model.pair_action[p])] = p
    assert set(got) == set(outcomes)
    assert len(outcomes) > 100
    for key, p in got.items():
        mine = model.outcomes(p)
        ref = outcomes[key]
        assert [o for o, _p, _e in mine] == [o for o, _p, _e in ref], key
        np.testing.assert_allclose([q for _o, q, _e in mine], [q for _o, q, _e in ref], rtol=1e-12)
        np.testing.assert_allclose([e for _o, _q, e in mine], [e for _o, _q, e in ref], rtol=1e-9)
        assert model.energy_wh[p] == pytest.approx(energy[key], rel=1e-9)
        assert model.duration_s[p] == pytest.approx(duration[key], rel=1e-9)


def test_expected_values_and_actions_match_plain_value_iteration(case):
    grid, _refine, _u, _v, goal, model, outcomes, energy, _duration = case
    sol = solve_physical(model, goal)
    goal_states = {(l, j, i, k) for l, j, i in zip(*np.nonzero(sol.goal_cells.mask), strict=True) for k in range(8)}
    ref = value_iteration(outcomes, energy, goal_states)
    finite = [s for s, v in ref.items() if math.isfinite(v)]
    assert all(math.isfinite(sol.value_wh[s]) for s in finite)
    assert all(not math.isfinite(sol.value_wh[s]) for s, v in ref.items() if not math.isfinite(v))
    assert len(finite) > 50
    for s in finite:
        assert sol.value_wh[s] == pytest.approx(ref[s], rel=1e-9, abs=TOLERANCE_WH), s
    chosen_ok = 0
    for s in finite:
        if s in goal_states:
            continue
        q = {a: energy[s, a] + sum(p * ref[o] for o, p, _e in outs)
             for (st, a), outs in outcomes.items() if st == s and all(math.isfinite(ref[o]) for o, _p, _e in outs)}
        best = min(q.values())
        assert q[int(sol.action[s])] <= best + 10 * TOLERANCE_WH, (s, q, int(sol.action[s]))
        chosen_ok += 1
    assert chosen_ok > 50


def test_a_second_goal_reuses_the_goal_free_samples(case):
    grid, refine, u, v, _goal, model, _o, _e, _d = case
    settings = plan_settings()
    free = sample_transitions(u, v, grid, settings, refine=refine)
    other = goal_at(grid, 0, 1, 1)
    mask = goal_mask(grid, u, v, refine, other)
    patched = assemble(enter_goal(free, u, v, grid, settings, refine=refine, goal_mask=mask), grid, settings,
                       refine=refine)
    fresh = assemble(sample_transitions(u, v, grid, settings, refine=refine, goal_mask=mask), grid, settings,
                     refine=refine)
    for name in ("pair_state", "pair_action", "ptr", "out_state", "out_prob", "out_energy_max_wh", "energy_wh",
                 "duration_s"):
        assert np.array_equal(getattr(patched, name), getattr(fresh, name)), name
    # The goal changes the samples near it only, and there it does change them.
    assert not np.array_equal(patched.out_state, model.out_state) or not np.array_equal(patched.energy_wh,
                                                                                       model.energy_wh)
