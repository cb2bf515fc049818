"""The mission's safety envelope, checked when goals and tables are uploaded, not when they fail later.

A goal or a table that the vehicle could not fly inside the mission's safety section is refused
at upload time with a reason the ground station sees (MISSION_ACK or FTP NAK, and STATUSTEXT);
the running plan goes on. What is checked (docs/executive.md, "Uploads inside the envelope"):

- a goal's depth is within ``max_depth_m``, its position is not 0, 0 (a position no ground
  station means: ArduSub reports it before a GPS fix), and it lies inside the geofence and inside
  the area the forecast covers (the mission's box, or the grid of the table in use);
- a goal's radius is at most ``MAX_GOAL_RADIUS_CELLS``: a wider one would call the vehicle
  arrived far from where the operator asked;
- a table's layers and goal are within ``max_depth_m`` and its goal inside the geofence.

Pure functions: the loop calls them, the tests call them directly too.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from executive.geofence import inside
from planner.contract.geodesy import BBox
from planner.contract.mission import MissionGoal
from planner.contract.table import PolicyTable

MAX_GOAL_RADIUS_CELLS = 10


@dataclass(frozen=True, slots=True)
class Envelope:
    """The mission's safety section as the executive holds it (``HelmConfig``), and the forecast's area."""

    max_depth_m: float | None = None
    geofence: tuple[tuple[float, float], ...] | None = None  # (lon_deg, lat_deg) vertices
    coverage: BBox | None = None  # the mission's planning box; None: the table in use says


def check_goals(goals: Sequence[MissionGoal], envelope: Envelope, table: PolicyTable | None) -> str | None:
    """None when every goal is inside the envelope; else why the first one that is not is refused."""
    for n, mg in enumerate(goals):
        reason = _goal(mg.goal.lat_deg, mg.goal.lon_deg, mg.goal.depth_m, envelope)
        if reason is None and mg.goal.radius_cells > MAX_GOAL_RADIUS_CELLS:
            reason = f"radius {mg.goal.radius_cells} cells is over {MAX_GOAL_RADIUS_CELLS}"
        if reason is None and envelope.coverage is None and table is not None:
            if table.lookup(mg.goal.lat_deg, mg.goal.lon_deg, mg.goal.depth_m, 0.0).reason == "outside_grid":
                reason = "it is outside the forecast's grid (the table in use)"
        if reason is not None:
            return f"goal {n} ({mg.goal.lon_deg:.6f}, {mg.goal.lat_deg:.6f}, {mg.goal.depth_m:g} m): {reason}"
    return None


def check_table(table: PolicyTable, envelope: Envelope) -> str | None:
    """None when the table's layers and goal are inside the envelope; else why not."""
    deepest = max(float(d) for d in table.depth_m)
    if envelope.max_depth_m is not None and deepest > envelope.max_depth_m:
        return f"its layers reach {deepest:g} m, deeper than max_depth_m {envelope.max_depth_m:g}"
    reason = _goal(table.goal_lat_deg, table.goal_lon_deg, table.goal_depth_m, envelope)
    return None if reason is None else f"its goal: {reason}"


def _goal(lat_deg: float, lon_deg: float, depth_m: float, envelope: Envelope) -> str | None:
    if not (math.isfinite(lat_deg) and math.isfinite(lon_deg) and math.isfinite(depth_m)):
        return "not a finite position"
    if lat_deg == 0.0 and lon_deg == 0.0:
        return "0, 0 is no goal (a position before a GPS fix)"
    if envelope.max_depth_m is not None and depth_m > envelope.max_depth_m:
        return f"deeper than max_depth_m {envelope.max_depth_m:g}"
    if envelope.geofence is not None and not inside(lon_deg, lat_deg, envelope.geofence):
        return "outside the geofence"
    box = envelope.coverage
    if box is not None and not (box.west_deg <= lon_deg <= box.east_deg and box.south_deg <= lat_deg <= box.north_deg):
        return (f"outside the forecast's area (the mission's box {box.west_deg:g}, {box.south_deg:g},"
                f" {box.east_deg:g}, {box.north_deg:g})")
    return None
