"""The tide's timing fitted onboard: the current met, the shift, and the slices looked up with it.

The pure part (``executive.tide_watch``) on its own; the loop's part with a real ``Executive`` fed
parsed MAVLink messages in this thread, as in test_timeline.py, and its log audited.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from executive import durable, tide_watch  # noqa: E402
from executive.recorder import Topic  # noqa: E402
from executive.state import DepthTarget, PositionTarget, SetMode, VehicleState, VelocityYaw  # noqa: E402
from planner.contract import tide_timing  # noqa: E402
from planner.contract.actions import Action  # noqa: E402
from planner.contract.modes import SubMode  # noqa: E402
from planner.contract.table import PolicyTable  # noqa: E402
from planner.shore.replay.audit import audit  # noqa: E402
from planner.shore.replay.divelog import open_dive  # noqa: E402
from tests.executive.test_timeline import Vehicle, _everywhere, _log  # noqa: E402

M2_S = 12.42 * 3600.0
HOURS = 13
T0 = 1_768_435_200.0  # 2026-01-15T00:00:00Z
LATE_S = 3600.0  # the truth's tide runs an hour behind the forecast's


def forecast_current(t: float) -> float:
    return 0.6 * math.sin(2 * math.pi * (t - T0) / M2_S)


@pytest.fixture(scope="module")
def tidal(demo_plan) -> PolicyTable:
    """Hourly slices, DRIFT in even ones and FORWARD in odd ones, with an eastward M2 current in every layer."""
    base = demo_plan.table
    times = tuple(time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(T0 + 3600.0 * n)) for n in range(HOURS))
    stack = np.stack([_everywhere(base, Action.DRIFT if n % 2 == 0 else Action.FORWARD) for n in range(HOURS)])
    current = np.zeros((HOURS, base.n_layers, 2))
    current[:, :, 0] = np.array([forecast_current(T0 + 3600.0 * n) for n in range(HOURS)])[:, None]
    return PolicyTable.from_bytes(base.with_slices(times, stack, current).to_bytes())


def test_commands_say_which_velocity_is_through_the_water() -> None:
    w = tide_watch.commanded(tide_watch.TideWatch(), VelocityYaw(0.3, 0.4, 0.0, 90.0), 5.0)
    assert (w.water_ne_m_s, w.since_s) == ((0.3, 0.4), 5.0)
    assert tide_watch.commanded(w, VelocityYaw(0.305, 0.4, 0.0, 91.0), 9.0) is w  # the same command again
    assert tide_watch.commanded(w, SetMode(SubMode.GUIDED), 9.0) is w
    d = tide_watch.commanded(w, DepthTarget(5.0), 9.0)
    assert (d.water_ne_m_s, d.since_s) == ((0.0, 0.0), 9.0)
    assert tide_watch.commanded(w, SetMode(SubMode.ALT_HOLD), 9.0).water_ne_m_s == (0.0, 0.0)  # DRIFT
    assert tide_watch.commanded(d, PositionTarget(1.0, 2.0, 3.0), 10.0).water_ne_m_s is None
    assert tide_watch.commanded(w, SetMode(SubMode.SURFACE), 10.0).water_ne_m_s is None


def test_nothing_is_measured_before_the_command_settles_or_without_slice_currents(tidal, demo_plan) -> None:
    lat, lon = tidal.cell_centre(*(int(x) for x in np.argwhere(tidal.water[0])[0]))
    vehicle = VehicleState(time_s=40.0, lat_deg=lat, lon_deg=lon, depth_m=0.0, heading_deg=0.0, position_s=40.0)
    w = tide_watch.commanded(tide_watch.TideWatch(), DepthTarget(0.0), 20.0)
    assert tide_watch.measured(w, tidal, vehicle, 40.0, T0 + 40.0, 0.1, 0.2, fresh=True, running=True)[0] is w  # 20 s: not settled
    assert tide_watch.measured(w, tidal, vehicle, 60.0, T0 + 60.0, 0.1, 0.2, fresh=False, running=True)[0] is w  # a rejected position
    assert tide_watch.measured(w, tidal, vehicle, 60.0, None, 0.1, 0.2, fresh=True, running=True)[0] is w  # no UTC
    assert tide_watch.measured(w, demo_plan.table, vehicle, 60.0, T0 + 60.0, 0.1, 0.2, fresh=True, running=True)[0] is w
    after, event = tide_watch.measured(w, tidal, vehicle, 60.0, T0 + 60.0, 0.1, 0.2, fresh=True, running=True)
    assert after.table_crc32 == tidal.crc32 and event is None


def test_the_logged_shift_reads_back() -> None:
    assert tide_watch.logged_shift("tide timing: table 0000abcd looked up at UTC -3600 s: the current ...") == (0xABCD, -3600.0)
    assert tide_watch.logged_shift("plan swapped") is None


class LateTide(Vehicle):
    """A vehicle that flies the executive's commands in the truth's current, an hour behind the forecast's:
    its ground velocity is the current met plus the velocity last commanded (none in a depth hold)."""

    def __init__(self, table: PolicyTable, log: Path, **kwargs) -> None:  # type: ignore[no-untyped-def]
        super().__init__(table, log, **kwargs)
        self.water = [0.0, 0.0]  # north, east through the water
        send = self.executive._send_command

        def sent(now_s: float, cmd) -> None:  # type: ignore[no-untyped-def]
            if isinstance(cmd, VelocityYaw):
                self.water = [cmd.north_m_s, cmd.east_m_s]
            elif isinstance(cmd, DepthTarget) or (isinstance(cmd, SetMode) and cmd.mode is SubMode.ALT_HOLD):
                self.water = [0.0, 0.0]
            send(now_s, cmd)

        self.executive._send_command = sent  # type: ignore[method-assign]

    def fly(self, hours: float, start_ms: int = 0) -> None:
        """Set up (UTC at boot: the first slice's time), then a position every 15 s for ``hours``."""
        self.time_ms = start_ms
        self.heartbeat()
        self.system_time(T0 + start_ms / 1000.0)
        water = np.argwhere(self.table.water[0])
        j, i = (int(x) for x in water[len(water) // 2])
        lat, lon = self.table.cell_centre(j, i)
        for _ in range(int(hours * 3600 / 15)):
            self.time_ms += 15_000
            east = forecast_current(T0 + self.time_ms / 1000.0 - LATE_S) + self.water[1]
            self._feed(self.mav.global_position_int_encode(self.time_ms, round(lat * 1e7), round(lon * 1e7), 0, 0,
                                                           round(self.water[0] * 100), round(east * 100), 0,
                                                           round(self.table.bearing_deg(j, 0) * 100) % 36000))


def flown(table: PolicyTable, log: Path) -> tuple[list[dict], list[tuple[str, str]]]:
    """Five hours of ``LateTide`` under ``table``: the log's decisions and events."""
    v = LateTide(table, log)
    try:
        v.fly(5.0)
    finally:
        v.close()
    decisions, _, events = _log(log)
    return decisions, events


def test_the_executive_finds_the_tide_late_and_looks_its_slices_up_earlier(tidal, tmp_path) -> None:
    """The vehicle drifts (DRIFT) and moves (FORWARD, a velocity east) with the truth's current, an hour
    behind the forecast's; once the record spans enough of the tide, the slices are looked up an hour
    earlier, the log says so, and the audit finds every decision where the loop made it."""
    decisions, events = flown(tidal, tmp_path / "exec.mcap")
    shifts = [text for _, text in events if text.startswith(tide_watch.SHIFT_PREFIX)]
    assert shifts, "the tide's timing was never fitted"
    first = tide_watch.logged_shift(shifts[0])
    assert first is not None and first[0] == tidal.crc32 and first[1] == pytest.approx(-LATE_S, abs=900)
    last = tide_watch.logged_shift(shifts[-1])
    assert last is not None and last[1] == pytest.approx(-LATE_S, abs=300)
    # After the fit, each decision uses the slice nearest UTC less an hour.
    late = [d for d in decisions if d["time_s"] > 4.5 * 3600]
    assert late and all(d["slice"] == round((d["time_s"] - LATE_S) / 3600.0) for d in late)
    result = audit(open_dive(tmp_path / "exec.mcap"))
    assert result.clean and result.timed == len(decisions)
    assert result.time_varying == (f"{tidal.crc32:08x}: time-varying, {HOURS} slices from 2026-01-15T00:00:00Z to "
                                   "2026-01-15T12:00:00Z, the tide's timing fitted onboard",)
    policy = [m.payload for m in open_dive(tmp_path / "exec.mcap").messages([Topic.POLICY])]
    assert policy[0]["slices"]["timing_correction"] is True


def test_with_a_reference_per_block_the_vehicle_fits_its_own_blocks_current(tidal, tmp_path) -> None:
    """Blocks of 4 cells: the vehicle's block carries the M2 current, every other block the opposite one,
    so the layer's mean would be nearly still; the fit finds the hour against its own block."""
    water = np.argwhere(tidal.water[0])
    j, i = (int(x) for x in water[len(water) // 2])  # where LateTide flies
    rows, cols = -(-tidal.ny // 4), -(-tidal.nx // 4)
    current = np.zeros((HOURS, tidal.n_layers * rows * cols, 2))
    current[:, :, 0] = -tidal.slice_current_m_s[:, :1, 0]
    own = (j // 4) * cols + i // 4  # layer 0's block of cell (j, i)
    current[:, own, 0] = tidal.slice_current_m_s[:, 0, 0]
    blocked = PolicyTable.from_bytes(tidal.with_slices(tidal.slice_times, tidal.slices, current, block_cells=4).to_bytes())
    _, events = flown(blocked, tmp_path / "exec.mcap")
    shifts = [tide_watch.logged_shift(text) for _, text in events if text.startswith(tide_watch.SHIFT_PREFIX)]
    assert shifts and shifts[-1] is not None and shifts[-1][1] == pytest.approx(-LATE_S, abs=300)
    assert audit(open_dive(tmp_path / "exec.mcap")).clean
    policy = [m.payload for m in open_dive(tmp_path / "exec.mcap").messages([Topic.POLICY])]
    assert policy[0]["slices"]["timing_block_cells"] == 4


def test_a_restart_keeps_the_record_and_the_shift(tidal, tmp_path) -> None:
    """Killed after four hours (the executive saves its state at every fit), resumed from the state
    directory: the first decisions already look the slices up an hour early, the log says the shift was
    kept, the audit of the new log agrees, and the kept record goes on being fitted."""
    state = tmp_path / "state"
    first = LateTide(tidal, tmp_path / "exec.mcap", state_dir=state)
    try:
        first.fly(4.0)
        shift = first.executive.tide.shift_for(tidal)
    finally:
        first.close()
    assert shift == pytest.approx(-LATE_S, abs=900)
    resumed = durable.load(state)
    assert resumed.tide is not None and resumed.tide.shift_for(tidal) == shift
    assert len(resumed.tide.clock.record.observations) >= 200  # minutes of the four hours' record
    second = LateTide(tidal, tmp_path / "resumed.mcap", tide=resumed.tide)
    try:
        second.fly(1.0, start_ms=first.time_ms + 600_000)  # back ten minutes later
    finally:
        second.close()
    decisions, _, events = _log(tmp_path / "resumed.mcap")
    kept = [text for _, text in events if text.startswith(tide_watch.SHIFT_PREFIX)]
    assert kept[0].endswith("minutes of the current met)") and tide_watch.logged_shift(kept[0]) == (tidal.crc32, shift)
    assert decisions and all(d["slice"] == math.ceil((d["time_s"] + shift) / 3600.0 - 0.5) for d in decisions)  # ties: the earlier
    assert second.executive.tide.clock.last_fit is not None and second.executive.tide.clock.last_fit.accepted
    result = audit(open_dive(tmp_path / "resumed.mcap"))
    assert result.clean and result.timed == len(decisions)


def test_a_saved_record_reads_back_or_is_refused_by_name() -> None:
    clock = tide_timing.TideClock(record=tide_timing.CurrentRecord(observations=(
        tide_timing.Observation(T0, 0, 0.25, -0.5), tide_timing.Observation(T0 + 60.0, 1, 0.3, 0.0))), shift_s=-1200.0)
    watch = tide_watch.TideWatch(clock=clock, water_ne_m_s=(0.1, 0.2), since_s=3.0, table_crc32=0xABCD,
                                 layout=("blocks", 4, 21, 29, -118.26, 33.3, 0.02, 0.02, 0.0, 5.0))
    saved = tide_watch.saved(watch)
    back = tide_watch.restored(json.loads(json.dumps(saved)))  # as state.json holds it
    assert back.clock.record.observations == clock.record.observations and back.clock.shift_s == -1200.0
    assert back.layout == watch.layout
    assert back.table_crc32 == 0xABCD and back.water_ne_m_s is None  # the command is not kept: the helm sends again
    assert tide_watch.saved(tide_watch.TideWatch()) is None
    for bad, words in (({**saved, "shift_s": 1e6}, "shift_s"), ({**saved, "observations": [[T0, -1, 0.0, 0.0]]}, "observation"),
                       ({**saved, "observations": [[T0, 0, "x", 0.0]]}, "observation"),
                       ({**saved, "observations": [[T0, 0, 0.0]]}, "observation"),
                       ({**saved, "layout": {"blocks": 4}}, "layout")):
        with pytest.raises(ValueError, match=words):
            tide_watch.restored(bad)


def test_a_shift_the_current_no_longer_supports_is_withdrawn_and_logged(tidal) -> None:
    lat, lon = tidal.cell_centre(*(int(x) for x in np.argwhere(tidal.water[0])[0]))
    w = tide_watch.commanded(tide_watch.TideWatch(), DepthTarget(0.0), 0.0)
    events = []
    rng = np.random.default_rng(3)
    for n in range(int(9 * 3600 / 20)):  # four hours of the late tide, then five of a current it does not explain
        t = 60.0 + 20.0 * n
        vehicle = VehicleState(time_s=t, lat_deg=lat, lon_deg=lon, depth_m=0.0, heading_deg=0.0, position_s=t)
        east = forecast_current(T0 + t - LATE_S) if t < 4 * 3600 else float(rng.normal(0.0, 0.4))
        north = 0.0 if t < 4 * 3600 else float(rng.normal(0.0, 0.4))
        w, event = tide_watch.measured(w, tidal, vehicle, t, T0 + t, north, east, fresh=True, running=True)
        if event is not None:
            events.append(event.text)
    shifts = [tide_watch.logged_shift(text) for text in events]
    assert shifts[0] is not None and shifts[0][1] == pytest.approx(-LATE_S, abs=900)
    assert shifts[-1] == (tidal.crc32, 0.0) and "no longer explains" in events[-1]
    assert w.shift_for(tidal) == 0.0


def test_another_table_after_a_shift_is_announced_so_the_audit_drops_the_shift_too(tidal) -> None:
    other = PolicyTable.from_bytes(tidal.with_slices(tidal.slice_times, tidal.slices,
                                                     tidal.slice_current_m_s * 0.5).to_bytes())
    assert other.crc32 != tidal.crc32
    lat, lon = tidal.cell_centre(*(int(x) for x in np.argwhere(tidal.water[0])[0]))
    vehicle = VehicleState(time_s=100.0, lat_deg=lat, lon_deg=lon, depth_m=0.0, heading_deg=0.0, position_s=100.0)
    shifted = tide_watch.TideWatch(clock=tide_timing.TideClock(shift_s=-3600.0), water_ne_m_s=(0.0, 0.0), since_s=0.0,
                                   table_crc32=tidal.crc32)
    after, event = tide_watch.measured(shifted, other, vehicle, 100.0, T0 + 100.0, 0.0, 0.1, fresh=True, running=True)
    assert event is not None and tide_watch.logged_shift(event.text) == (other.crc32, 0.0)
    assert after.shift_for(other) == 0.0 and after.shift_for(tidal) == 0.0
    # Back to the first table: the log's last word was "none" for the other one, so the audit uses none for it too.
    back, event = tide_watch.measured(after, tidal, vehicle, 101.0, T0 + 101.0, 0.0, 0.1, fresh=True, running=True)
    assert event is None and back.shift_for(tidal) == 0.0


def test_a_table_that_numbers_its_regions_otherwise_starts_a_record_of_its_own(tidal) -> None:
    lat, lon = tidal.cell_centre(*(int(x) for x in np.argwhere(tidal.water[0])[0]))
    vehicle = VehicleState(time_s=100.0, lat_deg=lat, lon_deg=lon, depth_m=0.0, heading_deg=0.0, position_s=100.0)
    record = tide_timing.CurrentRecord(observations=(tide_timing.Observation(T0 + 40.0, 0, 0.1, 0.0),))
    w = tide_watch.TideWatch(clock=tide_timing.TideClock(record=record), water_ne_m_s=(0.0, 0.0), since_s=0.0,
                             table_crc32=tidal.crc32, layout=tide_watch.region_layout(tidal))
    per_layer = PolicyTable.from_bytes(tidal.with_slices(tidal.slice_times, tidal.slices,
                                                         tidal.slice_current_m_s * 0.5).to_bytes())
    kept, _ = tide_watch.measured(w, per_layer, vehicle, 100.0, T0 + 100.0, 0.0, 0.1, fresh=True, running=True)
    assert kept.clock.record.observations == record.observations  # layers numbered alike: the record goes on
    whole = PolicyTable.from_bytes(tidal.with_slices(tidal.slice_times, tidal.slices, tidal.slice_current_m_s * 0.5,
                                                     block_cells=1000).to_bytes())  # a block as large as the grid
    kept, _ = tide_watch.measured(w, whole, vehicle, 100.0, T0 + 100.0, 0.0, 0.1, fresh=True, running=True)
    assert kept.clock.record.observations == record.observations  # one block a layer: a layer
    current = np.zeros((HOURS, tidal.n_layers * (-(-tidal.ny // 3)) * (-(-tidal.nx // 3)), 2))
    blocked = PolicyTable.from_bytes(tidal.with_slices(tidal.slice_times, tidal.slices, current, block_cells=3).to_bytes())
    fresh, _ = tide_watch.measured(w, blocked, vehicle, 100.0, T0 + 100.0, 0.0, 0.1, fresh=True, running=True)
    assert fresh.clock.record.observations == () and fresh.layout == tide_watch.region_layout(blocked)


def test_nothing_is_measured_while_the_helm_does_not_run_the_plan(tidal) -> None:
    lat, lon = tidal.cell_centre(*(int(x) for x in np.argwhere(tidal.water[0])[0]))
    vehicle = VehicleState(time_s=100.0, lat_deg=lat, lon_deg=lon, depth_m=0.0, heading_deg=0.0, position_s=100.0)
    w = tide_watch.commanded(tide_watch.TideWatch(), VelocityYaw(0.0, 0.5, 0.0, 90.0), 0.0)
    taken, _ = tide_watch.measured(w, tidal, vehicle, 100.0, T0 + 100.0, 0.0, 0.6, fresh=True, running=False)
    assert taken.water_ne_m_s is None and taken.clock.record == w.clock.record  # overridden: the command is stale


def test_a_slice_looked_up_before_the_first_says_the_vehicles_own_utc_and_the_shift(tidal) -> None:
    from executive import timeline

    f = timeline.follow(timeline.Timeline(), tidal, T0 + 1800.0, -3600.0)
    assert f.current.index == 0 and f.current.status == "before_start"
    assert f.events[0].text.endswith("vehicle UTC 2026-01-15T00:30:00Z, looked up at UTC -3600 s)")
    assert timeline.slice_for(tidal, T0 + 7200.0, -3600.0).index == 1
