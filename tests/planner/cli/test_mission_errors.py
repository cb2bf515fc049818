"""A mission's errors name its file and line, also those found after loading (a forecast that is not there, a goal
on land in `lrauv batch` or `lrauv upload`); a mission's ``forecast.file`` may be an http(s) URL. Through
``planner.cli.main`` as a user types it, on small missions beside the test."""

from __future__ import annotations

from pathlib import Path

import pytest

from planner.cli import main
from planner.contract.mission import load_mission
from tests.planner.cli.test_frictions import error_line
from tests.planner.forecast.test_remote import server  # noqa: F401  (the HTTP server fixture)
from tests.support import REPO

SYNTHETIC = "  synthetic: {seed: 0, hours: 72}\n"
MISSING = "  file: missing.nc\n"
EMPTY_DIR = "  directory: empty\n"
URL_FILE = "  file: HTTPS://example.org/fc/scb.nc\n"
SECOND_GOAL = "  - {lat_deg: 33.40, lon_deg: -117.84, depth_m: 0, radius_cells: 1, on_arrival: hold}\n"
ON_LAND = "  - {lat_deg: 33.65, lon_deg: -117.75, depth_m: 0}\n"  # as in test_frictions
QUICK = ["--scheduler=in-process", "--quiet"]  # no Dask cluster to start


def two_goals(folder: Path, name: str, *, forecast: str = SYNTHETIC, second: str = SECOND_GOAL) -> Path:
    """missions/two-goals.yaml with its forecast source and second goal replaced."""
    text = (REPO / "missions" / "two-goals.yaml").read_text()
    assert SYNTHETIC in text and SECOND_GOAL in text
    path = folder / f"{name}.yaml"
    path.write_text(text.replace(SYNTHETIC, forecast).replace(SECOND_GOAL, second))
    return path


def line_of(path: Path, text: str) -> int:
    return path.read_text().splitlines(keepends=True).index(text) + 1


def test_a_missing_forecast_file_names_the_mission_line(tmp_path, capsys):
    path = two_goals(tmp_path, "nofile", forecast=MISSING)
    line = error_line(capsys, ["batch", str(path), f"--out={tmp_path / 'out'}", *QUICK])
    assert line.endswith(f"{path}:{line_of(path, MISSING)} forecast.file: {tmp_path / 'missing.nc'}:"
                         " forecast file not found; check the path"), line


