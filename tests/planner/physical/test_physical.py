"""The physical planning model (planner.physical.model) and its two solvers (planner.physical.solve).

Transitions are checked against closed forms in still water and uniform currents; the robust
solver against a plain Bellman iteration of its own equation, the expected solver against value
iteration; then resolution independence and the whole pipeline on the synthetic forecast.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from planner.contract.actions import Action
from planner.contract.errors import LrauvError
from planner.grid import Grid
from planner.contract.geodesy import BBox
from planner.physical.model import (
    PhysicalModel,
    build_physical,
    fine_grid,
    member_offsets_m_s,
    refine_factor,
    start_offsets,
    transition_limit_s,
)
from planner.physical.expected import by_cell
from planner.physical.solve import PhysicalSolution, solve_physical
from planner.contract.settings import Goal, PhysicalSettings, PlanSettings
from planner.paper.solve import goal_cells_on
from planner.contract.vehicle import VehicleParams, power_draw_w

FORWARD, DRIFT, UP, DOWN = int(Action.FORWARD), int(Action.DRIFT), int(Action.UP), int(Action.DOWN)
PARAMS = VehicleParams()
# No forecast error: the forecast member only, start points spread over the cell.
EXACT = PhysicalSettings(current_error_m_s=0.0, error_members=0)
# A small box off Southern California: dx ~ 1864 m, dy ~ 2224 m (6 x 5 cells).
BOX = BBox(west_deg=-118.0, south_deg=33.0, east_deg=-117.9, north_deg=33.08)


# --------------------------------------------------------------------------- helpers


def small_grid(nx: int = 6, ny: int = 5, depths=(0.0, 10.0), bbox: BBox = BOX) -> Grid:
    return Grid.from_bbox(bbox, nx=nx, ny=ny, depths_m=list(depths))


def uniform(grid: Grid, refine: int, east: float = 0.0, north: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    fg = fine_grid(grid, refine)
    shape = (grid.n_layers, fg.ny, fg.nx)
    return np.full(shape, float(east)), np.full(shape, float(north))


def settings(criterion: str = "robust", physical: PhysicalSettings = EXACT, vehicle: VehicleParams = PARAMS) -> PlanSettings:
    return PlanSettings(model="physical", criterion=criterion, physical=physical, vehicle=vehicle)


def build(u, v, grid, s, refine, goal: Goal | None = None) -> PhysicalModel:
    mask = None
    if goal is not None:
        water = np.isfinite(u[:, ::refine, ::refine]) & np.isfinite(v[:, ::refine, ::refine])
        mask = goal_cells_on(grid, water, goal).mask
    return build_physical(u, v, grid, s, refine=refine, goal_mask=mask)


def pair(model: PhysicalModel, l: int, j: int, i: int, k: int, action: int) -> int | None:
    """The pair of (state, action), or None when the action is unavailable there."""
    for p in model.pairs_of(l, j, i, k):
        if int(model.pair_action[p]) == action:
            return p
    return None


def goal_at(grid: Grid, l: int, j: int, i: int, radius: int = 0) -> Goal:
    return Goal(lon_deg=float(grid.lon_deg[i]), lat_deg=float(grid.lat_deg[j]), depth_m=float(grid.depth_m[l]),
                radius_cells=radius)


def flat(arr_lijk: np.ndarray) -> np.ndarray:
    """Solution arrays (L, ny, nx, 8) -> the model's internal heading-major flat index."""
    return np.moveaxis(arr_lijk, -1, 0).ravel()


def goal_state_mask(model: PhysicalModel, sol: PhysicalSolution) -> np.ndarray:
    return np.broadcast_to(sol.goal_cells.mask[None], (8,) + sol.goal_cells.mask.shape).ravel()


def swirl(grid: Grid, refine: int, amplitude: float = 0.35) -> tuple[np.ndarray, np.ndarray]:
    """A gyre (stream function sin * sin over the box), weaker in the lower layer."""
    fg = fine_grid(grid, refine)
    X, Y = np.meshgrid(np.linspace(0.0, 1.0, fg.nx), np.linspace(0.0, 1.0, fg.ny), indexing="xy")
    u1 = -amplitude * np.sin(np.pi * X) * np.cos(np.pi * Y)
    v1 = amplitude * np.cos(np.pi * X) * np.sin(np.pi * Y)
    scale = np.linspace(1.0, 0.5, grid.n_layers)[:, None, None]
    return u1[None] * scale, v1[None] * scale


@pytest.fixture(scope="module")
def swirl_case():
    """6 x 5 x 2 with a gyre, one land cell in the upper layer, forecast error members (3 x 3 x 9 samples)."""
    grid = small_grid()
    refine = 2
    u, v = swirl(grid, refine)
    u[0, 2 * refine, 2 * refine] = np.nan  # land at planning cell (l=0, j=2, i=2)
    v[0, 2 * refine, 2 * refine] = np.nan
    goal = goal_at(grid, 0, 3, 4)
    return grid, refine, u, v, goal


