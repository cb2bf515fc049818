"""Uploads, replanning, multi-goal missions and failsafes on a running executive, over real UDP.

The simulated vehicle (``vehicle_sim.endpoint.Simulator``) runs in a thread on an
ephemeral port, the executive in another, with its ground-station link on a second
ephemeral port. Uploads go in as a ground station sends them: ``lrauv upload``, the
project's own clients, and pymavlink's MAVFTP client. Every thread is stopped by its test.
"""

from __future__ import annotations

import io
import os
from dataclasses import replace
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavftp  # noqa: E402

from executive import goal_tables
from executive.recorder import read_messages  # noqa: E402
from executive.state import Phase  # noqa: E402
from planner.contract.modes import SubMode
from planner.cli import main as lrauv  # noqa: E402
from planner.contract.errors import LrauvError  # noqa: E402
from planner.shore.ftp_client import put_file  # noqa: E402
from planner.contract.mission import load_mission  # noqa: E402
from planner.shore.mission_client import upload_goals  # noqa: E402
from planner.contract.settings import Goal  # noqa: E402
from planner.contract.mission import goals_to_items  # noqa: E402

from tests.support.helpers import DEMO_MISSION, plan_for, start_west_of_goal  # noqa: E402
from tests.support.live_rig import WALL_LIMIT_S, Live, following  # noqa: E402

DEMO = DEMO_MISSION

pytestmark = pytest.mark.slow


def _plan(forecast: Path, goal: Goal, **settings):  # type: ignore[no-untyped-def]
    return plan_for(forecast, goal, **settings).table


@pytest.fixture()
def live(demo_plan, synthetic_forecast, tmp_path):
    table = demo_plan.table
    mission = load_mission(DEMO)
    plan = goal_tables.MissionPlan(goals=mission.goals, tables=(table,))
    rig = Live(synthetic_forecast, plan, tmp_path / "exec.mcap", start=start_west_of_goal(table), watch=tmp_path / "inbox")
    with following(rig):
        yield rig


@pytest.fixture(scope="module")
def optimistic_table(synthetic_forecast):
    """The demo goal planned another way: a different table for the same goal and grid."""
    mission = load_mission(DEMO)
    return _plan(synthetic_forecast, mission.goals[0].goal, criterion="optimistic")


def _policy(log: Path) -> list[dict]:
    return [payload for _topic, _t, payload in read_messages(log, ["/executive/policy"])]


def test_lrauv_upload_sends_goals_and_table_and_the_table_is_swapped_in(live, optimistic_table, tmp_path):
    path = tmp_path / "optimistic.lrpt"
    optimistic_table.save(path)
    before = live.executive._counts["decisions"]
    code = lrauv(["upload", str(DEMO), "--to", f"udpout:127.0.0.1:{live.gcs_port}", "--table", str(path), "--quiet"])
    assert code == 0
    assert live.wait(lambda: live.executive.table.crc32 == optimistic_table.crc32, 10.0)
    assert [w["source"] for w in live.executive.swaps] == ["upload /tables/goal-0.lrpt"]  # same goals: kept, no swap
    swap = live.executive.swaps[-1]
    assert swap["table_crc32"] == f"{optimistic_table.crc32:08x}"
    assert swap["previous"]["table_crc32"] != swap["table_crc32"]
    assert live.wait(lambda: live.executive._counts["decisions"] > before + 20, 10.0)
    live.stop()
    records = _policy(live.executive.config.log_path)
    crc = f"{optimistic_table.crc32:08x}"
    assert {r["reason"] for r in records if r.get("table_crc32") == crc} == {"received", "swapped"}


def test_pymavlink_mavftp_put_uploads_a_table(live, optimistic_table):
    conn = live.ground_station()
    try:
        ftp = mavftp.MAVFTP(conn, target_system=1, target_component=191)
        blob = optimistic_table.to_bytes()
        assert ftp.cmd_put(["t.lrpt", "/tables/t.lrpt"], fh=io.BytesIO(blob)).error_code == 0
        assert ftp.process_ftp_reply("put", timeout=20).error_code == mavftp.FtpError.Success
    finally:
        conn.close()
    assert live.wait(lambda: live.executive.table.crc32 == optimistic_table.crc32, 10.0)


