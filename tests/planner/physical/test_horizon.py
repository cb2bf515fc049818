"""The time-varying physical plan (planner.physical.horizon) on small grids.

- A current that does not change gives every slice the stationary plan's values: they satisfy the
  time-expanded equations, and the solver must find them.
- A current that turns gives the values of a plain, literal backward recursion (Jacobi sweeps
  from infinity over the models' per-(state, action) arrays) for both criteria.
- Through ``make_plan``: a slice per forecast step within the horizon, the table carries them and
  the executive's lookup by UTC time gets each slice's actions.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from planner.contract.errors import ContractError, ForecastError
from planner.contract.settings import Goal, PhysicalSettings, PlanSettings
from planner.contract.table import PolicyTable
from planner.paper.solve import goal_cells_on
from planner.physical.horizon import solve_horizon
from planner.physical.model import PhysicalModel, assemble, enter_goal, sample_transitions
from planner.physical.solve import solve_physical
from tests.planner.physical.test_physical import goal_at, small_grid, swirl

SETTINGS = PhysicalSettings(start_points=2, error_members=3, current_error_m_s=0.05)
HOUR_S = 3600.0


def models(criterion: str, factors: list[float], *, east_m_s: float = 0.0) -> tuple[list[PhysicalModel], Goal]:
    """One model per slice: the swirl times ``factors[n]`` plus an eastward current."""
    grid = small_grid()
    refine = 2
    base_u, base_v = swirl(grid, refine)
    goal = goal_at(grid, 0, 3, 4)
    settings = PlanSettings(model="physical", criterion=criterion, physical=SETTINGS)
    out = []
    for f in factors:
        u, v = base_u * f + east_m_s, base_v * f
        water = np.isfinite(u[:, ::refine, ::refine])
        mask = goal_cells_on(grid, water, goal).mask
        stats = enter_goal(sample_transitions(u, v, grid, settings, refine=refine), u, v, grid, settings,
                           refine=refine, goal_mask=mask)
        out.append(assemble(stats, grid, settings, refine=refine))
    return out, goal


@pytest.mark.parametrize("criterion", ["expected", "robust"])
def test_a_steady_current_gives_every_slice_the_stationary_values(criterion):
    slices, goal = models(criterion, [1.0, 1.0, 1.0])
    stationary = solve_physical(slices[0], goal)
    h = solve_horizon(lambda n: slices[n], np.array([0.0, 1.0, 2.0]) * HOUR_S, goal)
    want = stationary.value_wh
    assert np.isfinite(want).sum() > 100
    for n in range(3):
        got = h.value_wh[n]
        assert np.array_equal(np.isfinite(got), np.isfinite(want)), n
        fin = np.isfinite(want)
        np.testing.assert_allclose(got[fin], want[fin], rtol=1e-7, atol=1e-9)
    assert (h.action[0] == stationary.action)[np.isfinite(want)].mean() > 0.9  # ties may go either way


def reference(slices: list[PhysicalModel], times_s: np.ndarray, goal: Goal, robust: bool) -> np.ndarray:
    """Literal backward recursion: the last slice's stationary values, then Jacobi sweeps from infinity,
    each over every (state, action) pair at once. An action's chance of staying in its own state
    within the slice is solved for (expected), or the action is not taken (robust): from infinity
    it would never get a value."""
    T = len(slices)
    last = solve_physical(slices[-1], goal)
    K, (L, ny, nx) = 8, slices[0].water.shape
    n_states = slices[0].n_states
    value = np.full((T, n_states), math.inf)
    value[-1] = np.moveaxis(last.value_wh, -1, 0).ravel()
    goal_flat = np.broadcast_to(last.goal_cells.mask[None], (K, L, ny, nx)).ravel()
    for n in range(T - 2, -1, -1):
        md = slices[n]
        pair_of = np.repeat(np.arange(md.pair_state.size), np.diff(md.ptr))
        owner, o, prob = md.pair_state[pair_of], md.out_state, md.out_prob
        land = np.array([max(k for k in range(T) if times_s[k] <= times_s[n] + d) for d in md.duration_s])
        nxt = np.minimum(land + 1, T - 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(land == T - 1, 0.0, (times_s[n] + md.duration_s - times_s[land]) / (times_s[nxt] - times_s[land]))
        m, w = land[pair_of], w[pair_of]
        here = np.where(m == n, 1.0 - w, 0.0)  # the weight on this slice's own (unknown) values
        fixed = np.where((m > n) & (w < 1), (1 - w) * value[m, o], 0.0) + np.where(w > 0, w * value[nxt[pair_of], o], 0.0)
        stays = (here > 0) & (o == owner)
        usable = np.ones(md.pair_state.size, dtype=bool)
        if robust:
            usable[pair_of[stays]] = False
        stay = np.bincount(pair_of, weights=np.where(stays, prob * here, 0.0), minlength=usable.size)
        V = np.full(n_states, math.inf)
        V[goal_flat] = 0.0
        for _sweep in range(1_000_000):
            with np.errstate(invalid="ignore"):
                x = np.where(here > 0, here * V[o], 0.0) + fixed
            x[stays] = np.where(robust, x[stays], fixed[stays])
            if robust:
                q = np.full(usable.size, -math.inf)
                np.maximum.at(q, pair_of, md.out_energy_max_wh + x)
            else:
                q = md.energy_wh + np.bincount(pair_of, weights=prob * x, minlength=usable.size)
                q = q / (1.0 - stay)
            q[~usable] = math.inf
            new = np.full(n_states, math.inf)
            np.minimum.at(new, md.pair_state, q)
            new[goal_flat] = 0.0
            both = np.isfinite(new) & np.isfinite(V)
            done = np.array_equal(np.isfinite(new), np.isfinite(V)) and (not both.any() or
                                                                          np.max(np.abs(new - V)[both]) < 1e-13)
            V = new
            if done:
                break
        else:
            raise AssertionError("the reference did not converge")
        value[n] = V
    return value


@pytest.mark.parametrize("criterion", ["expected", "robust"])
def test_a_turning_current_gives_the_literal_recursions_values(criterion):
    times = np.array([0.0, 0.5, 1.5, 3.0]) * HOUR_S  # uneven: landings fall in the same, next and later slices
    slices, goal = models(criterion, [1.0, 0.3, -0.6, -1.0], east_m_s=0.1)
    h = solve_horizon(lambda n: slices[n], times, goal)
    want = reference(slices, times, goal, criterion == "robust")
    for n in range(times.size):
        got = np.moveaxis(h.value_wh[n], -1, 0).ravel()
        assert np.array_equal(np.isfinite(got), np.isfinite(want[n])), n
        fin = np.isfinite(want[n])
        assert fin.sum() > 100
        np.testing.assert_allclose(got[fin], want[n][fin], rtol=1e-7, atol=1e-9)
    # The slices differ: time matters to this plan.
    assert not np.allclose(np.nan_to_num(h.value_wh[0], posinf=0), np.nan_to_num(h.value_wh[2], posinf=0))


@pytest.fixture(scope="module")
def gyre_file(tmp_path_factory):
    from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre

    path = tmp_path_factory.mktemp("gyre") / "gyre.nc"
    write_gyre(path, DoubleGyreSettings(eps=0.25, hours=4.0, step_h=1.0, depths_m=(0.0, 5.0)))
    return path


def gyre_request(path, **settings):
    from planner.contract.geodesy import BBox
    from planner.pipeline import PlanRequest

    base = PlanSettings(model="physical", criterion="expected", physical=SETTINGS, time_varying=True, **settings)
    return PlanRequest(forecast_path=path, goal=Goal(lon_deg=-117.9, lat_deg=33.4, depth_m=0.0, radius_cells=1),
                       depths_m=(0.0, 5.0), settings=base,
                       bbox=BBox(west_deg=-118.15, south_deg=33.32, east_deg=-117.85, north_deg=33.45), nx=9, ny=5)


def test_make_plan_makes_a_slice_per_forecast_step_within_the_horizon(gyre_file):
    from planner.pipeline import make_plan

    result = make_plan(gyre_request(gyre_file, horizon_h=3.0))
    table = result.table
    assert result.horizon is not None and table.n_slices == 4  # steps 0, 1, 2, 3 h
    assert table.slice_times[0] == "2026-01-15T00:00:00Z" and table.slice_times[-1] == "2026-01-15T03:00:00Z"
    back = PolicyTable.from_bytes(table.to_bytes())
    assert back.slice_times == table.slice_times and np.array_equal(back.slices, result.horizon.action)
    for n, when in enumerate(back.slice_unix_s):
        chosen = back.slice_at(when)
        assert chosen.index == n and np.array_equal(chosen.table.actions, result.horizon.action[n])
    assert back.slice_at(back.slice_unix_s[-1] + 60.0).status == "past_horizon"
    assert not np.array_equal(result.horizon.action[0], result.horizon.action[2])  # the gyre moves
    assert np.array_equal(result.solution.action, result.horizon.action[0])


def test_a_time_varying_plan_needs_two_steps_and_the_physical_model(gyre_file):
    from planner.pipeline import make_plan

    with pytest.raises(ForecastError, match="two or more forecast steps within planning.horizon_h = 0.5 h"):
        make_plan(gyre_request(gyre_file, horizon_h=0.5))
    with pytest.raises(ContractError, match="time_varying: needs the physical model"):
        replace(PlanSettings(), time_varying=True)


def test_lrauv_plan_time_varying_writes_the_slices(gyre_file, tmp_path, capsys):
    from planner.cli import main

    out = tmp_path / "tv.lrpt"
    cmd = ["plan", "--forecast", str(gyre_file), "--model", "physical", "--criterion", "expected",
           "--bbox", "-118.15,33.32,-117.85,33.45", "--nx", "9", "--ny", "5", "--depths", "0,5",
           "--goal", "-117.9,33.4,0", "--time-varying", "--horizon-h", "2", "--out", str(out), "--quiet"]
    assert main(cmd) == 0
    printed = capsys.readouterr().out
    assert "x 3 time slices" in printed and "slices     3 slices, 2026-01-15T00:00:00Z to 2026-01-15T02:00:00Z" in printed
    assert "timing     " not in printed
    assert PolicyTable.load(out).n_slices == 3
    assert main(cmd + ["--horizon-h", "0.2"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "two or more forecast steps" in err


def test_slices_every_few_steps_or_a_clear_refusal(gyre_file):
    from planner.forecast import open_forecast
    from planner.pipeline import slice_steps

    f = open_forecast(gyre_file)  # hourly, 0..4 h
    assert slice_steps(f, 0, 4.0) == [0, 1, 2, 3, 4]
    assert slice_steps(f, 0, 4.0, 2.0) == [0, 2, 4]
    assert slice_steps(f, 1, 4.0, 3.0) == [1, 4]
    with pytest.raises(ForecastError, match="slice_h = 1.5 h is not a whole number of the forecast's steps"):
        slice_steps(f, 0, 4.0, 1.5)


def test_replay_plans_a_time_varying_table_again_from_its_header(gyre_file, tmp_path):
    from planner.contract.errors import ShoreError
    from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre
    from planner.pipeline import make_plan
    from planner.shore.replay.nominal import plan_again

    table = make_plan(gyre_request(gyre_file, horizon_h=2.0)).table
    again = plan_again(table, gyre_file)
    assert np.array_equal(again.table.slices, table.slices) and again.table.slice_times == table.slice_times
    other = write_gyre(tmp_path / "other.nc", DoubleGyreSettings(eps=0.25, phase_rad=1.0, hours=4.0, step_h=1.0,
                                                                depths_m=(0.0, 5.0)))
    with pytest.raises(ShoreError, match=r"actions that differ from the table"):
        plan_again(table, other)


def test_with_timing_correction_the_table_carries_each_slices_mean_current(gyre_file):
    from planner.pipeline import make_plan, region_mean_current

    plain = make_plan(gyre_request(gyre_file, horizon_h=2.0)).table
    assert plain.slice_current_m_s is None  # off by default: the bytes a time-varying table always had
    result = make_plan(gyre_request(gyre_file, horizon_h=2.0, timing_correction=True, timing_block_cells=1000))
    table = PolicyTable.from_bytes(result.table.to_bytes())
    assert table.slice_current_m_s is not None and table.slice_current_m_s.shape == (3, 2, 2)  # a block a layer
    assert table.current_block_cells is None  # written as a table of one mean per layer
    assert np.array_equal(table.slices, plain.slices)  # the plan is the same; only the lookup may shift
    # Slice 0's is the mean of the planning grid's water currents, to the cm/s.
    assert np.allclose(table.slice_current_m_s[0], region_mean_current(result.u_m_s, result.v_m_s), atol=0.005)
    # By default, blocks of 4 x 4 cells: the 9 x 5 grid is 2 x 3 blocks a layer.
    default = make_plan(gyre_request(gyre_file, horizon_h=2.0, timing_correction=True)).table
    assert default.current_block_cells == 4 and default.current_blocks() == (2, 3)
    assert default.slice_current_m_s is not None and default.slice_current_m_s.shape == (3, 12, 2)
    # Per block of 3 x 3 cells: each block's own mean, looked up by the cell's block.
    blocked = make_plan(gyre_request(gyre_file, horizon_h=2.0, timing_correction=True, timing_block_cells=3))
    back = PolicyTable.from_bytes(blocked.table.to_bytes())
    rows, cols = back.current_blocks()
    assert back.current_block_cells == 3 and (rows, cols) == (-(-back.ny // 3), -(-back.nx // 3))
    assert back.slice_current_m_s is not None and back.slice_current_m_s.shape == (3, 2 * rows * cols, 2)
    assert np.array_equal(back.slices, plain.slices)
    l, j, i = 1, back.ny - 1, 4
    u, v = blocked.u_m_s[l, j // 3 * 3:j // 3 * 3 + 3, 3:6], blocked.v_m_s[l, j // 3 * 3:j // 3 * 3 + 3, 3:6]
    wet = np.isfinite(u) & np.isfinite(v)
    assert np.allclose(back.slice_current_m_s[0, back.current_region((l, j, i))], [u[wet].mean(), v[wet].mean()],
                       atol=0.005)


def test_the_mean_current_of_a_layer_skips_land_and_a_layer_of_land_is_still():
    from planner.pipeline import region_mean_current

    u = np.array([[[0.2, np.nan], [0.4, 0.6]], [[np.nan, np.nan], [np.nan, np.nan]]])
    v = np.array([[[0.1, 0.3], [np.nan, -0.1]], [[np.nan, np.nan], [np.nan, np.nan]]])
    assert np.allclose(region_mean_current(u, v), [[0.4, 0.0], [0.0, 0.0]])  # nodes with both components: (0,0), (1,1)
    # Blocks of one cell: layer 0's four in row order, (0, 1) and (1, 0) without both components; layer 1 land.
    assert np.allclose(region_mean_current(u, v, 1), [[0.2, 0.1], [0, 0], [0, 0], [0.6, -0.1]] + [[0, 0]] * 4)


def test_lrauv_plan_of_the_tidal_mission_carries_the_slices_currents_and_says_so(tmp_path, capsys):
    from planner.cli import main
    from planner.forecast.synthetic.tidal import TidalSettings, write_tidal
    from tests.support import REPO

    forecast = write_tidal(tmp_path / "tidal.nc", TidalSettings())
    out = tmp_path / "tidal.lrpt"
    assert main(["plan", str(REPO / "missions" / "eval-tidal.yaml"), "--forecast", str(forecast), "--time-varying",
                 "--horizon-h", "3", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    table = PolicyTable.load(out)
    regions = table.n_current_regions
    assert f"timing     each slice's mean current per block of 4 x 4 cells ({regions} blocks) carried" in printed
    assert table.slice_current_m_s is not None and table.slice_current_m_s.shape == (4, regions, 2) and regions > 1
    # The channel's flood runs east along it: the first slice's current is eastward, strong in the channel's middle.
    assert table.slice_current_m_s[0, table.current_region((0, table.ny // 2, table.nx // 2)), 0] > 0.2
    # The flag overrides the mission's key, either way; on a stationary plan it is refused, not ignored.
    assert main(["plan", str(REPO / "missions" / "eval-tidal.yaml"), "--forecast", str(forecast), "--time-varying",
                 "--horizon-h", "3", "--no-timing-correction", "--out", str(out), "--quiet"]) == 0
    assert PolicyTable.load(out).slice_current_m_s is None and "timing " not in capsys.readouterr().out
    assert main(["plan", str(REPO / "missions" / "eval-tidal.yaml"), "--forecast", str(forecast), "--time-varying",
                 "--horizon-h", "3", "--timing-block-cells", "5", "--out", str(out), "--quiet"]) == 0
    assert "each slice's mean current per block of 5 x 5 cells (15 blocks) carried" in capsys.readouterr().out
    assert PolicyTable.load(out).current_block_cells == 5
    assert main(["plan", str(REPO / "missions" / "eval-tidal.yaml"), "--forecast", str(forecast), "--time-varying",
                 "--no-timing-correction", "--timing-block-cells", "5", "--out", str(out), "--quiet"]) == 2
    assert "--timing-block-cells: a reference current per block is for the tide's timing" in capsys.readouterr().err
    assert main(["plan", str(REPO / "missions" / "eval-tidal.yaml"), "--forecast", str(forecast),
                 "--timing-correction", "--out", str(tmp_path / "stationary.lrpt"), "--quiet"]) == 2
    assert "--timing-correction: a stationary plan has no slices" in capsys.readouterr().err
