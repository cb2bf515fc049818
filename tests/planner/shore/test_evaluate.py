"""Closed-loop evaluation: planner.shore.evaluation.runs, planner.shore.evaluation.campaign and ``lrauv evaluate``.

Everything runs on a coarse double gyre (planner.forecast.synthetic.double_gyre) written into a temporary folder,
with a copy of missions/eval-double-gyre.yaml on a 21 x 9 grid pointing at it, so that a plan
takes a fraction of a second. Figures are checked against what the simulator's physics
(vehicle_sim.dynamics) gives by hand, not pinned numbers.
"""

from __future__ import annotations

import csv
import json
import math
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from planner.contract.actions import Action
from planner.shore.evaluation.campaign import (
    CampaignSpec,
    make_plans,
    prepare,
    request_for,
    resolution_change,
    run_all,
    run_one,
    settings_for,
    start_state,
)
from planner.cli import main
from planner.cluster import IN_PROCESS
from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre
from planner.contract.errors import LrauvError
from planner.shore.evaluation.runs import (
    DEFAULT_METHODS,
    METHODS,
    OUTCOMES,
    FeedbackPilot,
    NaivePilot,
    Referee,
    RunResult,
    Start,
    fly,
    pick_starts,
    realise,
    summarise,
)
from planner.forecast import open_forecast
from planner.contract.mission import load_mission
from planner.physical.solve import PhysicalSolution
from planner.pipeline import make_plan
from vehicle_sim.dynamics import Setpoint, SetpointKind
from planner.contract.geodesy import M_PER_DEG_LAT
from planner.contract.vehicle import VehicleParams, power_draw_w
from vehicle_sim.world import World, load_truth
from tests.support import REPO

GYRE_MISSION = REPO / "missions" / "eval-double-gyre.yaml"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
RUN_COLUMNS = ["method", "start", "outcome", "time_s", "energy_wh", "predicted_wh", "marked_reachable"]

# A coarse gyre: 21 x 9 points on the default box, one layer, a day of hourly steps.
TRUTH = DoubleGyreSettings(peak_speed_m_s=1.5, eps=0.1, depths_m=(0.0,), spacing_deg=0.02, hours=24.0)
STEADY = replace(TRUTH, eps=0.0)
GYRE_OPTIONS = ["--peak-speed-m-s", "1.5", "--depths", "0", "--spacing-deg", "0.02", "--hours", "24"]


def _mission_text(forecast: Path) -> str:
    text = GYRE_MISSION.read_text()
    for old, new in (("../out/gyre/forecast.nc", str(forecast)), ("nx: 41", "nx: 21"), ("ny: 18", "ny: 9")):
        assert old in text, f"{GYRE_MISSION} no longer has {old!r}"
        text = text.replace(old, new)
    return text