# --------------------------------------------------------------------------- 1. still water FORWARD


@pytest.mark.parametrize("k, axis", [(0, "east"), (2, "north"), (4, "west"), (6, "south")])
def test_forward_in_still_water_moves_one_cell_at_cruise_speed(k, axis):
    grid = small_grid()
    u, v = uniform(grid, 2)
    model = build(u, v, grid, settings(), 2)
    l, j, i = 0, 2, 2
    p = pair(model, l, j, i, k, FORWARD)
    assert p is not None
    di, dj = {"east": (1, 0), "north": (0, 1), "west": (-1, 0), "south": (0, -1)}[axis]
    assert [o[:2] for o in model.outcomes(p)] == [((l, j + dj, i + di, k), 1.0)]
    dx_m, dy_m = grid.cell_size_m()
    spacing = float(dx_m[j]) if dj == 0 else dy_m
    expected_s = spacing / PARAMS.cruise_speed_m_s
    assert model.duration_s[p] == pytest.approx(expected_s, rel=0.005)
    power = power_draw_w(PARAMS, PARAMS.cruise_speed_m_s, False)
    assert power == PARAMS.hotel_w + PARAMS.propulsion_w
    assert model.energy_wh[p] == pytest.approx(power * expected_s / 3600.0, rel=0.005)
    # One outcome: its worst sample costs about the mean (the start rows differ only in latitude, so in dx).
    assert model.out_energy_max_wh[model.ptr[p]] == pytest.approx(model.energy_wh[p], rel=0.005)
    assert model.samples_per_action == EXACT.start_points ** 2


@pytest.mark.parametrize("k", [0, 2, 5])
def test_course_offset_forwards_in_still_water_follow_their_course(k):
    """FORWARD_LEFT/RIGHT: a third of the way to the neighbouring bearing; the one-spacing end in
    still water is then spacing / (speed x cos of the course's angle to the axis it crosses)."""
    from planner.contract.headings import courses_deg, heading_index

    grid = small_grid()
    u, v = uniform(grid, 2)
    model = build(u, v, grid, settings(), 2)
    l, j, i = 0, 2, 2
    bearings = grid.bearings_deg()
    courses = courses_deg(bearings)[j, k]
    left, right = float(bearings[j, (k + 1) % 8]), float(bearings[j, (k - 1) % 8])
    b = float(bearings[j, k])
    assert courses[0] == pytest.approx(b)
    for course, neighbour in ((courses[1], left), (courses[2], right)):
        turn = (course - b + 180.0) % 360.0 - 180.0
        gap = (neighbour - b + 180.0) % 360.0 - 180.0
        assert turn == pytest.approx(gap / 3.0)  # towards the neighbour, a third of the way
        assert heading_index(float(course), bearings[j]) == k  # the heading still reads as k
    # The 24 courses of a row are evenly spaced: a third of each gap between neighbouring bearings.
    row = courses_deg(bearings)[j]
    for kk in range(8):
        gap = (float(bearings[j, kk]) - float(bearings[j, (kk + 1) % 8])) % 360.0
        assert (row[kk, 1] - row[(kk + 1) % 8, 2]) % 360.0 == pytest.approx(gap / 3.0)
        assert (row[kk, 0] - row[kk, 1]) % 360.0 == pytest.approx(gap / 3.0)
    dx_m, dy_m = grid.cell_size_m()
    for action, course in ((int(Action.FORWARD_LEFT), courses[1]), (int(Action.FORWARD_RIGHT), courses[2])):
        p = pair(model, l, j, i, k, action)
        assert p is not None
        rad = math.radians(float(course))
        east, north = abs(math.sin(rad)), abs(math.cos(rad))
        expected_s = min(float(dx_m[j]) / east if east > 1e-9 else math.inf, dy_m / north if north > 1e-9 else math.inf)
        assert model.duration_s[p] == pytest.approx(expected_s / PARAMS.cruise_speed_m_s, rel=0.01)
        # Every sample ends one spacing away along the course: in the cells that direction reaches.
        for (_l, jj, ii, kk), _prob, _e in model.outcomes(p):
            assert kk == k and (ii - i) * math.sin(rad) >= 0 and (jj - j) * math.cos(rad) >= 0
    # Switched off: the eight bearings only, as before course offsets existed.
    plain = build(u, v, grid, settings(physical=replace(EXACT, course_offsets=False)), 2)
    assert not np.isin(plain.pair_action, [int(Action.FORWARD_LEFT), int(Action.FORWARD_RIGHT)]).any()
    assert pair(plain, l, j, i, k, FORWARD) is not None
    p_on, p_off = pair(model, l, j, i, k, FORWARD), pair(plain, l, j, i, k, FORWARD)
    assert model.outcomes(p_on) == plain.outcomes(p_off) and model.energy_wh[p_on] == plain.energy_wh[p_off]


# --------------------------------------------------------------------------- 2. DRIFT in a uniform current


