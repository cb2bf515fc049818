"""Plain helpers shared by the tests (fixtures are in conftest.py)."""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from tests.support import REPO

if TYPE_CHECKING:
    import pytest

DEMO_MISSION = REPO / "missions" / "demo.yaml"


def plan_for(forecast: Path, goal=None, *, mission: Path = DEMO_MISSION, **settings):  # type: ignore[no-untyped-def]
    """``make_plan`` for a goal (default: the mission's first) on the mission's grid, at the first step."""
    from planner.contract.mission import load_mission
    from planner.pipeline import PlanRequest, make_plan

    m = load_mission(mission)
    request = PlanRequest(forecast_path=forecast, goal=goal or m.goals[0].goal, depths_m=m.region.depths_m,
                          settings=replace(m.settings, **settings), bbox=m.region.bbox, nx=m.region.nx,
                          ny=m.region.ny, time_index=0)
    return make_plan(request)


def start_west_of_goal(table, cells: int = 3) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """(lon, lat) of a water position ``cells`` cells west of the goal (open water in the built-in forecast)."""
    lat, lon = table.goal_lat_deg, table.goal_lon_deg - cells * table.dlon_deg
    assert table.lookup(lat, lon, 0.0, 0.0).reason == "ok"
    return lon, lat


def wait_until(predicate, timeout_s: float) -> bool:  # type: ignore[no-untyped-def]
    """Poll ``predicate`` every 20 ms until it is true (True) or ``timeout_s`` passes (False)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return False


def sim_cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    """``python -m vehicle_sim ARGS`` run to completion, output captured."""
    return subprocess.run([sys.executable, "-m", "vehicle_sim", *args], capture_output=True, text=True, check=False,
                          timeout=timeout, cwd=REPO)


def audit_log(path: Path):  # type: ignore[no-untyped-def]
    """The decision audit of a finished executive log (``lrauv replay``'s): ``AuditResult``."""
    from planner.shore.replay.audit import audit
    from planner.shore.replay.divelog import open_dive

    return audit(open_dive(path))


def assert_audit_clean(path: Path) -> None:
    """Every logged decision is made again, the same, by ``helm.step`` on the logged inputs."""
    result = audit_log(path)
    assert result.decisions > 0, f"{path}: no decision to audit"
    assert result.clean, "\n".join(m.describe() for m in result.mismatches[:10])


def error_line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """The one ``lrauv: error:`` line of a ``planner.cli.main`` run that must exit 2 without a traceback."""
    from planner.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.startswith("lrauv: error:")]
    assert len(lines) == 1, err
    return lines[0]
