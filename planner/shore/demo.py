"""``lrauv demo``: the whole loop, as an operator would run it, in two processes over UDP.

Starts ``lrauv sim`` (the simulated vehicle, on the truth forecast) and then
``lrauv exec`` (the executive, with the policy table planned on an earlier
forecast issue) as separate processes talking MAVLink over 127.0.0.1, waits
for the executive to reach the goal, stops both, draws the track and prints
where everything is. Both processes are always stopped, also on errors.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from vehicle_sim.cli import wait_ready


@dataclass(frozen=True, slots=True)
class DemoResult:
    exec_status: int
    exec_output: str
    track_csv: Path
    log_path: Path
    wall_s: float


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("demo", help="run the simulated vehicle and the executive over UDP to the goal")
    p.add_argument("--table", type=Path, required=True, help="policy table from `lrauv plan`")
    p.add_argument("--mission", type=Path, required=True, help="mission YAML (vehicle, safety, goal)")
    p.add_argument("--truth", type=Path, required=True, help="forecast the simulator uses as the true currents")
    p.add_argument("--start", required=True, help="LON,LAT of the vehicle at the start")
    p.add_argument("--depth-m", type=float, default=0.0)
    p.add_argument("--heading-deg", type=float, default=0.0)
    p.add_argument("--speedup", type=float, default=1000.0, help="simulator speedup over real time (default 1000)")
    p.add_argument("--out", type=Path, default=Path("out/demo"), help="directory for the log, track and pictures")
    p.add_argument("--timeout-s", type=float, default=170.0, help="wall-time limit for the run")
    p.add_argument("--seed", type=int, default=0)


def run(args: argparse.Namespace) -> int:
    args.out.mkdir(parents=True, exist_ok=True)
    result = run_closed_loop(
        table=args.table, mission=args.mission, truth=args.truth, start=args.start, depth_m=args.depth_m,
        heading_deg=args.heading_deg, speedup=args.speedup, out=args.out, timeout_s=args.timeout_s, seed=args.seed,
    )
    sys.stdout.write(result.exec_output)
    picture = _plot(args.table, result.track_csv, args.out / "pictures" / "track.png")
    print(f"track      {result.track_csv}")
    print(f"picture    {picture}")
    print(f"demo       {result.wall_s:.1f} s wall in all")
    return result.exec_status


def run_closed_loop(*, table: Path, mission: Path | None, truth: Path, start: str, depth_m: float, heading_deg: float,
                    speedup: float, out: Path, timeout_s: float, seed: int = 0) -> DemoResult:
    """Run sim and exec as processes until the executive exits; returns its status and output."""
    t0 = time.monotonic()
    lrauv = [sys.executable, "-m", "planner.cli"]
    track = out / "track.csv"
    log = out / "demo.mcap"
    sim_cmd = [*lrauv, "sim", "--forecast", str(truth), "--start", start, "--depth-m", str(depth_m),
               "--heading-deg", str(heading_deg), "--speedup", str(speedup), "--listen", "127.0.0.1:0",
               "--seed", str(seed), "--track", str(track)]
    if mission is not None:
        sim_cmd += ["--mission", str(mission)]
    sim = subprocess.Popen(sim_cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ex: subprocess.Popen[str] | None = None
    try:
        port = wait_ready(sim)
        exec_cmd = [*lrauv, "exec", "--table", str(table), "--link", f"udpout:127.0.0.1:{port}", "--log", str(log),
                    "--exit-on-arrival", "--max-wall-s", str(timeout_s)]
        if mission is not None:
            exec_cmd += ["--mission", str(mission)]
        ex = subprocess.Popen(exec_cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        output, _ = ex.communicate(timeout=timeout_s + 30.0)
        status = ex.returncode
    finally:
        for proc in (ex, sim):
            stop_process(proc)
    return DemoResult(exec_status=status, exec_output=output, track_csv=track, log_path=log, wall_s=time.monotonic() - t0)


def stop_process(proc: subprocess.Popen[str] | None) -> None:
    """Terminate a child (kill it after 10 s) and reap it; nothing if it already exited."""
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=10.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def read_track(path: Path) -> dict[str, list[float]]:
    """The simulator's ``--track`` CSV as columns of floats."""
    cols: dict[str, list[float]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            for key, value in row.items():
                cols.setdefault(key, []).append(float(value))
    return cols


def _plot(table_path: Path, track_csv: Path, out: Path) -> Path:
    from planner.shore.plots import plot_track
    from planner.contract.table import PolicyTable

    table = PolicyTable.load(table_path)
    track = read_track(track_csv)
    return plot_track(table, track["lon_deg"], track["lat_deg"], track["mode"], out)
