"""``lrauv demo``: the whole loop, as an operator would run it, in two processes over UDP.

Starts ``lrauv sim`` (the simulated vehicle, on the truth forecast) and then
``lrauv exec`` (the executive, with the policy table planned on an earlier
forecast issue) as separate processes talking MAVLink over 127.0.0.1, waits
for the executive to reach the goal, stops both, draws the track and prints
where everything is. Both processes are always stopped, also on errors.
"""

from __future__ import annotations

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


def draw_track(table_path: Path, track_csv: Path, out: Path, *, truth: Path | None = None) -> Path:
    """The simulator's track over the table's region, as a PNG at ``out``; with ``truth`` (the simulator's
    forecast, whose first step is the track's time 0) over its currents, with UTC time marks."""
    from planner.contract.table import PolicyTable
    from planner.shore.plots import plot_track, track_times_and_currents

    table = PolicyTable.load(table_path)
    track = read_track(track_csv)
    start_unix_s, currents = track_times_and_currents(table, track["time_s"], truth)
    return plot_track(table, track["lon_deg"], track["lat_deg"], track["mode"], out, time_s=track["time_s"],
                      start_unix_s=start_unix_s, currents=currents)
