"""Scale-out on a real Dask cluster (2 worker processes on 127.0.0.1): the same results as one process.

Issue: ensembles, batch plans and Monte Carlo runs as Dask tasks; a local cluster by default,
``--scheduler ADDRESS`` for an existing one; results bit for bit equal to single-process runs.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from planner.shore.batch import BatchItem, collect, plan_item
from planner.shore.evaluation.campaign import CampaignSpec, prepare, run_all
from planner.cli import main
from planner.cluster import IN_PROCESS, DaskRunner, InProcess, chunks
from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre
from planner.contract.mission import load_mission
from vehicle_sim.world import World

distributed = pytest.importorskip("distributed")

GYRE = DoubleGyreSettings(spacing_deg=0.02, depths_m=(0.0,), hours=12.0, peak_speed_m_s=1.5)
MISSION = """\
name: gyre-{name}
forecast: {{file: {forecast}, time_index: 0}}
region: {{bbox: [-118.20, 33.30, -117.80, 33.467], nx: 21, ny: 9, depths_m: [0]}}
vehicle: {{cruise_speed_m_s: 1.0}}
planning: {{model: {model}, criterion: {criterion}}}
goals:
  - {{lat_deg: 33.385, lon_deg: -117.86, depth_m: 0, radius_cells: 1}}
  - {{lat_deg: 33.40, lon_deg: -118.10, depth_m: 0, radius_cells: 1}}
"""


@pytest.fixture(scope="module")
def cluster():
    """A real local cluster: 2 single-threaded worker processes; stopped at the end of the module."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  scheduler_port=0, silence_logs=40) as c, distributed.Client(c, set_as_default=False) as client:
        yield c, DaskRunner(client, what="test cluster")


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("scale")
    out = {"truth": write_gyre(d / "truth.nc", GYRE), "steady": write_gyre(d / "steady.nc", dataclasses.replace(GYRE, eps=0.0))}
    for name, model, criterion in (("physical", "physical", "expected"), ("paper", "paper", "robust")):
        path = d / f"{name}.yaml"
        path.write_text(MISSION.format(name=name, forecast=out["steady"], model=model, criterion=criterion))
        out[name] = path
    return out


def test_cluster_has_two_worker_processes(cluster):
    c, runner = cluster
    assert runner.workers == 2
    pids = set(runner.client.run(lambda: __import__("os").getpid()).values())
    assert len(pids) == 2 and __import__("os").getpid() not in pids


def test_monte_carlo_on_dask_equals_one_process(cluster, files):
    _c, runner = cluster
    spec = CampaignSpec(mission=load_mission(files["physical"]), forecast_path=files["steady"],
                        truth=World.load(files["truth"]), n_starts=6, dt_s=5.0, max_time_s=8 * 3600.0)
    campaign = prepare(spec)
    here = run_all(campaign, runner=InProcess())
    there = run_all(campaign, runner=runner)
    assert len(here.results) == 6 * len(spec.methods)
    # repr round-trips every float exactly (and shows NaN, which == would not call equal)
    assert [repr(r) for r in there.results] == [repr(r) for r in here.results]
    assert {r.outcome for r in here.results} & {"arrived"}  # the comparison is about real runs


def test_runs_are_split_across_both_workers(cluster, files):
    _c, runner = cluster
    seen = runner.map(_pid_of, list(range(8)))
    assert len(set(seen)) == 2


def _pid_of(_item: int) -> int:
    import os
    import time

    time.sleep(0.2)  # long enough that one worker cannot take every task
    return os.getpid()


def test_batch_plans_on_dask_equal_one_process(cluster, files, tmp_path):
    _c, runner = cluster
    items = collect([files["physical"], files["paper"]], tmp_path, None)
    assert [(i.vehicle, i.goal_index) for i in items] == [("physical", 0), ("physical", 1), ("paper", 0), ("paper", 1)]
    here = InProcess().map(plan_item, items)
    there = runner.map(plan_item, items)
    assert all(r.error is None for r in here)
    assert [r.table for r in there] == [r.table for r in here]
    assert len({r.table for r in here}) == 4  # four different plans


