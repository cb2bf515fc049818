"""The executive's vehicle clock: extrapolation through a silence, at real time and at a simulator's speedup."""

from __future__ import annotations

import pytest

from executive.clock import SILENCE_GRACE_WALL_S, VehicleClock

GRACE = SILENCE_GRACE_WALL_S
LINK_LOSS_TIMEOUT_S = 30.0  # HelmConfig's default


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
    assert clock.now_s(last_wall + 30.0) == pytest.approx(109.5 + 30.0)  # a vehicle's silence: link lost on time
    assert clock.wall_until(140.0, last_wall + 30.0) == pytest.approx(0.5)


def test_at_a_speedup_time_waits_out_the_grace_then_runs_on_at_real_time():
    """A simulator's silence counts as wall time: a process stalled 3 s at 10x is 2 s of silence, not 30 s."""
    clock = _fed(1000.0)
    last_wall = 19 * 0.5 / 1000.0
    assert clock.rate == pytest.approx(1000.0)
    # A simulator waiting for us in lockstep, or descheduled: no vehicle time passes.
    assert clock.now_s(last_wall + 0.05) == 109.5
    assert clock.now_s(last_wall + 0.9 * GRACE) == 109.5
    # Then vehicle time runs on from the end of the grace at real time, not at the measured 1000x.
    assert clock.now_s(last_wall + GRACE + 0.03) == pytest.approx(109.5 + 0.03)
    assert clock.wall_until(139.5, last_wall + GRACE + 0.03) == pytest.approx(30.0 - 0.03)
    assert clock.wall_until(109.0, last_wall) == 0.0
    assert clock.last_s == 109.5
    stalled = _fed(10.0)
    assert stalled.now_s(19 * 0.05 + 3.0) == pytest.approx(109.5 + 3.0 - GRACE)
    # A dead simulator is still noticed, after the timeout in wall seconds (plus the grace).
    assert stalled.now_s(19 * 0.05 + GRACE + LINK_LOSS_TIMEOUT_S + 0.1) - 109.5 > LINK_LOSS_TIMEOUT_S


def test_before_any_rate_is_measured_the_clock_holds_too():
    clock = VehicleClock()
    clock.observe(50.0, 0.0)
    assert clock.now_s(0.001) == 50.0  # a simulator's first timestamps arrive within microseconds
    assert clock.now_s(GRACE + 2.0) == pytest.approx(52.0)  # then real time


@pytest.mark.parametrize("rate", [1.0, 1000.0])
def test_vehicle_time_never_steps_back_until_a_reboot(rate: float):
    """A message older than the extrapolation holds the clock until the vehicle's time passes it."""
    clock = _fed(rate)
    last_wall = 19 * 0.5 / rate
    silence = GRACE + 4.0  # wall seconds: the extrapolation runs 4 s (real time) or 3 s past 109.5
    ahead = clock.now_s(last_wall + silence)
    assert ahead > 112.0
    clock.observe(110.0, last_wall + silence)  # the vehicle's own time went on less far (a stalled simulator)
    assert clock.now_s(last_wall + silence) == ahead
    assert clock.now_s(last_wall + silence + 0.01) == ahead  # held, however the wall clock goes
    clock.observe(ahead + 0.5, last_wall + silence + 0.02)
    assert clock.now_s(last_wall + silence + 0.02) == ahead + 0.5
    assert clock.now_s(last_wall) == ahead + 0.5  # asked about an earlier wall time: still never back
    assert clock.observe(20.0, last_wall + silence + 0.03)  # a reboot starts the clock afresh
    assert clock.now_s(last_wall + silence + 0.03) == 20.0 and clock.reboots == 1
