"""A person, a ground station or an autopilot failsafe that takes over wins; the safety stop is final.

Over real UDP with a scripted autopilot (tests/support/scripted_autopilot.py): the vehicle is
armed in GUIDED, following the plan; then something the executive did not command happens.
The executive must stop commanding (heartbeats go on), say so in the log and by STATUSTEXT,
and resume only on MAV_CMD_MISSION_START from an operator. A safety stop holds across an
autopilot reboot and a restart (``--resume``) until MAV_CMD_MISSION_START clears it.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from executive import durable
from executive import mission_protocol as mp
from executive.helm import HelmConfig
from executive.recorder import Topic
from executive.state import Phase, Situation
from planner.contract.actions import Action
from planner.contract.mission import goals_to_items
from planner.contract.modes import SubMode
from planner.shore.replay.divelog import open_dive
from tests.support.helpers import assert_audit_clean
from tests.support.scripted_autopilot import Stepped

MAV = mavutil.mavlink
COMMANDS = ("COMMAND_LONG", "SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT")


class Dive:
    """The vehicle at a FORWARD state's cell, position and attitude every 0.5 s, a heartbeat every second."""

    def __init__(self, table, log: Path, helm: HelmConfig | None = None, **executive) -> None:  # type: ignore[no-untyped-def]
        self.rig = Stepped(table, log, helm=helm, **executive)
        self.ap = self.rig.ap
        states = np.argwhere(table.actions == int(Action.FORWARD))
        l, j, i, k = (int(x) for x in states[len(states) // 2])
        self.lat, self.lon = table.cell_centre(j, i)
        self.depth = float(table.depth_m[l])
        self.heading = table.bearing_deg(j, k)
        self.sent: list = []  # type: ignore[type-arg]

    def seconds(self, n: int, *, depth_m: float | None = None, status: int = MAV.MAV_STATE_ACTIVE) -> list:  # type: ignore[type-arg]
        """``n`` vehicle seconds of telemetry; what the executive sent meanwhile."""
        out = []
        for _ in range(n):
            self.ap.heartbeat(status)
            self.ap.ekf(position_ok=True)  # as ArduSub streams it (positions are used only with its flag)
            for _ in range(2):
                self.ap.position(self.lat, self.lon, self.depth if depth_m is None else depth_m, self.heading, dt_ms=500)
                self.ap.attitude(math.radians(self.heading))
                out += self.rig.pump()
        self.sent += out
        return out

    def mission_start(self) -> list:  # type: ignore[type-arg]
        self.rig.send_as_gcs(self.rig.gcs.command_long_encode(1, 191, MAV.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0))
        return self.rig.pump()

    def upload_mission(self) -> mp.MissionResult | None:
        """The running goals uploaded again by the mission protocol, as a ground station behind the autopilot would."""
        goals = self.rig.executive.plan.goals
        sender = mp.MissionSender((1, 191))
        outs = sender.start(goals_to_items(goals, home_lat_deg=self.lat, home_lon_deg=self.lon), 0.0)
        for _ in range(20):
            for out in outs:
                self.rig.send_as_gcs(mp.encode(self.rig.gcs, out))
            outs = ()
            for msg in self.rig.pump():
                if msg.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                    outs += sender.on_request(int(msg.seq), 0.0)
                elif msg.get_type() == "MISSION_ACK":
                    outs += sender.on_ack(int(msg.type), 0.0)
            if sender.done:
                return sender.result
        return None

    def close(self) -> list[str]:
        self.rig.close()
        return [m.payload["message"] for m in open_dive(self.rig.log_path).messages([Topic.LOG])]


def _commands(sent: list) -> list:  # type: ignore[type-arg]
    return [m for m in sent if m.get_type() in COMMANDS]


def test_a_mission_upload_ends_an_override(demo_plan, tmp_path):
    d = Dive(demo_plan.table, tmp_path / "exec.mcap")
    try:
        d.seconds(3)
        d.ap.mode = SubMode.MANUAL
        d.seconds(3)
        assert d.rig.executive.helm.phase is Phase.OVERRIDDEN
        assert d.upload_mission() is mp.MissionResult.ACCEPTED
        d.seconds(3)
        assert d.rig.executive.helm.phase is Phase.RUNNING and d.ap.mode is SubMode.GUIDED
    finally:
        events = d.close()
    assert any(e.startswith("operator resume: override ended by a mission upload") for e in events), events
    assert_audit_clean(d.rig.log_path)


@pytest.mark.parametrize("takeover", ["MANUAL by a pilot", "disarmed", "autopilot failsafe"])
def test_the_executive_yields_to_what_it_did_not_command_until_mission_start(demo_plan, tmp_path, takeover):
    d = Dive(demo_plan.table, tmp_path / "exec.mcap")
    try:
        d.seconds(3)
        assert d.rig.executive.helm.phase is Phase.RUNNING and _commands(d.sent)
        status = MAV.MAV_STATE_ACTIVE
        if takeover == "MANUAL by a pilot":
            d.ap.mode = SubMode.MANUAL
        elif takeover == "disarmed":
            d.ap.armed = False
        else:
            d.ap.mode, status = SubMode.SURFACE, MAV.MAV_STATE_CRITICAL
        after = d.seconds(20, status=status)
        assert d.rig.executive.helm.phase is Phase.OVERRIDDEN
        assert _commands(after) == []  # no mode, no arming, no target: the takeover stands
        assert [m for m in after if m.get_type() == "HEARTBEAT"]  # heartbeats go on
        texts = [m.text for m in after if m.get_type() == "STATUSTEXT"]
        assert any(t.startswith("overridden") for t in texts), texts
        replies = d.mission_start()
        acks = [m for m in replies if m.get_type() == "COMMAND_ACK"]
        assert [(a.command, a.result) for a in acks] == [(MAV.MAV_CMD_MISSION_START, MAV.MAV_RESULT_ACCEPTED)]
        resumed = d.seconds(3)
        assert d.ap.mode is SubMode.GUIDED and d.ap.armed and d.rig.executive.helm.phase is Phase.RUNNING
        assert _commands(resumed)
    finally:
        events = d.close()
    assert sum(e.startswith("overridden:") for e in events) == 1, events
    assert any(e.startswith("operator resume: override ended by MAV_CMD_MISSION_START from 255/190") for e in events)
    assert_audit_clean(d.rig.log_path)


def test_surface_becoming_alt_hold_at_the_surface_is_not_an_override(demo_plan, tmp_path):
    """ArduSub ends SURFACE in ALT_HOLD by itself (mode reason SURFACE_COMPLETE) after the executive asked for it."""
    helm = HelmConfig(cruise_speed_m_s=1.0, max_mission_time_s=2.0)
    d = Dive(demo_plan.table, tmp_path / "exec.mcap", helm=helm)
    try:
        d.seconds(4)  # the mission time runs out: SURFACE is asked for, and obeyed
        assert d.ap.mode is SubMode.SURFACE and d.rig.executive.helm.stop is Situation.MISSION_TIME
        d.ap.mode = SubMode.ALT_HOLD
        d.seconds(3)
        assert d.rig.executive.helm.phase is Phase.SAFE
    finally:
        d.close()


def test_the_safety_stop_holds_across_a_reboot_and_a_restart_until_mission_start(demo_plan, tmp_path):
    helm = HelmConfig(cruise_speed_m_s=1.0, max_depth_m=20.0)
    state_dir = tmp_path / "state"
    d = Dive(demo_plan.table, tmp_path / "exec.mcap", helm=helm, state_dir=state_dir)
    try:
        d.seconds(2)
        d.seconds(8, depth_m=21.0)  # 1 m too deep for longer than the 5 s window
        assert d.rig.executive.helm.stop is Situation.TOO_DEEP and d.ap.mode is SubMode.SURFACE
        d.ap.time_ms, d.ap.mode, d.ap.armed = 1_000, SubMode.MANUAL, False  # the autopilot reboots
        after = d.seconds(6)
        assert d.rig.executive.clock.reboots == 1
        assert d.rig.executive.helm.phase is Phase.SAFE and d.ap.mode is SubMode.SURFACE
        assert d.upload_mission() is mp.MissionResult.ACCEPTED  # an upload does not clear the stop
        after += d.seconds(3)
        assert d.rig.executive.helm.phase is Phase.SAFE and d.ap.mode is SubMode.SURFACE
        assert not any(m.get_type() == "COMMAND_LONG" and m.command == MAV.MAV_CMD_DO_SET_MODE
                       and int(m.param2) == SubMode.GUIDED for m in after)
    finally:
        events = d.close()
    assert any("safety stop (too_deep) holds until an operator clears it" in e for e in events), events
    assert_audit_clean(d.rig.log_path)
    # A restart from the saved state: the stop holds there too, until MISSION_START.
    saved = durable.load(state_dir)
    assert saved.safety_stop == "too_deep"
    again = Dive(saved.plan.table, tmp_path / "again.mcap", helm=helm, safety_stop=Situation(saved.safety_stop))
    try:
        again.seconds(3)
        assert again.rig.executive.helm.phase is Phase.SAFE and again.ap.mode is SubMode.SURFACE
        again.mission_start()
        again.seconds(3)
        assert again.rig.executive.helm.phase is Phase.RUNNING and again.ap.mode is SubMode.GUIDED
    finally:
        events = again.close()
    assert any("safety stop (too_deep) cleared by MAV_CMD_MISSION_START" in e for e in events), events
    assert durable.load(state_dir).safety_stop == "too_deep"  # the second run had no state dir of its own
    assert_audit_clean(again.rig.log_path)


def test_a_link_lost_while_overridden_commands_nothing():
    """The person or failsafe that took over keeps the vehicle through a silence: no on_breach mode is asked for."""
    from executive.helm import HelmState, step
    from executive.state import VehicleState

    config = HelmConfig(on_breach="surface")
    helm = HelmState(phase=Phase.OVERRIDDEN, overridden="the autopilot's mode became MANUAL (from GUIDED), not asked for",
                     seen_mode=int(SubMode.MANUAL), seen_armed=True)
    events = []
    for t in range(40, 100, 2):
        tick = step(helm, VehicleState(time_s=float(t), mode=int(SubMode.MANUAL), armed=True), None, config,
                    now_s=float(t), link_ok=False)
        assert tick.commands == () and tick.helm.phase is Phase.OVERRIDDEN
        helm, events = tick.helm, events + [e.text for e in tick.events]
    assert [e.split(":")[0] for e in events] == ["link lost while overridden"]
    back = step(helm, VehicleState(time_s=101.0, mode=int(SubMode.MANUAL), armed=True, heartbeat_s=101.0), None, config,
                now_s=101.0, link_ok=True)
    assert back.helm.phase is Phase.OVERRIDDEN and back.commands == () and not back.helm.silent
    assert [e.text.split(";")[0] for e in back.events] == ["link regained"]


def test_a_safety_stop_surfaces_without_a_position_after_a_reboot_underwater():
    """After a reboot the EKF has no position (no GPS under water); SURFACE needs none, so the stop asks for it at once."""
    from executive.helm import HelmState, rebooted, step
    from executive.state import SetMode, VehicleState

    helm = rebooted(HelmState(phase=Phase.SAFE, stop=Situation.TOO_DEEP))
    vehicle = VehicleState(time_s=3.0, mode=int(SubMode.MANUAL), armed=False, heartbeat_s=3.0, ekf_reported=True,
                           depth_m=40.0)
    tick = step(helm, vehicle, None, HelmConfig(on_breach="surface"), now_s=3.0, link_ok=True)
    assert tick.helm.phase is Phase.SAFE and SetMode(SubMode.SURFACE) in tick.commands
    assert any("safety stop (too_deep) holds" in e.text for e in tick.events)
    # With on_breach hold the stop needs a position to hold: it waits for the EKF's.
    held = step(helm, vehicle, None, HelmConfig(on_breach="hold"), now_s=3.0, link_ok=True)
    assert held.helm.phase is Phase.SETUP and not [c for c in held.commands if isinstance(c, SetMode)]
