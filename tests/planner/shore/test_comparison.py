"""The energy comparison of two methods over the starts both arrived from, and its bootstrap interval."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.shore.evaluation.comparison import compare_energy, every_pair
from planner.shore.evaluation.runs import RunResult


def _r(method: str, start: int, energy: float, outcome: str = "arrived") -> RunResult:
    return RunResult(method=method, start=start, outcome=outcome, time_s=0.0, energy_wh=energy,
                     predicted_wh=math.nan, marked_reachable=True)


def _pairs(a: np.ndarray, b: np.ndarray) -> list[RunResult]:
    return [_r("a", i, float(x)) for i, x in enumerate(a)] + [_r("b", i, float(y)) for i, y in enumerate(b)]


def test_ratio_over_the_starts_both_arrived_from():
    results = [_r("a", 0, 10.0), _r("a", 1, 30.0), _r("a", 2, 99.0, "timed_out"), _r("a", 3, 5.0),
               _r("b", 0, 8.0), _r("b", 1, 20.0), _r("b", 2, 10.0), _r("b", 3, 1.0, "stranded")]
    c = compare_energy(results, "a", "b")
    assert (c.method, c.against, c.starts) == ("a", "b", 2)
    assert c.excess == pytest.approx(40.0 / 28.0 - 1.0)
    assert c.low <= c.excess <= c.high
    # Two starts: a resample holds start 0 twice (10 / 8), start 1 twice (30 / 20) or both (40 / 28).
    assert c.low == pytest.approx(0.25) and c.high == pytest.approx(0.5)
    assert compare_energy(results, "a", "b") == c  # seeded: the same runs, the same interval


def test_equal_energies_have_no_spread_and_too_few_starts_no_interval():
    same = compare_energy(_pairs(np.array([5.0, 7.0, 9.0]), np.array([5.0, 7.0, 9.0])), "a", "b")
    assert (same.excess, same.low, same.high) == (0.0, 0.0, 0.0)
    one = compare_energy([_r("a", 0, 3.0), _r("b", 0, 2.0)], "a", "b")
    assert one.starts == 1 and one.excess == pytest.approx(0.5) and math.isnan(one.low) and math.isnan(one.high)
    none = compare_energy([_r("a", 0, 3.0), _r("b", 1, 2.0)], "a", "b")
    assert none.starts == 0 and math.isnan(none.excess)


def test_the_interval_narrows_with_more_starts_and_covers_the_truth():
    # b's energies spread widely over starts; a spends 5 % more than b on each start, give or take 10 %.
    rng = np.random.default_rng(1)

    def draw(n: int) -> list[RunResult]:
        b = rng.uniform(20.0, 200.0, n)
        return _pairs(b * 1.05 * (1.0 + rng.normal(0.0, 0.1, n)), b)

    few, many = compare_energy(draw(50), "a", "b"), compare_energy(draw(800), "a", "b")
    assert many.high - many.low < 0.5 * (few.high - few.low)
    # A 95 % interval holds the true 5 % in about 95 of 100 campaigns of 100 starts.
    # Paired: a start's two energies move together, so the interval is about as wide as the 10 % noise
    # over 100 starts makes it (2 x 1.96 x 0.1 x 1.05 / 10 = 0.04), not as wide as the spread of the
    # energies themselves (about 0.3 for an unpaired bootstrap).
    held, widths = 0, []
    for _ in range(100):
        c = compare_energy(draw(100), "a", "b", resamples=1000)
        held += c.low <= 0.05 <= c.high
        widths.append(c.high - c.low)
    assert 85 <= held <= 100
    assert 0.03 < float(np.median(widths)) < 0.06


def test_every_pair_once_in_order():
    results = [_r(m, 0, e) for m, e in (("x", 1.0), ("y", 2.0), ("z", 4.0))]
    got = [(c.method, c.against, round(c.excess, 6)) for c in every_pair(results, ["x", "y", "z"])]
    assert got == [("x", "y", -0.5), ("x", "z", -0.75), ("y", "z", -0.5)]
