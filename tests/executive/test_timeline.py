"""Time-varying plans in the executive: the slice of the vehicle's UTC time decides, and the log says which.

The pure part (``executive.timeline.follow``) is tested on its own; the loop's part with a real
``Executive`` fed parsed MAVLink messages in this thread (``Executive._on_message``), so the
vehicle's time is the messages' ``time_boot_ms`` and nothing depends on the machine's speed.
"""

from __future__ import annotations

import calendar
import os
import socket
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from executive import timeline  # noqa: E402
from executive.helm import HelmConfig  # noqa: E402
from executive.plausibility import Limits  # noqa: E402
from executive.loop import ExecConfig, Executive  # noqa: E402
from executive.recorder import LogLevel, Topic  # noqa: E402
from planner.contract.actions import Action  # noqa: E402
from planner.contract.modes import SubMode  # noqa: E402
from planner.contract.table import PolicyTable  # noqa: E402
from planner.shore.replay.divelog import open_dive  # noqa: E402

TIMES = ("2026-01-15T00:00:00Z", "2026-01-15T01:00:00Z")
T0 = calendar.timegm(time.strptime(TIMES[0], "%Y-%m-%dT%H:%M:%SZ"))
HORIZON = T0 + 3600.0


def _everywhere(table: PolicyTable, action: Action) -> np.ndarray:
    """``action`` in every water state, UNREACHABLE on land."""
    out = np.full(table.actions.shape, int(Action.UNREACHABLE), dtype=np.uint8)
    out[table.water] = int(action)
    return out


@pytest.fixture(scope="module")
def timed(demo_plan) -> PolicyTable:
    """Two slices an hour apart whose actions differ in every water state: DRIFT, then FORWARD."""
    base = demo_plan.table
    stack = np.stack([_everywhere(base, Action.DRIFT), _everywhere(base, Action.FORWARD)])
    return PolicyTable.from_bytes(base.with_slices(TIMES, stack).to_bytes())


# -- the pure part ----------------------------------------------------------------------------


def test_a_stationary_table_is_its_own_slice_and_says_nothing(demo_plan):
    f = timeline.follow(timeline.Timeline(), demo_plan.table, None)
    assert f.current.table is demo_plan.table and f.current.status == "stationary"
    assert f.events == () and f.timeline == timeline.Timeline()


def test_each_change_of_slice_or_status_is_announced_once(timed):
    seen: list[tuple[int, str, str, str]] = []
    state = timeline.Timeline()
    for unix in (None, None, T0 - 60, T0 + 60, T0 + 1000, T0 + 2000, HORIZON + 1, HORIZON + 500,
                 HORIZON - 1, HORIZON + 2):
        f = timeline.follow(state, timed, unix)
        state = f.timeline
        seen.extend((f.current.index, f.current.status, e.level, e.text) for e in f.events)
    assert [(n, status, level) for n, status, level, _ in seen] == [
        (0, "time_unknown", "warning"), (0, "before_start", "warning"), (0, "in_horizon", "info"),
        (1, "in_horizon", "info"), (1, "past_horizon", "warning"), (1, "in_horizon", "info"),
        (1, "past_horizon", "info"),  # passed again after the clock stepped back: the warning went out once
    ]
    texts = [text for *_, text in seen]
    assert texts[0] == ("UTC unknown: using the first slice's plan (no SYSTEM_TIME with UTC yet;"
                        " first slice 2026-01-15T00:00:00Z)")
    assert texts[1] == ("before the plan's first slice: using the first slice's plan (first slice 2026-01-15T00:00:00Z,"
                        " vehicle UTC 2026-01-14T23:59:00Z)")
    assert texts[3] == "time-varying plan: slice 1 of 2 (2026-01-15T01:00:00Z)"
    assert texts[4] == "past the plan's horizon: using the last slice's plan (last slice 2026-01-15T01:00:00Z)"


