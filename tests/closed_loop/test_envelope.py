"""Uploads are checked against the mission's safety section at upload time; wp list returns what is flown.

A simulated vehicle and an executive in threads over real UDP (tests/support/live_rig.py), with
a ground station on the executive's ground-station port using the project's own clients
(mission protocol and MAVLink FTP) and raw pymavlink for MISSION_SET_CURRENT. Every refusal
must reach the ground station (MISSION_ACK or FTP NAK, and STATUSTEXT) and leave the running
plan as it was.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from executive import goal_tables
from executive.envelope import MAX_GOAL_RADIUS_CELLS
from executive.state import Phase
from planner.contract.errors import LrauvError
from planner.contract.mission import goals_to_items, items_to_goals, load_mission
from planner.shore.ftp_client import put_file
from planner.shore.mission_client import download_items, upload_goals
from tests.support.helpers import DEMO_MISSION, start_west_of_goal
from tests.support.live_rig import Live, following

pytestmark = pytest.mark.slow

FENCE = ((-118.35, 33.2), (-117.6, 33.2), (-117.6, 33.8), (-118.35, 33.8))  # around the demo grid


@pytest.fixture()
def two_goal_live(demo_plan, synthetic_forecast, tmp_path):
    """Two goals that the demo table both serves (they differ in on_arrival only), the second one active."""
    table = demo_plan.table
    (goal,) = load_mission(DEMO_MISSION).goals
    goals = (replace(goal, on_arrival="next"), goal)
    plan = goal_tables.MissionPlan(goals=goals, tables=(table, table), index=1)
    rig = Live(synthetic_forecast, plan, tmp_path / "exec.mcap", start=start_west_of_goal(table),
               max_depth_m=20.0, geofence=FENCE)
    with following(rig):
        yield rig


def test_goals_and_tables_outside_the_envelope_are_refused_at_upload(two_goal_live, demo_plan):
    live = two_goal_live
    running = live.executive.plan
    good = running.goals[1]
    conn = live.ground_station()
    try:
        for change, why in [({"depth_m": 10_000.0}, "deeper than max_depth_m 20"),
                            ({"lat_deg": 0.0, "lon_deg": 0.0}, "0, 0 is no goal"),
                            ({"lon_deg": -117.5}, "outside the geofence"),
                            ({"radius_cells": MAX_GOAL_RADIUS_CELLS + 1}, "cells is over")]:
            bad = replace(good, goal=replace(good.goal, **change))
            with pytest.raises(LrauvError, match=why):
                upload_goals(conn, goals_to_items((good, bad), home_lat_deg=33.4, home_lon_deg=-117.8))
        deep = replace(demo_plan.table, depth_m=np.array([0.0, 50.0, 100.0, 300.0]))  # same goal, layers to 300 m
        with pytest.raises(LrauvError):
            put_file(conn, deep.to_bytes(), "/tables/deep.lrpt")
        # What a download returns is what the vehicle is flying: the running goals, the active one marked.
        flown = items_to_goals(download_items(conn))
    finally:
        conn.close()
    assert live.executive.plan is running and live.executive.helm.phase is Phase.RUNNING
    assert flown == running.goals
    live.stop()
    refusals = [r["refusal"] for r in _policy(live) if r["reason"] == "refused"]
    assert any("layers reach 300 m, deeper than max_depth_m 20" in r for r in refusals), refusals
    assert sum(r.startswith("mission:") for r in refusals) == 4, refusals


def test_an_extended_mission_keeps_the_active_goal_and_mission_set_current_moves_it(two_goal_live):
    live = two_goal_live
    running = live.executive.plan
    extra = replace(running.goals[1], goal=replace(running.goals[1].goal, lat_deg=running.goals[1].goal.lat_deg - 0.04))
    conn = live.ground_station()
    try:
        upload_goals(conn, goals_to_items((*running.goals, extra), home_lat_deg=33.4, home_lon_deg=-117.8))
        assert live.wait(lambda: len(live.executive.plan.goals) == 3, 10.0)
        assert live.executive.plan.index == 1  # goal 0 was reached before: it is not flown again
        flown = items_to_goals(download_items(conn))
        conn.mav.mission_set_current_send(1, 191, 1)  # item 1 is goal 0 (item 0 is home)
        current = conn.recv_match(type="MISSION_CURRENT", blocking=True, timeout=10.0)
        assert live.wait(lambda: live.executive.plan.index == 0, 10.0)
        conn.mav.mission_set_current_send(1, 191, 3)  # goal 2 has no table yet: refused, with the reason
        text = conn.recv_match(type="STATUSTEXT", blocking=True, timeout=10.0,
                               condition="'MISSION_SET_CURRENT' in STATUSTEXT.text")
    finally:
        conn.close()
    assert flown == (*running.goals, extra)
    assert current is not None and current.seq == 1
    assert text is not None and "goal 2 has no table" in text.text  # the first 50-byte chunk
    assert live.executive.plan.index == 0


def _policy(live):  # type: ignore[no-untyped-def]
    from executive.recorder import read_messages

    return [p for _topic, _t, p in read_messages(live.executive.config.log_path, ["/executive/policy"])]
