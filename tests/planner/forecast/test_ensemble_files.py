"""planner.forecast.synthetic.ensemble: synthetic forecast ensembles in one CF file with a ``member`` dimension.

Files are written to tmp_path and read back with netCDF4 (raw values, no
decoding) and xarray; a member selected with xarray and written alone is read by
``planner.forecast.open_forecast`` like any model file.
"""

from __future__ import annotations

import argparse
import pathlib
from dataclasses import replace

import netCDF4
import numpy as np
import pytest
import xarray as xr

from planner.forecast.synthetic import ensemble
from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre
from planner.forecast.synthetic.ensemble import (
    MEMBER_DIM,
    gyre_ensemble,
    scb_ensemble,
    write_gyre_ensemble,
    write_scb_ensemble,
)
from planner.cli.forecast import write_ensemble_from_args
from planner.contract.errors import LrauvError
from planner.forecast import open_forecast
from planner.forecast.synthetic.scb import SyntheticSettings, _forecast_scene, synthesize, write_synthetic

GYRE = DoubleGyreSettings(hours=6.0)
SCB = SyntheticSettings(seed=3, hours=6)
DIMS = (MEMBER_DIM, "time", "depth", "lat", "lon")


def _raw(path: pathlib.Path, name: str) -> np.ndarray:
    """A variable's stored values (no masking or scaling: _FillValue is NaN, so land is already NaN)."""
    with netCDF4.Dataset(path) as nc:
        nc.set_auto_maskandscale(False)
        return np.asarray(nc[name][:])


def _attrs(path: pathlib.Path) -> dict[str, object]:
    with netCDF4.Dataset(path) as nc:
        return {k: nc.getncattr(k) for k in nc.ncattrs()}


