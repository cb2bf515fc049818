"""The closed loop over real UDP on 127.0.0.1: ``lrauv sim`` as a process, the executive in a thread.

Between them, where a test needs it, ``tests.support.linkfault.LinkFaultProxy``: a UDP
proxy that can drop, duplicate and reorder datagrams or cut one direction, and
that reads the simulator's side of the conversation (modes, STATUSTEXT) as a
ground station would. Every process and thread a test starts is stopped by it.
"""

from __future__ import annotations

import time

import pytest

from executive.recorder import read_messages
from planner.contract.modes import SubMode
from tests.support import REPO
from tests.support.helpers import assert_audit_clean, start_west_of_goal, wait_until
from tests.support.linkfault import Faults, LinkFaultProxy
from tests.support.loop_rig import FAILSAFE_SLACK_S, SPEEDUP, ExecThread, Sim

# SURFACE, or ALT_HOLD once at the surface: ArduSub completes SURFACE by itself (SURFACE_COMPLETE).
SURFACED = (SubMode.SURFACE, SubMode.ALT_HOLD)

pytestmark = pytest.mark.slow


def test_demo_processes_reach_the_goal(demo_plan, synthetic_forecast, tmp_path):
    """``lrauv demo``'s path: sim and exec as separate processes over UDP, to the goal."""
    from planner.shore.demo import read_track, run_closed_loop

    table_path = tmp_path / "demo.lrpt"
    demo_plan.table.save(table_path)
    lon, lat = start_west_of_goal(demo_plan.table)
    result = run_closed_loop(table=table_path, mission=REPO / "missions" / "demo.yaml", truth=synthetic_forecast,
                             start=f"{lon},{lat}", depth_m=0.0, heading_deg=90.0, speedup=SPEEDUP, out=tmp_path,
                             timeout_s=90.0)
    assert result.exec_status == 0, result.exec_output
    assert "goal       reached" in result.exec_output
    track = read_track(result.track_csv)
    t = demo_plan.table
    # The vehicle really is at the goal: within the goal region (radius 1 cell around the goal cell).
    assert abs(track["lat_deg"][-1] - t.goal_lat_deg) <= 1.6 * t.dlat_deg
    assert abs(track["lon_deg"][-1] - t.goal_lon_deg) <= 1.6 * t.dlon_deg
    assert track["energy_used_wh"][-1] > 0
    decisions = [p for _, _, p in read_messages(result.log_path, ["/executive/decision"])]
    assert {d["action"] for d in decisions} >= {"FORWARD", "AT_GOAL"}
    assert_audit_clean(result.log_path)


def test_executive_copes_with_lost_duplicated_and_reordered_telemetry(demo_plan, synthetic_forecast, tmp_path):
    lon, lat = start_west_of_goal(demo_plan.table, cells=2)  # two cells: thousands of lossy messages, a shorter suite
    # Lockstep with slack (docs/executive.md, "Lockstep with the simulator"): a lost step does not stall
    # the simulator, and 1.5 s keeps the executive's heartbeats within ArduSub's 5 s failsafe (which
    # counts them: MAV_GCS_SYSID set to the executive's system, 1).
    sim = Sim(synthetic_forecast, (lon, lat), "--heading-deg", "90", "--position-delay-s", "10",
              "--lockstep-slack-s", f"{FAILSAFE_SLACK_S:g}", "--gcs-sysid", "1")
    relay = LinkFaultProxy(sim.port, speedup=SPEEDUP, seed=7, down=Faults(loss=0.25, duplicate=0.10, reorder=0.05))
    ex = None
    try:
        ex = ExecThread(demo_plan.table, relay.port, tmp_path / "lossy.mcap")
        summary = ex.join()
    finally:
        if ex is not None:
            ex.stop()
        relay.close()
        sim.stop()
    assert summary is not None and summary.reached, summary
    down = relay.counters("down")
    assert down.dropped > 100 and down.duplicated > 50 and down.reordered > 10
    # No decision went back in time although datagrams came twice and out of order.
    times = [p["time_s"] for _, _, p in read_messages(tmp_path / "lossy.mcap", ["/executive/decision"])]
    assert times == sorted(times)
    assert_audit_clean(tmp_path / "lossy.mcap")  # stale and duplicated datagrams are dropped again the same way


def test_simulator_fails_safe_when_the_executive_heartbeat_stops(demo_plan, synthetic_forecast, tmp_path):
    lon, lat = start_west_of_goal(demo_plan.table, cells=6)
    # ArduSub counts only MAV_GCS_SYSID's heartbeats: set to the executive's system (1), as on a vehicle
    # whose companion computer is its ground station.
    sim = Sim(synthetic_forecast, (lon, lat), "--position-delay-s", "5", "--heartbeat-timeout-s", "5",
              "--gcs-sysid", "1")
    relay = LinkFaultProxy(sim.port, speedup=SPEEDUP)
    ex = ExecThread(demo_plan.table, relay.port, tmp_path / "hb.mcap")
    try:
        assert wait_until(lambda: relay.mode() == SubMode.GUIDED, 30), relay.modes[-3:]
        time.sleep(0.2)
        ex.stop()  # the executive's process dies: no more heartbeats from component 191
        assert wait_until(lambda: any("heartbeat lost" in t for _, t in relay.texts), 20), relay.texts
        assert wait_until(lambda: relay.mode() in SURFACED, 20), relay.modes[-3:]
    finally:
        ex.stop()
        relay.close()
        sim.stop()