def test_drift_in_a_uniform_current_takes_spacing_over_current_speed():
    grid = small_grid()
    u, v = uniform(grid, 2, east=0.2)
    # dx / 0.2 m/s ~ 9300 s: longer than the default limit (4 crossings at cruise speed ~ 8900 s).
    assert transition_limit_s(grid, settings()) < float(grid.cell_size_m()[0][2]) / 0.2
    s = settings(physical=replace(EXACT, max_transition_s=20_000.0))
    assert transition_limit_s(grid, s) == 20_000.0
    model = build(u, v, grid, s, 2)
    assert model.samples_per_action == 9  # the forecast only: 3 x 3 start points x 1 member
    l, j, i, k = 0, 2, 2, 3
    p = pair(model, l, j, i, k, DRIFT)
    assert p is not None
    outs = model.outcomes(p)
    assert [o[0] for o in outs] == [(l, j, i + 1, k)] and outs[0][1] == 1.0
    duration = float(grid.cell_size_m()[0][j]) / 0.2
    assert model.duration_s[p] == pytest.approx(duration, rel=0.01)
    hotel = power_draw_w(PARAMS, 0.0, False)
    assert hotel == PARAMS.hotel_w
    assert model.energy_wh[p] == pytest.approx(hotel * model.duration_s[p] / 3600.0, rel=1e-9)
    assert model.energy_wh[p] == pytest.approx(hotel * duration / 3600.0, rel=0.01)
    # With the default limit the drift is cut short at the limit (and still counted as a move).
    short = build(u, v, grid, settings(), 2)
    ps = pair(short, l, j, i, k, DRIFT)
    assert short.duration_s[ps] == pytest.approx(transition_limit_s(grid, settings()), rel=1e-9)


def test_error_members_multiply_the_samples():
    grid = small_grid()
    u, v = uniform(grid, 1, east=0.2)
    model = build(u, v, grid, settings(physical=PhysicalSettings(start_points=2, error_members=5)), 1)
    assert model.samples_per_action == 4 * 6
    p = pair(model, 0, 2, 2, 0, FORWARD)
    assert math.isclose(float(np.sum(model.out_prob[model.ptr[p]:model.ptr[p + 1]])), 1.0, rel_tol=1e-12)


# --------------------------------------------------------------------------- 3. members and start points