@pytest.fixture(scope="module")
def gyre(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The truth (eps 0.1), the steady forecast (eps 0), and a mission on the steady forecast."""
    d = tmp_path_factory.mktemp("eval")
    paths = {"truth": write_gyre(d / "truth.nc", TRUTH), "steady": write_gyre(d / "steady.nc", STEADY)}
    paths["mission"] = d / "mission.yaml"
    paths["mission"].write_text(_mission_text(paths["steady"]))
    return paths


@pytest.fixture(scope="module")
def mission(gyre):
    return load_mission(gyre["mission"])


@pytest.fixture(scope="module")
def table(gyre, mission):
    """The physical-expected plan's table on the steady gyre (the referee's geometry)."""
    settings = settings_for("physical-expected", mission.settings)
    spec = CampaignSpec(mission=mission, forecast_path=gyre["steady"], truth=World.calm(), n_starts=1)
    return make_plan(request_for(spec, settings, 0)).table


def _spec(mission, forecast: Path, truth, **kw) -> CampaignSpec:
    kw = {"n_starts": 4, "seed": 0, "dt_s": 5.0, "max_time_s": 12 * 3600.0, **kw}
    return CampaignSpec(mission=mission, forecast_path=forecast, truth=truth, **kw)


# --------------------------------------------------------------------------- the command


def test_evaluate_end_to_end_writes_table_csv_json_and_plots(tmp_path, capsys):
    truth, steady = tmp_path / "truth.nc", tmp_path / "steady.nc"
    assert main(["forecast", "gyre", str(truth), "--eps", "0.1", *GYRE_OPTIONS]) == 0
    assert main(["forecast", "gyre", str(steady), "--eps", "0", *GYRE_OPTIONS]) == 0
    mission_path = tmp_path / "mission.yaml"
    mission_path.write_text(_mission_text(steady))
    capsys.readouterr()
    out = tmp_path / "out"
    n = 4
    rc = main(["evaluate", str(mission_path), "--truth", str(truth), "--starts", str(n), "--dt-s", "5",
               "--max-hours", "12", "--out", str(out), "--quiet"])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    assert "Traceback" not in printed.err

    # Two tables (runs by outcome, then figures), each with one row per method; n runs each; 100 columns at most.
    counts, figures = printed.out.split("\n\n")[:2]
    for table in (counts, figures):
        rows = {line.split()[0]: line.split() for line in table.splitlines() if line.split()[0] in METHODS}
        assert sorted(rows) == sorted(DEFAULT_METHODS), table
    rows = {line.split()[0]: line.split() for line in counts.splitlines() if line.split()[0] in METHODS}
    assert all(int(r[1]) == n and sum(map(int, r[3:])) == n for r in rows.values()), printed.out
    assert max(len(line) for line in printed.out.splitlines()) <= 100, printed.out

    # runs.csv: starts x methods rows, the documented columns, every outcome a known one.
    with open(out / "runs.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == RUN_COLUMNS
        runs = list(reader)
    assert len(runs) == n * len(DEFAULT_METHODS)
    assert {(r["method"], int(r["start"])) for r in runs} == {(m, s) for m in DEFAULT_METHODS for s in range(n)}
    assert {r["outcome"] for r in runs} <= set(OUTCOMES)
    assert all(float(r["time_s"]) >= 0 and float(r["energy_wh"]) >= 0 for r in runs)
    assert all(r["marked_reachable"] in ("0", "1") for r in runs)
    # Energy predictions only from the physical model's plans.
    for r in runs:
        if r["method"] in ("paper", "naive"):
            assert r["predicted_wh"] == "", r
        elif r["outcome"] != "refused":
            assert float(r["predicted_wh"]) > 0, r
    assert any(r["outcome"] == "arrived" for r in runs)

    # summary.json: per-method outcome counts add up to the runs and match runs.csv.
    summary = json.loads((out / "summary.json").read_text())
    assert summary["meta"]["starts"] == n and summary["meta"]["truth"] == [str(truth)]
    assert [m["method"] for m in summary["methods"]] == list(DEFAULT_METHODS)
    for m in summary["methods"]:
        assert m["runs"] == n
        assert set(m["outcomes"]) == set(OUTCOMES)
        assert sum(m["outcomes"].values()) == n
        from_csv = Counter(r["outcome"] for r in runs if r["method"] == m["method"])
        assert {o: c for o, c in m["outcomes"].items() if c} == dict(from_csv)
        assert m["success_rate"] == pytest.approx(from_csv["arrived"] / n)
        assert m["marked_reachable"] == sum(int(r["marked_reachable"]) for r in runs if r["method"] == m["method"])
        assert int(rows[m["method"]][3]) == m["outcomes"]["arrived"]  # the table's "arrived" column
    # Each pair of methods once, over the starts both arrived from; against naive, the table's "vs naive".
    pairs = [(c["method"], c["against"]) for c in summary["comparisons"]]
    assert pairs == [(a, b) for i, a in enumerate(DEFAULT_METHODS) for b in DEFAULT_METHODS[i + 1:]]
    arrived = {(r["method"], int(r["start"])) for r in runs if r["outcome"] == "arrived"}
    by_method = {m["method"]: m for m in summary["methods"]}
    for c in summary["comparisons"]:
        assert c["starts"] == sum((c["method"], s) in arrived and (c["against"], s) in arrived for s in range(n))
        if c["starts"] >= 2:
            assert c["low"] <= c["excess"] <= c["high"]
        if c["against"] == "naive" and c["starts"]:
            assert c["excess"] == pytest.approx(by_method[c["method"]]["energy_vs_naive"])
    assert "paired bootstrap" in printed.out
    for name in ("outcomes.png", "energy.png"):
        data = (out / name).read_bytes()
        assert data[:8] == PNG_SIGNATURE and len(data) > 1000, name


@pytest.mark.parametrize("mission_h, noted", [(48.0, True), (0.05, False)])
def test_runs_cut_before_the_missions_limit_are_noted(gyre, tmp_path, capsys, mission_h, noted):
    # Three minutes are too short for any run to arrive: each times out at --max-hours. The note says so only
    # when the mission itself would have let the vehicle go on.
    text = gyre["mission"].read_text()
    assert "max_mission_time_h: 48" in text
    mission_path = tmp_path / "mission.yaml"
    mission_path.write_text(text.replace("max_mission_time_h: 48", f"max_mission_time_h: {mission_h:g}"))
    capsys.readouterr()
    rc = main(["evaluate", str(mission_path), "--truth", str(gyre["truth"]), "--starts", "3", "--dt-s", "5",
               "--max-hours", "0.05", "--methods", "naive", "--scheduler", IN_PROCESS, "--quiet"])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    row = next(line.split() for line in printed.out.splitlines() if line.startswith("naive "))
    assert row[6] == "3", printed.out  # the timeout column
    notes = [line for line in printed.out.splitlines() if line.startswith("note")]
    if noted:
        assert notes == ["note       3 run(s) timed out at 0.05 h (--max-hours); the mission allows 48 h"], printed.out
    else:
        assert notes == [], printed.out


def test_same_spec_same_results(gyre, mission):
    def once():
        spec = _spec(mission, gyre["steady"], World.load(gyre["truth"]), methods=("physical-expected", "naive"))
        return run_all(prepare(spec))

    a, b = once(), once()
    assert a.starts == b.starts
    assert len(a.results) == 2 * len(a.starts) == 8
    assert a.results == b.results
    assert len({r.time_s for r in a.results}) > 1  # not trivially equal


def test_an_evaluation_reports_its_runs_up_to_their_number(gyre, mission):
    from tests.planner.cli.test_progress import Recorder, assert_climbs_to_total

    spec = _spec(mission, gyre["steady"], World.load(gyre["truth"]), methods=("naive",), n_starts=2)
    meter = Recorder()
    campaign = run_all(prepare(spec, meter=meter), meter=meter)
    assert len(campaign.results) == 2
    assert meter.counts("runs") == [(0, 2), (1, 2), (2, 2)]  # one tick per run, here in this process
    assert_climbs_to_total(meter.counts("runs"))


# --------------------------------------------------------------------------- physics


class _Drift:
    """A pilot that never thrusts: holds the surface and drifts; remembers the last state it saw."""

    def __init__(self) -> None:
        self.last = None
        self.calls = 0

    def command(self, body):
        self.last = body
        self.calls += 1
        return Setpoint(kind=SetpointKind.DEPTH, depth_m=0.0)


def _east_m(lon_a: float, lon_b: float, lat: float) -> float:
    return (lon_b - lon_a) * M_PER_DEG_LAT * math.cos(math.radians(lat))


def test_drift_moves_with_the_current_and_spends_hotel_power_only(table):
    params = VehicleParams()
    referee = Referee(table=table)
    lat, lon = table.cell_centre(1, 1)  # south-west, far from the goal cells
    assert referee.judge(_body_at(lat, lon)) is None
    start = Start(lon_deg=lon, lat_deg=lat, depth_m=0.0, heading_deg=30.0)
    pilot = _Drift()
    outcome, t, energy = fly(pilot, World.uniform(0.3, 0.0), start, params, referee, dt_s=5.0, max_time_s=7200.0)
    assert outcome == "timed_out"
    assert t == pytest.approx(7200.0)
    last = pilot.last
    assert last.time_s == pytest.approx(t - 5.0)
    assert _east_m(lon, last.lon_deg, lat) == pytest.approx(0.3 * last.time_s, rel=0.01)
    assert last.lat_deg == pytest.approx(lat, abs=1e-12)  # no northward motion
    assert last.heading_deg == pytest.approx(30.0)  # nothing turned it
    assert energy == pytest.approx(float(power_draw_w(params, 0.0, False)) * t / 3600.0, rel=1e-9)

    # Drifting west it leaves the region when it crosses the grid's west edge (half a cell west of column 0).
    outcome, t, energy = fly(_Drift(), World.uniform(-0.3, 0.0), start, params, referee, dt_s=5.0, max_time_s=86400.0)
    assert outcome == "left_region"
    edge_lon = table.lon0_deg - 0.5 * table.dlon_deg
    assert 0.3 * t == pytest.approx(_east_m(edge_lon, lon, lat), rel=0.01)
    assert energy == pytest.approx(8.0 * t / 3600.0, rel=1e-9)


def _body_at(lat: float, lon: float):
    from vehicle_sim.dynamics import Body

    return Body(lat_deg=lat, lon_deg=lon, depth_m=0.0)


def _naive_start(table, distance_m: float) -> Start:
    lat = table.goal_lat_deg
    lon = table.goal_lon_deg - distance_m / (M_PER_DEG_LAT * math.cos(math.radians(lat)))
    return Start(lon_deg=lon, lat_deg=lat, depth_m=0.0, heading_deg=90.0)


def test_naive_fails_in_a_cross_current_faster_than_the_vehicle_and_arrives_in_still_water(table):
    params = VehicleParams(cruise_speed_m_s=1.0)
    referee = Referee(table=table)
    start = _naive_start(table, 10_000.0)
    assert referee.judge(_body_at(start.lat_deg, start.lon_deg)) is None
    pilot = NaivePilot(table.goal_lon_deg, table.goal_lat_deg, table.goal_depth_m, params)

    outcome, t, energy = fly(pilot, World.uniform(0.0, 1.5), start, params, referee, dt_s=2.0, max_time_s=6 * 3600.0)
    assert outcome in ("timed_out", "left_region")
    assert energy > 0

    outcome, t, energy = fly(NaivePilot(table.goal_lon_deg, table.goal_lat_deg, table.goal_depth_m, params),
                             World.calm(), start, params, referee, dt_s=2.0, max_time_s=6 * 3600.0)
    assert outcome == "arrived"
    # The run ends where the line east first enters a goal cell (the goal radius is a cell).
    step_m = 1.0
    d = 0.0
    while referee.judge(_body_at(start.lat_deg, start.lon_deg + d / (M_PER_DEG_LAT * math.cos(math.radians(start.lat_deg))))) is None:
        d += step_m
    cell_m = table.dlon_deg * M_PER_DEG_LAT * math.cos(math.radians(start.lat_deg))
    assert 10_000.0 - (table.goal_radius_cells + 1) * cell_m < d < 10_000.0
    # Straight east at 1 m/s, after a 5 s acceleration (0.2 m/s^2): about distance / speed.
    assert t == pytest.approx(d / params.cruise_speed_m_s, abs=2 * 2.0 + 3.0)
    assert energy == pytest.approx(float(power_draw_w(params, 1.0, False)) * t / 3600.0, rel=0.005)


# --------------------------------------------------------------------------- starts


def test_pick_starts_in_water_outside_the_goal_and_seeded(gyre, table):
    referee = Referee(table=table)
    truth = World.load(gyre["truth"])
    a = pick_starts(referee, truth, 15, seed=7)
    assert len(a) == 15
    for s in a:
        cell = table.locate(s.lat_deg, s.lon_deg, s.depth_m)
        assert cell is not None
        assert table.water[cell]
        assert not referee.goal_mask[cell]
        assert referee.judge(_body_at(s.lat_deg, s.lon_deg)) is None
        assert truth.is_water(s.lat_deg, s.lon_deg, s.depth_m, 0.0)
        assert 0.0 <= s.heading_deg < 360.0
        assert s.depth_m in table.depth_m
    assert pick_starts(referee, truth, 15, seed=7) == a
    b = pick_starts(referee, truth, 15, seed=8)
    assert b != a
    assert len(set(a) & set(b)) == 0
    assert len(set(a)) == 15  # no repeats
    # The draws are sequential: fewer starts are a prefix of more.
    assert pick_starts(referee, truth, 3, seed=7) == a[:3]


# --------------------------------------------------------------------------- summary


def _r(method, start, outcome, energy=0.0, predicted=math.nan, marked=True, time_s=0.0):
    return RunResult(method=method, start=start, outcome=outcome, time_s=time_s, energy_wh=energy,
                     predicted_wh=predicted, marked_reachable=marked)


def test_summarise_by_hand():
    results = [
        _r("physical-expected", 0, "arrived", 10.0, 8.0, time_s=3600.0),
        _r("physical-expected", 1, "arrived", 12.0, 12.0, time_s=7200.0),
        _r("physical-expected", 2, "arrived", 30.0, 20.0, time_s=10800.0),
        _r("physical-expected", 3, "refused", 0.0, math.nan, marked=False),
        _r("naive", 0, "arrived", 8.0, time_s=1800.0),
        _r("naive", 1, "left_region", 5.0),
        _r("naive", 2, "arrived", 20.0, time_s=5400.0),
        _r("naive", 3, "stranded", 3.0),
        _r("paper", 0, "arrived", 9.0, time_s=3000.0),
        _r("paper", 1, "gave_up", 4.0),
        _r("paper", 2, "refused", marked=False),
        _r("paper", 3, "refused", marked=False),
    ]
    s = {m.method: m for m in summarise(results, ["physical-expected", "naive", "paper", "open-loop"])}

    pe = s["physical-expected"]
    assert (pe.runs, pe.marked_reachable) == (4, 3)
    assert pe.outcomes == {**dict.fromkeys(OUTCOMES, 0), "arrived": 3, "refused": 1}
    assert pe.success_rate == pytest.approx(0.75)
    assert pe.success_from_reachable == pytest.approx(1.0)
    assert pe.coverage == pytest.approx(1.0)  # starts 0..2 are arrived-from; all marked
    assert pe.median_time_h == pytest.approx(2.0)
    assert pe.median_energy_wh == pytest.approx(12.0)
    assert pe.median_predicted_wh == pytest.approx(12.0)
    assert pe.energy_error == pytest.approx(0.25)  # median of 0.25, 0, 0.5
    # Mean energy over the starts naive also arrived from (0 and 2): (10 + 30) / (8 + 20) - 1.
    assert pe.energy_vs_naive == pytest.approx(40.0 / 28.0 - 1.0)
    assert pe.both_with_naive == 2

    nv = s["naive"]
    assert (nv.runs, nv.marked_reachable) == (4, 4)
    assert nv.success_rate == pytest.approx(0.5)
    assert nv.success_from_reachable == pytest.approx(0.5)
    assert nv.coverage == pytest.approx(1.0)
    assert math.isnan(nv.energy_error) and math.isnan(nv.median_predicted_wh)
    assert nv.energy_vs_naive == pytest.approx(0.0)
    assert nv.both_with_naive == 2
    assert nv.outcomes["left_region"] == 1 and nv.outcomes["stranded"] == 1

    pa = s["paper"]
    assert pa.marked_reachable == 2
    assert pa.success_rate == pytest.approx(0.25)
    assert pa.success_from_reachable == pytest.approx(0.5)
    assert pa.coverage == pytest.approx(2.0 / 3.0)  # of starts 0, 1, 2 (someone arrived), it marks 0 and 1
    assert math.isnan(pa.energy_error)
    assert pa.energy_vs_naive == pytest.approx(9.0 / 8.0 - 1.0)
    assert pa.both_with_naive == 1
    assert pa.median_time_h == pytest.approx(3000.0 / 3600.0)

    ol = s["open-loop"]  # no runs: counts zero, figures undefined
    assert ol.runs == 0 and sum(ol.outcomes.values()) == 0
    assert math.isnan(ol.success_rate) and math.isnan(ol.coverage) and math.isnan(ol.energy_vs_naive)


# --------------------------------------------------------------------------- replanning


def test_replanning_schedules_a_table_per_forecast_step(gyre, mission):
    truth = World.load(gyre["truth"])
    # Plan on the time-varying gyre itself, again every 3 h of a 12 h run: forecast steps 0, 3, 6, 9.
    spec = _spec(mission, gyre["truth"], truth, n_starts=2, replan_s=3 * 3600.0,
                 methods=("physical-expected", "physical-robust", "open-loop", "naive"))
    campaign = prepare(spec)
    plans = campaign.plans
    for method in ("physical-expected", "physical-robust"):
        sched = plans[method].schedule
        assert [t for t, _ in sched] == [0.0, 3 * 3600.0, 6 * 3600.0, 9 * 3600.0]
        tables = [tab for _, tab in sched]
        assert len({id(t) for t in tables}) == 4
        assert plans[method].first.table is tables[0]
        # Around each boundary: the old table just before it, the new one from it on.
        at = plans[method].table_at
        assert at(-1.0) is tables[0] and at(0.0) is tables[0]
        for n in (1, 2, 3):
            assert at(n * 3 * 3600.0 - 1e-3) is tables[n - 1]
            assert at(n * 3 * 3600.0) is tables[n]
        assert at(1e9) is tables[3]
        # The gyre moves: the plans differ.
        assert any((a.actions != tables[0].actions).any() for a in tables[1:])
    # The table at 3 h is the plan made at forecast step 3.
    settings = settings_for("physical-expected", mission.settings)
    direct = make_plan(request_for(spec, settings, 3)).table
    assert (plans["physical-expected"].schedule[1][1].actions == direct.actions).all()
    # Open loop replays one plan; naive has none.
    assert len(plans["open-loop"].schedule) == 1
    assert plans["open-loop"].first is plans["physical-expected"].first
    assert plans["naive"].schedule == () and plans["naive"].first is None
    for method in spec.methods:
        r = run_one(campaign, method, 0)
        assert r.method == method and r.start == 0 and r.outcome in OUTCOMES
        assert r.time_s >= 0 and r.energy_wh >= 0


def test_replanning_past_the_forecast_end_reuses_the_last_step(gyre, mission):
    forecast = open_forecast(gyre["truth"])
    assert forecast.time_s.size == 25  # 0..24 h hourly
    spec = _spec(mission, gyre["truth"], World.calm(), max_time_s=36 * 3600.0, replan_s=6 * 3600.0,
                 methods=("physical-expected",))
    notes: list[str] = []
    plans = make_plans(spec, forecast, note=notes.append)
    sched = plans["physical-expected"].schedule
    # Replan times 0, 6, ..., 30 h; 24 h and 30 h both map to the last step, planned once.
    assert [t / 3600.0 for t, _ in sched] == [0.0, 6.0, 12.0, 18.0, 24.0]
    assert len(notes) == 5
    assert plans["physical-expected"].table_at(35 * 3600.0) is sched[-1][1]


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(("extra", "named"), [
    (["--methods", "bogus"], "--methods"),
    (["--starts", "0"], "--starts"),
    (["--cruise-speed", "-1"], "--cruise-speed"),
    (["--replan-h", "-2"], "replan"),
    (["--time-index", "99"], "time index 99"),
])
def test_bad_options_exit_2_with_one_line(gyre, capsys, extra, named):
    rc = main(["evaluate", str(gyre["mission"]), "--truth", str(gyre["truth"]), "--starts", "2", "--quiet", *extra])
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("lrauv: error:") and named in lines[0]
    assert "Traceback" not in err


def test_negative_seed_exits_2_with_one_line(gyre, capsys):
    rc = main(["evaluate", str(gyre["mission"]), "--truth", str(gyre["truth"]), "--starts", "2", "--quiet",
               "--seed", "-1", "--methods", "naive"])
    err = capsys.readouterr().err
    assert rc == 2 and "--seed" in err and len(err.strip().splitlines()) == 1, err


def test_bad_truth_files_exit_2_naming_the_file(gyre, tmp_path, capsys):
    missing = tmp_path / "nowhere.nc"
    text = tmp_path / "notes.nc"
    text.write_text("these are not currents\n")
    for bad in (missing, text):
        rc = main(["evaluate", str(gyre["mission"]), "--truth", str(bad), "--starts", "2", "--quiet"])
        err = capsys.readouterr().err
        assert rc == 2, err
        lines = err.strip().splitlines()
        assert len(lines) == 1, err
        assert lines[0].startswith("lrauv: error:") and bad.name in lines[0]
        assert "Traceback" not in err


def test_campaign_spec_rejects_bad_values(mission, gyre):
    with pytest.raises(LrauvError, match="--methods"):
        _spec(mission, gyre["steady"], World.calm(), methods=())
    with pytest.raises(LrauvError, match="--dt-s"):
        _spec(mission, gyre["steady"], World.calm(), dt_s=0.0)
    with pytest.raises(LrauvError, match="--max-hours"):
        _spec(mission, gyre["steady"], World.calm(), max_time_s=math.nan)
    with pytest.raises(LrauvError, match="--replan-h"):
        _spec(mission, gyre["steady"], World.calm(), replan_s=math.inf)
    with pytest.raises(LrauvError, match="--seed"):
        _spec(mission, gyre["steady"], World.calm(), seed=-1)


# --------------------------------------------------------------------------- open loop


def test_open_loop_replays_the_expected_plans_nominal_path(gyre, mission, monkeypatch):
    import planner.shore.evaluation.campaign as campaign_module

    seen: dict[int, list] = {}
    real = campaign_module.OpenLoopPilot

    def recording(steps, table, params):
        seen[len(seen)] = list(steps)
        return real(steps, table, params)

    monkeypatch.setattr(campaign_module, "OpenLoopPilot", recording)
    truth = World.load(gyre["steady"])  # the truth is the forecast, steady
    # Open loop arrives only now and then on this coarse gyre (mean durations, no feedback): 10
    # starts, so that the replay is seen to reach the goal at all.
    spec = _spec(mission, gyre["steady"], truth, n_starts=10, seed=2, methods=("physical-expected", "open-loop"))
    campaign = run_all(prepare(spec))
    plan = campaign.plans["open-loop"]
    assert plan.first is campaign.plans["physical-expected"].first
    sol = plan.first.solution
    assert isinstance(sol, PhysicalSolution)

    open_runs = [r for r in campaign.results if r.method == "open-loop"]
    flown = [r for r in open_runs if r.outcome != "refused"]
    assert len(seen) == len(flown) > 0
    for steps, r in zip(seen.values(), flown):
        state = start_state(plan.first.table, campaign.starts[r.start])
        nominal = [s for s in sol.nominal(state) if s.action not in (Action.AT_GOAL, Action.UNREACHABLE)]
        assert [(s.action, s.l, s.j, s.k, s.duration_s) for s in steps] == \
               [(s.action, s.l, s.j, s.k, s.duration_s) for s in nominal]
        assert steps and all(s.duration_s > 0 for s in steps)
        assert r.predicted_wh == pytest.approx(float(sol.value_wh[state]))
    assert any(r.outcome == "arrived" for r in open_runs), [r.outcome for r in open_runs]
    # Feedback on the same plan in the same (steady, exact) truth arrives at least as often.
    fb = [r for r in campaign.results if r.method == "physical-expected"]
    assert sum(r.outcome == "arrived" for r in fb) >= sum(r.outcome == "arrived" for r in open_runs)


# --------------------------------------------------------------------------- the feedback pilot, as the executive


def _boundary_case(table):
    """A FORWARD state whose east or west water neighbour, at the same heading, does something else."""
    found = [(tuple(int(x) for x in s), di) for s in np.argwhere(table.actions == int(Action.FORWARD)) for di in (1, -1)
             if 0 <= s[2] + di < table.nx and table.water[s[0], s[1], s[2] + di]
             and table.actions[s[0], s[1], s[2] + di, s[3]] not in (int(Action.FORWARD), int(Action.AT_GOAL))]
    assert found, "the plan has no FORWARD state beside another action"
    return found[len(found) // 2]


def _pilot_body(table, state, past_edge: float, di: int, time_s: float):
    """A body in ``state``'s row, ``past_edge`` of a spacing beyond its east (di 1) or west edge, on its heading."""
    from vehicle_sim.dynamics import Body

    l, j, i, k = state
    lat, lon = table.cell_centre(j, i)
    return Body(lat_deg=lat, lon_deg=lon + di * (0.5 + past_edge) * table.dlon_deg, depth_m=table.depth_m[l],
                heading_deg=table.bearing_deg(j, k), time_s=time_s)


