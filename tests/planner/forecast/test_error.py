"""The forecast error measured from data (planner.forecast.error), on real netCDF files the tests write."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from planner.contract.geodesy import BBox
from planner.forecast import open_forecast
from planner.forecast.error import measure_error
from planner.forecast.resample import resample
from planner.forecast.synthetic.tidal import TidalSettings, with_forecast_error, write_tidal
from planner.grid import Grid

BOX = BBox(west_deg=-118.2, south_deg=33.35, east_deg=-117.8, north_deg=33.45)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("tide")
    truth = TidalSettings(hours=6, depths_m=(0.0,))
    return (write_tidal(root / "truth.nc", truth),
            write_tidal(root / "forecast.nc", with_forecast_error(truth, phase_error_h=1.0, amplitude_error=-0.2)))


def grid() -> Grid:
    return Grid.from_bbox(BOX, nx=25, ny=11, depths_m=[0.0])


def test_a_stationary_plan_measures_the_forecasts_own_change(files):
    truth_path, _ = files
    f = open_forecast(truth_path)
    g = grid()
    est = measure_error(f, g, 0, 3.0, time_varying=False, default_m_s=0.03)
    assert est.source == "forecast change" and "over the next 3 h (3 steps" in est.detail
    u0, v0 = resample(f, g, time_index=0)
    diffs = []
    for n in (1, 2, 3):
        u, v = resample(f, g, time_index=n)
        diffs += [(u - u0)[np.isfinite(u)], (v - v0)[np.isfinite(v)]]
    want = math.sqrt(np.mean(np.concatenate(diffs) ** 2))
    assert est.current_error_m_s == pytest.approx(want, rel=1e-12)
    assert est.current_error_m_s > 0.1  # the tide turns: far more than the 0.03 default


def test_a_time_varying_plan_measures_from_a_previous_issue_or_keeps_the_default(files):
    truth_path, forecast_path = files
    f, prev = open_forecast(forecast_path), open_forecast(truth_path)
    est = measure_error(f, grid(), 0, 6.0, time_varying=True, default_m_s=0.03)
    assert est.source == "default" and est.current_error_m_s == 0.03 and "carries the forecast's change" in est.detail
    est = measure_error(f, grid(), 0, 6.0, time_varying=True, previous=prev, default_m_s=0.03)
    assert est.source == "previous issue" and "at the 7 valid time(s)" in est.detail
    assert 0.05 < est.current_error_m_s < 1.0
    same = measure_error(prev, grid(), 0, 6.0, time_varying=True, previous=prev, default_m_s=0.03)
    assert same.current_error_m_s == 0.0


def test_a_mission_asks_for_a_measured_error(tmp_path):
    from planner.contract.mission import load_mission

    text = open("missions/eval-tidal.yaml").read().replace(
        "  criterion: expected\n", "  criterion: expected\n  physical: {current_error_m_s: measured}\n", 1)
    path = tmp_path / "m.yaml"
    path.write_text(text)
    m = load_mission(path)
    assert m.settings.error_measured and m.settings.physical.current_error_m_s == 0.03
    path.write_text(text.replace("measured", "lots"))
    with pytest.raises(Exception, match="current_error_m_s"):
        load_mission(path)


def test_plan_says_what_it_chose_and_warns_when_most_states_are_unreachable(files, tmp_path):
    from planner.contract.mission import load_mission
    from planner.pipeline import PlanRequest, make_plan
    from planner.plan_summary import summary_lines

    truth_path, _ = files
    mission = load_mission("missions/eval-tidal.yaml")
    request = PlanRequest.for_mission(mission, truth_path)
    settings = replace(request.settings, error_measured=True, horizon_h=6.0)
    result = make_plan(replace(request, settings=settings))
    lines = summary_lines(result, out=tmp_path / "t.lrpt", size=0)
    assert any(line.startswith("error      ") and "forecast change" in line for line in lines)
    assert result.model.settings.physical.current_error_m_s == round(result.error.current_error_m_s, 4)
    assert any(line.startswith("warning    fewer than half the water states") and "time in the state" in line
               for line in lines), lines
    # Planned with time in the state over the same 6 hours, the advice is the horizon, not time in the state.
    varying = make_plan(replace(request, settings=replace(settings, time_varying=True)))
    warned = [line for line in summary_lines(varying, out=tmp_path / "t.lrpt", size=0) if "fewer than half" in line]
    assert len(warned) == 1 and "within the plan's 6 h of slices" in warned[0] and "--horizon-h" in warned[0]
    assert "time in the state" not in warned[0]
    # Asked for 12 h of a 6-hour file: the plan says the forecast ends, not that the horizon is short.
    short = make_plan(replace(request, settings=replace(settings, time_varying=True, horizon_h=12.0)))
    warned = [line for line in summary_lines(short, out=tmp_path / "t.lrpt", size=0) if "fewer than half" in line]
    assert len(warned) == 1 and "the forecast ends there (planning.horizon_h asks 12 h)" in warned[0]


@pytest.fixture(scope="module")
def members(tmp_path_factory, files):
    """Three members of one ensemble run: the tide early, late and weak, on one grid and the same steps."""
    root = tmp_path_factory.mktemp("ensemble")
    base = TidalSettings(hours=6, depths_m=(0.0,))
    return [files[1],
            write_tidal(root / "m1.nc", with_forecast_error(base, phase_error_h=-0.5, amplitude_error=0.1)),
            write_tidal(root / "m2.nc", with_forecast_error(base, phase_error_h=0.5, amplitude_error=-0.1))]


def test_the_ensemble_mean_is_the_members_mean_with_land_where_any_member_has_land(members, tmp_path):
    from planner.forecast.ensemble import ensemble_mean

    fs = [open_forecast(p) for p in members]
    mean = ensemble_mean(fs)
    assert mean.source.startswith("mean of 3 members of ") and mean.identity.startswith("ensemble-mean:")
    want = (fs[0].u_east_m_s + fs[1].u_east_m_s + fs[2].u_east_m_s) / 3.0
    assert np.allclose(mean.u_east_m_s, want, rtol=1e-15, atol=0.0, equal_nan=True)
    assert np.array_equal(np.isnan(mean.v_north_m_s), np.isnan(fs[0].v_north_m_s) | np.isnan(fs[2].v_north_m_s))
    short = write_tidal(tmp_path / "short.nc", TidalSettings(hours=3, depths_m=(0.0,)))
    with pytest.raises(Exception, match=r"short\.nc: ensemble member differs .* in its times"):
        ensemble_mean([fs[0], open_forecast(short)])


def test_an_ensembles_spread_sizes_the_error_of_a_plan_on_its_mean(members):
    from planner.forecast.ensemble import ensemble_mean

    fs = [open_forecast(p) for p in members]
    g = grid()
    est = measure_error(ensemble_mean(fs), g, 0, 3.0, time_varying=True, members=fs, default_m_s=0.03)
    assert est.source == "ensemble spread" and "3 members" in est.detail and "over 4 step(s)" in est.detail
    sq, n = 0.0, 0
    for step in range(4):
        fields = [resample(f, g, time_index=step) for f in fs]
        for comp in (0, 1):
            stack = np.stack([f[comp] for f in fields])
            water = np.all(np.isfinite(stack), axis=0)
            sq += float(np.sum(np.var(stack[:, water], axis=0, ddof=1)))
            n += int(water.sum())
    assert est.current_error_m_s == pytest.approx(math.sqrt(sq / n) * math.sqrt(1 + 1 / 3), rel=1e-12)
    assert 0.03 < est.current_error_m_s < 1.0
    alike = measure_error(fs[0], g, 0, 3.0, time_varying=True, members=[fs[0], fs[0]], default_m_s=0.03)
    assert alike.source == "ensemble spread" and alike.current_error_m_s == 0.0


def test_a_time_varying_plan_given_members_flies_their_mean_with_their_spread_as_error(members, tmp_path):
    from planner.contract.mission import load_mission
    from planner.pipeline import PlanRequest, plan_with_scheduler
    from planner.plan_summary import summary_lines

    mission = load_mission("missions/eval-tidal.yaml")
    request = PlanRequest.for_mission(mission, members[0])
    settings = replace(request.settings, error_measured=True, time_varying=True, horizon_h=2.0)
    request = replace(request, settings=settings, ensemble=tuple(members[1:]), nx=13, ny=7)
    result = plan_with_scheduler(request, scheduler="in-process")
    assert result.table.time_varying and result.table.n_slices == 3
    assert result.table.forecast_source.startswith("mean of 3 members of ")
    assert result.error is not None and result.error.source == "ensemble spread"
    assert result.model.settings.physical.current_error_m_s == round(result.error.current_error_m_s, 4)
    lines = summary_lines(result, out=tmp_path / "t.lrpt", size=0)
    assert any(line.startswith("error      ") and "ensemble spread" in line for line in lines), lines
