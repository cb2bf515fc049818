"""Scale-out figures for docs/scale-out.md: Dask's per-task overhead and the speed-up from 1 to 2 workers.

    .venv/bin/python bench/bench_dask.py [--starts 60] [--repeat 3]

1. Per-task overhead: 2,000 tasks that do nothing on a local cluster of 2 worker processes,
   as ``planner.cluster.DaskRunner.map`` sends them (submit, run, gather), per task.
2. Monte Carlo: one ``lrauv evaluate`` campaign (the double gyre, all five methods) flown in
   this process, on a local cluster of 1 worker and of 2 workers; the results are checked equal.
3. Ensemble sampling: the physical model's transitions of an 8-member double-gyre ensemble,
   one task per member, in this process, on 1 and on 2 workers.
Prints wall times (best of ``--repeat``) and writes nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from distributed import Client, LocalCluster  # noqa: E402

from planner.cluster import local_cluster  # noqa: E402

from planner.shore.evaluation.campaign import CampaignSpec, prepare, run_all  # noqa: E402
from planner.cluster import DaskRunner, InProcess  # noqa: E402
from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre  # noqa: E402
from planner.contract.mission import load_mission  # noqa: E402
from vehicle_sim.world import World  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def _nothing(x: int) -> int:
    return x


def _cluster(n: int) -> tuple[LocalCluster, Client]:
    cluster = local_cluster(n)
    return cluster, Client(cluster, set_as_default=False)


def best(fn, repeat: int) -> float:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--members", type=int, default=8)
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        gyre = DoubleGyreSettings(peak_speed_m_s=1.5)
        truth = write_gyre(d / "truth.nc", gyre)
        steady = write_gyre(d / "steady.nc", dataclasses.replace(gyre, eps=0.0))
        text = (REPO / "missions" / "eval-double-gyre.yaml").read_text().replace("../out/gyre/forecast.nc", str(steady))
        (d / "m.yaml").write_text(text)
        spec = CampaignSpec(mission=load_mission(d / "m.yaml"), forecast_path=steady, truth=World.load(truth),
                            n_starts=args.starts)
        campaign = prepare(spec)
        n_runs = args.starts * len(spec.methods)

        cluster, client = _cluster(2)
        with cluster, client:
            runner = DaskRunner(client, what="2 workers")
            runner.map(_nothing, list(range(100)))  # warm
            n = 2000
            t = best(lambda: runner.map(_nothing, list(range(n))), args.repeat)
            print(f"per-task overhead: {n} empty tasks on 2 workers in {t:.2f} s = {1000 * t / n:.2f} ms per task")

        here_s = best(lambda: run_all(campaign, runner=InProcess()), args.repeat)
        reference = run_all(campaign, runner=InProcess()).results
        print(f"monte carlo, in this process: {n_runs} runs in {here_s:.1f} s")
        for workers in (1, 2):
            cluster, client = _cluster(workers)
            with cluster, client:
                runner = DaskRunner(client, what=f"{workers} workers")
                got = run_all(campaign, runner=runner).results  # also warms the workers
                assert [repr(r) for r in got] == [repr(r) for r in reference], "Dask results differ"
                s = best(lambda: run_all(campaign, runner=runner), args.repeat)
                print(f"monte carlo, {workers} worker(s): {n_runs} runs in {s:.1f} s "
                      f"(speed-up over one worker process in this process: {here_s / s:.2f}x)")
        _ensemble(args, d)
    return 0


def _ensemble(args: argparse.Namespace, d: Path) -> None:
    """Sampling an ensemble's members as tasks (planner.pipeline.make_plan's member tasks)."""
    try:
        from planner.pipeline import member_tasks, sample_member
    except ImportError:
        print("ensemble sampling: not available in this version")
        return
    from planner.forecast.synthetic.ensemble import write_gyre_ensemble
    from planner.pipeline import PlanRequest
    from planner.contract.settings import Goal, PlanSettings

    mission = load_mission(d / "m.yaml")
    path = write_gyre_ensemble(d / "ens.nc", DoubleGyreSettings(peak_speed_m_s=1.5), members=args.members, seed=1)
    g = mission.goals[0].goal
    request = PlanRequest(forecast_path=path, goal=Goal(lon_deg=g.lon_deg, lat_deg=g.lat_deg, depth_m=0.0),
                          depths_m=(0.0,), settings=PlanSettings(model="physical", criterion="expected",
                                                                 vehicle=mission.settings.vehicle),
                          bbox=mission.region.bbox, nx=81, ny=35)
    tasks = member_tasks(request)
    here_s = best(lambda: InProcess().map(sample_member, tasks), args.repeat)
    print(f"ensemble sampling, in this process: {len(tasks)} members in {here_s:.2f} s")
    for workers in (1, 2):
        cluster, client = _cluster(workers)
        with cluster, client:
            runner = DaskRunner(client, what=f"{workers} workers")
            runner.map(sample_member, tasks)
            s = best(lambda: runner.map(sample_member, tasks), args.repeat)
            print(f"ensemble sampling, {workers} worker(s): {len(tasks)} members in {s:.2f} s ({here_s / s:.2f}x)")


if __name__ == "__main__":
    sys.exit(main())
