"""``lrauv demo``: the whole loop, as an operator would run it, in two processes over UDP.

Starts ``lrauv sim`` (the simulated vehicle, on the truth forecast) and then
``lrauv exec`` (the executive, with the policy table planned on an earlier
forecast issue) as separate processes talking MAVLink over 127.0.0.1, waits
for the executive to reach the goal, stops both, draws the track and prints
where everything is. Both processes are always stopped, also on errors.
"""

from __future__ import annotations

import csv
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner.contract.progress import SILENT, Progress
from planner.contract.table import PolicyTable
from planner.shore.replay.layout import write_layout
from planner.shore.replay.track_filter import path_length_m
from vehicle_sim.cli import wait_ready

POLL_S = 0.5  # how often the closed loop's progress is read off the simulator's track file


@dataclass(frozen=True, slots=True)
class DemoResult:
    exec_status: int
    exec_output: str
    track_csv: Path
    log_path: Path
    wall_s: float
    layout_path: Path | None = None  # the Foxglove layout written beside the log


def check_inputs(*, table: Path, mission: Path | None, truth: Path, timeout_s: float, speedup: float) -> None:
    """What the executive would refuse, refused here before a process starts or a file of an earlier run in
    the output folder is replaced: the table, the mission, the table's goal among the mission's, the limits."""
    from executive.goal_tables import assign
    from planner.contract.errors import ShoreError
    from planner.contract.mission import load_mission

    if not (math.isfinite(timeout_s) and timeout_s > 0):
        raise ShoreError(f"--timeout-s: expected seconds of wall time > 0; got {timeout_s:g}")
    if not (math.isfinite(speedup) and speedup > 0):
        raise ShoreError(f"--speedup: expected a factor > 0; got {speedup:g}")
    if not truth.is_file():
        raise ShoreError(f"--truth {truth}: no such file")
    loaded = PolicyTable.load(table)
    if mission is not None:  # the executive's own check: a table must serve one of the mission's goals
        assign(load_mission(mission).goals, [(str(table), loaded)], str(mission))


def run_closed_loop(*, table: Path, mission: Path | None, truth: Path, start: str, depth_m: float, heading_deg: float,
                    speedup: float, out: Path, timeout_s: float, seed: int = 0, meter: Progress = SILENT) -> DemoResult:
    """Run sim and exec as processes until the executive exits; returns its status and output.

    ``meter`` hears the vehicle time (hours) against the run's limit (``timeout_s`` of wall time at
    ``speedup``), with the distance to the table's goal, read off the simulator's track file as it grows.
    """
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
        output = wait_watching(ex, timeout_s + 30.0, TrackWatch(track, table, timeout_s * speedup / 3600.0, meter))
        status = ex.returncode
    finally:
        for proc in (ex, sim):
            stop_process(proc)
    layout = write_layout(out / "demo.foxglove-layout.json")  # open demo.mcap in Foxglove with it
    return DemoResult(exec_status=status, exec_output=output, track_csv=track, log_path=log, wall_s=time.monotonic() - t0,
                      layout_path=layout)


class TrackWatch:
    """The simulator's latest track row, as progress: vehicle hours of the limit, km to the goal."""

    def __init__(self, track: Path, table: Path, limit_h: float, meter: Progress) -> None:
        self.track, self.limit_h, self.meter = track, limit_h, meter
        self.goal: tuple[float, float] | None = None
        if meter is not SILENT:
            t = PolicyTable.load(table)
            self.goal = (t.goal_lat_deg, t.goal_lon_deg)
        self.hours = 0.0

    def poll(self) -> None:
        if self.goal is None:
            return
        row = last_track_row(self.track)
        if row is None:
            return
        self.hours = max(self.hours, row["time_s"] / 3600.0)
        km = path_length_m(np.array([row["lat_deg"], self.goal[0]]), np.array([row["lon_deg"], self.goal[1]])) / 1000
        self.meter.update("closed loop", min(self.hours, self.limit_h), self.limit_h, unit="h",
                          detail=f"vehicle {self.hours:.2f} h, {km:.2f} km to the goal")


def wait_watching(proc: subprocess.Popen[str], timeout_s: float, watch: TrackWatch) -> str:
    """``proc``'s output once it exits, polling ``watch`` meanwhile; ``TimeoutExpired`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            # communicate() again after its timeout loses no output (Python's subprocess documentation).
            output, _ = proc.communicate(timeout=min(POLL_S, max(deadline - time.monotonic(), 0.0)))
        except subprocess.TimeoutExpired:
            if time.monotonic() >= deadline:
                raise
            watch.poll()
            continue
        watch.poll()
        return output


def last_track_row(path: Path) -> dict[str, float] | None:
    """The last complete row of the simulator's track CSV as written so far (it is buffered), or None."""
    try:
        with open(path, "rb") as f:
            header = f.readline().decode().strip().split(",")
            size = os.fstat(f.fileno()).st_size
            f.seek(max(size - 4096, 0))
            lines = f.read().split(b"\n")
    except OSError:
        return None
    for line in reversed(lines[:-1]):  # the text after the last newline may be a row half written
        values = line.decode(errors="replace").split(",")
        if len(values) == len(header) and values != header:
            try:
                return {k: float(v) for k, v in zip(header, values, strict=True)}
            except ValueError:
                continue
    return None


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
