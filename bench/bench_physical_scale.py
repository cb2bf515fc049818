"""Benchmark the physical model at size: whole ``lrauv plan`` processes from the demo grid to millions of states.

Not a test. For each grid, ``lrauv plan missions/demo-physical.yaml --forecast <SCB issue 0> --nx NX --ny NY
--goal-radius R`` runs ``--repeat`` times after one warm-up run (numba's compile cache); the table
gives the best of them: "plan" (sampling plus solve, as the command reports it), "process" (the
whole command, start-up and table write included) and the process's peak RSS. ``--paper`` times
the paper model's plan on the same grid for the ratio per state. ``--repo`` runs another checkout
(older code) the same way, so old and new are measured the same day on the same machine.

    .venv/bin/python bench/bench_physical_scale.py [--sizes 1,2,4] [--repeat 3] [--repo PATH] [--paper] [--json OUT]
    .venv/bin/python bench/bench_physical_scale.py --plot docs/benchmarks-physical-scale.png --label new --json new.json \
        --label old --json old.json   # the cost per state-action of each run against the states

Sizes are multiples of the demo grid's spacing: 1 is 29 x 21 (19,488 states), 4 is 113 x 81
(292,896), ``4M`` is 500 x 250 (4,000,000). Then, in this process, a second goal on the same
forecast against the first (``--second-goal``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEMO = (29, 21)
# Both forms the command has printed: "(sampling S s, transitions T s, solve V s)" and, since 2026-11-29,
# "(transitions T s, of which sampling S s; solve V s)"; old code is timed the same way.
_PLAN = re.compile(r"plan ([0-9.]+) s \((?:sampling [0-9.]+ s, )?transitions ([0-9.]+) s(?:, of which sampling [0-9.]+ s)?"
                   r"[,;] solve ([0-9.]+) s\)")
_PAPER_PLAN = re.compile(r"plan ([0-9.]+) s")


def grid_of(size: str) -> tuple[int, int, int]:
    """(nx, ny, goal radius in cells) of a size: a multiple of the demo spacing, or ``4M``/``16M``."""
    if size == "4M":
        return 500, 250, 9
    if size == "16M":
        return 1000, 500, 18
    k = int(size)
    return (DEMO[0] - 1) * k + 1, (DEMO[1] - 1) * k + 1, k


def compile_bytecode(repo: Path) -> None:
    """The checkout's bytecode, as ``make`` compiles it: old and new code then start alike."""
    subprocess.run([sys.executable, "-m", "compileall", "-q", "planner", "executive", "vehicle_sim"], cwd=repo,
                   check=True, stdout=subprocess.DEVNULL)


