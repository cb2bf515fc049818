"""Progress on long work: the library reports growing counts to a meter, the command line draws bars only on a terminal."""

from __future__ import annotations

import fcntl
import os
import pty
import select
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from tests.support import REPO

LRAUV = str(Path(sys.executable).parent / "lrauv")
TINY = ["--bbox=-118.26,33.30,-117.70,33.70", "--nx=8", "--ny=6", "--depths=0,10", "--goal=-117.90,33.50,0",
        "--goal-radius=1"]


class Recorder:
    """A ``Progress`` that keeps every call."""

    def __init__(self) -> None:
        self.updates: list[tuple[str, float, float, str]] = []
        self.notes: list[str] = []

    def update(self, task: str, done: float, total: float, *, unit: str = "", detail: str = "") -> None:
        self.updates.append((task, done, total, detail))

    def note(self, text: str) -> None:
        self.notes.append(text)

    def counts(self, task: str) -> list[tuple[float, float]]:
        return [(d, t) for name, d, t, _ in self.updates if name == task]


def assert_climbs_to_total(counts: list[tuple[float, float]]) -> None:
    assert len(counts) >= 2, counts
    done = [d for d, _ in counts]
    assert done == sorted(done), counts
    assert {t for _, t in counts} == {counts[-1][1]} and done[-1] == counts[-1][1] > 0, counts


@pytest.mark.parametrize("model", ["paper", "physical"])
def test_a_small_plan_reports_sampling_and_solving_up_to_their_totals(synthetic_forecast, model):
    from tests.support.helpers import DEMO_MISSION
    from planner.contract.mission import load_mission
    from planner.pipeline import PlanRequest, make_plan
    from dataclasses import replace

    m = load_mission(DEMO_MISSION)
    settings = replace(m.settings, model=model, criterion="robust")
    request = PlanRequest(forecast_path=synthetic_forecast, goal=m.goals[0].goal, depths_m=(0.0, 10.0),
                          settings=settings, bbox=m.region.bbox, nx=10, ny=8, time_index=0)
    meter = Recorder()
    make_plan(request, meter=meter)
    assert_climbs_to_total(meter.counts("solving"))
    if model == "physical":
        assert_climbs_to_total(meter.counts("sampling"))


def test_a_plan_off_a_terminal_draws_no_bar(synthetic_forecast, tmp_path):
    proc = subprocess.run([LRAUV, "plan", f"--forecast={synthetic_forecast}", *TINY, f"--out={tmp_path / 't.lrpt'}"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "planning on" in proc.stderr  # the notes still come
    assert "%|" not in proc.stderr and "\r" not in proc.stderr and "\u2588" not in proc.stderr, proc.stderr


def _under_a_terminal(args: list[str]) -> tuple[int, str]:
    """Run ``args`` with stdin, stdout and stderr on a pseudo-terminal; its exit status and all it wrote."""
    main, child = pty.openpty()
    # A terminal has a size (a bare pseudo-terminal's is 0 x 0, on which tqdm draws nothing): 24 rows of 100.
    fcntl.ioctl(child, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    proc = subprocess.Popen(args, stdin=child, stdout=child, stderr=child, close_fds=True, cwd=REPO)
    os.close(child)
    chunks = []
    while True:
        ready, _, _ = select.select([main], [], [], 120.0)
        if not ready:
            proc.kill()
            break
        try:
            data = os.read(main, 4096)
        except OSError:  # the child closed the terminal (Linux: EIO)
            break
        if not data:
            break
        chunks.append(data)
    os.close(main)
    return proc.wait(timeout=30), b"".join(chunks).decode(errors="replace")


@pytest.mark.parametrize("quiet", [False, True])
def test_a_plan_on_a_terminal_shows_its_bars_unless_quiet(synthetic_forecast, tmp_path, quiet):
    status, text = _under_a_terminal([LRAUV, "plan", f"--forecast={synthetic_forecast}", *TINY, "--model=physical",
                                      f"--out={tmp_path / 't.lrpt'}", *(["--quiet"] if quiet else [])])
    assert status == 0, text
    if quiet:
        assert "%|" not in text and "sampling:" not in text, text
    else:
        assert "sampling: 100%|" in text and "solving: 100%|" in text, text


# --------------------------------------------------------------------------- replay and audit


def test_a_replay_reports_reading_and_auditing_up_to_the_logs_totals(dive_log):
    from executive.recorder import Topic
    from planner.shore.replay.audit import audit
    from planner.shore.replay.dive import load_dive
    from planner.shore.replay.divelog import open_dive

    meter = Recorder()
    log = open_dive(dive_log, meter=meter)
    dive = load_dive(log, meter=meter)
    result = audit(log, meter=meter)
    reading = meter.counts("reading the log")
    assert_climbs_to_total(reading)
    assert reading[-1][1] == dive_log.stat().st_size
    decisions = log.counts[Topic.DECISION]
    for task in ("reading decisions", "auditing decisions"):
        counts = meter.counts(task)
        assert_climbs_to_total(counts)
        assert counts[-1][1] == decisions
        assert len(counts) > 2  # it moves along the log, not only at its ends
    assert len(dive.track) == result.decisions == decisions


def test_a_replay_off_a_terminal_draws_no_bar(dive_log, capsys):
    from planner.cli import main

    assert main(["replay", str(dive_log), "--no-audit"]) == 0  # stderr is pytest's capture, not a terminal
    out, err = capsys.readouterr()
    assert "decisions" in out  # the summary still comes
    for text in (out, err):
        assert "%|" not in text and "\r" not in text and "\u2588" not in text, text


def test_a_replay_on_a_terminal_shows_its_bars(dive_log):
    status, text = _under_a_terminal([LRAUV, "replay", str(dive_log), "--no-audit"])  # the audit's: in-process above
    assert status == 0, text
    for task in ("reading the log", "reading decisions"):
        assert f"{task}: 100%|" in text, text


# --------------------------------------------------------------------------- the demo's closed loop


def test_the_closed_loop_reads_vehicle_time_and_distance_off_the_track_file_as_written(demo_plan, tmp_path):
    from planner.shore.demo import TrackWatch, last_track_row, wait_watching

    table = tmp_path / "demo.lrpt"
    demo_plan.table.save(table)
    track = tmp_path / "track.csv"
    meter = Recorder()
    watch = TrackWatch(track, table, 10.0, meter)
    watch.poll()  # no file yet: nothing to say
    assert meter.updates == [] and last_track_row(track) is None
    goal_lat, goal_lon = demo_plan.table.goal_lat_deg, demo_plan.table.goal_lon_deg
    header = "time_s,lat_deg,lon_deg,depth_m,heading_deg,mode,armed,energy_used_wh\n"
    # one degree of latitude south of the goal at 1 h, then a row cut off by the writer's buffer
    track.write_text(header + f"0.000,{goal_lat - 2},{goal_lon},0,0,19,0,0\n"
                     f"3600.000,{goal_lat - 1},{goal_lon},0,0,19,1,1.5\n7200.0,{goal_lat}")
    assert last_track_row(track)["time_s"] == 3600.0
    proc = subprocess.Popen([sys.executable, "-c", "print('arrived')"], stdout=subprocess.PIPE, text=True)
    assert wait_watching(proc, 60.0, watch) == "arrived\n" and proc.returncode == 0
    task, done, total, detail = meter.updates[-1]
    assert (task, done, total) == ("closed loop", 1.0, 10.0)
    assert detail == "vehicle 1.00 h, 111.19 km to the goal", detail  # a degree of latitude on the spec's sphere