def test_feedback_pilot_keeps_a_cell_within_the_executives_margin(table):
    """A vehicle on a boundary, pushed back and forth, does not make the decision chatter (executive.helm)."""
    state, di = _boundary_case(table)
    l, j, i, k = state
    params = VehicleParams()
    pilot = FeedbackPilot(lambda _t: table, params)
    here = pilot.command(_pilot_body(table, state, -0.5, di, 0.0))  # the cell centre
    assert here.kind is SetpointKind.VELOCITY and here.yaw_deg == pytest.approx(table.bearing_deg(j, k))
    over = _pilot_body(table, state, 0.05, di, 2.0)  # 5 % into the neighbour: still this cell's action
    assert table.locate(over.lat_deg, over.lon_deg, over.depth_m) == (l, j, i + di)
    assert pilot.command(over) is here
    beyond = _pilot_body(table, state, 0.15, di, 4.0)  # past the 10 % margin: the neighbour's action
    theirs = pilot.command(beyond)
    neighbour = (l, j, i + di, k)
    assert theirs == realise(Action(int(table.actions[neighbour])), neighbour, table, beyond, params)[0]
    assert theirs != here
    # Without a margin the raw cell decides at once, as HelmConfig(cell_margin=0) does.
    raw = FeedbackPilot(lambda _t: table, params, cell_margin=0.0)
    assert raw.command(_pilot_body(table, state, -0.5, di, 0.0)) == here
    assert raw.command(over) != here