@pytest.mark.parametrize("damage", ["flipped byte", "truncated", "not a table", "another goal"])
def test_a_bad_table_is_refused_and_the_running_plan_goes_on(live, optimistic_table, synthetic_forecast, damage):
    running = live.executive.table
    blob = bytearray(optimistic_table.to_bytes())
    if damage == "flipped byte":
        blob[len(blob) // 2] ^= 0x40
    elif damage == "truncated":
        blob = blob[: len(blob) // 2]
    elif damage == "not a table":
        blob = bytearray(b"CDF\x01" + bytes(2000))
    else:
        g = running
        blob = bytearray(_plan(synthetic_forecast, Goal(lon_deg=g.goal_lon_deg - 0.05, lat_deg=g.goal_lat_deg,
                                                        depth_m=0.0)).to_bytes())
    conn = live.ground_station()
    try:
        with pytest.raises(LrauvError, match="refused by the vehicle") as error:
            put_file(conn, bytes(blob), "/tables/bad.lrpt", timeout_s=2.0)
    finally:
        conn.close()
    before = live.executive._counts["decisions"]
    assert live.wait(lambda: live.executive._counts["decisions"] > before + 10, 10.0)
    assert live.executive.table is running and live.executive.swaps == []
    live.stop()
    refused = [r for r in _policy(live.executive.config.log_path) if r["reason"] == "refused"]
    assert len(refused) == 1 and refused[0]["refusal"]
    # The reason reaches the ground station whole (STATUSTEXT chunks, joined), not cut at 50 characters.
    said = f"{refused[0]['refusal']}; the running plan goes on"
    assert len(said) > 50 and str(error.value).endswith(f"(TerminateSession NAK Fail): {said}"), str(error.value)


def test_bad_mission_items_are_refused_and_the_running_plan_goes_on(live):
    running = live.executive.plan
    mission = load_mission(DEMO)
    items = list(goals_to_items(mission.goals, home_lat_deg=33.4, home_lon_deg=-117.8))
    items[1] = replace(items[1], command=22)  # NAV_TAKEOFF is not a goal
    conn = live.ground_station()
    try:
        with pytest.raises(LrauvError, match="22"):
            upload_goals(conn, items)
    finally:
        conn.close()
    assert live.executive.plan is running and live.executive.staged is None


def test_a_new_forecast_in_the_watched_directory_is_planned_off_loop_and_swapped_in(live, tmp_path):
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    running = live.executive.table
    inbox = tmp_path / "inbox"
    inbox.mkdir(exist_ok=True)
    staging = tmp_path / "issue1.nc"
    write_synthetic(staging, SyntheticSettings(seed=0, hours=24), issue_number=1)
    os.replace(staging, inbox / "issue1.nc")  # appears whole, as a forecast feed should deliver it
    # An onboard plan is a child process: seconds on a quiet machine, a minute or more on a busy one. The
    # wait ends at the swap; its limit is the rig's safety net, not a deadline.
    assert live.wait(lambda: live.executive.swaps, WALL_LIMIT_S), "no swap after a new forecast"
    swap = live.executive.swaps[-1]
    assert swap["source"] == "onboard plan (new forecast issue1.nc)"
    assert swap["previous"]["table_crc32"] == f"{running.crc32:08x}" and swap["table_crc32"] != swap["previous"]["table_crc32"]
    assert swap["forecast_identity"] != running.forecast_identity
    live.stop()
    # The old plan ran while the new one was computed: decisions between the request and the swap.
    log = live.executive.config.log_path
    asked = [t for _topic, t, p in read_messages(log, ["/log"]) if p["message"].startswith("planning goal 0 onboard")]
    during = [t for _topic, t, _p in read_messages(log, ["/executive/decision"]) if asked[0] < t < swap["time_s"]]
    assert len(asked) == 1 and len(during) > 10, (asked, len(during))


def _events(log: Path) -> list[str]:
    return [payload["message"] for _topic, _t, payload in read_messages(log, ["/log"])]


# Around the goal only (a table whose goal is outside the fence is refused): the vehicle starts 3 cells west, outside.
FAR_FENCE = ((-117.815, 33.385), (-117.785, 33.385), (-117.785, 33.415), (-117.815, 33.415))


@pytest.mark.parametrize(("limits", "start_depth_m", "situation", "mode"), [
    ({"geofence": FAR_FENCE}, 0.0, "outside the geofence", SubMode.SURFACE),
    ({"geofence": FAR_FENCE, "on_breach": "drift"}, 0.0, "outside the geofence", SubMode.ALT_HOLD),
    ({"max_mission_time_s": 120.0}, 0.0, "exceeds max_mission_time_h", SubMode.SURFACE),
    ({"min_battery_pct": 99.8}, 0.0, "under min_battery_pct", SubMode.SURFACE),
    # the demo table's layers reach 15 m: a tighter limit would refuse the table itself (executive.envelope)
    ({"max_depth_m": 15.0, "on_breach": "hold"}, 18.0, "exceeds max_depth_m", SubMode.GUIDED),
])
def test_each_safety_limit_fires_its_action_on_the_vehicle(demo_plan, synthetic_forecast, tmp_path, limits,
                                                           start_depth_m, situation, mode):
    table = demo_plan.table
    mission = load_mission(DEMO)
    plan = goal_tables.MissionPlan(goals=mission.goals, tables=(table,))
    rig = Live(synthetic_forecast, plan, tmp_path / "exec.mcap", start=start_west_of_goal(table), start_depth_m=start_depth_m,
               **limits)
    try:
        assert rig.wait(lambda: rig.executive.helm.phase is Phase.SAFE, 60.0), "the limit never fired"
        # SURFACE completes as ArduSub's does: ALT_HOLD once at the surface (mode reason SURFACE_COMPLETE).
        done = (mode, SubMode.ALT_HOLD) if mode is SubMode.SURFACE else (mode,)
        assert rig.wait(lambda: rig.sim.mode in done, 20.0), f"the vehicle is in {rig.sim.mode}, not {mode}"
    finally:
        rig.stop()
    events = _events(tmp_path / "exec.mcap")
    assert any(situation in e and "plan suspended" in e for e in events), events


@pytest.mark.parametrize("second_table", ["planned on shore", "planned onboard"])
def test_a_two_goal_mission_reaches_both_goals_in_order(demo_plan, synthetic_forecast, tmp_path, second_table):
    first = demo_plan.table
    mission = load_mission(DEMO)
    lon, lat = start_west_of_goal(first, 2)
    second_goal = Goal(lon_deg=lon, lat_deg=lat, depth_m=0.0)  # back where the vehicle started
    second = _plan(synthetic_forecast, second_goal) if second_table == "planned on shore" else None
    goals = (replace(mission.goals[0], on_arrival="next"), replace(mission.goals[0], goal=second_goal, on_arrival="hold"))
    plan = goal_tables.MissionPlan(goals=goals, tables=(first, second))
    # At 1000x the simulator's 5 s heartbeat failsafe is 5 ms of wall time; in lockstep (the rig's default)
    # the vehicle waits for the executive, also while it plans goal 1 onboard, so it stays on.
    rig = Live(synthetic_forecast, plan, tmp_path / "exec.mcap", start=(lon, lat), exit_on_arrival=True, speedup=1000.0)
    summary = rig.join()
    assert summary.reached and rig.executive.plan.index == 1
    events = _events(tmp_path / "exec.mcap")
    on_to = [n for n, e in enumerate(events) if "goal 0 reached: on to goal 1" in e]
    arrived = [n for n, e in enumerate(events) if e.startswith("goal reached")]
    assert len(on_to) == 1 and len(arrived) == 2 and arrived[0] < on_to[0] < arrived[1]
    sources = [w["source"] for w in rig.executive.swaps]
    if second is None:  # planned when goal 0 was reached, while the vehicle held there
        assert sources == ["onboard plan (next goal)", "next goal"]
        assert any("planning goal 1 onboard, holding" in e for e in events[arrived[0]:on_to[0]])
    else:
        assert sources == ["next goal"]


def test_a_forecast_uploaded_by_ftp_is_planned_onboard_and_swapped_in(live, tmp_path):
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    running = live.executive.table
    blob = write_synthetic(tmp_path / "issue1.nc", SyntheticSettings(seed=0, hours=24), issue_number=1).read_bytes()
    conn = live.ground_station()
    try:
        put_file(conn, blob, "/forecasts/issue1.nc", timeout_s=2.0)
    finally:
        conn.close()
    assert live.wait(lambda: live.executive.swaps, WALL_LIMIT_S), "no swap after an uploaded forecast"  # planned onboard
    swap = live.executive.swaps[-1]
    assert swap["source"] == "onboard plan (new forecast issue1.nc)" and swap["forecast_identity"] != running.forecast_identity
    assert (live.executive.config.work_dir / "forecasts" / "issue1.nc").read_bytes() == blob


def test_replanning_on_a_period(demo_plan, synthetic_forecast, tmp_path):
    table = demo_plan.table
    plan = goal_tables.MissionPlan(goals=load_mission(DEMO).goals, tables=(table,))
    rig = Live(synthetic_forecast, plan, tmp_path / "exec.mcap", start=start_west_of_goal(table),
               replan_period_s=600.0)  # 3 s of wall time at 200x
    try:
        # Each onboard plan is a child process: 40 s of wall time each on a busy 2-core machine.
        assert rig.wait(lambda: len(rig.executive.swaps) >= 2, WALL_LIMIT_S), rig.executive.swaps
    finally:
        rig.stop()
    assert [w["source"] for w in rig.executive.swaps[:2]] == ["onboard plan (period)"] * 2
