"""Shared fixtures: real netCDF forecasts written by the synthetic generator, small plans."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_OCEAN = Path(os.environ.get("LRAUV_OCEAN_DATA", REPO.parent / "shared" / "data" / "ocean"))


@pytest.fixture(scope="session")
def synthetic_forecast(tmp_path_factory) -> Path:
    """The built-in Southern California Bight forecast as a real netCDF file (24 h)."""
    from planner.synthetic import SyntheticSettings, write_synthetic

    return write_synthetic(tmp_path_factory.mktemp("forecast") / "scb.nc", SyntheticSettings(seed=0, hours=24))


@pytest.fixture(scope="session")
def demo_plan(synthetic_forecast):
    """The demo mission's plan on the synthetic forecast (the paper's 29 x 21 x 4 grid)."""
    from tests.helpers import plan_for

    return plan_for(synthetic_forecast)


@pytest.fixture()
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)