def test_batch_command_with_scheduler_address_writes_every_goal(cluster, files, tmp_path, capsys, monkeypatch):
    c, _runner = cluster
    fleet = tmp_path / "fleet.yaml"
    fleet.write_text(f"fleet:\n  - {{vehicle: alpha, mission: {files['physical']}}}\n"
                     f"  - {{vehicle: beta, mission: {files['paper']}}}\n")
    # A relative --out, as a user types it: a path is one word, which wraps to a line of its own but is never cut,
    # so pytest's long temporary folders (a worker's among them) would make its lines what they measure.
    monkeypatch.chdir(tmp_path)
    rc = main(["batch", str(fleet), "--out", "out", "--scheduler", c.scheduler_address, "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0, out
    written = sorted(p.relative_to(tmp_path / "out").as_posix() for p in (tmp_path / "out").rglob("*.lrpt"))
    assert written == ["alpha/goal-0.lrpt", "alpha/goal-1.lrpt", "beta/goal-0.lrpt", "beta/goal-1.lrpt"]
    assert max(len(line) for line in out.splitlines()) <= 100, out  # labelled lines wrap under their value
    single = plan_item(BatchItem(vehicle="x", goal_index=1, request=collect([files["paper"]], tmp_path, None)[1].request,
                                 out=tmp_path / "x.lrpt"))
    assert (tmp_path / "out" / "beta" / "goal-1.lrpt").read_bytes() == single.table


def test_evaluate_with_scheduler_address_equals_in_process(cluster, files, tmp_path, capsys):
    c, _runner = cluster
    common = ["evaluate", str(files["physical"]), "--truth", str(files["truth"]), "--starts", "3", "--dt-s", "5",
              "--max-hours", "6", "--quiet"]
    assert main([*common, "--scheduler", c.scheduler_address, "--out", str(tmp_path / "dask")]) == 0
    assert main([*common, "--scheduler", IN_PROCESS, "--out", str(tmp_path / "here")]) == 0
    capsys.readouterr()
    assert (tmp_path / "dask" / "runs.csv").read_bytes() == (tmp_path / "here" / "runs.csv").read_bytes()


def test_unreachable_scheduler_exits_2_with_one_line(files, tmp_path, capsys):
    rc = main(["batch", str(files["paper"]), "--out", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:9", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and "tcp://127.0.0.1:9" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_fleet_file_errors_name_file_line_and_key(tmp_path, capsys):
    fleet = tmp_path / "fleet.yaml"
    fleet.write_text("fleet:\n  - {vehicle: a, mission: m.yaml}\n  - {vehicle: a, mission: n.yaml}\n")
    assert main(["batch", str(fleet), "--out", str(tmp_path / "o"), "--scheduler", IN_PROCESS]) == 2
    err = capsys.readouterr().err
    assert f"{fleet}:3 fleet[1].vehicle" in err and "twice" in err
    fleet.write_text("fleet:\n  - {vehicle: a, mision: m.yaml}\n")
    assert main(["batch", str(fleet), "--out", str(tmp_path / "o"), "--scheduler", IN_PROCESS]) == 2
    assert "fleet[0].mision" in capsys.readouterr().err


def test_one_bad_goal_fails_the_batch_after_planning_the_others(files, tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text(MISSION.format(name="bad", forecast=files["steady"], model="physical", criterion="expected")
                   .replace("lon_deg: -118.10", "lon_deg: -119.50"))  # the second goal is off the grid
    rc = main(["batch", str(bad), "--out", str(tmp_path / "o"), "--scheduler", IN_PROCESS])
    out, err = capsys.readouterr()
    assert rc == 2
    assert (tmp_path / "o" / "bad" / "goal-0.lrpt").exists() and not (tmp_path / "o" / "bad" / "goal-1.lrpt").exists()
    assert "failed     bad goal 1:" in out and "1 of 2 goals could not be planned" in err


@pytest.mark.parametrize("n, workers", [(0, 2), (1, 2), (7, 2), (100, 2), (1000, 16), (5, 1)])
def test_chunks_cover_every_run_once_in_order(n, workers):
    parts = chunks(n, workers)
    flat = [i for r in parts for i in r]
    assert flat == list(range(n))
    assert len(parts) <= max(1, workers * 4)
    if n:
        assert max(len(r) for r in parts) - min(len(r) for r in parts) <= max(len(r) for r in parts)


def test_in_process_runner_passes_shared_arguments():
    assert InProcess().map(lambda x, k: x * k, [1, 2, 3], k=np.int64(2)) == [2, 4, 6]


# --------------------------------------------------------------------------- ensembles


@pytest.fixture(scope="module")
def ensemble(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from planner.forecast.synthetic.ensemble import write_gyre_ensemble

    return write_gyre_ensemble(tmp_path_factory.mktemp("ens") / "ens.nc", GYRE, members=3, seed=1)


def _ensemble_request(path: Path, criterion: str, members=None):
    from planner.contract.geodesy import BBox
    from planner.pipeline import PlanRequest
    from planner.contract.settings import Goal, PlanSettings

    return PlanRequest(forecast_path=path, goal=Goal(lon_deg=-117.86, lat_deg=33.385, depth_m=0.0), depths_m=(0.0,),
                       settings=PlanSettings(model="physical", criterion=criterion),
                       bbox=BBox(west_deg=-118.20, south_deg=33.30, east_deg=-117.80, north_deg=33.467), nx=21, ny=9,
                       members=members)


@pytest.mark.parametrize("criterion", ["robust", "expected"])
def test_ensemble_plan_on_dask_equals_one_process(cluster, ensemble, criterion):
    from planner.pipeline import make_plan

    _c, runner = cluster
    here = make_plan(_ensemble_request(ensemble, criterion))
    there = make_plan(_ensemble_request(ensemble, criterion), runner=runner)
    assert here.model.members == 3 and here.model.samples_per_action == 3 * 81
    assert there.table.to_bytes() == here.table.to_bytes()
    assert np.array_equal(there.solution.value_wh, here.solution.value_wh, equal_nan=True)
    assert here.table.forecast_identity.startswith("ensemble:")


def test_robust_over_members_is_at_least_every_members_worst_case(ensemble):
    """Members are outcomes: the worst case over all members' samples is never cheaper than one member's."""
    from planner.pipeline import MemberRef, make_plan

    together = make_plan(_ensemble_request(ensemble, "robust")).solution.value_wh
    alone = [make_plan(_ensemble_request(ensemble, "robust", (MemberRef(path=ensemble, member=k),))).solution.value_wh
             for k in range(3)]
    for v in alone:
        both = np.isfinite(v) & np.isfinite(together)
        assert np.all(together[both] >= v[both] - 1e-9)
        assert not np.any(np.isfinite(together) & ~np.isfinite(v))  # reachable together -> reachable alone
    assert np.any(together > np.maximum.reduce(alone) + 1e-6)  # and members do combine, not just pick one


def test_expected_over_members_lies_between_the_members(ensemble):
    from planner.pipeline import MemberRef, make_plan

    together = make_plan(_ensemble_request(ensemble, "expected")).solution
    alone = [make_plan(_ensemble_request(ensemble, "expected", (MemberRef(path=ensemble, member=k),))).solution.value_wh
             for k in range(3)]
    ok = np.isfinite(together.value_wh) & np.all([np.isfinite(v) for v in alone], axis=0)
    assert ok.sum() > 100
    lo, hi = np.minimum.reduce(alone)[ok], np.maximum.reduce(alone)[ok]
    v = together.value_wh[ok]
    # Not a theorem state by state (the mixed policy differs), but far from both ends it would be wrong.
    assert np.median((v - lo) / np.maximum(hi - lo, 1e-9)) > 0.05 and np.median((hi - v) / np.maximum(hi - lo, 1e-9)) > 0.05


def test_paper_model_refuses_an_ensemble(ensemble, tmp_path, capsys):
    mission = tmp_path / "m.yaml"
    mission.write_text(MISSION.format(name="p", forecast=ensemble, model="paper", criterion="robust"))
    rc = main(["plan", str(mission), "--out", str(tmp_path / "t.lrpt"), "--scheduler", IN_PROCESS, "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "3 forecast members needs the physical model" in err and err.count("\n") == 1
    assert not (tmp_path / "t.lrpt").exists()


def test_plan_command_plans_an_ensemble_on_the_cluster(cluster, ensemble, files, tmp_path, capsys):
    c, _runner = cluster
    out = tmp_path / "ens.lrpt"
    rc = main(["plan", str(files["physical"]), "--forecast", str(ensemble), "--out", str(out),
               "--scheduler", c.scheduler_address, "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    from planner.pipeline import make_plan
    from planner.contract.table import PolicyTable

    mission = load_mission(files["physical"])
    request = dataclasses.replace(_ensemble_request(ensemble, "expected"), settings=mission.settings)
    assert PolicyTable.load(out).actions.tobytes() == make_plan(request).table.actions.tobytes()
    assert "3 forecast members" in text or "ensemble:" in text


def test_holdout_command_compares_ensemble_and_single_member_plans(ensemble, files, capsys):
    rc = main(["holdout", str(files["physical"]), "--ensemble", str(ensemble), "--starts", "3", "--dt-s", "10",
               "--max-hours", "6", "--scheduler", IN_PROCESS, "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0, out
    rows = [line.split() for line in out.splitlines() if line.strip() and line.split()[0].isdigit()]
    assert [r[0] for r in rows] == ["0", "1", "2"] and all(r[1] == "3" for r in rows)
    assert "ensemble" in out and "single-member plans" in out
    assert max(len(line) for line in out.splitlines()) <= 100, out