@pytest.mark.parametrize("members", [3, 8, 20])
@pytest.mark.parametrize("error", [0.03, 0.1])
def test_member_offsets_have_zero_mean_and_the_error_as_standard_deviation(members, error):
    off = member_offsets_m_s(PhysicalSettings(error_members=members, current_error_m_s=error))
    assert off.shape == (members + 1, 2)
    assert np.array_equal(off[0], [0.0, 0.0])  # the forecast itself first
    np.testing.assert_allclose(off.mean(axis=0), [0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(off.std(axis=0), [error, error], rtol=1e-12)  # population std, M + 1 members
    assert member_offsets_m_s(PhysicalSettings(error_members=0)).tolist() == [[0.0, 0.0]]


@pytest.mark.parametrize("points", [1, 2, 3, 4, 9])
def test_start_offsets_are_symmetric_and_inside_the_cell(points):
    off = start_offsets(PhysicalSettings(start_points=points))
    assert off.shape == (points * points, 2)
    assert np.all(np.abs(off) < 0.5)
    key = lambda a: sorted(map(tuple, np.round(a, 12)))  # noqa: E731
    assert key(off) == key(-off)  # symmetric about the centre
    assert key(off) == key(off[:, ::-1])  # the same lattice on both axes
    np.testing.assert_allclose(off.mean(axis=0), [0.0, 0.0], atol=1e-15)
    assert len({tuple(r) for r in off.tolist()}) == points * points


def test_refine_factor_and_fine_grid():
    grid = small_grid()  # dlon 0.02, dlat 0.02
    assert refine_factor(grid, None) == 1
    assert refine_factor(grid, 0.02) == 1
    assert refine_factor(grid, 0.01) == 2
    assert refine_factor(grid, 0.007) == 3
    assert refine_factor(grid, 1e-5) == 8
    fg = fine_grid(grid, 3)
    assert (fg.nx, fg.ny) == (16, 13)
    np.testing.assert_allclose(fg.lon_deg[::3], grid.lon_deg, atol=1e-12)
    np.testing.assert_allclose(fg.lat_deg[::3], grid.lat_deg, atol=1e-12)


# --------------------------------------------------------------------------- 4. land and the grid edge


def test_land_east_makes_forward_east_unavailable():
    grid = small_grid()
    refine = 2
    u, v = uniform(grid, refine)
    u[:, :, 3 * refine] = np.nan  # planning column i = 3 is land in both layers
    v[:, :, 3 * refine] = np.nan
    model = build(u, v, grid, settings(), refine)
    assert not model.water[:, :, 3].any() and model.water[:, :, 2].all()
    for j in range(grid.ny):
        assert pair(model, 0, j, 2, 0, FORWARD) is None  # east: into land
        assert pair(model, 0, j, 2, 4, FORWARD) is not None  # west: open water
        assert pair(model, 0, j, 4, 0, FORWARD) is not None  # east of the land column
        assert pair(model, 0, j, 4, 4, FORWARD) is None  # west of it: into land
    # No pair starts on land.
    assert not np.any(np.broadcast_to(~model.water[None], (8,) + model.water.shape).ravel()[model.pair_state])


def test_drift_out_of_the_grid_is_unavailable():
    grid = small_grid()
    u, v = uniform(grid, 1, east=0.5)
    model = build(u, v, grid, settings(), 1)
    nx = grid.nx
    for k in range(8):
        assert pair(model, 0, 2, nx - 1, k, DRIFT) is None  # pushed out of the east edge
        assert pair(model, 0, 2, nx - 3, k, DRIFT) is not None  # inside: one cell east
    assert pair(model, 0, 2, nx - 1, 0, FORWARD) is None
    assert pair(model, 0, 2, nx - 1, 4, FORWARD) is not None  # against the current, into the grid
    assert pair(model, 0, 2, 0, 4, DRIFT) is not None  # the current carries it back in from the west edge


# --------------------------------------------------------------------------- 5. goal entry


def test_forward_ends_on_entering_the_goal():
    grid = small_grid()
    u, v = uniform(grid, 1)
    goal = goal_at(grid, 0, 2, 4)
    model = build(u, v, grid, settings(), 1, goal)
    dx = float(grid.cell_size_m()[0][2])
    # Next to the goal: the starts are spread over the cell, so the goal's edge is half a spacing away on average.
    p = pair(model, 0, 2, 3, 0, FORWARD)
    assert [o[0] for o in model.outcomes(p)] == [(0, 2, 4, 0)]
    assert model.duration_s[p] == pytest.approx(0.5 * dx / PARAMS.cruise_speed_m_s, rel=0.01)
    assert model.duration_s[p] < 0.75 * dx
    # Two cells away: the full spacing (no start point is within one spacing of the goal's edge).
    p2 = pair(model, 0, 2, 2, 0, FORWARD)
    assert [o[0] for o in model.outcomes(p2)] == [(0, 2, 3, 0)]
    assert model.duration_s[p2] == pytest.approx(dx / PARAMS.cruise_speed_m_s, rel=0.005)
    # Without a goal mask the same move runs the full spacing.
    plain = build(u, v, grid, settings(), 1)
    assert plain.duration_s[pair(plain, 0, 2, 3, 0, FORWARD)] == pytest.approx(dx, rel=0.005)


# --------------------------------------------------------------------------- 6. glides


def test_glides_take_layer_spacing_over_glide_rate_with_the_buoyancy_engine():
    grid = small_grid(depths=(0.0, 10.0, 30.0))
    refine = 2
    u, v = uniform(grid, refine)
    u[2, 2 * refine, 1 * refine] = np.nan  # the bottom layer is land at (j=2, i=1)
    v[2, 2 * refine, 1 * refine] = np.nan
    vp = VehicleParams(glide_rate_m_s=0.25)
    model = build(u, v, grid, settings(vehicle=vp), refine)
    gliding_w = power_draw_w(vp, 0.0, True)
    assert gliding_w == vp.hotel_w + vp.buoyancy_w
    for k in (0, 5):
        cases = [(0, DOWN, 1, 10.0 / 0.25), (1, UP, 0, 10.0 / 0.25), (1, DOWN, 2, 20.0 / 0.25), (2, UP, 1, 20.0 / 0.25)]
        for l, action, lt, seconds in cases:
            p = pair(model, l, 3, 3, k, action)
            assert p is not None, (l, action)
            assert model.outcomes(p) == [((lt, 3, 3, k), 1.0, pytest.approx(gliding_w * seconds / 3600.0, rel=1e-9))]
            assert model.duration_s[p] == pytest.approx(seconds, rel=1e-9)
            assert model.energy_wh[p] == pytest.approx(gliding_w * seconds / 3600.0, rel=1e-9)
        assert pair(model, 0, 3, 3, k, UP) is None  # the top layer
        assert pair(model, 2, 3, 3, k, DOWN) is None  # the bottom layer
        assert pair(model, 1, 2, 1, k, DOWN) is None  # land below
        assert pair(model, 1, 2, 1, k, UP) is not None
        assert pair(model, 2, 2, 1, k, UP) is None  # a land state has no pairs at all


# --------------------------------------------------------------------------- 7. robust solver


def bellman_robust(model: PhysicalModel, goal_states: np.ndarray) -> np.ndarray:
    """V(s) = min_a max_o (E_max(s, a, o) + V(o)) from V = inf (goal 0), until nothing changes."""
    n = model.n_states
    value = np.full(n, np.inf)
    value[goal_states] = 0.0
    is_goal = np.zeros(n, dtype=bool)
    is_goal[goal_states] = True
    for _ in range(n + 2):
        q = robust_q(model, value)
        new = np.full(n, np.inf)
        np.minimum.at(new, model.pair_state, q)
        new[is_goal] = 0.0
        if np.array_equal(new, value):
            return value
        value = new
    raise AssertionError("the reference Bellman iteration did not settle")


def robust_q(model: PhysicalModel, value: np.ndarray) -> np.ndarray:
    """max over each pair's outcomes of (E_max + V(outcome)), plain python."""
    q = np.empty(model.n_pairs)
    for p in range(model.n_pairs):
        lo, hi = int(model.ptr[p]), int(model.ptr[p + 1])
        q[p] = max(float(model.out_energy_max_wh[e]) + float(value[model.out_state[e]]) for e in range(lo, hi))
    return q


def test_robust_solver_equals_plain_bellman_iteration(swirl_case):
    grid, refine, u, v, goal = swirl_case
    model = build(u, v, grid, settings("robust", physical=PhysicalSettings(error_members=4, current_error_m_s=0.05)),
                  refine, goal)
    sol = solve_physical(model, goal)
    goal_mask = goal_state_mask(model, sol)
    goal_states = np.flatnonzero(goal_mask)
    ref = bellman_robust(model, goal_states)
    got = flat(sol.value_wh)
    assert np.array_equal(np.isinf(got), np.isinf(ref))
    finite = np.isfinite(ref)
    assert finite.sum() > 0.8 * model.water.sum() * 8  # nearly everything is reachable: a real test
    np.testing.assert_allclose(got[finite], ref[finite], rtol=1e-12, atol=0)
    # Every chosen action attains the minimum, and the time-to-go is the policy's worst case.
    q = robust_q(model, ref)
    t = flat(sol.time_s)
    action = flat(sol.action)
    assert np.all(action[goal_mask] == Action.AT_GOAL) and np.all(got[goal_mask] == 0.0)
    for s in np.flatnonzero(finite & ~goal_mask):
        p = int(sol.policy_pair[s])
        assert p >= 0 and model.pair_state[p] == s and action[s] == model.pair_action[p]
        assert q[p] == pytest.approx(ref[s], rel=1e-12)
        lo, hi = int(model.ptr[p]), int(model.ptr[p + 1])
        assert s not in model.out_state[lo:hi]  # never an action that may leave it where it is
        worst_t = max(t[o] for o in model.out_state[lo:hi])
        assert t[s] == pytest.approx(model.duration_s[p] + worst_t, rel=1e-12)
    assert np.all(action[~finite] == Action.UNREACHABLE)


def test_robust_unreachable_states_in_a_strong_current():
    """1.5 m/s east everywhere, the vehicle makes 1 m/s: nothing east of the goal can reach it."""
    grid = small_grid(nx=8, depths=(0.0,))
    u, v = uniform(grid, 1, east=1.5)
    goal = goal_at(grid, 0, 2, 3)
    model = build(u, v, grid, settings("robust", physical=PhysicalSettings()), 1, goal)
    sol = solve_physical(model, goal)
    ref = bellman_robust(model, np.flatnonzero(goal_state_mask(model, sol)))
    got = flat(sol.value_wh)
    assert np.array_equal(np.isinf(got), np.isinf(ref))
    np.testing.assert_allclose(got[np.isfinite(ref)], ref[np.isfinite(ref)], rtol=1e-12)
    assert np.all(np.isinf(sol.value_wh[0, :, 5:, :]))  # east of the goal
    assert np.all(np.isfinite(sol.value_wh[0, 2, 1:3, :]))  # upstream, on the goal's row: drift there


# --------------------------------------------------------------------------- 8. expected solver


def proper_states(model: PhysicalModel, is_goal: np.ndarray) -> np.ndarray:
    """States from which some policy reaches the goal with probability 1 (plain fixed point)."""
    alive = np.ones(model.n_states, dtype=bool)
    outs = [model.out_state[model.ptr[p]:model.ptr[p + 1]] for p in range(model.n_pairs)]
    while True:
        usable = [alive[o].all() for o in outs]
        found = is_goal.copy()
        grew = True
        while grew:  # backward reachability through usable pairs
            grew = False
            for p in range(model.n_pairs):
                s = model.pair_state[p]
                if usable[p] and not found[s] and found[outs[p]].any():
                    found[s] = True
                    grew = True
        new = alive & found
        if np.array_equal(new, alive):
            return alive
        alive = new


def value_iteration(model: PhysicalModel, finite: np.ndarray, is_goal: np.ndarray, tol: float = 1e-10):
    """V <- min_a (c + sum P V) over the states ``finite`` and pairs whose outcomes all lie in it, from V = 0."""
    rows = np.repeat(np.arange(model.n_pairs), np.diff(model.ptr))
    P = sp.csr_matrix((model.out_prob, (rows, model.out_state)), shape=(model.n_pairs, model.n_states))
    ok = np.array([finite[model.out_state[model.ptr[p]:model.ptr[p + 1]]].all() for p in range(model.n_pairs)])
    ok &= finite[model.pair_state] & ~is_goal[model.pair_state]
    Pk, cost, owner = P[ok], model.energy_wh[ok], model.pair_state[ok]
    value = np.zeros(model.n_states)
    for it in range(200_000):
        q = cost + Pk @ value
        new = np.full(model.n_states, np.inf)
        np.minimum.at(new, owner, q)
        new[~finite | is_goal] = 0.0
        change = np.max(np.abs(new - value))
        value = new
        if change < tol:
            return value, it
    raise AssertionError("value iteration did not converge")


@pytest.mark.parametrize("case", ["swirl", "strong"])
def test_expected_solver_equals_value_iteration(swirl_case, case):
    if case == "swirl":
        grid, refine, u, v, goal = swirl_case
    else:  # a current stronger than the vehicle east of x = 3: unreachable states, and cycles
        grid, refine = small_grid(nx=8), 1
        u, v = uniform(grid, refine, east=0.3)
        u[:, :, 4:] = 1.3
        goal = goal_at(grid, 0, 2, 3)
    model = build(u, v, grid, settings("expected", physical=PhysicalSettings()), refine, goal)
    sol = solve_physical(model, goal)
    is_goal = goal_state_mask(model, sol).copy()
    got = flat(sol.value_wh)
    finite = np.isfinite(got)
    water = np.broadcast_to(model.water[None], (8,) + model.water.shape).ravel()
    # inf exactly where no policy reaches the goal with probability 1.
    assert np.array_equal(finite, proper_states(model, is_goal) & water)
    if case == "strong":
        assert (~finite & water).sum() > 0.3 * water.sum()
        assert np.all(np.isinf(sol.value_wh[:, :, 5:, :]))
    ref, iters = value_iteration(model, finite, is_goal)
    assert iters > 5
    np.testing.assert_allclose(got[finite], ref[finite], rtol=1e-6, atol=0)
    assert np.all(got[is_goal] == 0.0) and np.all(got[finite & ~is_goal] > 0.0)
    # The chosen actions keep the vehicle in the finite set, and the policy reaches the goal w.p. 1.
    action = flat(sol.action)
    states = np.flatnonzero(finite & ~is_goal)
    for s in states:
        p = int(sol.policy_pair[s])
        assert p >= 0 and model.pair_state[p] == s and action[s] == model.pair_action[p]
        assert np.all(finite[model.out_state[model.ptr[p]:model.ptr[p + 1]]])
    index = np.full(model.n_states, -1)
    index[states] = np.arange(states.size)
    A = np.zeros((states.size, states.size))
    for r, s in enumerate(states):
        p = int(sol.policy_pair[s])
        for e in range(model.ptr[p], model.ptr[p + 1]):
            if index[model.out_state[e]] >= 0:
                A[r, index[model.out_state[e]]] += model.out_prob[e]
    assert np.max(np.abs(np.linalg.eigvals(A))) < 1.0 - 1e-9  # transient: absorbed at the goal
    # Its own Bellman equation holds (the policy's value), and the time-to-go is the policy's mean time.
    c = model.energy_wh[sol.policy_pair[states]]
    np.testing.assert_allclose(np.linalg.solve(np.eye(states.size) - A, c), got[states], rtol=1e-9)
    d = model.duration_s[sol.policy_pair[states]]
    np.testing.assert_allclose(np.linalg.solve(np.eye(states.size) - A, d), flat(sol.time_s)[states], rtol=1e-9)
    assert sol.residual_wh <= 1e-6
    assert np.all(action[water & ~finite] == Action.UNREACHABLE)


def test_by_cell_puts_a_cells_headings_together_in_the_searchs_cell_order():
    n_cells = 5
    # Internal index k * n_cells + cell; the search met cell 3 first, then 0, then 4 (cell 1 and 2: none).
    order = np.array([1 * 5 + 3, 0 * 5 + 0, 6 * 5 + 3, 2 * 5 + 4, 7 * 5 + 0, 0 * 5 + 3, 5 * 5 + 4])
    got = by_cell(order, n_cells)
    assert sorted(got.tolist()) == sorted(order.tolist())  # a permutation of the same states
    cell_heading = [(int(s) % n_cells, int(s) // n_cells) for s in got]
    assert cell_heading == [(3, 0), (3, 1), (3, 6), (0, 0), (0, 7), (4, 2), (4, 5)]
    assert by_cell(order[:0], n_cells).size == 0


# --------------------------------------------------------------------------- 9. zero-cost cycles


FREE = VehicleParams(hotel_w=0.0, propulsion_w=0.0, buoyancy_w=0.0)


def test_zero_power_vehicle_costs_the_floor_and_policy_iteration_settles():
    grid = small_grid()
    u, v = uniform(grid, 1)
    goal = goal_at(grid, 0, 2, 4)
    ps = PhysicalSettings()
    model = build(u, v, grid, settings("expected", physical=ps, vehicle=FREE), 1, goal)
    assert np.all(model.energy_wh == ps.min_cost_wh) and np.all(model.out_energy_max_wh == ps.min_cost_wh)
    sol = solve_physical(model, goal)
    is_goal = goal_state_mask(model, sol)
    got = flat(sol.value_wh)
    water = np.broadcast_to(model.water[None], (8,) + model.water.shape).ravel()
    assert np.all(np.isfinite(got[water]))  # still water, no land: everything reaches the goal
    assert np.all(got[~is_goal & water] >= ps.min_cost_wh * (1 - 1e-9))  # at least one action
    assert 1 <= sol.iterations < ps.max_iterations
    # The robust criterion too: the worst case counts actions.
    rob = solve_physical(build(u, v, grid, settings("robust", physical=ps, vehicle=FREE), 1, goal), goal)
    assert np.all(np.isfinite(rob.value_wh[model.water]))
    assert np.all(flat(rob.value_wh)[~is_goal & water] >= ps.min_cost_wh * (1 - 1e-9))


def test_policy_iteration_guard_raises():
    """The first policy (backward search) takes the first usable pair it meets: a DRIFT that reaches the goal only
    with a small probability. It is proper but slow; one sweep of value iteration from its value does not make it
    optimal, so policy iteration after it needs more than the one iteration allowed."""
    grid = small_grid()
    u, v = uniform(grid, 1)
    goal = goal_at(grid, 0, 2, 4)
    ps = PhysicalSettings(tolerance_wh=1e-9)
    model = build(u, v, grid, settings("expected", physical=ps, vehicle=FREE), 1, goal)
    full = solve_physical(model, goal)
    assert full.sweeps >= 2 and full.iterations >= 1
    one = build(u, v, grid, settings("expected", physical=replace(ps, max_iterations=1), vehicle=FREE), 1, goal)
    with pytest.raises(LrauvError, match="max_iterations"):
        solve_physical(one, goal)
    # The same with real power figures.
    real = build(u, v, grid, settings("expected", physical=replace(PhysicalSettings(), max_iterations=1)), 1, goal)
    with pytest.raises(LrauvError, match="did not settle in 1 iterations"):
        solve_physical(real, goal)


# --------------------------------------------------------------------------- 10. resolution


def test_value_does_not_depend_much_on_the_planning_resolution():
    lat0 = 33.0
    dlat = 20_000.0 / (6_371_000.0 * math.pi / 180.0)
    dlon = dlat / math.cos(math.radians(lat0 + dlat / 2))
    box = BBox(west_deg=-118.0, south_deg=lat0, east_deg=-118.0 + dlon, north_deg=lat0 + dlat)
    goal_lon, start_lon, mid_lat = -118.0 + 0.8 * dlon, -118.0 + 0.2 * dlon, lat0 + 0.5 * dlat
    values = {}
    for n, radius in ((11, 1), (21, 2)):
        grid = Grid.from_bbox(box, nx=n, ny=n, depths_m=[0.0])
        u, v = uniform(grid, 1, east=0.1)
        goal = Goal(lon_deg=goal_lon, lat_deg=mid_lat, depth_m=0.0, radius_cells=radius)
        model = build(u, v, grid, settings("expected", physical=PhysicalSettings()), 1, goal)
        sol = solve_physical(model, goal)
        i, j, _ = grid.nearest_cell(start_lon, mid_lat)
        values[n] = float(sol.value_wh[0, j, i, 0])
    # ~12 km less half the goal's width at 1.1 m/s over ground, 20 W: about 50 Wh.
    assert 30.0 < values[11] < 70.0
    assert abs(values[21] - values[11]) < 0.1 * values[11], values


# --------------------------------------------------------------------------- 11. end to end


@pytest.fixture(scope="module")
def physical_plans(synthetic_forecast):
    from planner.pipeline import PlanRequest, make_plan

    goal = Goal(lat_deg=33.40, lon_deg=-117.80, depth_m=0.0, radius_cells=1)
    box = BBox(west_deg=-118.26, south_deg=33.30, east_deg=-117.70, north_deg=33.70)
    out = {}
    for criterion in ("robust", "expected"):
        request = PlanRequest(forecast_path=synthetic_forecast, goal=goal, depths_m=(0.0, 5.0, 10.0, 15.0),
                              settings=PlanSettings(model="physical", criterion=criterion), bbox=box, nx=29, ny=21,
                              time_index=0)
        out[criterion] = make_plan(request)
    return out


def test_make_plan_physical_end_to_end(physical_plans):
    rob, exp = physical_plans["robust"], physical_plans["expected"]
    for result in (rob, exp):
        sol, table = result.solution, result.table
        assert isinstance(sol, PhysicalSolution)
        assert table.model == "physical"
        acts = table.actions
        assert acts.shape == result.grid.shape
        assert np.all(acts <= Action.FORWARD_RIGHT)
        at_goal = acts == Action.AT_GOAL
        assert np.array_equal(at_goal, np.broadcast_to(sol.goal_cells.mask[..., None], acts.shape))
        assert np.all(acts[~result.model.water] == Action.UNREACHABLE)
        assert np.array_equal(acts == Action.UNREACHABLE, ~np.isfinite(sol.value_wh))
        reach = np.isfinite(sol.value_wh) & ~at_goal
        assert reach.sum() > 0.5 * result.model.water.sum() * 8
        moves = acts[reach]
        assert np.all((moves <= Action.DOWN) | (moves == Action.FORWARD_LEFT) | (moves == Action.FORWARD_RIGHT))
        # The course offsets are used (the default), on both sides.
        assert (moves == Action.FORWARD_LEFT).any() and (moves == Action.FORWARD_RIGHT).any()
    # Every state the worst case can bring home, the mean can too, and the worst case is never cheaper.
    r, e = rob.solution.value_wh, exp.solution.value_wh
    assert np.all(np.isfinite(e)[np.isfinite(r)])
    both = np.isfinite(r) & np.isfinite(e)
    assert np.all(r[both] >= e[both] - 1e-6), float(np.min(r[both] - e[both]))
    assert np.mean(r[both] > e[both] + 1e-3) > 0.5  # the worst case costs more almost everywhere
    # The nominal path from a reachable start well away from the goal ends at the goal.
    for result in (rob, exp):
        sol = result.solution
        start = (0, 10, 5, 0)
        assert np.isfinite(sol.value_wh[start])
        path = sol.nominal(start)
        assert path[0].action != Action.AT_GOAL and len(path) > 3
        assert path[-1].action == Action.AT_GOAL
        assert sol.goal_cells.mask[path[-1].l, path[-1].j, path[-1].i]
        assert all(step.duration_s > 0 for step in path[:-1])


def test_a_second_goal_on_the_same_forecast_reuses_the_samples_and_plans_the_same(synthetic_forecast):
    from planner.pipeline import PlanRequest, SampleCache, make_plan

    box = BBox(west_deg=-118.26, south_deg=33.30, east_deg=-117.70, north_deg=33.70)
    first = PlanRequest(forecast_path=synthetic_forecast, goal=Goal(lat_deg=33.40, lon_deg=-117.80, depth_m=0.0),
                        depths_m=(0.0, 5.0), settings=PlanSettings(model="physical", criterion="expected"), bbox=box,
                        nx=15, ny=11, time_index=0)
    second = replace(first, goal=Goal(lat_deg=33.60, lon_deg=-118.10, depth_m=5.0, radius_cells=1))
    cache = SampleCache()
    a = make_plan(first, samples=cache)
    b = make_plan(second, samples=cache)
    assert cache.hits == 1
    alone = make_plan(second)
    assert b.table.to_bytes() == alone.table.to_bytes()
    np.testing.assert_array_equal(b.solution.value_wh, alone.solution.value_wh)
    assert not np.array_equal(a.solution.value_wh, b.solution.value_wh)
    # Another step of the forecast is another forecast: sampled again.
    make_plan(replace(second, time_index=1), samples=cache)
    assert cache.hits == 1


# --------------------------------------------------------------------------- regressions: goal entry past the move, ties at the cost floor


@pytest.mark.parametrize("points, rk4_steps", [(5, 8), (3, 1)])
def test_goal_entry_after_the_one_spacing_end_does_not_count(points, rk4_steps):
    """From two cells west of a goal cell every sample ends one spacing on, at most 0.5 - 1 / (2 S) into the
    next cell, short of the goal's edge: one outcome (the next cell), one spacing long, as without the goal."""
    grid = small_grid()
    u, v = uniform(grid, 1)
    goal = goal_at(grid, 0, 2, 4)
    ps = replace(EXACT, start_points=points, rk4_steps=rk4_steps)
    model = build(u, v, grid, settings(physical=ps), 1, goal)
    p = pair(model, 0, 2, 2, 0, FORWARD)
    dx = float(grid.cell_size_m()[0][2])
    assert [o[:2] for o in model.outcomes(p)] == [((0, 2, 3, 0), 1.0)]
    assert model.duration_s[p] == pytest.approx(dx / PARAMS.cruise_speed_m_s, rel=0.005)


def test_zero_power_expected_values_are_optimal_with_the_default_tolerance():
    grid = small_grid()
    u, v = uniform(grid, 1)
    goal = goal_at(grid, 0, 2, 4)
    model = build(u, v, grid, settings("expected", physical=PhysicalSettings(), vehicle=FREE), 1, goal)
    sol = solve_physical(model, goal)
    got = flat(sol.value_wh)
    finite = np.isfinite(got)
    ref, _ = value_iteration(model, finite, goal_state_mask(model, sol).copy(), tol=1e-16)
    rob = solve_physical(build(u, v, grid, settings("robust", physical=PhysicalSettings(), vehicle=FREE), 1, goal), goal)
    assert np.all(got[finite] <= flat(rob.value_wh)[finite] + 1e-12)  # the mean never above the worst case
    np.testing.assert_allclose(got[finite], ref[finite], rtol=1e-6)  # got 4e-6 Wh where 3e-6 is optimal
