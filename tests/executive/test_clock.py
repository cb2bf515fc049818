"""The executive's vehicle clock: extrapolation through a silence, at real time and at a simulator's speedup."""

from __future__ import annotations

import pytest

from executive.clock import SILENCE_GRACE_WALL_S, VehicleClock

GRACE = SILENCE_GRACE_WALL_S


def _fed(rate: float) -> VehicleClock:
    """A clock that has seen timestamps at ``rate`` vehicle seconds per wall second for a while."""
    clock = VehicleClock()
    for n in range(20):
        clock.observe(100.0 + n * 0.5, n * 0.5 / rate)
    return clock


def test_at_real_time_the_silence_is_extrapolated_at_once():
    clock = _fed(1.0)
    last_wall = 19 * 0.5
    assert clock.rate == pytest.approx(1.0)
    assert clock.now_s(last_wall + 0.3) == pytest.approx(109.5 + 0.3)
    assert clock.now_s(last_wall + 30.0) == pytest.approx(109.5 + 30.0)
    assert clock.wall_until(110.0, last_wall) == pytest.approx(0.5)


def test_at_a_speedup_time_waits_out_the_grace_then_runs_on_from_the_last_timestamp():
    clock = _fed(1000.0)
    last_wall = 19 * 0.5 / 1000.0
    assert clock.rate == pytest.approx(1000.0)
    # A simulator waiting for us in lockstep, or descheduled: no vehicle time passes.
    assert clock.now_s(last_wall + 0.05) == 109.5
    assert clock.now_s(last_wall + 0.9 * GRACE) == 109.5
    # A real silence: vehicle time runs on at the rate, from the end of the grace.
    assert clock.now_s(last_wall + GRACE + 0.03) == pytest.approx(109.5 + 30.0)
    assert clock.wall_until(139.5, last_wall) == pytest.approx(GRACE + 0.03)
    assert clock.wall_until(109.0, last_wall) == 0.0
    assert clock.last_s == 109.5


def test_before_any_rate_is_measured_the_clock_holds_too():
    clock = VehicleClock()
    clock.observe(50.0, 0.0)
    assert clock.now_s(0.001) == 50.0  # a simulator's first timestamps arrive within microseconds
    assert clock.now_s(GRACE + 2.0) == pytest.approx(52.0)  # then the 1x guess
