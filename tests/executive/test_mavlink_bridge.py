"""The bridge's unit conversions, against messages built and parsed by pymavlink itself."""

from __future__ import annotations

import dataclasses

import pytest

from executive import mavlink_bridge as bridge
from executive.state import VehicleState

KNOWN = VehicleState(time_s=5.0, lat_deg=33.1, lon_deg=-118.1, depth_m=3.0, heading_deg=10.0, mode=4, armed=True,
                     position_ok=True, battery_pct=80.0, energy_used_wh=12.0, heartbeat_s=4.0)


def _wire(msg):  # type: ignore[no-untyped-def]
    """Through bytes and back, as a datagram would come."""
    ap = bridge.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    rx = bridge.mavlink.MAVLink(None)
    (out,) = rx.parse_buffer(msg.pack(ap))
    return out


def _unchanged(after: VehicleState, *changed: str) -> None:
    for f in dataclasses.fields(VehicleState):
        if f.name not in changed:
            assert getattr(after, f.name) == getattr(KNOWN, f.name), f.name


def test_global_position_int_converts_units_and_keeps_the_rest():
    m = bridge.mavlink.MAVLink_global_position_int_message(123_400, 334_000_000, -1_178_000_000, -4_000, -2_500,
                                                           0, 0, 0, 27_050)
    after = bridge.apply(KNOWN, _wire(m), 0.0)
    assert after.time_s == pytest.approx(123.4)
    assert (after.lat_deg, after.lon_deg) == pytest.approx((33.4, -117.8))
    assert after.depth_m == pytest.approx(2.5)  # relative_alt -2500 mm: 2.5 m below the surface
    assert after.heading_deg == pytest.approx(270.5)
    _unchanged(after, "time_s", "lat_deg", "lon_deg", "depth_m", "heading_deg")
    unknown = bridge.mavlink.MAVLink_global_position_int_message(1_000, 0, 0, 0, 500, 0, 0, 0, 65_535)
    above = bridge.apply(KNOWN, _wire(unknown), 0.0)
    assert above.heading_deg == KNOWN.heading_deg and above.depth_m == 0.0  # hdg unknown; above the surface -> 0


def test_attitude_sets_heading_from_yaw_and_keeps_the_rest():
    m = bridge.mavlink.MAVLink_attitude_message(7_000, 0.0, 0.0, -1.5707963, 0.0, 0.0, 0.0)
    after = bridge.apply(KNOWN, _wire(m), 0.0)
    assert after.time_s == pytest.approx(7.0) and after.heading_deg == pytest.approx(270.0, abs=1e-4)
    _unchanged(after, "time_s", "heading_deg")
