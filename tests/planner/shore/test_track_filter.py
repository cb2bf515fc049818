"""The track filtered of position noise, and simplified to a tolerance (``planner.shore.replay.track_filter``).

Synthetic tracks of known length with white and correlated (first-order Gauss-Markov)
noise, and the real closed-loop dive (``dive_log`` in conftest.py) with noise added to
its decisions' positions, measured against the simulator's true track (its ``--track``
CSV beside the log).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from planner.contract.geodesy import EARTH_RADIUS_M
from planner.shore.demo import read_track
from planner.shore.replay.dive import load_dive
from planner.shore.replay.divelog import open_dive
from planner.shore.replay.summary import distance_to_polyline_m, summarise
from planner.shore.replay.track_filter import (
    filter_track,
    group_median,
    local_xyz_m,
    path_length_m,
    simplify,
)

from tests.planner.shore.mcap_logs import rewrite_log

LAT0, LON0 = 33.4, -117.9
M_PER_DEG = math.radians(1.0) * EARTH_RADIUS_M


def _to_deg(east_m: np.ndarray, north_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return LAT0 + north_m / M_PER_DEG, LON0 + east_m / (M_PER_DEG * math.cos(math.radians(LAT0)))


def _gauss_markov(rng: np.random.Generator, n: int, sigma_m: float, tau_s: float, dt_s: float) -> np.ndarray:
    """First-order Gauss-Markov noise: standard deviation ``sigma_m``, correlation time ``tau_s``."""
    a = math.exp(-dt_s / tau_s)
    steps = rng.normal(0.0, sigma_m * math.sqrt(1 - a * a), n)
    out = np.empty(n)
    s = rng.normal(0.0, sigma_m)
    for i in range(n):
        s = a * s + steps[i]
        out[i] = s
    return out


def _lawnmower(dt_s: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Legs at 1 m/s with turns in place, then slow drifts: (time, east, north, true length m)."""
    legs = [(600, 1.0, 0.0), (9, 0.0, 10.0), (300, 1.0, 0.0), (9, 0.0, 10.0), (600, 1.0, 0.0), (2000, 0.1, 0.0),
            (18, 0.0, -10.0), (900, 1.0, 0.0), (3000, 0.05, 0.01)]  # (seconds, m/s, deg/s)
    t, x, y, h = [0.0], [0.0], [0.0], 0.0
    for duration, speed, rate in legs:
        for _ in range(int(duration / dt_s)):
            h += rate * dt_s
            t.append(t[-1] + dt_s)
            x.append(x[-1] + speed * dt_s * math.sin(math.radians(h)))
            y.append(y[-1] + speed * dt_s * math.cos(math.radians(h)))
    xa, ya = np.array(x), np.array(y)
    return np.array(t), xa, ya, float(np.sum(np.hypot(np.diff(xa), np.diff(ya))))


@pytest.mark.parametrize(("white_m", "correlated_m", "tau_s"), [(0.5, 0.0, 1.0), (2.0, 0.0, 1.0), (0.5, 1.0, 30.0),
                                                               (0.5, 2.0, 120.0), (1.0, 1.0, 10.0)])
def test_filtered_length_is_within_3_percent_of_the_true_length(white_m, correlated_m, tau_s):
    rng = np.random.default_rng(7)
    t, x, y, true_m = _lawnmower()
    noisy = [a + rng.normal(0.0, white_m, a.size) + (_gauss_markov(rng, a.size, correlated_m, tau_s, 0.5)
                                                     if correlated_m else 0.0) for a in (x, y)]
    lat, lon = _to_deg(*noisy)
    depth = np.full(t.size, 3.0)
    assert path_length_m(lat, lon) > 2.5 * true_m  # every fix summed: the noise is most of it
    f = filter_track(t, lat, lon, depth)
    assert f.length_m() == pytest.approx(true_m, rel=0.03)
    assert f.fixes == t.size and len(f) < t.size / 50
    assert f.time_s[0] == t[0] and f.time_s[-1] == t[-1] and np.all(np.diff(f.time_s) >= 0)
    assert np.allclose(f.depth_m, 3.0)


def test_repeats_gaps_unknown_positions_and_a_step_back_in_time():
    t = np.array([0.0, 0.5, 0.5, 1.0, 100.0, 100.5, 40.0, 41.0])  # a reboot steps time back at the end
    lat = np.array([33.0, 33.001, 33.001, np.nan, 33.002, 33.002, 33.003, 33.004])
    lon = np.full(t.size, -118.0)
    f = filter_track(t, lat, lon, np.full(t.size, np.nan), window_s=30.0)
    assert f.fixes == 5  # the repeat and the unknown position count nothing
    assert np.all(np.diff(f.time_s) >= 0) and f.time_s[-1] == 100.0  # the running latest time
    assert f.lat_deg[0] == 33.0 and f.lat_deg[-1] == 33.004 and np.isnan(f.depth_m).all()
    assert f.length_m() == pytest.approx(0.004 * M_PER_DEG, rel=1e-6)  # northwards all the way
    with pytest.raises(ValueError, match="window_s"):
        filter_track(t, lat, lon, lat, window_s=0.0)


