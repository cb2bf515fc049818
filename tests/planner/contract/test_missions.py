"""Mission files: every file in missions/ is valid; errors name the file, line and key path."""

from __future__ import annotations

from pathlib import Path

import pytest

from planner.contract.errors import MissionError
from planner.contract.mission import load_mission
from tests.support import REPO

MISSIONS = sorted((REPO / "missions").glob("*.yaml"))


def test_there_are_missions():
    assert MISSIONS


@pytest.mark.parametrize("path", MISSIONS, ids=lambda p: p.name)
def test_every_mission_file_is_valid(path):
    mission = load_mission(path)
    assert mission.goals and mission.region.depths_m


def edit(tmp_path: Path, old: str, new: str) -> Path:
    text = (REPO / "missions" / "demo.yaml").read_text()
    assert old in text
    out = tmp_path / "m.yaml"
    out.write_text(text.replace(old, new))
    return out


def line_of(path: Path, needle: str) -> int:
    return next(n for n, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


@pytest.mark.parametrize(
    "old, new, key, message",
    [
        ("depth_m: 0, radius_cells", "depth_m: 40, radius_cells", "goals[0].depth_m", "40 m is deeper than the deepest layer 15 m"),
        ("criterion: robust", "criterion: safest", "planning.criterion", "expected one of robust, optimistic"),
        ("nx: 29", "nx: 29\n  colour: blue", "region.colour", "unknown key"),
        ("forward: 4,", "forward: 4.5,", "planning.costs.forward", "integer"),
        ("on_breach: surface", "on_breach: explode", "safety.on_breach", "expected one of surface, drift, hold"),
        ("cruise_speed_m_s: 1.0", "cruise_speed_m_s: fast", "vehicle.cruise_speed_m_s", "expected a number"),
        ("bbox: [-118.26, 33.30, -117.70, 33.70]", "bbox: [-117.70, 33.30, -118.26, 33.70]", "region.bbox", "WEST < EAST"),
        ("min_battery_pct: 10", "min_battery_pct: 150", "safety.min_battery_pct", "expected at most 100 %; got 150"),
        ("criterion: robust", "criterion: robust\n  timing_correction: often", "planning.timing_correction", "true or false"),
        ("criterion: robust", "criterion: robust\n  timing_block_cells: 4", "planning.timing_block_cells",
         "needs planning.timing_correction: true"),
        ("criterion: robust", "criterion: robust\n  timing_correction: true\n  timing_block_cells: 0",
         "planning.timing_block_cells", "expected at least 1; got 0"),
    ],
)
def test_errors_name_file_line_and_key(tmp_path, old, new, key, message):
    path = edit(tmp_path, old, new)
    with pytest.raises(MissionError) as err:
        load_mission(path)
    text = str(err.value)
    needle = new.split("\n")[-1].strip().split(":")[0]
    assert text.startswith(f"{path}:{line_of(path, needle)} {key}:"), text
    assert message in text


def test_unknown_top_level_key_and_bad_yaml(tmp_path):
    path = edit(tmp_path, "name: scb-demo", "name: scb-demo\nspeed: 3")
    with pytest.raises(MissionError, match=r"m.yaml:\d+ speed: unknown key"):
        load_mission(path)
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(MissionError, match="not valid YAML"):
        load_mission(bad)


def test_too_many_goals(tmp_path):
    goals = "".join("  - {lat_deg: 33.4, lon_deg: -117.8, depth_m: 0}\n" for _ in range(10_000))
    text = (REPO / "missions" / "demo.yaml").read_text()
    start = text.index("goals:")
    end = text.index("replanning:")
    path = tmp_path / "many.yaml"
    path.write_text(text[:start] + "goals:\n" + goals + text[end:])
    with pytest.raises(MissionError, match="at most 1000 goals; got 10000"):
        load_mission(path)


def test_the_tidal_evaluation_fits_the_tides_timing():
    mission = load_mission(REPO / "missions" / "eval-tidal.yaml")
    assert mission.settings.timing_correction and not mission.settings.time_varying  # the evaluation plans it varying
