"""The simulator's truth from a sequence of forecasts (vehicle_sim.world.TruthSequence, ``lrauv sim --forecast``).

Real netCDF files from the synthetic generator: issue 0 (issued at the scenario start) and
issue 1 (issued ``issue_interval_h`` = 6 h later), 30 hours each.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from tests.support.helpers import sim_cli
from vehicle_sim.world import TruthSequence, World, WorldError, load_truth

HOURS = 30
ISSUE_1_S = 6 * 3600.0  # SyntheticSettings.issue_interval_h
LAT, LON = 33.45, -118.10  # open water in the synthetic forecast
POINTS = [(LAT, LON, 0.0), (LAT + 0.013, LON - 0.021, 7.5), (33.38, -117.95, 3.0)]


@pytest.fixture(scope="module")
def issues(tmp_path_factory) -> tuple[Path, Path]:
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    d = tmp_path_factory.mktemp("issues")
    settings = SyntheticSettings(seed=0, hours=HOURS)
    return (write_synthetic(d / "issue0.nc", settings, issue_number=0),
            write_synthetic(d / "issue1.nc", settings, issue_number=1))


@pytest.fixture(scope="module")
def worlds(issues) -> tuple[World, World]:
    return World.load(issues[0]), World.load(issues[1])


def _box(b) -> tuple[float, float, float, float]:  # type: ignore[no-untyped-def]
    return b.west_deg, b.south_deg, b.east_deg, b.north_deg


def _undated_copy(src: Path, dst: Path) -> Path:
    with xr.open_dataset(src, decode_times=False) as ds:
        ds = ds.load()
    ds["time"].attrs["units"] = "hours"  # no "since": no reference date
    ds.to_netcdf(dst)
    return dst


# -- the sequence ------------------------------------------------------------------------------------


def test_each_issue_is_the_truth_from_its_own_issue_time(issues, worlds):
    w0, w1 = worlds
    seq = load_truth([issues[1], issues[0]])  # given out of order: sorted by start time
    assert isinstance(seq, TruthSequence) and [m.source for m in seq.members] == [w0.source, w1.source]
    assert seq.offsets_s == (0.0, ISSUE_1_S)
    assert seq.start_unix_s == w0.start_unix_s and seq.dated
    assert seq.duration_s == ISSUE_1_S + HOURS * 3600.0
    for lat, lon, depth in POINTS:
        for t in (-600.0, 0.0, 3600.0, 2.5 * 3600.0, ISSUE_1_S - 1.0):  # before issue 1: issue 0 at the same time
            assert seq.current_at(t, lat, lon, depth) == w0.current_at(t, lat, lon, depth)
            assert seq.source_at(t) == w0.source
        for t in (ISSUE_1_S, ISSUE_1_S + 1.0, 12 * 3600.0, 35 * 3600.0, 50 * 3600.0):  # from then on: issue 1
            assert seq.current_at(t, lat, lon, depth) == w1.current_at(t - ISSUE_1_S, lat, lon, depth)
            assert seq.is_water(lat, lon, depth, t) == w1.is_water(lat, lon, depth, t - ISSUE_1_S)
            assert seq.source_at(t) == w1.source
    # The switch is real: the two issues disagree at the same absolute time.
    t = 9 * 3600.0
    assert seq.current_at(t, LAT, LON, 0.0) != w0.current_at(t, LAT, LON, 0.0)
    assert _box(seq.bbox) == _box(w0.bbox) and seq.max_depth_m == w0.max_depth_m


def test_the_issues_match_the_generator_at_absolute_times(issues):
    from planner.forecast.synthetic.scb import SyntheticSettings, current_at

    settings = SyntheticSettings(seed=0, hours=HOURS)
    seq = load_truth(issues)
    # A grid node at whole hours and a level: the interpolation returns the node (the file's float32).
    for t_s, issue in ((3 * 3600.0, 0), (5 * 3600.0, 0), (6 * 3600.0, 1), (9 * 3600.0, 1)):
        want = [float(x) for x in current_at(settings, t_s, LON, LAT, 5.0, issue_number=issue)]
        assert seq.current_at(t_s, LAT, LON, 5.0) == pytest.approx(want, abs=1e-6)


def test_a_one_file_sequence_is_the_plain_world(issues, worlds):
    w0 = worlds[0]
    one = TruthSequence((w0,))
    for lat, lon, depth in POINTS:
        for t in (-10.0, 0.0, 4321.0, 40 * 3600.0):
            assert one.current_at(t, lat, lon, depth) == w0.current_at(t, lat, lon, depth)
            assert one.is_water(lat, lon, depth, t) == w0.is_water(lat, lon, depth, t)
    assert (one.start_unix_s, one.duration_s, _box(one.bbox), one.max_depth_m, one.source, one.dated) == (
        w0.start_unix_s, w0.duration_s, _box(w0.bbox), w0.max_depth_m, w0.source, w0.dated)
    loaded = load_truth([issues[0]])
    assert isinstance(loaded, World) and loaded.current_at(100.0, LAT, LON, 2.0) == w0.current_at(100.0, LAT, LON, 2.0)


def test_a_directory_is_every_nc_file_in_it(tmp_path, issues):
    d = tmp_path / "dir"
    d.mkdir()
    shutil.copy(issues[1], d / "a_newer.nc")  # name order is not start order
    (d / "notes.txt").write_text("not a forecast")
    single = load_truth([d])
    assert isinstance(single, World)
    shutil.copy(issues[0], d / "b_older.nc")
    seq = load_truth([d])
    assert isinstance(seq, TruthSequence)
    assert [Path(w.source).name for w in seq.members] == ["b_older.nc", "a_newer.nc"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(WorldError, match=r"no \*\.nc files"):
        load_truth([empty])


def test_bad_members_are_named(tmp_path, issues):
    undated = _undated_copy(issues[1], tmp_path / "undated.nc")
    assert not World.load(undated).dated  # alone it is still a usable (undated) truth
    with pytest.raises(WorldError, match="undated.nc.*no reference date"):
        load_truth([issues[0], undated])
    twin = shutil.copy(issues[0], tmp_path / "twin.nc")
    with pytest.raises(WorldError, match="same time"):
        load_truth([issues[0], twin])
    with pytest.raises(WorldError, match="at least one"):
        TruthSequence(())


def _box_world(west: float, east: float, start_unix_s: float, u: float) -> World:
    shape = (2, 2, 3, 4)
    return World(source=f"box {west:g}..{east:g}", time_s=(0.0, 3600.0), depth_m=(0.0, 10.0),
                 lat_deg=(30.0, 31.0, 32.0), lon_deg=tuple(np.linspace(west, east, 4).tolist()),
                 u_east_m_s=np.full(shape, u), v_north_m_s=np.zeros(shape), start_unix_s=start_unix_s, dated=True,
                 duration_s=3600.0, depth_covered_m=10.0)


def test_members_need_not_share_a_grid_but_must_share_an_area():
    a = _box_world(-120.0, -116.0, 1e9, 0.1)
    b = _box_world(241.0, 245.0, 1e9 + 7200.0, 0.2)  # 0..360 longitudes: -119..-115
    seq = TruthSequence((a, b))
    assert (seq.bbox.west_deg, seq.bbox.east_deg) == (-119.0, -116.0)
    assert seq.current_at(3600.0, 31.0, -117.0, 5.0) == pytest.approx((0.1, 0.0))
    assert seq.current_at(7200.0, 31.0, -117.0, 5.0) == pytest.approx((0.2, 0.0))
    assert seq.current_at(7200.0, 31.0, -119.5, 5.0) == (0.0, 0.0)  # outside b: no water
    with pytest.raises(WorldError, match=r"box 0\.\.10: shares no lon/lat area"):
        TruthSequence((a, _box_world(0.0, 10.0, 2e9, 0.3)))


# -- the command line ----------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", ["missing", "undated", "not_netcdf", "empty_dir"])
def test_cli_bad_member_is_one_line_naming_the_file_and_status_2(tmp_path, issues, bad):
    path = tmp_path / f"{bad}.nc"
    if bad == "undated":
        _undated_copy(issues[1], path)
    elif bad == "not_netcdf":
        path.write_text("hello\n")
    elif bad == "empty_dir":
        path = tmp_path / "empty_dir"
        path.mkdir()
    done = sim_cli("--forecast", str(issues[0]), "--forecast", str(path), "--start", f"{LON},{LAT}",
                "--listen", "127.0.0.1:0", "--duration-s", "1")
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lrauv sim: error: ") and done.stdout == ""
    assert str(path) in lines[0] and "Traceback" not in done.stderr


def test_cli_runs_on_a_sequence_past_the_first_issue(tmp_path, issues):
    track = tmp_path / "t.csv"
    # 34 h after issue 0's start: beyond issue 0 (30 h), inside issue 1 (6..36 h).
    done = sim_cli("--forecast", str(issues[1]), "--forecast", str(issues[0]), "--start", f"{LON},{LAT}",
                "--start-time", "2026-01-16T10:00:00Z", "--speedup", "1e9", "--no-lockstep", "--listen", "127.0.0.1:0",
                "--duration-s", "30", "--track", str(track), "--quiet")
    assert done.returncode == 0, done.stderr
    assert len(track.read_text().splitlines()) == 1 + 31
    late = sim_cli("--forecast", str(issues[0]), "--forecast", str(issues[1]), "--start", f"{LON},{LAT}",
                "--start-time", "2026-01-16T13:00:00Z", "--listen", "127.0.0.1:0", "--duration-s", "1")
    assert late.returncode == 2 and "outside the forecast" in late.stderr