def test_group_median_matches_numpy_per_group():
    rng = np.random.default_rng(3)
    group = np.sort(rng.integers(0, 40, 1000))
    _, group = np.unique(group, return_inverse=True)
    values = rng.normal(size=1000)
    values[::17] = np.nan
    expected = [np.nanmedian(values[group == g]) for g in range(group.max() + 1)]
    assert np.allclose(group_median(values, group), expected, equal_nan=True)


def test_douglas_peucker_keeps_every_point_within_the_tolerance():
    rng = np.random.default_rng(5)
    s = np.linspace(0.0, 4000.0, 2000)
    points = np.column_stack([s, 300.0 * np.sin(s / 600.0) + rng.normal(0.0, 0.3, s.size), -np.abs(np.sin(s / 900)) * 20])
    for tol in (0.5, 2.0, 10.0):
        kept = simplify(points, tol)
        assert kept[0] == 0 and kept[-1] == points.shape[0] - 1 and np.all(np.diff(kept) > 0)
        assert kept.size < points.shape[0] * (0.5 if tol < 1 else 0.05)
        worst = max(_distance_3d(points[a:b + 1], points[a], points[b]).max() for a, b in zip(kept[:-1], kept[1:]))
        assert worst <= tol
    assert simplify(points, 0.5).size > simplify(points, 10.0).size
    assert list(simplify(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]), 0.0)) == [0, 2]
    with pytest.raises(ValueError, match="tolerance_m"):
        simplify(points, -1.0)


def _distance_3d(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance to the segment a-b, written out again here (not the module's own)."""
    ab = b - a
    t = np.clip(((p - a) * ab).sum(axis=1) / max(float((ab * ab).sum()), 1e-300), 0.0, 1.0)
    return np.sqrt((((a + t[:, None] * ab) - p) ** 2).sum(axis=1))


# -- the real dive ---------------------------------------------------------------------------


def _truth_length_m(dive_log: Path, first_s: float, last_s: float) -> float:
    truth = {k: np.asarray(v) for k, v in read_track(dive_log.parent / "track.csv").items()}
    span = (truth["time_s"] >= first_s) & (truth["time_s"] <= last_s)
    return path_length_m(truth["lat_deg"][span], truth["lon_deg"][span])


def test_the_real_dive_filtered_is_as_long_as_the_simulators_true_track(dive_log):
    dive = load_dive(open_dive(dive_log))
    s = summarise(dive)
    true_m = _truth_length_m(dive_log, float(dive.track.time_s[0]), float(np.nanmax(dive.track.time_s)))
    assert true_m > 1000.0
    assert s.distance_m == pytest.approx(true_m, rel=0.01)


def test_the_real_dive_with_noisy_fixes_still_measures_its_true_length(dive_log, tmp_path):
    """0.5 m white and 1.5 m correlated (60 s) noise on every fix: the summary's distance stays within 3 %."""
    rng = np.random.default_rng(11)
    noise: dict[tuple[float, float], tuple[float, float]] = {}
    drift = iter(zip(_gauss_markov(rng, 100_000, 1.5, 60.0, 0.5), _gauss_markov(rng, 100_000, 1.5, 60.0, 0.5)))

    def noisy(topic: str, message) -> bytes:  # type: ignore[no-untyped-def]
        if topic != "/executive/decision":
            return message.data
        p = json.loads(message.data)
        if p.get("lat_deg") is None:
            return message.data
        key = (p["lat_deg"], p["lon_deg"])
        if key not in noise:  # the same fix (a decision on an attitude message) keeps the same error
            east, north = (float(v) for v in rng.normal(0.0, 0.5, 2) + np.array(next(drift)))
            noise[key] = (north / M_PER_DEG, east / (M_PER_DEG * math.cos(math.radians(p["lat_deg"]))))
        p["lat_deg"] += noise[key][0]
        p["lon_deg"] += noise[key][1]
        return json.dumps(p).encode()

    path = rewrite_log(dive_log, tmp_path / "noisy.mcap", noisy)
    dive = load_dive(open_dive(path))
    s = summarise(dive)
    true_m = _truth_length_m(dive_log, float(dive.track.time_s[0]), float(np.nanmax(dive.track.time_s)))
    assert s.fix_distance_m > 1.5 * true_m  # what the summary said before: the jitter summed
    assert s.distance_m == pytest.approx(true_m, rel=0.03)


def test_the_filtered_track_simplified_stays_within_the_tolerance_of_the_real_dive(dive_log):
    f = load_dive(open_dive(dive_log)).track.filtered()
    xyz = local_xyz_m(f.lat_deg, f.lon_deg, f.depth_m)
    kept = simplify(xyz, 2.0)
    assert 2 <= kept.size < len(f)
    d = distance_to_polyline_m(f.lat_deg, f.lon_deg, f.lat_deg[kept], f.lon_deg[kept])
    assert float(d.max()) <= 2.0 + 1e-6
