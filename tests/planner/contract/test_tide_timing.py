"""The tide's timing fitted to the current met (planner.contract.tide_timing)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.contract import tide_timing as tt

M2_S = 12.42 * 3600.0
T0 = 1_780_000_000.0  # a UTC time, Unix s


def reference(hours: float = 48.0) -> tuple[np.ndarray, np.ndarray]:
    """Hourly slices of a one-layer M2 current along the east axis, 0.8 m/s, on a 0.05 m/s residual."""
    times = T0 + 3600.0 * np.arange(int(hours) + 1)
    current = np.zeros((times.size, 1, 2))
    current[:, 0, 0] = 0.05 + 0.8 * np.sin(2 * math.pi * (times - T0) / M2_S)
    return times, current


def met(t: float, late_s: float, scale: float) -> tuple[float, float]:
    """The truth's current at UTC ``t``: the reference's tide ``late_s`` later, ``scale`` times as strong."""
    return 0.05 + scale * 0.8 * math.sin(2 * math.pi * (t - late_s - T0) / M2_S), 0.0


def record(hours: float, late_s: float = 3600.0, scale: float = 0.8, every_s: float = 10.0) -> tt.TideClock:
    times, current = reference()
    clock = tt.TideClock()
    for t in np.arange(T0, T0 + hours * 3600.0, every_s):
        east, north = met(float(t), late_s, scale)
        clock = tt.advance(clock, float(t), 0, east, north, times, current)
    return clock


def test_a_tide_an_hour_late_is_found_an_hour_late_and_its_strength_with_it() -> None:
    clock = record(4.0)
    fit = clock.last_fit
    assert fit is not None and fit.accepted
    assert clock.shift_s == pytest.approx(-3600.0, abs=tt.STEP_S)  # look the plan up an hour earlier
    assert fit.scale == pytest.approx(0.8, abs=0.1)
    assert fit.r2 > 0.95


@pytest.mark.parametrize("late_s", [-5400.0, 0.0, 2700.0])
def test_the_fitted_shift_follows_the_error(late_s: float) -> None:
    assert record(5.0, late_s=late_s).shift_s == pytest.approx(-late_s, abs=tt.STEP_S)


def test_too_short_a_record_shifts_nothing() -> None:
    clock = record(1.5)
    assert clock.last_fit is not None and not clock.last_fit.accepted
    assert clock.shift_s == 0.0


def test_a_current_that_does_not_follow_the_forecast_shifts_nothing() -> None:
    times, current = reference()
    rng = np.random.default_rng(0)
    clock = tt.TideClock()
    for t in np.arange(T0, T0 + 6 * 3600.0, 10.0):
        clock = tt.advance(clock, float(t), 0, float(rng.normal(0.0, 0.3)), float(rng.normal(0.0, 0.3)), times, current)
    assert clock.last_fit is not None and not clock.last_fit.accepted and clock.shift_s == 0.0


def test_one_bad_measurement_decides_nothing() -> None:
    times, current = reference()
    good = record(4.0)
    clock = tt.TideClock()
    for n, t in enumerate(np.arange(T0, T0 + 4 * 3600.0, 10.0)):
        east, north = met(float(t), 3600.0, 0.8)
        if n == 700:
            east, north = 3.0, -4.0  # one wild sample inside a minute: the minute's median ignores it
        if n == 900:
            east = math.nan
        clock = tt.advance(clock, float(t), 0, east, north, times, current)
    assert clock.shift_s == good.shift_s
    # The two minutes keep their medians within a few mm/s (the NaN leaves five samples of six).
    assert np.allclose([o.east_m_s for o in clock.record.observations], [o.east_m_s for o in good.record.observations],
                       atol=0.002)


def test_an_impossible_current_is_not_recorded() -> None:
    rec = tt.observe(tt.CurrentRecord(), T0, 0, 0.2, 0.1)
    assert tt.observe(rec, T0 + 1.0, 0, 60.0, 0.0) is rec


def test_a_current_that_stops_following_the_forecast_sets_the_shift_back_to_none() -> None:
    times, current = reference()
    clock = record(4.0)
    assert clock.shift_s == pytest.approx(-3600.0, abs=tt.STEP_S)
    t = T0 + 4 * 3600.0
    rng = np.random.default_rng(1)
    shifts = []
    for n in range(int(7 * 3600 / 10)):  # somewhere whose current the layer's mean does not describe
        clock = tt.advance(clock, t + 10.0 * n, 0, float(rng.normal(0.0, 0.3)), float(rng.normal(0.0, 0.3)), times,
                           current)
        shifts.append(clock.shift_s)
    assert clock.last_fit is not None and not clock.last_fit.accepted and clock.last_fit.span_s >= tt.MIN_SPAN_S
    assert clock.shift_s == 0.0
    assert shifts[0] != 0.0  # it took a record that no longer fits, not the first odd minute


def test_a_record_emptied_by_a_pause_keeps_the_last_shift_until_it_spans_enough_again() -> None:
    times, current = reference()
    clock = record(4.0)
    shift = clock.shift_s
    assert shift != 0.0
    t = T0 + 10.5 * 3600.0  # no measurement for six and a half hours (a position hold): the old record is gone
    for n in range(int(1800 / 10)):
        east, north = met(t + 10.0 * n, 3600.0, 0.8)
        clock = tt.advance(clock, t + 10.0 * n, 0, east, north, times, current)
    assert clock.last_fit is not None and clock.last_fit.span_s < tt.MIN_SPAN_S and not clock.last_fit.accepted
    assert clock.shift_s == shift


def test_the_record_keeps_the_last_window_only() -> None:
    clock = record(8.0, every_s=15.0)
    obs = clock.record.observations
    assert obs[-1].unix_s - obs[0].unix_s <= tt.WINDOW_S
    assert len(obs) == pytest.approx(tt.WINDOW_S / tt.BIN_S, abs=2)


def test_a_minute_of_too_few_measurements_is_dropped_so_a_lone_wild_one_withdraws_nothing() -> None:
    """A wild measurement just before a pause is its minute's only sample: the minute is dropped."""
    times, current = reference()
    clock = record(4.0)
    shift = clock.shift_s
    assert shift != 0.0
    t = T0 + 4 * 3600.0
    clock = tt.advance(clock, t, 0, 3.0, -2.0, times, current)  # then nothing for 90 s
    t += 90.0
    for n in range(int(3600 / 10)):
        east, north = met(t + 10.0 * n, 3600.0, 0.8)
        clock = tt.advance(clock, t + 10.0 * n, 0, east, north, times, current)
    assert clock.shift_s == shift
    assert all(abs(o.east_m_s) < 1.0 for o in clock.record.observations)