def test_feedback_pilot_drifts_where_the_plan_has_no_action_and_resumes_after(table):
    """States the plan marks unreachable: drift at the layer's depth (executive.helm), not give up."""
    state, di = _boundary_case(table)
    l, j, i, k = state
    actions = table.actions.copy()
    actions[l, j, i, :] = int(Action.UNREACHABLE)  # this cell: no action at any heading
    cut = replace(table, actions=actions)
    params = VehicleParams()
    pilot = FeedbackPilot(lambda _t: cut, params)
    inside = _pilot_body(cut, state, -0.5, di, 0.0)
    sp = pilot.command(inside)
    assert sp == Setpoint(kind=SetpointKind.DEPTH, depth_m=cut.depth_m[l])  # no thrust, the layer's depth
    # Carried into the neighbour (past the margin), the plan's action there takes over.
    beyond = _pilot_body(cut, state, 0.15, di, 600.0)
    neighbour = (l, j, i + di, k)
    assert pilot.command(beyond) == realise(Action(int(cut.actions[neighbour])), neighbour, cut, beyond, params)[0]

    # Flown: a current towards the neighbour carries the drifting vehicle out of the cut cell,
    # and the run goes on (it does not end where the plan had no action).
    referee = Referee(table=cut)
    lat, lon = cut.cell_centre(j, i)
    start = Start(lon_deg=lon, lat_deg=lat, depth_m=cut.depth_m[l], heading_deg=cut.bearing_deg(j, k))
    seen = []

    class Recording(FeedbackPilot):
        def command(self, body):
            sp = super().command(body)
            seen.append((body, sp))
            return sp

    outcome, t, _energy = fly(Recording(lambda _t: cut, params), World.uniform(0.3 * di, 0.0), start, params, referee,
                              dt_s=5.0, max_time_s=3 * 3600.0)
    assert outcome != "gave_up"
    drift = Setpoint(kind=SetpointKind.DEPTH, depth_m=cut.depth_m[l])
    resumed = next(n for n, (_body, sp) in enumerate(seen) if sp != drift)  # the plan took over here
    assert resumed > 0 and all(sp == drift for _body, sp in seen[:resumed])
    body = seen[resumed][0]
    assert cut.locate(body.lat_deg, body.lon_deg, body.depth_m)[1:] == (j, i + di)  # carried out of the cut cell


