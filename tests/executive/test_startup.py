"""Start-up and SURFACE as ArduSub runs them, over real UDP with a scripted autopilot.

The script is ArduSub SITL as observed (research facts, "Observed again with the project's
executive"): before its GPS is found (9 s) it sends GLOBAL_POSITION_INT with lat = lon = 0; its
EKF has an absolute horizontal position (EKF_POS_HORIZ_ABS) only at 41 s; it accepts arming in
MANUAL at any time but refuses GUIDED before then (COMMAND_ACK FAILED, "Mode change failed:
GUIDED requires position"); SURFACE ascends at about 1 m/s and, once at the surface, switches
itself to ALT_HOLD (mode reason SURFACE_COMPLETE). On a serial or TCP link it first writes boot
text, which pymavlink's robust parser returns as BAD_DATA.

Everything is stepped (``Stepped``): each datagram is handled before the next is sent, and time
is the script's vehicle time, so no outcome depends on the machine's speed.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from executive.helm import HelmConfig  # noqa: E402
from executive.mode_requests import Progress, progress  # noqa: E402
from executive.recorder import Topic  # noqa: E402
from executive.state import Phase, VehicleState  # noqa: E402
from planner.contract.actions import Action  # noqa: E402
from planner.contract.modes import SubMode  # noqa: E402
from planner.shore.replay.divelog import open_dive  # noqa: E402
from tests.support.helpers import assert_audit_clean  # noqa: E402
from tests.support.scripted_autopilot import Stepped  # noqa: E402

MAV = mavutil.mavlink
GPS_FOUND_S = 9.0  # ArduSub SITL: lat = lon = 0 before this
EKF_POSITION_S = 41.0  # ArduSub SITL: EKF_POS_HORIZ_ABS from this on; GUIDED refused before
AT_SURFACE_M = 0.15  # ArduSub's surface detector (SURFACE_DEPTH -10 cm, plus 5 cm)
HELM = HelmConfig(cruise_speed_m_s=1.0, on_arrival="hold")


@dataclass(frozen=True)
class Sent:
    time_s: float  # the script's vehicle time when the executive sent it
    msg: Any

    @property
    def request(self) -> str | None:
        """'ARM', or the mode asked for by DO_SET_MODE; None for anything else."""
        if self.msg.get_type() != "COMMAND_LONG":
            return None
        if self.msg.command == MAV.MAV_CMD_COMPONENT_ARM_DISARM:
            return "ARM" if self.msg.param1 == 1 else "DISARM"
        if self.msg.command == MAV.MAV_CMD_DO_SET_MODE:
            return SubMode(int(self.msg.param2)).name
        return None


class ArduSub:
    """ArduSub's start-up and SURFACE (module docstring), scripted at 2 Hz behind a stepped executive."""

    def __init__(self, table, log: Path, *, helm: HelmConfig = HELM, boot_s: float, depth_m: float | None = None,  # type: ignore[no-untyped-def]
                 layer: int | None = None, ekf_every_s: float | None = 5.0, ready: bool = False) -> None:
        """``boot_s``: the vehicle time at which the executive first hears it; ``ready``: already armed in GUIDED with
        its EKF's position (the executive started after the autopilot). ``ekf_every_s``: EKF_STATUS_REPORT's
        interval (the executive asks for 5 s), None for an autopilot that never sends it."""
        self.rig = Stepped(table, log, helm=helm, ekf_ready=ready)
        self.ap = self.rig.ap
        if not ready:
            self.ap.mode, self.ap.armed = SubMode.MANUAL, False
        states = np.argwhere(table.actions == int(Action.FORWARD))
        if layer is not None:
            states = states[states[:, 0] == layer]
        l, j, i, k = (int(x) for x in states[len(states) // 2])
        self.lat, self.lon = table.cell_centre(j, i)
        self.heading = table.bearing_deg(j, k)
        self.depth = float(table.depth_m[l]) if depth_m is None else depth_m
        self.ekf_every_s = ekf_every_s
        self.ready = ready
        self.t_s = boot_s
        self.sent: list[Sent] = []
        self.refused = 0  # GUIDED requests refused for want of a position
        self.ap.time_ms = round(boot_s * 1000)
        self.ap.heartbeat()  # heard first
        self.pump()

    def run(self, until_s: float) -> None:
        """Telemetry every 0.5 s up to ``until_s``: heartbeat each second, EKF status at its interval."""
        while self.t_s < until_s:
            self.t_s = round(self.t_s + 0.5, 3)
            self.ap.time_ms = round(self.t_s * 1000)
            self._move(0.5)
            if self.t_s % 1.0 == 0:
                self.ap.heartbeat()
            if self.ekf_every_s is not None and self.t_s % self.ekf_every_s == 0:
                self.ap.ekf(position_ok=self.ready or self.t_s >= EKF_POSITION_S)
            fix = self.ready or self.t_s >= GPS_FOUND_S
            self.ap.position(self.lat if fix else 0.0, self.lon if fix else 0.0, self.depth, self.heading, dt_ms=0)
            self.pump()
            self.ap.attitude(math.radians(self.heading))
            self.pump()

    def _move(self, dt_s: float) -> None:
        if self.ap.mode is SubMode.SURFACE:
            self.depth = max(AT_SURFACE_M / 2, self.depth - 1.0 * dt_s)  # ArduSub's ascent, about 1 m/s
            if self.depth <= AT_SURFACE_M:
                self.ap.mode = SubMode.ALT_HOLD  # mode reason SURFACE_COMPLETE

    def pump(self) -> list[Sent]:
        """What the executive sent for the last message; its mode and arming requests answered as ArduSub does."""
        mode, armed = self.ap.mode, self.ap.armed
        sent = [Sent(self.t_s, m) for m in self.rig.pump()]
        self.ap.mode, self.ap.armed = mode, armed  # the stepped rig obeys everything: ArduSub does not
        for s in sent:
            if s.request == "GUIDED" and not (self.ready or self.t_s >= EKF_POSITION_S):
                self.refused += 1
                self.ap.conn.mav.command_ack_send(MAV.MAV_CMD_DO_SET_MODE, MAV.MAV_RESULT_FAILED)
                self.ap.conn.mav.statustext_send(MAV.MAV_SEVERITY_WARNING, b"Mode change failed: GUIDED requires position")
            elif s.request in ("GUIDED", "ALT_HOLD", "SURFACE", "MANUAL"):
                self.ap.mode = SubMode[s.request]
                self.ap.conn.mav.command_ack_send(MAV.MAV_CMD_DO_SET_MODE, MAV.MAV_RESULT_ACCEPTED)
            elif s.request == "ARM":  # accepted in MANUAL before the EKF has initialised
                self.ap.armed = True
                self.ap.conn.mav.command_ack_send(MAV.MAV_CMD_COMPONENT_ARM_DISARM, MAV.MAV_RESULT_ACCEPTED)
            elif s.msg.get_type() == "COMMAND_LONG" and s.msg.command == MAV.MAV_CMD_SET_MESSAGE_INTERVAL:
                self.ap.conn.mav.command_ack_send(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, MAV.MAV_RESULT_ACCEPTED)
        self.sent += sent
        return sent

    def requests(self) -> list[Sent]:
        return [s for s in self.sent if s.request is not None]

    def close(self) -> tuple[list[dict], list[tuple[int, str]]]:  # type: ignore[type-arg]
        """The logged decisions and (level, text) events."""
        self.rig.close()
        dive = open_dive(self.rig.log_path)
        decisions = [m.payload for m in dive.messages([Topic.DECISION])]
        events = [(m.payload["level"], m.payload["message"]) for m in dive.messages([Topic.LOG])]
        return decisions, events


def _spaced(requests: list[Sent], retry_s: float) -> bool:
    """No request (the same mode, or arming) went out twice within ``retry_s``."""
    last: dict[str, float] = {}
    for s in requests:
        assert s.request is not None
        if s.request in last and s.time_s - last[s.request] < retry_s:
            return False
        last[s.request] = s.time_s
    return True


_WARNING = 3  # foxglove.Log level WARNING (INFO 2)


def test_nothing_is_armed_or_asked_for_before_the_ekf_has_an_absolute_position(demo_plan, tmp_path):
    # The companion computer boots after the autopilot: it first hears ArduSub 6 s after ArduSub's boot,
    # sees 0, 0 until the GPS is found, then GPS positions long before the EKF vouches for them.
    s = ArduSub(demo_plan.table, tmp_path / "exec.mcap", boot_s=6.0)
    try:
        s.run(EKF_POSITION_S - 0.5)
        assert s.requests() == [] and s.ap.mode is SubMode.MANUAL and not s.ap.armed
        assert s.rig.executive.helm.phase is Phase.SETUP
        s.run(EKF_POSITION_S + 10.0)
        assert s.rig.executive.helm.phase is Phase.RUNNING and s.ap.mode is SubMode.GUIDED and s.ap.armed
    finally:
        decisions, events = s.close()
    first = {r.request: r.time_s for r in reversed(s.requests())}
    assert first["GUIDED"] >= EKF_POSITION_S and first["ARM"] >= EKF_POSITION_S, first
    assert s.refused == 0  # never "GUIDED requires position"
    assert _spaced(s.requests(), HELM.retry_s)
    assert decisions and all(d["time_s"] >= EKF_POSITION_S for d in decisions)
    assert not any(d["lat_deg"] == 0.0 and d["lon_deg"] == 0.0 for d in decisions)
    waiting = [text for _, text in events if text.startswith("set-up: waiting for")]
    assert waiting == [  # said once per thing waited for, not every tick
        "set-up: waiting for the EKF's absolute position (no EKF_STATUS_REPORT from the autopilot yet)"
        " before arming and asking for GUIDED",
        "set-up: waiting for the EKF's absolute position (EKF_STATUS_REPORT without EKF_POS_HORIZ_ABS)"
        " before arming and asking for GUIDED"], waiting
    # ArduSub starting up is no fault: no warning from the executive's own checks (0, 0, positions without the flag).
    assert not [text for level, text in events if level >= _WARNING and "dropped" in text], events
    assert_audit_clean(s.rig.log_path)


def test_an_autopilot_that_never_reports_its_ekf_is_waited_for_with_one_warning(demo_plan, tmp_path):
    helm = HelmConfig(cruise_speed_m_s=1.0, position_timeout_s=20.0)
    s = ArduSub(demo_plan.table, tmp_path / "exec.mcap", helm=helm, boot_s=60.0, ekf_every_s=None)
    try:
        s.run(130.0)  # GPS positions for 70 s, and no EKF_STATUS_REPORT
        assert s.rig.executive.helm.phase is Phase.SETUP
    finally:
        decisions, events = s.close()
    assert s.requests() == [] and decisions == []
    warned = [text for level, text in events if level >= _WARNING]
    assert warned == [
        "not started: waited 20 s for the EKF's absolute position (no EKF_STATUS_REPORT from the autopilot yet);"
        " the executive arms and asks for GUIDED only once the autopilot's EKF reports an absolute horizontal"
        " position (EKF_POS_HORIZ_ABS)"], events


def test_surface_is_asked_once_and_complete_at_the_surface_whatever_mode_follows(demo_plan, tmp_path):
    helm = HelmConfig(cruise_speed_m_s=1.0, max_mission_time_s=10.0)  # on_breach surface after 10 s
    s = ArduSub(demo_plan.table, tmp_path / "exec.mcap", helm=helm, boot_s=100.0, ready=True)
    try:
        s.run(220.0)  # the ascent takes seconds; then 100 s at the surface in ALT_HOLD
        helm_state = s.rig.executive.helm
        assert helm_state.phase is Phase.SAFE and helm_state.overridden is None
    finally:
        decisions, events = s.close()
    surface = [r for r in s.requests() if r.request == "SURFACE"]
    assert len(surface) == 1, [r.time_s for r in surface]
    assert s.ap.mode is SubMode.ALT_HOLD and s.depth <= AT_SURFACE_M  # ArduSub ended SURFACE by itself
    assert [r.request for r in s.requests()] == ["SURFACE"]  # nor ALT_HOLD, GUIDED or arming asked after it
    assert [text for _, text in events if text.startswith("at the surface")] == [
        "at the surface: SURFACE complete (the autopilot reports SURFACE)"]  # before ArduSub's own 15 cm
    assert not any("overridden" in text for _, text in events)
    assert decisions[-1]["situation"] == "mission_time" and decisions[-1]["mode"] == "SURFACE"
    assert_audit_clean(s.rig.log_path)


def test_surface_asked_at_the_surface_ends_in_alt_hold_at_once_and_that_is_no_override(demo_plan, tmp_path):
    # At the surface in GUIDED: ArduSub enters SURFACE and leaves it for ALT_HOLD before its next HEARTBEAT.
    helm = HelmConfig(cruise_speed_m_s=1.0, max_mission_time_s=5.0)
    s = ArduSub(demo_plan.table, tmp_path / "exec.mcap", helm=helm, boot_s=100.0, ready=True, layer=0, depth_m=0.1)
    try:
        s.run(140.0)
        assert s.rig.executive.helm.phase is Phase.SAFE and s.rig.executive.helm.overridden is None
    finally:
        _, events = s.close()
    assert [r.request for r in s.requests()] == ["SURFACE"]
    assert s.ap.mode is SubMode.ALT_HOLD
    assert not any("overridden" in text for _, text in events), events
    assert_audit_clean(s.rig.log_path)


def test_a_clock_that_steps_back_never_sends_a_request_twice_within_retry_s(demo_plan, tmp_path):
    # Set-up in MANUAL with the EKF's position: a position at 101.0 s brings GUIDED and arming. An ATTITUDE
    # stamped 30 ms earlier then arrives (newer than the last ATTITUDE: not stale) and runs the helm at an
    # earlier vehicle time than the requests; they must not go out again within retry_s.
    s = ArduSub(demo_plan.table, tmp_path / "exec.mcap", boot_s=100.0, ekf_every_s=None)
    s.ready = True  # still MANUAL and disarmed
    try:
        s.ap.ekf(position_ok=True)
        s.ap.time_ms = 100_500
        s.ap.attitude(math.radians(s.heading))
        s.pump()
        s.ap.time_ms = 101_000
        s.ap.position(s.lat, s.lon, s.depth, s.heading, dt_ms=0)
        asked = s.pump()
        assert sorted(r.request for r in asked if r.request) == ["ARM", "GUIDED"]
        s.ap.mode, s.ap.armed = SubMode.MANUAL, False  # neither has taken effect yet
        for ms in (100_970, 101_030):
            s.ap.time_ms = ms
            s.ap.attitude(math.radians(s.heading))
            s.pump()
    finally:
        s.close()
    assert sorted(r.request for r in s.requests()) == ["ARM", "GUIDED"]


def test_boot_text_before_mavlink_is_counted_without_a_word(demo_plan, tmp_path):
    # ArduSub on SERIAL0 writes its banner before MAVLink: about 20 "bad" frames per run.
    banner = [text % n for n in range(7) for text in (b"Init ArduSub V4.7.0-dev (abcdef%02d)\r\n",
                                                       b"\r\nFree RAM: 1874%02d\r\n", b"FMUv5 000000%02d\r\n")]
    s = ArduSub(demo_plan.table, tmp_path / "exec.mcap", boot_s=100.0, ready=True)
    try:
        for line in banner:
            s.ap.conn.write(line)
            s.pump()
        s.run(110.0)
        ex = s.rig.executive
        assert ex.helm.phase is Phase.RUNNING
        bad = ex._summary(0.0).messages_bad
    finally:
        _, events = s.close()
    assert bad >= len(banner)  # counted (the run summary prints it)
    assert not any(m.msg.get_type() == "STATUSTEXT" for m in s.sent)  # nothing said to a ground station
    assert not [text for level, text in events if level >= _WARNING], events


def test_each_mode_has_its_completion_condition():
    """The table in docs/executive.md, "Modes the executive asks for" (executive.mode_requests)."""
    def at(mode: SubMode, depth_m: float = 8.0, armed: bool = True) -> VehicleState:
        return VehicleState(depth_m=depth_m, mode=int(mode), armed=armed)

    def p(asked: SubMode, vehicle: VehicleState, previous: Progress | None = None) -> Progress:
        return progress(asked, vehicle, previous, surface_depth_m=0.5)

    assert p(SubMode.GUIDED, at(SubMode.MANUAL)) is Progress.ASK
    assert p(SubMode.GUIDED, at(SubMode.GUIDED, armed=False)) is Progress.UNDERWAY
    assert p(SubMode.GUIDED, at(SubMode.GUIDED)) is Progress.COMPLETE
    assert p(SubMode.ALT_HOLD, at(SubMode.GUIDED)) is Progress.ASK
    assert p(SubMode.ALT_HOLD, at(SubMode.ALT_HOLD)) is Progress.COMPLETE
    assert p(SubMode.SURFACE, at(SubMode.GUIDED)) is Progress.ASK
    assert p(SubMode.SURFACE, at(SubMode.SURFACE)) is Progress.UNDERWAY
    assert p(SubMode.SURFACE, at(SubMode.SURFACE, depth_m=0.4), Progress.UNDERWAY) is Progress.COMPLETE
    # ArduSub's own end of SURFACE, seen or not; and then whatever it reads, SURFACE is never asked again.
    assert p(SubMode.SURFACE, at(SubMode.ALT_HOLD, depth_m=0.1), Progress.UNDERWAY) is Progress.COMPLETE
    assert p(SubMode.SURFACE, at(SubMode.ALT_HOLD, depth_m=0.1)) is Progress.COMPLETE
    assert p(SubMode.SURFACE, at(SubMode.ALT_HOLD, depth_m=0.7), Progress.COMPLETE) is Progress.COMPLETE
    assert p(SubMode.SURFACE, at(SubMode.MANUAL, depth_m=0.1)) is Progress.ASK  # at the surface, never asked