def test_another_table_is_announced_afresh(timed, demo_plan):
    first = timeline.follow(timeline.Timeline(), timed, HORIZON + 1)
    other = timed.with_slices(("2026-01-15T00:00:00Z", "2026-01-15T00:30:00Z"), timed.slices)
    again = timeline.follow(first.timeline, other, HORIZON + 1)
    assert [e.level for e in again.events] == ["warning"] and "past the plan's horizon:" in again.events[0].text


# -- the loop -----------------------------------------------------------------------------------


class Vehicle:
    """Parsed MAVLink messages from the autopilot (system 1, component 1), fed to an ``Executive`` here."""

    def __init__(self, table: PolicyTable, log: Path, *, state_dir: Path | None = None, tide=None) -> None:  # type: ignore[no-untyped-def]
        self.sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # where the executive's output goes
        self.sink.bind(("127.0.0.1", 0))
        config = ExecConfig(link=f"udpout:127.0.0.1:{self.sink.getsockname()[1]}", log_path=log, state_dir=state_dir,
                            # The script moves the vehicle's clock on by minutes at once: no jump is doubted here.
                            helm=HelmConfig(limits=Limits(max_clock_jump_s=1e9)))
        self.executive = Executive(config, table, tide=tide)
        self.table = table
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = mavlink.MAVLink(None)
        self.time_ms = 10_000

    def _feed(self, msg) -> None:  # type: ignore[no-untyped-def]
        (parsed,) = self.parser.parse_buffer(msg.pack(self.mav))
        self.executive._on_message(parsed, time.monotonic())
        self.executive._write_later()

    def heartbeat(self) -> None:  # armed in GUIDED: set-up is done at the first position
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        self._feed(self.mav.heartbeat_encode(mavlink.MAV_TYPE_SUBMARINE, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base,
                                             int(SubMode.GUIDED), mavlink.MAV_STATE_ACTIVE))
        # The EKF has its absolute position, as ArduSub streams it (positions are used only then).
        self._feed(self.mav.ekf_status_report_encode(mavlink.EKF_ATTITUDE | mavlink.EKF_POS_HORIZ_ABS, 0, 0, 0, 0, 0))

    def system_time(self, unix_s: float) -> None:
        self._feed(self.mav.system_time_encode(round(unix_s * 1e6), self.time_ms))

    def position(self, dt_s: float = 0.5) -> None:
        """``dt_s`` later, at the centre of the surface water cell nearest the grid's middle, heading east."""
        self.time_ms += round(dt_s * 1000)
        water = np.argwhere(self.table.water[0])
        j, i = (int(x) for x in water[np.argmin(np.hypot(*(water - (self.table.ny // 2, self.table.nx // 2)).T))])
        lat, lon = self.table.cell_centre(j, i)
        depth = self.table.depth_m[0]
        self._feed(self.mav.global_position_int_encode(self.time_ms, round(lat * 1e7), round(lon * 1e7),
                                                       round(-depth * 1000), round(-depth * 1000), 0, 0, 0,
                                                       round(self.table.bearing_deg(j, 0) * 100) % 36000))

    def close(self) -> None:
        self.executive.close()
        self.sink.close()


def _log(path: Path) -> tuple[list[dict], list[dict], list[tuple[str, str]]]:
    """Decisions, commands and (level, text) events in the order they were written (a reboot steps log time back)."""
    dive = open_dive(path)
    decisions = [m.payload for m in dive.messages([Topic.DECISION])]
    commands = [m.payload for m in dive.messages([Topic.COMMAND])]
    events = [(LogLevel(m.payload["level"]).name.lower(), m.payload["message"]) for m in dive.messages([Topic.LOG])]
    return decisions, commands, events


def test_the_decision_uses_the_slice_of_the_vehicles_utc_time(timed, tmp_path):
    v = Vehicle(timed, tmp_path / "exec.mcap")
    try:
        v.heartbeat()
        v.position()  # no SYSTEM_TIME yet: UTC unknown, the first slice (DRIFT)
        v.position()
        # UTC at boot is 40 minutes after the first slice: nearest to the second (FORWARD).
        v.system_time(T0 + 2400.0 + v.time_ms / 1000.0)
        v.position()
        v.position()
        v.position(dt_s=1200.0)  # 20 minutes later: past the last slice's time
        v.position()
        v.position(dt_s=600.0)
    finally:
        v.close()
    decisions, commands, events = _log(tmp_path / "exec.mcap")
    assert [(d["action"], d["slice"], d["slice_status"]) for d in decisions] == [
        ("DRIFT", 0, "time_unknown"), ("DRIFT", 0, "time_unknown"),
        ("FORWARD", 1, "in_horizon"), ("FORWARD", 1, "in_horizon"),
        ("FORWARD", 1, "past_horizon"), ("FORWARD", 1, "past_horizon"), ("FORWARD", 1, "past_horizon"),
    ]
    # What was commanded: ALT_HOLD for DRIFT (the vehicle reports GUIDED), then a velocity east at each refresh.
    steering = [(c["time_s"], c["kind"], c.get("mode")) for c in commands if c["kind"] != "SetMessageInterval"]
    assert steering == [(10.5, "SetMode", int(SubMode.ALT_HOLD)), (11.5, "VelocityYaw", None),
                        (1212.0, "VelocityYaw", None), (1812.5, "VelocityYaw", None)]
    slices = [(level, text) for level, text in events if "slice" in text]
    assert slices == [
        ("warning", "UTC unknown: using the first slice's plan (no SYSTEM_TIME with UTC yet; first slice"
                    " 2026-01-15T00:00:00Z)"),
        ("info", "time-varying plan: slice 1 of 2 (2026-01-15T01:00:00Z)"),
        ("warning", "past the plan's horizon: using the last slice's plan (last slice 2026-01-15T01:00:00Z)"),
    ]


def test_a_stationary_table_logs_the_records_it_always_did(demo_plan, tmp_path):
    v = Vehicle(demo_plan.table, tmp_path / "exec.mcap")
    try:
        v.heartbeat()
        v.system_time(T0 + v.time_ms / 1000.0)
        v.position()
        v.position()
    finally:
        v.close()
    decisions, _, events = _log(tmp_path / "exec.mcap")
    assert len(decisions) == 2
    assert all(list(d) == ["time_s", "lat_deg", "lon_deg", "depth_m", "heading_deg", "cell", "situation", "action",
                           "mode", "changed"] for d in decisions)
    assert not [text for _, text in events if "slice" in text or "horizon" in text]


def test_after_an_autopilot_reboot_the_utc_time_is_unknown_until_the_next_system_time(timed, tmp_path):
    v = Vehicle(timed, tmp_path / "exec.mcap")
    try:
        v.heartbeat()
        v.system_time(T0 + 2400.0 + v.time_ms / 1000.0)
        v.position()  # slice 1
        v.time_ms = 1_000  # time went back: the old boot's UTC offset says nothing of the new one
        for _ in range(3):  # a reboot is believed once three timestamps in a row agree (executive.plausibility)
            v.position()
        v.heartbeat()  # set-up again: the EKF's flag, then a position: a decision at once
        v.position()
        v.system_time(T0 + 600.0 + v.time_ms / 1000.0)  # UTC again: nearest to the first slice
        v.position()
    finally:
        v.close()
    decisions, _, events = _log(tmp_path / "exec.mcap")
    assert [(d["action"], d["slice"], d["slice_status"]) for d in decisions] == [
        ("FORWARD", 1, "in_horizon"), ("DRIFT", 0, "time_unknown"), ("DRIFT", 0, "in_horizon")]
    assert [text.split(":")[0] for _, text in events if "slice" in text] == [
        "time-varying plan", "UTC unknown", "time-varying plan"]
