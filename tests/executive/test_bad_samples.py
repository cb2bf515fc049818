"""Bad telemetry never decides anything: each fault class, sent once over real UDP, is dropped and logged.

A scripted autopilot (tests/support/scripted_autopilot.py) keeps the vehicle in one water cell
of the demo table, armed in GUIDED, and slips one bad sample in among good ones: a position
at 0, 0 (no fix), a 50 km jump, a 100 m depth reading, a battery reading of 0, a NaN yaw, a
time_boot_ms a day ahead, and the 32-bit wrap of time_boot_ms. The executive must go on
following the plan from the same cell (no surfacing, no safety stop, no reboot). The same
faults held for several samples are believed, and then a limit fires as it should.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from executive.helm import HelmConfig
from executive.plausibility import WRAP_S, BootTime, Gate, Limits, screen, stamp
from executive.recorder import Topic
from executive.state import Situation, VehicleState
from planner.contract.actions import Action
from planner.shore.replay.divelog import open_dive
from tests.support.helpers import assert_audit_clean
from tests.support.scripted_autopilot import Stepped

HELM = HelmConfig(cruise_speed_m_s=1.0, max_depth_m=20.0, min_battery_pct=10.0, position_timeout_s=5.0)


def _forward_state(table) -> tuple[int, int, int, int]:  # type: ignore[no-untyped-def]
    states = np.argwhere(table.actions == int(Action.FORWARD))
    return tuple(int(x) for x in states[len(states) // 2])  # type: ignore[return-value]


class Script:
    """The vehicle sitting at one FORWARD state's cell centre, sending position and attitude every 0.5 s."""

    def __init__(self, table, log: Path, helm: HelmConfig = HELM, start_ms: int = 50_000) -> None:  # type: ignore[no-untyped-def]
        self.rig = Stepped(table, log, helm=helm)
        self.ap = self.rig.ap
        self.ap.time_ms = start_ms
        l, j, i, k = self.state = _forward_state(table)
        self.lat, self.lon = table.cell_centre(j, i)
        self.depth = float(table.depth_m[l])
        self.heading = table.bearing_deg(j, k)
        self.ap.heartbeat()
        self.ap.battery(80)
        self.good(4)

    def good(self, n: int = 1) -> None:
        for _ in range(n):
            self.send(self.lat, self.lon, self.depth)

    def send(self, lat: float, lon: float, depth: float, dt_ms: int = 500) -> None:
        self.ap.position(lat, lon, depth, self.heading, dt_ms=dt_ms)
        self.rig.pump()
        self.ap.attitude(math.radians(self.heading))
        self.rig.pump()

    def close(self):  # type: ignore[no-untyped-def]
        self.rig.close()
        dive = open_dive(self.rig.log_path)
        decisions = [m.payload for m in dive.messages([Topic.DECISION])]
        events = [m.payload["message"] for m in dive.messages([Topic.LOG])]
        return decisions, events


def _one_of_each(s: Script) -> None:
    ap = s.ap
    s.send(0.0, 0.0, s.depth)  # no fix yet: ArduSub's 0, 0
    s.good(2)
    s.send(s.lat + 0.45, s.lon, s.depth)  # 50 km north in half a second
    s.good(2)
    s.send(s.lat, s.lon, 100.0)  # one 100 m depth reading (max_depth_m is 20)
    s.good(2)
    ap.battery(0)  # one reading of an empty battery (min_battery_pct is 10)
    s.rig.pump()
    ap.battery(79)
    s.good(2)
    ap.attitude(math.nan, dt_ms=100)  # a NaN yaw: never heading east
    s.rig.pump()
    s.good(2)
    ap.time_ms += 86_400_000  # one timestamp a day ahead
    s.good(1)
    ap.time_ms -= 86_400_000
    s.good(3)


def test_one_bad_sample_of_each_kind_is_dropped_and_the_plan_goes_on(demo_plan, tmp_path):
    s = Script(demo_plan.table, tmp_path / "exec.mcap")
    try:
        _one_of_each(s)
        assert s.rig.executive.helm.stop is None and s.rig.executive.helm.phase.value == "running"
    finally:
        decisions, events = s.close()
    assert decisions and all(d["situation"] == "following" and tuple(d["cell"][:3]) == s.state[:3] for d in decisions)
    assert all(d["heading_deg"] is not None and math.isfinite(d["heading_deg"]) for d in decisions)
    dropped = [e for e in events if "dropped" in e]
    for what in ("position 0, 0: no fix", "position sample dropped: a step of 50,", "depth sample dropped: a step of",
                 "battery sample dropped: a step of 80.0 %", "heading nan is not a heading", "ahead of the vehicle clock"):
        assert any(what in e for e in dropped), (what, dropped)
    assert not any("rebooted" in e or "plan suspended" in e for e in events), events
    assert_audit_clean(s.rig.log_path)  # the decision audit screens the samples the same way


def test_the_32_bit_wrap_of_time_boot_ms_is_not_a_reboot(demo_plan, tmp_path):
    s = Script(demo_plan.table, tmp_path / "exec.mcap", start_ms=2**32 - 4_600)
    try:
        s.good(2)  # the last milliseconds before the wrap
        s.ap.time_ms += 2_000 - 2**32  # uint32 milliseconds wrap to 0 after 49.7 days
        s.good(4)
        now_s = s.rig.executive.clock.now_s(0.0)
    finally:
        decisions, events = s.close()
    assert any("wrapped after 49.7 days" in e for e in events), events
    assert not any("rebooted" in e for e in events), events
    assert now_s > WRAP_S and decisions[-1]["time_s"] > WRAP_S
    assert [d["situation"] for d in decisions] == ["following"] * len(decisions)
    assert_audit_clean(s.rig.log_path)


