"""Forecasts on an OPeNDAP server: a DAP 2.0 server on 127.0.0.1 (tests/support/dap_server.py) and
netCDF-C's own DAP client, the part a plan needs copied into the cache."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from planner.cli import main
from planner.contract.errors import ForecastError
from planner.contract.geodesy import BBox
from planner.contract.table import PolicyTable
from planner.forecast import open_forecast
from planner.forecast.opendap import fetch_opendap, fetch_source, is_opendap
from tests.planner.forecast.test_remote import server  # noqa: F401 (the plain HTTP server fixture)
from tests.support.dap_server import DapServer, dap_server

PLAN = ["--bbox", "-118.10,33.35,-117.85,33.55", "--nx", "13", "--ny", "11", "--depths", "0,5",
        "--goal", "-117.95,33.45,0"]


@pytest.fixture()
def served(synthetic_forecast, tmp_path) -> Iterator[tuple[DapServer, str]]:
    folder = tmp_path / "dap"
    folder.mkdir()
    shutil.copy(synthetic_forecast, folder / "scb.nc")
    with dap_server(folder) as server:
        yield server, server.url("scb.nc")


def test_a_dap_dataset_reads_as_the_file_it_serves(served, synthetic_forecast, tmp_path):
    server, url = served
    assert is_opendap(url) and not is_opendap(url.replace("scb.nc", "none.nc"))
    fetched = fetch_opendap(url, tmp_path / "cache")
    assert fetched.downloaded and fetched.path.parent == tmp_path / "cache" / "forecasts"
    remote, local = open_forecast(fetched.path), open_forecast(synthetic_forecast)
    for a, b in ((remote.u_east_m_s, local.u_east_m_s), (remote.v_north_m_s, local.v_north_m_s)):
        assert np.array_equal(a, b, equal_nan=True) and np.isnan(a).any()  # land comes through as NaN
    assert np.array_equal(remote.time_s, local.time_s) and remote.time_origin == local.time_origin
    again = fetch_opendap(url, tmp_path / "cache")  # unchanged on the server: the copy is reused
    assert not again.downloaded and again.path == fetched.path and again.identity == fetched.identity
    assert server.requests["dods"] > 0 and server.requests["file"] == 0  # DAP requests only


def test_a_plan_over_dap_reads_only_its_region_and_plans_as_the_file(served, synthetic_forecast, tmp_path, capsys):
    server, url = served
    cache = tmp_path / "cache"
    assert main(["plan", "--forecast", url, *PLAN, "--cache-dir", str(cache), "--out", str(tmp_path / "dap.lrpt")]) == 0
    assert "cache      " + url in capsys.readouterr().out.replace("\n", " ")
    assert main(["plan", "--forecast", str(synthetic_forecast), *PLAN, "--out", str(tmp_path / "file.lrpt")]) == 0
    dap, file = PolicyTable.load(tmp_path / "dap.lrpt"), PolicyTable.load(tmp_path / "file.lrpt")
    assert np.array_equal(dap.actions, file.actions) and np.array_equal(dap.water, file.water)
    [copy] = (cache / "forecasts").glob("*.dap.nc")
    part = open_forecast(copy)
    whole = open_forecast(synthetic_forecast)
    assert part.u_east_m_s.shape[-1] < whole.u_east_m_s.shape[-1] and part.u_east_m_s.shape[-2] < whole.u_east_m_s.shape[-2]  # a window, not the file
    assert part.lon_deg[0] <= -118.10 and part.lon_deg[-1] >= -117.85  # that covers the bbox
    assert part.lat_deg[0] <= 33.35 and part.lat_deg[-1] >= 33.55


def test_forecast_info_reads_a_dap_url_as_the_file(served, synthetic_forecast, tmp_path, capsys):
    _server, url = served
    assert main(["forecast", "info", url, "--cache-dir", str(tmp_path / "cache")]) == 0
    remote = capsys.readouterr().out.splitlines()
    assert main(["forecast", "info", str(synthetic_forecast)]) == 0
    local = capsys.readouterr().out.splitlines()
    body = [line for line in local if line.startswith(("time:", "depth:", "lon:", "land:", "speed:"))]
    assert len(body) == 5 and all(line in remote for line in body)


def test_what_is_not_a_dap_dataset_says_so(served, tmp_path):
    server, url = served
    bad = url.replace("scb.nc", "none.nc")
    with pytest.raises(ForecastError, match=r"none\.nc: not an OPeNDAP dataset"):
        fetch_opendap(bad, tmp_path / "cache")
    with pytest.raises(ForecastError, match=r"none\.nc"):  # neither DAP nor a file: the download's own error
        fetch_source(bad, tmp_path / "cache")
    outside = BBox(west_deg=10.0, south_deg=10.0, east_deg=11.0, north_deg=11.0)
    with pytest.raises(ForecastError, match="lies outside the forecast"):
        fetch_opendap(url, tmp_path / "cache", bbox=outside)
    assert not list((tmp_path / "cache").rglob("*.nc"))  # nothing half-written


def test_a_plain_netcdf_url_is_still_downloaded_whole(server, synthetic_forecast, tmp_path):
    """A server that is not DAP (the .dds probe gets 404): the URL is the file, as before."""
    base, root, requests = server
    shutil.copy(synthetic_forecast, root / "scb.nc")
    fetched = fetch_source(f"{base}/scb.nc", tmp_path / "cache")
    assert fetched.path.read_bytes() == Path(synthetic_forecast).read_bytes()
    assert [path for path, _ in requests] == ["/scb.nc.dds", "/scb.nc"]


def test_a_mission_whose_forecast_is_a_dap_url_plans_its_region(served, tmp_path, capsys):
    from tests.support import REPO

    _server, url = served
    text = (REPO / "missions" / "demo.yaml").read_text()
    synthetic = "  synthetic: {seed: 0, hours: 72}\n"
    assert synthetic in text
    mission = tmp_path / "dap.yaml"
    mission.write_text(text.replace(synthetic, f"  file: {url}\n"))
    cache = tmp_path / "cache"
    assert main(["plan", str(mission), "--cache-dir", str(cache), "--out", str(tmp_path / "t.lrpt"), "--quiet"]) == 0
    table = PolicyTable.load(tmp_path / "t.lrpt")
    assert table.nx == 29 and table.ny == 21  # the mission's region, from the dataset's copy
    assert len(list((cache / "forecasts").glob("*.dap.nc"))) == 1