def test_executive_fails_safe_when_the_autopilot_goes_silent(demo_plan, synthetic_forecast, tmp_path):
    lon, lat = start_west_of_goal(demo_plan.table, cells=6)
    sim = Sim(synthetic_forecast, (lon, lat), "--position-delay-s", "5", "--heartbeat-timeout-s", "600")
    relay = LinkFaultProxy(sim.port, speedup=SPEEDUP)
    # A silence is counted at real time (docs/executive.md, "Time"): 3 s of it, in wall seconds at any speedup.
    ex = ExecThread(demo_plan.table, relay.port, tmp_path / "silent.mcap", link_loss_timeout_s=3.0)
    try:
        assert wait_until(lambda: relay.mode() == SubMode.GUIDED, 30), relay.modes[-3:]
        time.sleep(0.2)
        relay.cut(up=False, down=True)  # telemetry no longer reaches the executive; its commands still reach the vehicle
        # After the timeout it asks for SURFACE.
        assert wait_until(lambda: relay.mode() in SURFACED, 20), relay.modes[-3:]
        relay.cut(up=False, down=False)
        summary = ex.stop()
    finally:
        ex.stop()
        relay.close()
        sim.stop()
    logs = [p["message"] for _, _, p in read_messages(tmp_path / "silent.mcap", ["/log"])]
    assert any(m.startswith("link lost") for m in logs), logs
    assert summary is not None
    assert_audit_clean(tmp_path / "silent.mcap")  # link loss and its recovery run again the same way


def test_a_physical_plans_course_offsets_fly_over_mavlink(synthetic_forecast, tmp_path):
    """A physical plan with FORWARD_LEFT/RIGHT through ``lrauv exec`` and ``lrauv sim`` over UDP:
    the executive commands the offset course, the vehicle holds it, and the audit agrees."""
    from planner.contract.actions import Action
    from planner.contract.mission import load_mission
    from planner.pipeline import PlanRequest, make_plan
    from planner.shore.demo import run_closed_loop

    mission_path = REPO / "missions" / "demo-physical.yaml"
    result = make_plan(PlanRequest.for_mission(load_mission(mission_path), synthetic_forecast))
    table, sol = result.table, result.solution
    offsets = {Action.FORWARD_LEFT, Action.FORWARD_RIGHT}
    # The nearest start (east-bound, at the surface) whose nominal path begins with a course offset.
    gj, gi = round((table.goal_lat_deg - table.lat0_deg) / table.dlat_deg), round((table.goal_lon_deg - table.lon0_deg) / table.dlon_deg)
    candidates = sorted(((abs(j - gj) + abs(i - gi), j, i) for j in range(table.ny) for i in range(table.nx)
                         if 3 <= abs(j - gj) + abs(i - gi) <= 6 and table.water[0, j, i]))
    start = next(((j, i) for _d, j, i in candidates
                  if Action(int(table.actions[0, j, i, 0])) in offsets and len(sol.nominal((0, j, i, 0))) > 2), None)
    assert start is not None, "no start near the goal begins with a course offset"
    j, i = start
    lat, lon = table.cell_centre(j, i)
    table_path = tmp_path / "physical.lrpt"
    table.save(table_path)
    run = run_closed_loop(table=table_path, mission=mission_path, truth=synthetic_forecast, start=f"{lon},{lat}",
                          depth_m=0.0, heading_deg=float(table.bearing_deg(j, 0)), speedup=SPEEDUP, out=tmp_path,
                          timeout_s=90.0)
    assert run.exec_status == 0, run.exec_output
    assert "goal       reached" in run.exec_output
    messages = list(read_messages(run.log_path, ["/executive/decision", "/executive/command"]))
    decisions = [p for topic, _, p in messages if topic == "/executive/decision"]
    flown = [d for d in decisions if d["action"] in ("FORWARD_LEFT", "FORWARD_RIGHT")]
    assert flown, {d["action"] for d in decisions}
    # Each course-offset decision is followed by a velocity command along that state's offset course.
    courses = {(tuple(d["cell"]), d["action"]) for d in flown if d["changed"]}
    commanded = [p["yaw_deg"] for topic, _, p in messages if topic == "/executive/command" and p["kind"] == "VelocityYaw"]
    for (l, jj, ii, k), name in courses:
        course = table.course_deg(jj, k, Action[name])
        assert any(abs((y - course + 180.0) % 360.0 - 180.0) < 1e-6 for y in commanded), (name, course)
    # The vehicle holds the course: late in each such activity its measured heading is near it.
    late = [d for d in flown if not d["changed"] and d["heading_deg"] is not None]
    assert late
    errors = [abs((d["heading_deg"] - table.course_deg(d["cell"][1], d["cell"][3], Action[d["action"]]) + 180.0) % 360.0 - 180.0)
              for d in late]
    assert sorted(errors)[len(errors) // 2] < 3.0, errors[:20]
    assert_audit_clean(run.log_path)