def test_a_fault_that_persists_is_believed_and_a_limit_fires_only_after_its_window(demo_plan, tmp_path):
    s = Script(demo_plan.table, tmp_path / "exec.mcap")
    try:
        s.send(s.lat, s.lon, 22.0)  # deeper than max_depth_m 20, by a step the vehicle cannot make: doubted
        assert s.rig.executive.vehicle.depth_m == pytest.approx(s.depth)
        for _ in range(2):
            s.send(s.lat, s.lon, 22.0)  # the third agreeing sample is believed
        assert s.rig.executive.vehicle.depth_m == pytest.approx(22.0)
        assert s.rig.executive.helm.stop is None  # exceeded, but not yet for breach_window_s (5 s)
        for _ in range(10):
            s.send(s.lat, s.lon, 22.0)
        assert s.rig.executive.helm.stop is Situation.TOO_DEEP
    finally:
        decisions, events = s.close()
    fired = [e for e in events if "exceeds max_depth_m" in e]
    assert fired[0].endswith("on_breach if it lasts 5 s") and "plan suspended" in fired[1], fired
    assert decisions[-1]["situation"] == "too_deep"
    assert_audit_clean(s.rig.log_path)


def test_positions_the_ekf_disowns_are_not_used_and_their_absence_is_a_limit(demo_plan, tmp_path):
    s = Script(demo_plan.table, tmp_path / "exec.mcap")
    try:
        s.ap.ekf(position_ok=False)
        s.rig.pump()
        s.send(s.lat + 0.001, s.lon, s.depth)  # a small move the EKF does not vouch for
        assert s.rig.executive.vehicle.lat_deg == pytest.approx(s.lat)
        s.good(12)  # 6 s without a position the EKF stands by (position_timeout_s 5)
        assert s.rig.executive.helm.stop is Situation.POSITION_LOST
    finally:
        decisions, events = s.close()
    assert any("the EKF reports no absolute horizontal position" in e for e in events)
    assert decisions[-1]["situation"] == "position_lost"
    assert_audit_clean(s.rig.log_path)


def test_a_heading_that_stays_nan_is_unknown_and_nothing_is_steered_by_it(demo_plan, tmp_path):
    s = Script(demo_plan.table, tmp_path / "exec.mcap")
    try:
        for _ in range(4):
            s.ap.attitude(math.nan, dt_ms=250)
            s.rig.pump()
        assert s.rig.executive.vehicle.heading_deg is None
        s.ap.conn.mav.global_position_int_send(s.ap.time_ms + 250, round(s.lat * 1e7), round(s.lon * 1e7),
                                               round(-s.depth * 1000), round(-s.depth * 1000), 0, 0, 0, 65535)
        s.rig.pump()
    finally:
        decisions, events = s.close()
    assert decisions[-1]["situation"] == "no_heading" and decisions[-1]["heading_deg"] is None
    assert any("heading unknown" in e for e in events)


# -- the rules, directly --------------------------------------------------------------------------------


def test_screen_takes_a_change_only_after_persist_samples_agree():
    limits = Limits()
    v0 = VehicleState(time_s=1.0, lat_deg=33.4, lon_deg=-117.8, depth_m=5.0, heading_deg=90.0, battery_pct=80.0,
                      position_ok=True, ekf_reported=True)
    gate = screen(Gate(), VehicleState(), v0, "GLOBAL_POSITION_INT", limits).gate
    v = v0
    kept = []
    for n in range(3):
        jumped = replace(v, time_s=2.0 + n, lat_deg=34.0)
        out = screen(gate, v, jumped, "GLOBAL_POSITION_INT", limits)
        gate, v = out.gate, out.vehicle
        kept.append(v.lat_deg)
    assert kept == [33.4, 33.4, 34.0]
    # Two bad samples that disagree with each other never add up to a change.
    gate = screen(Gate(), VehicleState(), v0, "GLOBAL_POSITION_INT", limits).gate
    v = v0
    for n, lat in enumerate((34.0, 32.0, 34.0, 32.0)):
        out = screen(gate, v, replace(v, time_s=2.0 + n, lat_deg=lat), "GLOBAL_POSITION_INT", limits)
        gate, v = out.gate, out.vehicle
    assert v.lat_deg == 33.4


def test_stamp_drops_a_jump_until_it_persists_and_confirms_a_reboot():
    limits = Limits()
    boot = BootTime()
    one = stamp(boot, 1000.0 + 86_400.0, last_s=1000.0, expected_s=1000.5, rate=1.0, wall_s=0.0, limits=limits)
    assert one.verdict == "drop"
    back = stamp(BootTime(), 2.0, last_s=1000.0, expected_s=1000.5, rate=1.0, wall_s=0.0, limits=limits)
    assert back.verdict == "drop"
    again = stamp(back.boot, 2.5, last_s=1000.0, expected_s=1001.0, rate=1.0, wall_s=0.5, limits=limits)
    third = stamp(again.boot, 3.0, last_s=1000.0, expected_s=1001.5, rate=1.0, wall_s=1.0, limits=limits)
    assert (again.verdict, third.verdict) == ("drop", "reboot")