def test_resolution_change_compares_the_campaigns_plans_with_plans_at_half_the_spacing(gyre, mission):
    """``--resolution``: the start states' predictions on the campaign's grid against a grid of half the spacing."""
    spec = _spec(mission, gyre["steady"], World.load(gyre["truth"]), n_starts=12, seed=3,
                 methods=("physical-expected", "naive"))
    campaign = prepare(spec)
    out = resolution_change(campaign)
    assert set(out) == {"physical-expected", "physical-robust"}
    expected = campaign.plans["physical-expected"].first
    fine = make_plan(request_for(replace(spec, grid_scale=2), settings_for("physical-expected", mission.settings), 0))
    assert fine.grid.nx == 2 * expected.grid.nx - 1 and fine.grid.ny == 2 * expected.grid.ny - 1
    changes = []
    for s in campaign.starts:  # by hand, from the campaign's own coarse plan
        a, b = start_state(expected.table, s), start_state(fine.table, s)
        va, vb = float(expected.solution.value_wh[a]), float(fine.solution.value_wh[b])
        if math.isfinite(va) and math.isfinite(vb) and va > 0:
            changes.append(abs(vb / va - 1.0))
    r = out["physical-expected"]
    assert r["starts"] == len(changes) > 0
    assert r["median"] == pytest.approx(float(np.median(changes))) and r["max"] == pytest.approx(max(changes))
    assert r["median"] < 0.1  # the evaluation's resolution target (docs/evaluation.md), here over the starts
    assert out["physical-robust"]["starts"] > 0


