"""The three pictures of a plan in one folder: flow fields, a policy slice and the nominal path."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.shore.plots.flow import plot_flow_fields
from planner.shore.plots.nominal_path import default_start, plot_nominal_path
from planner.shore.plots.policy import check_heading, check_layer, plot_policy

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.shore.plots.currents import ForecastMoment
    from planner.shore.plots.solutions import AnySolution

__all__ = ["plot_all"]


def plot_all(
    u_m_s: NDArray[np.float64],
    v_m_s: NDArray[np.float64],
    solution: AnySolution,
    out_dir: str | os.PathLike[str],
    *,
    start: tuple[int, int, int, int] | None = None,
    heading: int = 0,
    layer: int | None = None,
    start_lon_lat: tuple[float, float] | None = None,
    when: ForecastMoment | None = None,
) -> list[Path]:
    """Write ``flow_fields.png``, ``policy_k{heading}_l{layer}.png`` and ``nominal_path.png``.

    ``out_dir`` is created if needed; ``start`` defaults to ``default_start``
    and ``layer`` to the goal layer; ``start_lon_lat`` is the vehicle's own start
    position (in ``start``'s cell), where the nominal path then begins; ``when``
    the forecast step planned on (``moment_of_plan``), named in every title.
    Returns the three paths in that order.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    k = check_heading(heading)
    l = solution.goal_cells.l if layer is None else check_layer(layer, solution.model.grid)
    return [
        plot_flow_fields(u_m_s, v_m_s, solution.model, out / "flow_fields.png", goal=solution.goal, when=when),
        plot_policy(solution, out / f"policy_k{k}_l{l}.png", heading=k, layer=l, when=when),
        plot_nominal_path(solution, default_start(solution) if start is None else start, out / "nominal_path.png",
                          start_lon_lat=start_lon_lat, when=when),
    ]
