"""Everyday friction at the command line: one coordinate order, a hint for swapped pairs, the mission
line of a bad goal, help for every subcommand. Through ``planner.cli.main`` as a user types it."""

from __future__ import annotations

from pathlib import Path

import pytest

from planner.cli import main
from tests.support import REPO
from tests.support.helpers import error_line

GRID = ["--bbox=-118.26,33.30,-117.70,33.70", "--nx=29", "--ny=21", "--depths=0,5,10,15"]


def test_a_swapped_goal_gets_a_hint(synthetic_forecast, tmp_path, capsys):
    line = error_line(capsys, ["plan", f"--forecast={synthetic_forecast}", *GRID, "--goal", "33.40,-117.80,0",
                               f"--out={tmp_path / 'x.lrpt'}", "--quiet"])
    assert "outside the planning grid" in line and "did you mean -117.8,33.4 (lon,lat)?" in line, line


def test_a_goal_merely_outside_gets_no_hint(synthetic_forecast, tmp_path, capsys):
    line = error_line(capsys, ["plan", f"--forecast={synthetic_forecast}", *GRID, "--goal=-119.5,33.40,0",
                               f"--out={tmp_path / 'x.lrpt'}", "--quiet"])
    assert "outside the planning grid" in line and "did you mean" not in line, line


def mission_with_goal(tmp_path: Path, goal: str) -> Path:
    text = (REPO / "missions" / "demo.yaml").read_text()
    old = "  - {lat_deg: 33.40, lon_deg: -117.80, depth_m: 0, radius_cells: 1, on_arrival: hold}"
    assert old in text
    path = tmp_path / "m.yaml"
    path.write_text(text.replace(old, goal))
    return path


def test_a_goal_on_land_names_the_mission_file_and_line(synthetic_forecast, tmp_path, capsys):
    path = mission_with_goal(tmp_path, "  - {lat_deg: 33.65, lon_deg: -117.75, depth_m: 0}")
    line_no = path.read_text().splitlines().index("  - {lat_deg: 33.65, lon_deg: -117.75, depth_m: 0}") + 1
    line = error_line(capsys, ["plan", str(path), f"--forecast={synthetic_forecast}",
                               f"--out={tmp_path / 'x.lrpt'}", "--quiet"])
    assert f"{path}:{line_no} goals[0]: goal (-117.75000, 33.65000, 0 m) is on land" in line, line


def test_a_mission_latitude_out_of_range_gets_a_hint(tmp_path, capsys):
    path = mission_with_goal(tmp_path, "  - {lat_deg: -117.80, lon_deg: 33.40, depth_m: 0}")
    line = error_line(capsys, ["plan", str(path), f"--out={tmp_path / 'x.lrpt'}"])
    assert "goals[0].lat_deg: expected a latitude in [-90, 90]; got -117.8; did you mean -117.8,33.4 (lon,lat)?" in line


@pytest.mark.parametrize("command", ["plan", "forecast", "evaluate", "batch", "holdout", "exec", "log", "sim", "demo",
                                     "upload", "waypoints", "replay"])
def test_every_subcommand_has_user_facing_help_with_an_example(command, capsys):
    with pytest.raises(SystemExit) as stop:
        main([command, "--help"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert "``" not in out and "python -m" not in out, out  # no developer docstring
    assert "example" in out and f"\n  lrauv {command} " in out, out