def test_the_time_varying_plan_is_flown_slice_by_slice_and_the_replanned_one_at_every_step(gyre, mission):
    """time-varying: one plan whose slice follows the run's clock; replanned: the stationary plan of every step."""
    truth = load_truth([gyre["truth"]])
    spec = _spec(mission, gyre["truth"], truth, methods=("time-varying", "replanned", "naive"), n_starts=3,
                 max_time_s=4 * 3600.0)
    campaign = run_all(prepare(spec))
    tv, rp = campaign.plans["time-varying"], campaign.plans["replanned"]
    timed = tv.schedule[0][1]
    assert len(tv.schedule) == 1 and timed.time_varying and timed.n_slices == 5  # 0..4 h, hourly
    for n in range(timed.n_slices):
        assert np.array_equal(tv.table_at(n * 3600.0).actions, timed.slices[n])
    assert tv.table_at(1799.0) is timed.slice_table(0) and tv.table_at(1801.0) is timed.slice_table(1)
    assert [t for t, _ in rp.schedule] == [0.0, 3600.0, 7200.0, 10800.0]  # every step before the runs' end
    assert all(not table.time_varying for _, table in rp.schedule)
    by = {(r.method, r.start): r for r in campaign.results}
    assert all(math.isfinite(by["time-varying", s].predicted_wh) for s in range(3) if by["time-varying", s].marked_reachable)
    summary = {s.method: s for s in summarise(campaign.results, spec.methods)}
    assert summary["naive"].all_arrived == summary["time-varying"].all_arrived