def test_a_forecast_directory_without_forecasts_names_the_mission_line(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    path = two_goals(tmp_path, "nodir", forecast=EMPTY_DIR)
    line = error_line(capsys, ["batch", str(path), f"--out={tmp_path / 'out'}", *QUICK])
    assert line.endswith(f"{path}:{line_of(path, EMPTY_DIR)} forecast.directory: {tmp_path / 'empty'}"
                         " holds no .nc files"), line


def test_a_forecast_on_the_command_line_needs_no_mission_forecast_file(synthetic_forecast, tmp_path, capsys):
    path = two_goals(tmp_path, "nofile", forecast=MISSING)
    assert load_mission(path).forecast.file == tmp_path / "missing.nc"  # loading does not look for it
    assert main(["batch", str(path), f"--forecast={synthetic_forecast}", f"--out={tmp_path / 'out'}", *QUICK]) == 0
    assert "2 of 2 goals planned" in capsys.readouterr().out


def test_a_batch_goal_on_land_names_its_mission_line(synthetic_forecast, tmp_path, capsys):
    path = two_goals(tmp_path, "land2", second=ON_LAND)
    assert main(["batch", str(path), f"--forecast={synthetic_forecast}", f"--out={tmp_path / 'out'}", *QUICK]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert captured.err.strip() == "lrauv: error: batch: 1 of 2 goals could not be planned (listed above)", captured.err
    words = " ".join(captured.out.split())  # lines over 100 columns wrap under their value
    assert f"failed land2 goal 1: {path}:{line_of(path, ON_LAND)} goals[1]: goal (-117.75000, 33.65000, 0 m) is on land:" \
        in words, captured.out


def test_an_upload_goal_on_land_names_its_mission_line(synthetic_forecast, tmp_path, capsys):
    path = two_goals(tmp_path, "land2", second=ON_LAND)
    # Refused while planning on shore, before the address is opened.
    line = error_line(capsys, ["upload", str(path), "--to=udpout:127.0.0.1:9", f"--forecast={synthetic_forecast}",
                               "--quiet"])
    assert f"{path}:{line_of(path, ON_LAND)} goals[1]: planning goal (-117.75, 33.65) failed:" in line, line
    assert "goal (-117.75000, 33.65000, 0 m) is on land" in line, line


def test_a_forecast_url_is_kept_as_written(tmp_path):
    path = two_goals(tmp_path, "url", forecast=URL_FILE)
    source = load_mission(path).forecast
    assert source.url == "HTTPS://example.org/fc/scb.nc" and source.file is None
    assert source.where == f"{path}:{line_of(path, URL_FILE)} forecast.file"
    grid = two_goals(tmp_path, "grid", forecast=URL_FILE + "  grid_file: http://example.org/fc/grid.nc\n")
    assert load_mission(grid).forecast.grid_file == "http://example.org/fc/grid.nc"  # a ROMS grid file's URL too


def test_a_mission_plans_on_its_forecast_url(server, synthetic_forecast, tmp_path, capsys):  # noqa: F811
    base, root, requests = server
    (root / "scb.nc").write_bytes(synthetic_forecast.read_bytes())
    path = two_goals(tmp_path, "url", forecast=f"  file: {base}/scb.nc\n")
    assert main(["batch", str(path), f"--out={tmp_path / 'out'}", *QUICK]) == 0
    assert "2 of 2 goals planned" in capsys.readouterr().out
    assert [r[0] for r in requests] == ["/scb.nc.dds", "/scb.nc"]  # not an OPeNDAP dataset: the file
    assert (tmp_path / "out" / "url" / "goal-1.lrpt").is_file()


def test_a_forecast_url_that_fails_names_the_mission_line(server, tmp_path, capsys):  # noqa: F811
    base, _, _ = server
    entry = f"  file: {base}/gone.nc\n"
    path = two_goals(tmp_path, "url404", forecast=entry)
    line = error_line(capsys, ["batch", str(path), f"--out={tmp_path / 'out'}", *QUICK])
    assert f"{path}:{line_of(path, entry)} forecast.file: {base}/gone.nc: HTTP 404" in line, line


@pytest.mark.parametrize(("command", "source"), [("plan", MISSING), ("plan", EMPTY_DIR), ("upload", EMPTY_DIR)])
def test_plan_and_upload_name_the_mission_line_of_a_forecast_that_is_not_there(tmp_path, capsys, command, source):
    (tmp_path / "empty").mkdir()
    path = two_goals(tmp_path, "src", forecast=source)
    key = source.strip().split(":")[0]
    args = [command, str(path), f"--out={tmp_path / 'out.lrpt'}", "--quiet"] if command == "plan" else \
        [command, str(path), "--to=udpout:127.0.0.1:9", "--timeout-s=0.2", "--quiet"]
    line = error_line(capsys, args)
    assert f"{path}:{line_of(path, source)} forecast.{key}: " in line, line


def test_a_region_outside_the_forecast_names_the_mission_line(synthetic_forecast, tmp_path, capsys):
    text = (REPO / "missions" / "two-goals.yaml").read_text()
    bbox = next(line for line in text.splitlines(keepends=True) if line.lstrip().startswith("bbox:"))
    path = tmp_path / "far.yaml"
    path.write_text(text.replace(bbox, "  bbox: [10.0, 50.0, 11.0, 51.0]\n"))
    line = error_line(capsys, ["plan", str(path), f"--forecast={synthetic_forecast}", f"--out={tmp_path / 'o.lrpt'}",
                               "--quiet"])
    assert f"{path}:{line_of(path, '  bbox: [10.0, 50.0, 11.0, 51.0]' + chr(10))} region.bbox: " in line, line
    assert "lies outside the forecast" in line, line
