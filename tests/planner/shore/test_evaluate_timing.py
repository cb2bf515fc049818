"""The evaluation's time-varying pilot fits the tide's timing as the executive does."""

from __future__ import annotations

import numpy as np
import pytest

from planner.contract.vehicle import VehicleParams
from planner.shore.evaluation.runs import FeedbackPilot
from tests.executive.test_tide_watch import LATE_S, T0, forecast_current, tidal  # noqa: F401 (a fixture)
from vehicle_sim.dynamics import Body, Setpoint, SetpointKind


def _fly(table, timing) -> list[int]:  # type: ignore[no-untyped-def]
    """Slices the pilot asks for over five hours of a drift in the tide an hour late, one a minute."""
    asked: list[float] = []

    def table_at(t_s: float):  # type: ignore[no-untyped-def]
        asked.append(t_s)
        return table.slice_at(T0 + t_s).table

    pilot = FeedbackPilot(table_at, VehicleParams(), timing=timing)
    lat, lon = table.cell_centre(*(int(x) for x in np.argwhere(table.water[0])[0]))
    seen = []
    water = (0.0, 0.0)  # the vehicle flies the pilot's last velocity through the water, none in a depth hold
    for n in range(5 * 60 * 6):
        t = 10.0 * n
        east = forecast_current(T0 + t - LATE_S)
        sp = pilot.command(Body(time_s=t, lat_deg=lat, lon_deg=lon, depth_m=0.0, ground_north_m_s=water[0],
                                ground_east_m_s=east + water[1], water_north_m_s=water[0], water_east_m_s=water[1]))
        assert isinstance(sp, Setpoint)
        water = (sp.north_m_s, sp.east_m_s) if sp.kind is SetpointKind.VELOCITY else (0.0, 0.0)
        if n % 6 == 0:
            seen.append(table.slice_at(T0 + asked[-1]).index)
    return seen


def test_with_slice_currents_the_pilot_looks_the_slices_up_an_hour_early(tidal):  # noqa: F811
    fitted = _fly(tidal, tidal)
    plain = _fly(tidal, None)
    minutes = np.arange(len(plain))
    assert plain == [tidal.slice_at(T0 + m * 60.0).index for m in minutes]
    late = minutes >= 4 * 60  # by then the fit has two hours of record past the first slice's hour
    assert [s for s, l in zip(fitted, late) if l] == [tidal.slice_at(T0 + m * 60.0 - LATE_S).index
                                                     for m, l in zip(minutes, late) if l]
    assert fitted != plain
    assert fitted[:60] == plain[:60]  # no shift before the record spans enough
