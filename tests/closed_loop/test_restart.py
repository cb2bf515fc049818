"""Crash and restart: ``kill -9`` the executive mid-mission, then ``lrauv exec --resume``.

Both sides are real processes over UDP, as at sea: ``lrauv sim`` with the GCS
heartbeat failsafe off (``FS_GCS_ENABLE 0``, an untethered AUV) and ``lrauv exec``
on a two-goal mission. The executive is killed on its way to the second goal.
Checked: the vehicle keeps its mode and stays armed, its velocity target running
out (ArduSub); the restarted executive recovers the killed log up to its last
complete record, takes the goals, tables and active goal from its durable state,
and brings the vehicle to the second goal; its log passes the decision audit.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from planner.shore.replay.divelog import open_dive
from executive.recorder import Topic, read_messages
from planner.contract.settings import Goal
from planner.shore.demo import stop_process, wait_ready

from tests.support import REPO
from tests.support.helpers import DEMO_MISSION, assert_audit_clean, plan_for, start_west_of_goal, wait_until

pytestmark = pytest.mark.slow

LRAUV = [sys.executable, "-m", "planner.cli"]
SPEEDUP = 1000.0


def _mission(tmp_path: Path, forecast: Path, first: Goal, second: Goal) -> Path:
    text = DEMO_MISSION.read_text()
    goals = (f"  - {{lat_deg: {first.lat_deg}, lon_deg: {first.lon_deg}, depth_m: 0, radius_cells: 1, on_arrival: next}}\n"
             f"  - {{lat_deg: {second.lat_deg}, lon_deg: {second.lon_deg}, depth_m: 0, radius_cells: 1,"
             " on_arrival: hold}\n")
    old = "  - {lat_deg: 33.40, lon_deg: -117.80, depth_m: 0, radius_cells: 1, on_arrival: hold}\n"
    assert old in text
    text = text.replace(old, goals).replace("  synthetic: {seed: 0, hours: 72}\n", f"  file: {forecast}\n")
    path = tmp_path / "two-goals.yaml"
    path.write_text(text)
    return path


def _state(state_dir: Path) -> dict:
    try:
        return json.loads((state_dir / "state.json").read_text())
    except (OSError, ValueError):
        return {}


def test_kill_9_then_resume_goes_on_to_the_active_goal(demo_plan, synthetic_forecast, tmp_path):
    first_table = demo_plan.table
    lon, lat = start_west_of_goal(first_table, 2)
    first = Goal(lon_deg=first_table.goal_lon_deg, lat_deg=first_table.goal_lat_deg, depth_m=0.0)
    second = Goal(lon_deg=lon, lat_deg=lat, depth_m=0.0)  # back where the vehicle started
    mission = _mission(tmp_path, synthetic_forecast, first, second)
    tables = []
    for n, goal in enumerate((first, second)):
        tables.append(tmp_path / f"goal-{n}.lrpt")
        plan_for(synthetic_forecast, goal, mission=mission).table.save(tables[-1])
    state_dir, log, track = tmp_path / "state", tmp_path / "run.mcap", tmp_path / "track.csv"
    sim = subprocess.Popen([*LRAUV, "sim", "--forecast", str(synthetic_forecast), "--start", f"{lon},{lat}",
                            "--speedup", str(SPEEDUP), "--listen", "127.0.0.1:0", "--heartbeat-timeout-s", "0",
                            "--track", str(track), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ex = again = None
    try:
        link = f"udpout:127.0.0.1:{wait_ready(sim)}"
        ex = subprocess.Popen([*LRAUV, "exec", "--table", str(tables[0]), "--table", str(tables[1]), "--mission",
                               str(mission), "--link", link, "--log", str(log), "--state-dir", str(state_dir),
                               "--max-wall-s", "90", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True)
        assert wait_until(lambda: _state(state_dir).get("goal_index") == 1, 60), _state(state_dir)
        time.sleep(0.3)  # some way towards the second goal
        os.kill(ex.pid, signal.SIGKILL)
        ex.wait(10)
        assert ex.returncode == -signal.SIGKILL
        time.sleep(0.5)  # about 500 s of vehicle time without the executive

        again = subprocess.run([*LRAUV, "exec", "--resume", str(state_dir), "--link", link, "--exit-on-arrival",
                                "--linger-s", "5", "--max-wall-s", "60"], capture_output=True, text=True, timeout=120,
                               cwd=REPO)
    finally:
        stop_process(ex)
        stop_process(sim)
    out = again.stdout
    assert again.returncode == 0, out + again.stderr
    words = " ".join(out.split())  # lines over 100 columns wrap under their value
    assert f"resumed from {state_dir}" in words and "goal 1 of 2" in words and "recovered into" in words, out
    assert "goal       reached" in out, out

    # The killed run's log, recovered up to its last complete record.
    recovered = tmp_path / "run.recovered.mcap"
    decisions = [p for _, _, p in read_messages(recovered, [Topic.DECISION.value])]
    assert decisions and any(d["situation"] == "at_goal" for d in decisions)  # goal 0 is in it
    killed_at_s = max(d["time_s"] for d in decisions)

    # The vehicle meanwhile: the same mode, still armed (no failsafe), its velocity target gone after 3 s.
    with open(track) as f:
        rows = [r for r in csv.DictReader(f)]
    before = [r for r in rows if float(r["time_s"]) <= killed_at_s]
    gap = [r for r in rows if killed_at_s + 5 < float(r["time_s"]) < killed_at_s + 300]
    assert gap, "the simulator's track has no rows after the kill"
    assert {r["mode"] for r in gap} == {before[-1]["mode"]} and {r["armed"] for r in gap} == {"1"}

    # The new log: the goals, tables and active goal from the durable state, and the mission finished.
    new_log = tmp_path / "run-resumed-1.mcap"
    dive = open_dive(new_log)
    assert dive.metadata["helm"]["goal_index"] == "1"
    assert dive.metadata["resumed"]["goal_index"] == "1"
    loaded = [m.payload for m in dive.messages([Topic.POLICY]) if m.payload["reason"] == "loaded"]
    assert [p["goal_index"] for p in loaded] == [0, 1]
    assert_audit_clean(new_log)
    end = [m.payload for m in dive.messages([Topic.DECISION])][-1]
    assert end["situation"] == "at_goal"
    assert abs(end["lat_deg"] - second.lat_deg) <= 1.6 * first_table.dlat_deg
    assert abs(end["lon_deg"] - second.lon_deg) <= 1.6 * first_table.dlon_deg
    assert _state(state_dir)["log"] == str(new_log)
