"""Benchmark the physical model (docs/physical-model.md): sampling and both solvers, with and
without the course offsets, on the demo grid and on the grid of half its spacing.

Not a test. Plans missions/demo-physical.yaml's goal on the synthetic SCB forecast (written
into a temporary folder, issue 0), best of ``--repeat`` after one warm-up (numba compiles on
first use). Prints a Markdown table for docs/benchmarks.md.

    .venv/bin/python bench/bench_physical.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    from planner.forecast import open_forecast
    from planner.contract.mission import load_mission
    from planner.pipeline import PlanRequest, make_plan
    from planner.contract.settings import Goal
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    mission = load_mission(REPO / "missions" / "demo-physical.yaml")
    with tempfile.TemporaryDirectory() as tmp:
        path = write_synthetic(Path(tmp) / "scb.nc", SyntheticSettings(hours=6), issue_number=0)
        forecast = open_forecast(path)
        print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
        print("| grid | states | courses | criterion | state-actions | sampling s | solve s | iterations |")
        print("|---|---|---|---|---|---|---|---|")
        for scale in (1, 2):
            for courses in (False, True):
                for criterion in ("expected", "robust"):
                    base = PlanRequest.for_mission(mission, path)
                    physical = replace(base.settings.physical, course_offsets=courses)
                    settings = replace(base.settings, criterion=criterion, physical=physical)
                    goal = base.goal
                    request = replace(base, settings=settings, nx=(base.nx - 1) * scale + 1, ny=(base.ny - 1) * scale + 1,
                                      goal=Goal(lon_deg=goal.lon_deg, lat_deg=goal.lat_deg, depth_m=goal.depth_m,
                                                radius_cells=goal.radius_cells * scale))
                    make_plan(request, forecast=forecast)  # warm-up: numba's cache, the resample
                    best: dict[str, float] = {}
                    for _ in range(args.repeat):
                        t0 = time.perf_counter()
                        result = make_plan(request, forecast=forecast)
                        total = time.perf_counter() - t0
                        t = result.timings_s
                        sample_s = t["transitions_s"]
                        solve_s = t["plan_s"] - sample_s
                        for key, value in (("sample", sample_s), ("solve", solve_s), ("total", total)):
                            best[key] = min(best.get(key, value), value)
                    grid = result.grid
                    sol = result.solution
                    print(f"| {grid.nx} x {grid.ny} x {grid.n_layers} | {grid.n_states:,} | {'yes' if courses else 'no'} "
                          f"| {criterion} | {result.model.n_pairs:,} | {best['sample']:.2f} | {best['solve']:.2f} "
                          f"| {sol.iterations if criterion == 'expected' else '-'} |", flush=True)  # type: ignore[union-attr]


if __name__ == "__main__":
    main()
