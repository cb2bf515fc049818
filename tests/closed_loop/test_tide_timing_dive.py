"""A dive through a tide that runs an hour behind its forecast: the executive fits the timing.

``lrauv sim`` flies the true M2 channel (planner.forecast.synthetic.tidal) in lockstep at 1000x;
the executive runs a time-varying plan made on a forecast whose tide runs an hour early, with
``planning.timing_correction``. From the ground velocity it is sent and the velocities it
commands, it must find the hour, announce it, use it, and the audit must find every decision
where the executive made it. Lockstep makes the run the same on a busy machine.
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from executive import tide_watch
from executive.recorder import read_messages
from planner.contract.mission import load_mission
from planner.forecast.synthetic.tidal import TidalSettings, with_forecast_error, write_tidal
from planner.shore.replay.audit import audit
from planner.shore.replay.divelog import open_dive
from tests.support import REPO
from tests.support.helpers import wait_until
from tests.support.loop_rig import WALL_LIMIT_S, ExecThread, Sim

pytestmark = pytest.mark.slow

EARLY_H = 1.0


@pytest.fixture(scope="module")
def channel(tmp_path_factory):  # type: ignore[no-untyped-def]
    from planner.pipeline import PlanRequest, make_plan

    folder = tmp_path_factory.mktemp("tide")
    truth = write_tidal(folder / "truth.nc", TidalSettings())
    forecast = write_tidal(folder / "forecast.nc", with_forecast_error(TidalSettings(), phase_error_h=EARLY_H))
    mission = load_mission(REPO / "missions" / "eval-tidal.yaml")
    request = PlanRequest.for_mission(mission, forecast)
    request = replace(request, settings=replace(request.settings, time_varying=True, horizon_h=24.0))
    return truth, make_plan(request).table


def test_the_executive_finds_the_tide_an_hour_late_and_the_audit_agrees(channel, tmp_path):
    """A dive from the channel's middle (its whole crossing takes longer), until the executive uses a shift
    within 15 minutes of the hour: the fit needs 2 hours of record, so about two and a half of the dive."""
    truth, table = channel
    assert table.slice_current_m_s is not None
    lon, lat = table.goal_lon_deg - 14 * table.dlon_deg, table.goal_lat_deg
    assert table.lookup(lat, lon, 0.0, 90.0).reason == "ok"
    log = tmp_path / "dive.mcap"
    sim = ex = None
    try:
        sim = Sim(truth, (lon, lat), "--heading-deg", "90", "--position-delay-s", "5", "--speedup", "1000")
        ex = ExecThread(table, sim.port, log)
        executive = ex.executive

        def fitted() -> bool:
            return abs(executive.tide.shift_for(table) + EARLY_H * 3600.0) <= 900.0

        # A deadline, not a measurement: lockstep makes the dive the same on any machine, only slower on a busy
        # one; the wait ends as soon as the executive uses the fitted hour (or stops).
        wait_until(lambda: fitted() or not ex.thread.is_alive(), timeout_s=WALL_LIMIT_S)
    finally:
        if ex is not None:
            ex.stop()
        if sim is not None:
            sim.stop()
    assert fitted(), f"no shift near the hour after {executive.vehicle.time_s / 3600:.2f} h of the dive"
    shifts = [tide_watch.logged_shift(p["message"]) for _, _, p in read_messages(log, ["/log"])]
    shifts = [s for s in shifts if s is not None]
    print(f"\nshifts {[s for _, s in shifts]}")
    assert shifts and all(crc == table.crc32 for crc, _ in shifts)
    assert shifts[-1][1] == pytest.approx(-EARLY_H * 3600.0, abs=900.0)
    result = audit(open_dive(log))
    assert result.clean, result.mismatches[:3]
    assert result.timed == result.decisions > 0
