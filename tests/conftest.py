"""Shared fixtures: real netCDF forecasts written by the synthetic generator, small plans."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from tests.support import REPO

SHARED_OCEAN = Path(os.environ.get("LRAUV_OCEAN_DATA", REPO.parent / "shared" / "data" / "ocean"))


@pytest.fixture(scope="session", autouse=True)
def forecast_cache(tmp_path_factory):
    """Downloaded and synthetic forecasts go to a temporary cache (planner.forecast.cache), never the user's;
    processes the tests start inherit it."""
    with pytest.MonkeyPatch.context() as mp:
        path = tmp_path_factory.mktemp("cache")
        mp.setenv("LRAUV_CACHE_DIR", str(path))
        yield path


@pytest.fixture(scope="session")
def synthetic_forecast(tmp_path_factory) -> Path:
    """The built-in Southern California Bight forecast as a real netCDF file (24 h)."""
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    return write_synthetic(tmp_path_factory.mktemp("forecast") / "scb.nc", SyntheticSettings(seed=0, hours=24))


@pytest.fixture(scope="session")
def demo_plan(synthetic_forecast):
    """The demo mission's plan on the synthetic forecast (the paper's 29 x 21 x 4 grid)."""
    from tests.support.helpers import plan_for

    return plan_for(synthetic_forecast)


@pytest.fixture()
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def dive_log(demo_plan, synthetic_forecast, tmp_path_factory) -> Path:
    """A short real dive's MCAP log, shared read-only by the replay, report, export and re-stream tests.

    ``lrauv sim`` and ``lrauv exec`` as processes over UDP on 127.0.0.1 (``make demo``'s path), from two
    cells west of the demo goal to the goal at 1000x: a few seconds of wall time.
    """
    from tests.support.helpers import DEMO_MISSION, start_west_of_goal
    from planner.shore.demo import run_closed_loop

    out = tmp_path_factory.mktemp("dive")
    table = out / "demo.lrpt"
    demo_plan.table.save(table)
    lon, lat = start_west_of_goal(demo_plan.table, cells=2)
    result = run_closed_loop(table=table, mission=DEMO_MISSION, truth=synthetic_forecast, start=f"{lon},{lat}",
                             depth_m=0.0, heading_deg=90.0, speedup=1000.0, out=out, timeout_s=90.0)
    assert result.exec_status == 0, result.exec_output
    return result.log_path
