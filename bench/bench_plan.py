"""Benchmark ``plan`` (transitions + solve + policy) at the paper size up to 16 M states, both criteria.

Not a test. Each case runs in its own process so that peak memory is its own;
the field is the synthetic Southern California Bight forecast sampled at the
case's resolution (4 layers, 8 headings). Prints a Markdown table for docs/benchmarks.md.

    .venv/bin/python bench/bench_plan.py [--sizes 19488,320000,4000000,16000000] [--repeat 3]

Also reports start-up: a fresh ``lrauv plan`` process on the paper-size grid with a
warm numba cache, and the one-off compile time with an empty cache.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# (nx, ny) for 4 layers x 8 headings: 29 x 21 is the paper's grid.
SIZES = {19_488: (29, 21), 320_000: (100, 100), 4_000_000: (500, 250), 16_000_000: (1000, 500)}


def run_case(nx: int, ny: int, criterion: str, repeat: int) -> dict:
    """In a child process: sample the field, then time build_transitions + solve."""
    import numpy as np

    from planner.grid import Grid
    from planner.contract.geodesy import BBox
    from planner.contract.settings import Goal, PlanSettings
    from planner.paper.solve import solve
    from planner.forecast.synthetic.scb import SyntheticSettings, current_at
    from planner.paper.transitions import build_transitions

    syn = SyntheticSettings()
    grid = Grid.from_bbox(
        BBox(west_deg=syn.west_deg, south_deg=syn.south_deg, east_deg=syn.east_deg, north_deg=syn.north_deg),
        nx=nx, ny=ny, depths_m=[0.0, 5.0, 10.0, 15.0],
    )
    lon, lat = np.meshgrid(grid.lon_deg, grid.lat_deg)
    u = np.empty((4, ny, nx))
    v = np.empty((4, ny, nx))
    for l, depth in enumerate(grid.depth_m):
        u[l], v[l] = current_at(syn, 0.0, lon, lat, np.full_like(lon, depth))
    goal = Goal(lon_deg=-117.80, lat_deg=33.40, depth_m=0.0, radius_cells=1)
    settings = PlanSettings(criterion=criterion)
    base_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        model = build_transitions(u, v, grid, settings)
        sol = solve(model, goal)
        times.append(time.perf_counter() - t0)
        reachable = float(sol.reachable.sum() / max(int(model.water.sum()) * 8, 1))
        del model, sol
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {
        "states": grid.n_states, "nx": nx, "ny": ny, "criterion": criterion,
        "first_s": times[0], "best_s": min(times), "median_s": sorted(times)[len(times) // 2],
        "peak_rss_mb": peak, "rss_before_mb": base_rss, "reachable": reachable,
    }


def child(args: list[str], env: dict | None = None) -> dict:
    proc = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True, env=env, cwd=REPO)
    if proc.returncode != 0:
        raise SystemExit(proc.stderr)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def startup(cache_dir: str | None) -> float:
    """Wall time of a whole ``lrauv plan`` process on the paper grid."""
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    with tempfile.TemporaryDirectory() as tmp:
        fc = write_synthetic(Path(tmp) / "f.nc", SyntheticSettings(hours=2))
        env = dict(os.environ)
        if cache_dir is not None:
            env["NUMBA_CACHE_DIR"] = cache_dir
        cmd = [str(Path(sys.executable).parent / "lrauv"), "plan", f"--forecast={fc}", "--bbox=-118.26,33.30,-117.70,33.70",
               "--nx=29", "--ny=21", "--depths=0,5,10,15", "--goal=-117.80,33.40,0", f"--out={tmp}/t.lrpt", "--quiet"]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, env=env)
        return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default=",".join(str(s) for s in SIZES))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--case", nargs=3, metavar=("NX", "NY", "CRITERION"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        nx, ny, crit = int(args.case[0]), int(args.case[1]), args.case[2]
        print(json.dumps(run_case(nx, ny, crit, args.repeat)))
        return
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as empty_cache:
        cold = startup(empty_cache)
    startup(None)
    warm = startup(None)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import planner.paper.solve"], check=True)
    imports = time.perf_counter() - t0
    print(f"start-up: `lrauv plan` on the paper grid, whole process: {warm:.2f} s with a warm numba cache, "
          f"{cold:.2f} s with an empty cache (compile); importing the solver: {imports:.2f} s\n")
    print("| states | grid | criterion | best (s) | median (s) | first (s) | peak RSS (MB) | RSS before plan (MB) | reachable |")
    print("|---:|---|---|---:|---:|---:|---:|---:|---:|")
    for size in (int(s) for s in args.sizes.split(",")):
        nx, ny = SIZES[size]
        for crit in ("robust", "optimistic"):
            r = child(["--case", str(nx), str(ny), crit, "--repeat", str(args.repeat)])
            print(f"| {r['states']:,} | {nx} x {ny} x 4 x 8 | {crit} | {r['best_s']:.4f} | {r['median_s']:.4f} | "
                  f"{r['first_s']:.4f} | {r['peak_rss_mb']:.0f} | {r['rss_before_mb']:.0f} | {r['reachable']:.1%} |", flush=True)


if __name__ == "__main__":
    main()