def run_plan(repo: Path, forecast: Path, nx: int, ny: int, radius: int, out: Path, *,
             model: str, extra: tuple[str, ...] = ()) -> tuple[float, float, int, str, float]:
    """One ``lrauv plan`` process: (reported plan s, wall s, peak RSS bytes, its output, reported solve s)."""
    cmd = [sys.executable, "-m", "planner.cli", "plan", "missions/demo-physical.yaml", "--forecast", str(forecast),
           "--nx", str(nx), "--ny", str(ny), "--goal-radius", str(radius), "--out", str(out), "--model", model, *extra]
    if model == "paper":
        cmd += ["--criterion", "robust"]
    env = dict(os.environ, PYTHONPATH=str(repo))
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=repo, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert proc.stdout is not None
    stdout = proc.stdout.read()
    _pid, status, usage = os.wait4(proc.pid, 0)  # the child's own peak RSS, not this process's
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{stdout}")
    rss = int(usage.ru_maxrss) * 1024  # Linux: kilobytes
    flat = " ".join(stdout.split())  # the summary wraps its lines at 100 columns
    match = _PLAN.search(flat) if model == "physical" else _PAPER_PLAN.search(flat)
    if match is None:
        raise SystemExit(f"no plan time in the output of {' '.join(cmd)}:\n{stdout}")
    solve = float(match.group(3)) if model == "physical" else float(match.group(1))
    return float(match.group(1)), wall, rss, stdout, solve


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1,2,4", help="comma-separated: multiples of the demo spacing, 4M, 16M")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--repo", type=Path, default=REPO, help="the checkout to run (default: this one)")
    parser.add_argument("--paper", action="store_true", help="also time the paper model on each grid")
    parser.add_argument("--second-goal", action="store_true", help="time a second goal on the same forecast")
    parser.add_argument("--json", type=Path, action="append", default=[], help="write the rows here (with --plot: read)")
    parser.add_argument("--label", action="append", default=[], help="with --plot: each --json file's legend")
    parser.add_argument("--plot", type=Path, help="draw the cost per state-action of --json files to this PNG")
    args = parser.parse_args()
    if args.plot is not None:
        plot(args.plot, args.json, args.label)
        return

    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
          f"code: {args.repo}")
    compile_bytecode(args.repo)
    with tempfile.TemporaryDirectory() as tmp:
        forecast = Path(tmp) / "forecast.nc"
        subprocess.run([sys.executable, "-m", "planner.cli", "forecast", "synth", str(forecast), "--issue", "0"],
                       cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), check=True, capture_output=True)
        print("| grid | states | state-actions | plan s (best) | of which solve s | process s (best) | peak RSS MB | "
              "us per state-action | paper plan s | ratio per state |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        rows = []
        for size in args.sizes.split(","):
            nx, ny, radius = grid_of(size)
            out = Path(tmp) / "plan.lrpt"
            runs = [run_plan(args.repo, forecast, nx, ny, radius, out, model="physical")
                    for _ in range(args.repeat + 1)]
            runs = runs[1:] or runs  # the first warms numba's cache; --repeat 0 keeps it (a single long run)
            plan = min(r[0] for r in runs)
            solve = min(r[4] for r in runs)
            wall = min(r[1] for r in runs)
            rss = max(r[2] for r in runs)
            text = runs[0][3]
            pairs = int(re.search(r"([0-9,]+) state-actions", text).group(1).replace(",", ""))  # type: ignore[union-attr]
            states = nx * ny * 4 * 8
            paper = "-"
            ratio = "-"
            if args.paper:
                paper_runs = [run_plan(args.repo, forecast, nx, ny, radius, out, model="paper")
                              for _ in range(args.repeat + 1)]
                paper_runs = paper_runs[1:] or paper_runs
                paper_s = min(r[0] for r in paper_runs)
                paper, ratio = f"{paper_s:.3f}", f"{plan / max(paper_s, 1e-6):,.0f}"
            print(f"| {nx} x {ny} x 4 x 8 | {states:,} | {pairs:,} | {plan:.2f} | {solve:.2f} | {wall:.2f} | {rss / 1e6:,.0f} | "
                  f"{plan / pairs * 1e6:.2f} | {paper} | {ratio} |", flush=True)
            rows.append({"states": states, "pairs": pairs, "plan_s": plan, "solve_s": solve, "process_s": wall,
                         "rss_mb": rss / 1e6})
            if args.json:
                args.json[0].write_text(json.dumps(rows, indent=1))
        if args.second_goal:
            second_goal(args.repo, forecast, args.repeat)


def second_goal(repo: Path, forecast: Path, repeat: int) -> None:
    """A first goal, then a second on the same forecast sharing its goal-free samples (``SampleCache``)."""
    code = f"""
import time
from dataclasses import replace
from pathlib import Path
from planner.contract.mission import load_mission
from planner.contract.settings import Goal
from planner.forecast import open_forecast
from planner.pipeline import PlanRequest, SampleCache, make_plan
mission = load_mission(Path("missions/demo-physical.yaml"))
request = PlanRequest.for_mission(mission, Path({str(forecast)!r}))
forecast = open_forecast(request.forecast_path)
other = replace(request, goal=Goal(lon_deg=-118.10, lat_deg=33.55, depth_m=0.0, radius_cells=1))
make_plan(request, forecast=forecast)  # warm-up
best = [1e9, 1e9]
for _ in range({repeat}):
    cache = SampleCache()
    t0 = time.perf_counter(); make_plan(request, forecast=forecast, samples=cache); t1 = time.perf_counter()
    make_plan(other, forecast=forecast, samples=cache); t2 = time.perf_counter()
    best = [min(best[0], t1 - t0), min(best[1], t2 - t1)]
print(f"first goal {{best[0]:.3f}} s, second goal {{best[1]:.3f}} s ({{100 * best[1] / best[0]:.0f}} %)")
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=repo, env=dict(os.environ, PYTHONPATH=str(repo)),
                            capture_output=True, text=True, check=True)
    print(result.stdout.strip())


def plot(out: Path, files: list[Path], labels: list[str]) -> None:
    """Microseconds of plan per state-action against the states, one line per --json file."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.6))
    for n, path in enumerate(files):
        rows = json.loads(path.read_text())
        ax.plot([r["states"] for r in rows], [r["plan_s"] / r["pairs"] * 1e6 for r in rows], "o-",
                label=labels[n] if n < len(labels) else path.stem)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("states")
    ax.set_ylabel("plan time per state-action (us)")
    ax.set_title("Physical model, expected criterion, 2-core machine")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