@pytest.fixture(scope="module")
def gyre_file(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    return write_gyre_ensemble(tmp_path_factory.mktemp("gyre") / "gyre_ens.nc", GYRE, 4, seed=7, spread=0.2)


@pytest.fixture(scope="module")
def scb_file(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    return write_scb_ensemble(tmp_path_factory.mktemp("scb") / "scb_ens.nc", SCB, 3, issue=1)


# --------------------------------------------------------------------------- layout


@pytest.mark.parametrize("kind", ["gyre", "scb"])
def test_shapes_and_member_coordinate(kind: str, gyre_file: pathlib.Path, scb_file: pathlib.Path) -> None:
    path, n, ny, nx = (gyre_file, 4, 34, 81) if kind == "gyre" else (scb_file, 3, 41, 57)
    with netCDF4.Dataset(path) as nc:
        for name in ("u", "v"):
            assert nc[name].dimensions == DIMS
            assert nc[name].shape == (n, 7, 4, ny, nx)
            assert nc[name].dtype == np.float32
            assert nc[name].chunking() == [1, 1, 4, ny, nx]
        member = nc[MEMBER_DIM]
        assert member.dimensions == (MEMBER_DIM,) and member.dtype == np.int32
        assert member[:].tolist() == list(range(n))
        assert member.getncattr("standard_name") == "realization"
        assert "_FillValue" not in member.ncattrs()
        attrs = {k: nc.getncattr(k) for k in nc.ncattrs()}
    assert attrs["Conventions"] == "CF-1.8"
    assert int(attrs["ensemble_members"]) == n
    assert "default_rng" in attrs["ensemble_method"]
    with xr.open_dataset(path) as ds:  # decodes like a model file: CF time, member coordinate
        assert ds["u"].dims == DIMS
        assert ds[MEMBER_DIM].values.tolist() == list(range(n))
        assert str(ds["time"].dtype).startswith("datetime64")


def test_gyre_member_parameters_are_recorded(gyre_file: pathlib.Path) -> None:
    members = gyre_ensemble(GYRE, 4, seed=7, spread=0.2)
    assert _raw(gyre_file, "member_eps").tolist() == [s.eps for s in members]
    assert _raw(gyre_file, "member_phase_rad").tolist() == [s.phase_rad for s in members]
    assert _raw(gyre_file, "member_peak_speed_m_s").tolist() == [s.peak_speed_m_s for s in members]
    attrs = _attrs(gyre_file)
    assert int(attrs["ensemble_seed"]) == 7 and attrs["ensemble_spread"] == 0.2
    assert "gyre_eps" not in attrs and attrs["settings"] == repr(GYRE)


# --------------------------------------------------------------------------- members


def test_gyre_members_equal_single_files_bit_for_bit(gyre_file: pathlib.Path, tmp_path: pathlib.Path) -> None:
    for m, settings in enumerate(gyre_ensemble(GYRE, 4, seed=7, spread=0.2)):
        single = write_gyre(tmp_path / f"m{m}.nc", settings)
        for name in ("u", "v"):
            assert _raw(gyre_file, name)[m].tobytes() == _raw(single, name).tobytes(), (m, name)
        for name in ("time", "depth", "lat", "lon"):
            assert _raw(gyre_file, name).tobytes() == _raw(single, name).tobytes(), name


def test_scb_members_equal_single_files_bit_for_bit(scb_file: pathlib.Path, tmp_path: pathlib.Path) -> None:
    assert _raw(scb_file, "member_error_draw").tolist() == [0, 1, 2]
    for m, settings in enumerate(scb_ensemble(SCB, 3)):
        assert settings == replace(SCB, error_draw=m)
        single = write_synthetic(tmp_path / f"m{m}.nc", settings, issue_number=1)
        assert int(_attrs(single)["error_draw"]) == m
        for name in ("u", "v"):
            assert _raw(scb_file, name)[m].tobytes() == _raw(single, name).tobytes(), (m, name)
        for name in ("time", "depth", "lat", "lon", "h"):
            assert _raw(scb_file, name).tobytes() == _raw(single, name).tobytes(), name


@pytest.mark.parametrize("kind", ["gyre", "scb"])
def test_members_differ(kind: str, gyre_file: pathlib.Path, scb_file: pathlib.Path) -> None:
    u = _raw(gyre_file if kind == "gyre" else scb_file, "u")
    for a in range(u.shape[0]):
        for b in range(a):
            assert not np.array_equal(u[a], u[b], equal_nan=True), (a, b)


def test_gyre_draws_are_as_documented() -> None:
    base = DoubleGyreSettings(eps=0.3, peak_speed_m_s=0.4, phase_rad=1.0, period_h=10.0)
    members = gyre_ensemble(base, 200, seed=1, spread=0.25)
    eps = np.array([s.eps for s in members])
    phase = np.array([s.phase_rad for s in members])
    peak = np.array([s.peak_speed_m_s for s in members])
    assert eps.min() >= 0.0 and eps.max() <= 0.5 and eps.max() > 0.45  # U[0, min(2 eps, 0.5)]
    assert phase.min() >= 0.0 and phase.max() < 2 * np.pi and np.ptp(phase) > 5.5
    assert peak.min() >= 0.4 * 0.75 and peak.max() <= 0.4 * 1.25 and np.ptp(peak) > 0.15
    assert {replace(s, eps=base.eps, phase_rad=base.phase_rad, peak_speed_m_s=base.peak_speed_m_s)
            for s in members} == {base}
    # Member after member from one generator: a smaller ensemble is a prefix of a larger one.
    assert gyre_ensemble(base, 5, seed=1, spread=0.25) == members[:5]
    steady = gyre_ensemble(replace(base, eps=0.0), 3, seed=1, spread=0.0)
    assert all(s.eps == 0.0 and s.peak_speed_m_s == 0.4 for s in steady)


def test_scb_members_have_the_documented_error_size(tmp_path: pathlib.Path) -> None:
    settings = SyntheticSettings(seed=5, hours=12)
    truth_path = write_synthetic(tmp_path / "truth.nc", settings)
    ut, vt = _raw(truth_path, "u"), _raw(truth_path, "v")
    for issue in (0, 2):
        path = write_scb_ensemble(tmp_path / f"ens{issue}.nc", settings, 3, issue=issue)
        u, v = _raw(path, "u"), _raw(path, "v")
        offset = issue * int(settings.issue_interval_h)  # member hour h is truth hour h + offset
        keep = ut.shape[0] - offset
        target = settings.error_scale * settings.error_decay**issue
        assert float(_attrs(path)["error_relative_rms"]) == target
        truth_ms = np.nanmean(ut[offset:] ** 2 + vt[offset:] ** 2)
        for m in range(u.shape[0]):
            assert np.array_equal(np.isnan(u[m, :keep]), np.isnan(ut[offset:]))
            error_ms = np.nanmean((u[m, :keep] - ut[offset:]) ** 2 + (v[m, :keep] - vt[offset:]) ** 2)
            assert np.sqrt(error_ms / truth_ms) == pytest.approx(target, rel=0.05), (issue, m)


def test_a_member_reads_as_a_single_forecast(scb_file: pathlib.Path, tmp_path: pathlib.Path) -> None:
    with xr.open_dataset(scb_file) as ds:
        one = ds.isel({MEMBER_DIM: 2}).load()
    one.to_netcdf(tmp_path / "member2.nc")
    forecast = open_forecast(tmp_path / "member2.nc")
    assert forecast.shape == (7, 4, 41, 57)
    assert np.array_equal(forecast.u_east_m_s.astype(np.float32), _raw(scb_file, "u")[2], equal_nan=True)
    assert np.array_equal(forecast.v_north_m_s.astype(np.float32), _raw(scb_file, "v")[2], equal_nan=True)


# --------------------------------------------------------------------------- determinism, atomicity


def test_same_seed_same_file_other_seed_differs(tmp_path: pathlib.Path) -> None:
    a = write_gyre_ensemble(tmp_path / "a.nc", GYRE, 3, seed=2).read_bytes()
    b = write_gyre_ensemble(tmp_path / "b.nc", GYRE, 3, seed=2).read_bytes()
    c = write_gyre_ensemble(tmp_path / "c.nc", GYRE, 3, seed=3)
    assert a == b
    assert not np.array_equal(_raw(tmp_path / "a.nc", "u"), _raw(c, "u"))
    d = write_scb_ensemble(tmp_path / "d.nc", SCB, 2).read_bytes()
    e = write_scb_ensemble(tmp_path / "e.nc", SCB, 2).read_bytes()
    f = write_scb_ensemble(tmp_path / "f.nc", replace(SCB, seed=4), 2)
    assert d == e
    assert not np.array_equal(_raw(tmp_path / "d.nc", "u"), _raw(f, "u"), equal_nan=True)


def test_atomic_write_replaces_in_place_and_failure_keeps_the_old_file(
    tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "sub" / "ens.nc"  # a missing parent folder is created
    assert write_gyre_ensemble(target, GYRE, 2, seed=0) == target
    write_gyre_ensemble(target, GYRE, 3, seed=0)
    assert sorted(p.name for p in target.parent.iterdir()) == ["ens.nc"]
    assert _raw(target, "u").shape[0] == 3
    before = target.read_bytes()

    def boom(self: xr.Dataset, *args: object, **kwargs: object) -> None:
        pathlib.Path(args[0]).write_bytes(b"partial")  # type: ignore[arg-type]
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", boom)
    for write in (lambda: write_gyre_ensemble(target, GYRE, 2, seed=1), lambda: write_scb_ensemble(target, SCB, 2)):
        with pytest.raises(OSError, match="disk full"):
            write()
        assert sorted(p.name for p in target.parent.iterdir()) == ["ens.nc"]
        assert target.read_bytes() == before


# --------------------------------------------------------------------------- bad arguments


@pytest.mark.parametrize(("call", "name"), [
    (lambda: gyre_ensemble(GYRE, 0, seed=0), "members"),
    (lambda: gyre_ensemble(GYRE, 2.0, seed=0), "members"),  # type: ignore[arg-type]
    (lambda: gyre_ensemble(GYRE, True, seed=0), "members"),
    (lambda: gyre_ensemble(GYRE, ensemble.MAX_MEMBERS + 1, seed=0), "members"),
    (lambda: gyre_ensemble(GYRE, 2, seed=-1), "seed"),
    (lambda: gyre_ensemble(GYRE, 2, seed="1"), "seed"),  # type: ignore[arg-type]
    (lambda: gyre_ensemble(GYRE, 2, seed=0, spread=1.0), "spread"),
    (lambda: gyre_ensemble(GYRE, 2, seed=0, spread=-0.1), "spread"),
    (lambda: gyre_ensemble(GYRE, 2, seed=0, spread=float("nan")), "spread"),
    (lambda: gyre_ensemble(SCB, 2, seed=0), "settings"),  # type: ignore[arg-type]
    (lambda: scb_ensemble(GYRE, 2), "settings"),  # type: ignore[arg-type]
    (lambda: scb_ensemble(replace(SCB, error_draw=1), 2), "error_draw"),
    (lambda: scb_ensemble(SCB, -3), "members"),
    (lambda: write_scb_ensemble("unused.nc", SCB, 2, issue=-1), "issue"),
    (lambda: write_scb_ensemble("unused.nc", SCB, 2, issue=1.0), "issue"),  # type: ignore[arg-type]
    (lambda: SyntheticSettings(error_draw=-1), "error_draw"),
    (lambda: SyntheticSettings(error_draw=True), "error_draw"),
])
def test_bad_arguments_name_the_argument(call, name: str, tmp_path: pathlib.Path,  # type: ignore[no-untyped-def]
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(LrauvError, match=f"`{name}`|{name}"):
        call()
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- planner.forecast.synthetic.scb unchanged


def test_synthetic_files_without_error_draw_are_unchanged() -> None:
    """``error_draw`` is new: settings without it keep their repr, attributes and random draws."""
    settings = SyntheticSettings()
    assert settings == SyntheticSettings(error_draw=None)
    assert repr(settings) == (
        "SyntheticSettings(seed=0, hours=72, spacing_deg=0.01, depths_m=(0.0, 5.0, 10.0, 15.0), "
        "issue_time='2026-01-15T00:00:00Z', west_deg=-118.26, south_deg=33.3, east_deg=-117.7, north_deg=33.7, "
        "n_eddies=4, eddy_radius_km=(3.0, 8.0), eddy_speed_m_s=(0.12, 0.28), eddy_drift_m_s=0.03, "
        "shelf_speed_m_s=-0.12, shelf_jet_km=3.0, background_speed_m_s=0.08, tide_m2_m_s=0.06, tide_k1_m_s=0.03, "
        "n_waves=6, wave_speed_m_s=0.03, depth_efold_m=20.0, veer_deg_per_m=1.5, max_speed_m_s=0.5, "
        "shelf_slope_nw_m_per_km=6.0, shelf_slope_se_m_per_km=25.0, basin_depth_m=600.0, shoal_lon_deg=-118.1, "
        "shoal_lat_deg=33.5, shoal_crest_m=8.0, shoal_radius_km=2.5, error_scale=0.3, error_decay=0.5, "
        "issue_interval_h=6.0)")
    small = SyntheticSettings(seed=9, hours=2)
    attrs = synthesize(small, issue_number=2).attrs
    assert "error_draw" not in attrs and attrs["settings"] == repr(small)
    assert attrs["history"] == ("created by planner.forecast.synthetic.scb v1.0, seed=9, issue=2; deterministic, "
                                "no wall-clock time")
    # Issue n's default draw is still default_rng([seed, 1, n]): its first draws are the extra waves' wavelengths.
    nw = small.n_waves
    for n in (0, 2):
        scene = _forecast_scene(small, n)
        wavelength_km = 2 * np.pi / np.hypot(scene.wave_kx[nw:], scene.wave_ky[nw:])
        expected = np.random.default_rng([small.seed, 1, n]).uniform(8.0, 30.0, size=nw)
        np.testing.assert_allclose(wavelength_km, expected, rtol=1e-12)
        other = _forecast_scene(replace(small, error_draw=0), n)
        assert not np.allclose(other.wave_kx[nw:], scene.wave_kx[nw:])
    member = synthesize(replace(small, error_draw=4), issue_number=2).attrs
    assert int(member["error_draw"]) == 4 and member["settings"] == f"{repr(small)[:-1]}, error_draw=4)"
    assert "error draw 4" in member["history"]


# --------------------------------------------------------------------------- command line


def _args(**kwargs: object) -> argparse.Namespace:
    names = ("kind", "members", "seed", "hours", "peak_speed_m_s", "eps", "spread", "period_h", "step_h",
             "spacing_deg", "bbox", "depths", "issue_time", "issue")
    defaults: dict[str, object] = dict.fromkeys(names)
    defaults.update(members=2, seed=0)
    defaults.update(kwargs)
    return argparse.Namespace(**defaults)


def test_write_ensemble_from_args(tmp_path: pathlib.Path) -> None:
    gyre = write_ensemble_from_args(_args(out=tmp_path / "g.nc", kind="gyre", members=3, seed=5, hours=4.0,
                                          eps=0.2, peak_speed_m_s=0.3, spread=0.1))
    expected = gyre_ensemble(DoubleGyreSettings(hours=4.0, eps=0.2, peak_speed_m_s=0.3), 3, seed=5, spread=0.1)
    assert _raw(gyre, "member_eps").tolist() == [s.eps for s in expected]
    assert _raw(gyre, "u").shape == (3, 5, 4, 34, 81)
    scb = write_ensemble_from_args(_args(out=tmp_path / "s.nc", kind="scb", seed=1, hours=3.0, issue=2))
    attrs = _attrs(scb)
    assert int(attrs["issue_number"]) == 2 and int(attrs["seed"]) == 1
    assert _raw(scb, "u").shape == (2, 4, 4, 41, 57)


@pytest.mark.parametrize(("changes", "option"), [
    ({"kind": "gyre", "members": 0}, "--members"),
    ({"kind": "gyre", "seed": -1}, "--seed"),
    ({"kind": "gyre", "spread": 1.5}, "--spread"),
    ({"kind": "gyre", "eps": 0.9}, "--eps"),
    ({"kind": "gyre", "peak_speed_m_s": -1.0}, "--peak-speed-m-s"),
    ({"kind": "gyre", "issue": 1}, "--issue"),
    ({"kind": "scb", "eps": 0.1}, "--eps"),
    ({"kind": "scb", "hours": 2.5}, "--hours"),
    ({"kind": "scb", "seed": -2}, "--seed"),
    ({"kind": "scb", "issue": -1}, "--issue"),
    ({"kind": "scb", "members": 0}, "--members"),
    ({"kind": "roms"}, "--kind"),
])
def test_bad_options_name_the_option(changes: dict, option: str, tmp_path: pathlib.Path) -> None:
    with pytest.raises(LrauvError, match=f"^{option}: "):
        write_ensemble_from_args(_args(out=tmp_path / "x.nc", **changes))
    assert list(tmp_path.iterdir()) == []


def test_cli_forecast_ensemble_when_wired(tmp_path: pathlib.Path) -> None:
    from planner.cli import build_parser, main

    parser = build_parser()
    forecast = next(a for a in parser._subparsers._group_actions[0].choices["forecast"]._actions  # type: ignore[union-attr]
                    if isinstance(a, argparse._SubParsersAction))
    if "ensemble" not in forecast.choices:
        pytest.skip("lrauv forecast ensemble is not in planner/cli.py yet")
    out = tmp_path / "ens.nc"
    assert main(["forecast", "ensemble", str(out), "--kind", "gyre", "--members", "2", "--seed", "3",
                 "--hours", "2", "--spread", "0.1"]) == 0
    assert _raw(out, "u").shape == (2, 3, 4, 34, 81)
    assert main(["forecast", "ensemble", str(out), "--kind", "scb", "--members", "2", "--hours", "2",
                 "--issue", "1"]) == 0
    assert int(_attrs(out)["issue_number"]) == 1
    assert main(["forecast", "ensemble", str(out), "--kind", "scb", "--members", "2", "--eps", "0.1"]) == 2
