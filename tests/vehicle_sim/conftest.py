"""Fixtures of the simulator's tests."""

from __future__ import annotations

import pytest

from tests.vehicle_sim.harness import Bench


@pytest.fixture()
def bench():
    made: list[Bench] = []

    def make(*args, **kwargs) -> Bench:  # type: ignore[no-untyped-def]
        made.append(Bench(*args, **kwargs))
        return made[-1]

    yield make
    for b in made:
        b.close()