def test_a_minute_cut_short_by_a_change_of_layer_keeps_its_own_time() -> None:
    rec = tt.CurrentRecord()
    for k in range(4):
        rec = tt.observe(rec, T0 + 10.0 * k, 0, 0.1, 0.0)  # 0 .. 30 s in layer 0
    rec = tt.observe(rec, T0 + 35.0, 1, 0.2, 0.0)  # layer 1 closes the minute early
    assert [(o.unix_s, o.region) for o in rec.observations] == [(T0 + 15.0, 0)]


def test_a_fit_that_needs_an_implausible_scale_is_not_accepted() -> None:
    times, current = reference()
    clock = tt.TideClock()
    for t in np.arange(T0, T0 + 4 * 3600.0, 10.0):
        east, north = met(float(t), 3600.0, 0.1)  # a tenth of the forecast's tide: the layer's mean says little here
        clock = tt.advance(clock, float(t), 0, east - 0.05 * 0.9, north, times, current)
    assert clock.last_fit is not None and clock.last_fit.scale < tt.SCALE_RANGE[0]
    assert not clock.last_fit.accepted and clock.shift_s == 0.0


def test_fit_refuses_fewer_than_two_increasing_slices() -> None:
    clock = record(3.0)
    times, current = reference()
    assert tt.fit(clock.record, times[:1], current[:1]) is None
    assert tt.fit(clock.record, times[::-1], current) is None
