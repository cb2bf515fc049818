"""A pilot who takes the simulated vehicle over keeps it; a mission upload hands it back, over real UDP.

The pilot is a ground station on the simulator's own port (system 255, as ArduSub expects a
GCS), switching the vehicle to MANUAL as a person with a joystick would. The executive must
leave it there for as long as nobody says otherwise, and resume when a mission is uploaded.
"""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from executive import goal_tables
from executive.state import Phase
from planner.contract.mission import goals_to_items, load_mission
from planner.contract.modes import SubMode
from planner.shore.mission_client import upload_goals
from tests.support.helpers import DEMO_MISSION, start_west_of_goal
from tests.support.live_rig import Live
from vehicle_sim.autopilot import AutopilotSettings

pytestmark = pytest.mark.slow

MAV = mavutil.mavlink


def test_a_pilot_taking_manual_keeps_the_vehicle_until_a_mission_upload(demo_plan, synthetic_forecast, tmp_path):
    table = demo_plan.table
    mission = load_mission(DEMO_MISSION)
    plan = goal_tables.MissionPlan(goals=mission.goals, tables=(table,))
    # FS_GCS_ENABLE 0: the pilot's station (system 255) is heard once, and ArduSub's GCS failsafe would
    # otherwise fire 5 s after its last heartbeat.
    live = Live(synthetic_forecast, plan, tmp_path / "exec.mcap", start=start_west_of_goal(table),
                autopilot=AutopilotSettings(heartbeat_timeout_s=0.0))
    pilot = mavutil.mavlink_connection(f"udpout:127.0.0.1:{live.sim.port}", source_system=255, source_component=190)
    try:
        assert live.wait(live.running), "the executive did not start following the plan"
        pilot.mav.heartbeat_send(MAV.MAV_TYPE_GCS, MAV.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        pilot.mav.command_long_send(1, 1, MAV.MAV_CMD_DO_SET_MODE, 0, MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                    int(SubMode.MANUAL), 0, 0, 0, 0, 0)
        assert live.wait(lambda: live.executive.helm.phase is Phase.OVERRIDDEN, 30.0), live.executive.helm.phase
        t0 = live.sim.time_s
        assert live.wait(lambda: live.sim.time_s > t0 + 60.0, 30.0)  # a vehicle minute later: still the pilot's
        assert live.sim.mode is SubMode.MANUAL and live.executive.helm.phase is Phase.OVERRIDDEN
        gcs = live.ground_station()
        try:
            upload_goals(gcs, goals_to_items(mission.goals, home_lat_deg=33.4, home_lon_deg=-117.8))
        finally:
            gcs.close()
        assert live.wait(lambda: live.sim.mode is SubMode.GUIDED and live.running(), 30.0), live.sim.mode
    finally:
        pilot.close()
        live.stop()  # also audits the decisions, the override and the resume included
