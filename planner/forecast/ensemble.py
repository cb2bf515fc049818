"""An ensemble's mean forecast: what a time-varying plan flies when it is given several members.

A time-varying plan keeps one current per slice, so it plans on the members' mean, the usual
best single estimate of an ensemble, and takes the members' spread as its forecast error
(``planner.forecast.error``). The members must share their grid, depths and times (members of
one file, or the files of one ensemble run, do); a node is land where any member has land, as
in the stationary ensemble plan (``planner.physical.sampling.combine``).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from planner.contract.errors import ForecastError
from planner.forecast.model import Forecast


def ensemble_mean(members: Sequence[Forecast]) -> Forecast:
    """The mean of ``members`` (two or more), node by node and step by step; NaN (land) where any member has land."""
    if len(members) < 2:
        raise ForecastError(f"an ensemble mean needs two or more members; got {len(members)}")
    first = members[0]
    for m in members[1:]:
        _check_alike(first, m)
    with np.errstate(invalid="ignore"):
        u = np.mean([m.u_east_m_s for m in members], axis=0)
        v = np.mean([m.v_north_m_s for m in members], axis=0)
    identity = "ensemble-mean:" + hashlib.sha256("|".join(m.identity for m in members).encode()).hexdigest()[:16]
    window = first.window if first.window is None else replace(first.window, member=None)
    return replace(first, source=f"mean of {len(members)} members of {first.source}", identity=identity,
                   u_east_m_s=u, v_north_m_s=v, window=window,
                   notes=(*first.notes, f"the mean of {len(members)} ensemble members"))


def _check_alike(first: Forecast, other: Forecast) -> None:
    """Refuse a member whose times, grid or depths differ from the first member's, naming what differs
    (equal axes give equal velocity shapes)."""
    what = None
    if first.time_origin != other.time_origin or not np.array_equal(first.time_s, other.time_s):
        what = (f"times ({first.time_s.size} step(s) from {first.time_origin}; this member "
                f"{other.time_s.size} from {other.time_origin})")
    elif not (np.array_equal(first.lon_deg, other.lon_deg) and np.array_equal(first.lat_deg, other.lat_deg)):
        what = f"lon/lat grid ({first.lon_deg.shape} against {other.lon_deg.shape})"
    elif not _same_depths(first.depth_m, other.depth_m):
        what = "depths"
    if what is not None:
        raise ForecastError(f"{other.source}: ensemble member differs from {first.source} in its {what}; expected "
                            "members of one ensemble run on one grid, with the same steps")


def _same_depths(a: NDArray[np.float64] | None, b: NDArray[np.float64] | None) -> bool:
    return a is None and b is None or a is not None and b is not None and np.array_equal(a, b)
