"""Forecasts from http(s) URLs: a real HTTP server on 127.0.0.1 (ephemeral port) serving real netCDF files."""

from __future__ import annotations

import functools
import http.server
import json
import re
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from planner.cli import main
from planner.contract.errors import ForecastError
from planner.forecast import file_identity, forecast_times, open_forecast
from planner.forecast.remote import fetch, is_url


class _Handler(http.server.SimpleHTTPRequestHandler):
    """The standard library's file server (it answers If-Modified-Since with 304), counting requests, quiet."""

    requests: list[tuple[str, str]] = []

    def do_GET(self) -> None:  # noqa: N802  (http.server's name)
        type(self).requests.append((self.path, self.headers.get("If-Modified-Since") or ""))
        super().do_GET()

    def log_message(self, format: str, *args: object) -> None:  # noqa: A002
        pass


@pytest.fixture()
def server(tmp_path) -> Iterator[tuple[str, Path, list[tuple[str, str]]]]:
    """(base URL, served folder, requests seen) of an HTTP server on 127.0.0.1, stopped after the test."""
    root = tmp_path / "www"
    root.mkdir()
    handler = type("Handler", (_Handler,), {"requests": []})
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(handler, directory=str(root)))
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}", root, handler.requests
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join()


def test_a_url_is_downloaded_to_the_cache_once_and_read_as_the_file(server, synthetic_forecast, tmp_path):
    base, root, requests = server
    (root / "scb.nc").write_bytes(synthetic_forecast.read_bytes())
    url = f"{base}/scb.nc"
    cache = tmp_path / "cache"
    first = fetch(url, cache)
    assert first.downloaded and first.path.parent == cache / "forecasts" and first.path.name.endswith("-scb.nc")
    assert first.path.read_bytes() == synthetic_forecast.read_bytes()
    assert first.identity == file_identity(synthetic_forecast)
    meta = json.loads(first.path.with_name(first.path.name + ".json").read_text())
    assert meta["url"] == url and meta["identity"] == first.identity and meta["last_modified"]
    # Asked again: a conditional GET, answered 304 by the server, reuses the copy.
    again = fetch(url, cache)
    assert not again.downloaded and again.path == first.path and again.identity == first.identity
    assert [r[1] != "" for r in requests] == [False, True]
    assert list(cache.rglob("*.tmp")) == []


def test_open_forecast_reads_a_url_with_the_url_as_its_source(server, synthetic_forecast):
    base, root, _ = server
    (root / "scb.nc").write_bytes(synthetic_forecast.read_bytes())
    url = f"{base}/scb.nc"  # the cache is the suite's (LRAUV_CACHE_DIR, tests/conftest.py)
    remote, local = open_forecast(url, time_index=2), open_forecast(synthetic_forecast, time_index=2)
    assert remote.source == url and remote.identity == local.identity
    assert np.array_equal(remote.u_east_m_s, local.u_east_m_s, equal_nan=True)
    assert np.array_equal(forecast_times(url).time_s, forecast_times(synthetic_forecast).time_s)


def test_lrauv_forecast_info_takes_a_url_unmangled(server, synthetic_forecast, tmp_path, capsys):
    base, root, _ = server
    (root / "scb.nc").write_bytes(synthetic_forecast.read_bytes())
    url = f"{base}/scb.nc"
    assert is_url(url) and not is_url(Path(url)) and not is_url("scb.nc")
    assert main(["forecast", "info", url, "--cache-dir", str(tmp_path / "c")]) == 0
    out = capsys.readouterr().out
    words = " ".join(out.split())  # lines over 100 columns wrap under their value
    assert out.startswith("cache      ") and f"{url} -> {tmp_path / 'c' / 'forecasts'}" in words and "downloaded" in words


@pytest.mark.parametrize(("name", "body", "expected"), [
    ("missing.nc", None, r"missing.nc: HTTP 404 File not found; expected a netCDF forecast file at that URL"),
    ("page.html", b"<html><body>OPeNDAP Dataset Access Form</body></html>",
     r"page.html: the server sent text/html starting '<html><body>OPeNDAP Dataset Access Form<', not a netCDF file"),
], ids=["404", "html"])
def test_a_bad_url_is_one_line_and_exit_2(server, tmp_path, capsys, name, body, expected):
    base, root, _ = server
    if body is not None:
        (root / name).write_bytes(body)
    cache = tmp_path / "cache"
    assert main(["plan", "missions/demo.yaml", "--forecast", f"{base}/{name}", "--cache-dir", str(cache),
                 "--out", str(tmp_path / "t.lrpt"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"lrauv: error: {base}/")
    assert re.search(expected, err), err
    assert not (tmp_path / "t.lrpt").exists()
    assert [p.name for p in cache.rglob("*") if p.is_file()] == []  # nothing half-written left in the cache


def test_an_unreachable_server_is_named(tmp_path):
    import socket

    with socket.socket() as s:  # a port nobody listens on: bound, never listening
        s.bind(("127.0.0.1", 0))
        url = f"http://127.0.0.1:{s.getsockname()[1]}/f.nc"
        with pytest.raises(ForecastError, match=r"f.nc: cannot download \(.*refused.*\); check the URL"):
            fetch(url, tmp_path)
