"""What the mission looks like on a map, as GeoJSON (RFC 7946) for the log's ``foxglove.GeoJSON`` topics.

Foxglove's Map panel shows the latest message of each GeoJSON topic, so each layer is written
whole whenever it changes (``executive.plan_changes``) and replaces the one before:

- goals: every goal of the mission as a Point, the active one marked;
- geofence: the safety section's polygon (an empty collection when the mission has none);
- plan: the running plan, i.e. the active goal's table: its grid's extent, its land (layer 0,
  one rectangle per run of land cells along a row) and its goal cells (within the goal radius,
  Chebyshev, of the goal's cell: spec section 6), the goal it steers to, and its nominal path
  from the start it was planned with, where the table carries one (``lrauv plan --start``).

Positions are ``[lon, lat]`` (RFC 7946 section 3.1.1); polygons are closed, exteriors
counter-clockwise (section 3.1.6). Pure functions of the plan; standard library and the
policy table only. The nominal path comes with the table, worked out on shore from the planning
forecast, which the executive does not keep: a plan made on board has none.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from executive.goal_tables import MissionPlan
from planner.contract.table import PolicyTable

__all__ = ["geofence_layer", "goals_layer", "plan_layer"]

Json = dict[str, Any]


def goals_layer(plan: MissionPlan | None) -> Json:
    """Each goal as a Point feature: index, depth, radius, what happens on arrival, whether it is active."""
    features = []
    for n, mission_goal in enumerate(() if plan is None else plan.goals):
        goal = mission_goal.goal
        features.append(_feature({"type": "Point", "coordinates": [goal.lon_deg, goal.lat_deg]}, {
            "name": f"goal {n}", "goal_index": n, "depth_m": goal.depth_m, "radius_cells": goal.radius_cells,
            "on_arrival": mission_goal.on_arrival, "active": plan is not None and n == plan.index,
            "has_table": plan is not None and plan.tables[n] is not None}))
    return _collection(features)


def geofence_layer(polygon: Sequence[tuple[float, float]] | None) -> Json:
    """The geofence of ``(lon_deg, lat_deg)`` vertices as a Polygon feature; none: an empty collection."""
    if not polygon:
        return _collection([])
    return _collection([_feature({"type": "Polygon", "coordinates": [_ring(list(polygon))]},
                                 {"name": "geofence", "vertices": len(polygon)})])


def plan_layer(plan: MissionPlan | None) -> Json:
    """The active goal's table on the map: grid extent, land, goal cells and goal (empty without a table)."""
    table = None if plan is None else plan.table
    if plan is None or table is None:
        return _collection([])
    crc = f"{table.crc32:08x}"
    west, south = table.lon0_deg - table.dlon_deg / 2, table.lat0_deg - table.dlat_deg / 2
    east, north = west + table.nx * table.dlon_deg, south + table.ny * table.dlat_deg
    features = [_feature({"type": "Polygon", "coordinates": [_box(west, south, east, north)]},
                         {"name": "plan grid", "table_crc32": crc, "goal_index": plan.index, "nx": table.nx,
                          "ny": table.ny, "forecast_identity": table.forecast_identity,
                          "forecast_time": table.forecast_time, "time_varying": table.time_varying})]
    land = _land_runs(table)
    if land:
        features.append(_feature({"type": "MultiPolygon", "coordinates": [[r] for r in land]},
                                 {"name": "land", "source": "policy table, layer 0", "table_crc32": crc}))
    cell = table.locate(table.goal_lat_deg, table.goal_lon_deg, table.goal_depth_m)
    if cell is not None:
        _, j, i = cell
        r = table.goal_radius_cells
        lat, lon = table.cell_centre(j, i)
        hx, hy = (r + 0.5) * table.dlon_deg, (r + 0.5) * table.dlat_deg
        features.append(_feature({"type": "Polygon", "coordinates": [_box(lon - hx, lat - hy, lon + hx, lat + hy)]},
                                 {"name": "goal cells", "radius_cells": r, "table_crc32": crc}))
    features.append(_feature({"type": "Point", "coordinates": [table.goal_lon_deg, table.goal_lat_deg]},
                             {"name": f"goal {plan.index} (running)", "depth_m": table.goal_depth_m,
                              "table_crc32": crc}))
    if len(table.nominal_path) >= 2:
        features.append(_feature({"type": "LineString", "coordinates": [list(p) for p in table.nominal_path]},
                                 {"name": "nominal path", "source": "planned on shore from its start",
                                  "vertices": len(table.nominal_path), "table_crc32": crc}))
    return _collection(features)


def _land_runs(table: PolicyTable) -> list[list[list[float]]]:
    """Rings of the land of layer 0: one rectangle per run of land cells along a row."""
    rings = []
    water = table.water[0]
    for j in range(table.ny):
        row = water[j]
        i = 0
        while i < table.nx:
            if row[i]:
                i += 1
                continue
            start = i
            while i < table.nx and not row[i]:
                i += 1
            lat, lon = table.cell_centre(j, start)
            west, south = lon - table.dlon_deg / 2, lat - table.dlat_deg / 2
            rings.append(_box(west, south, west + (i - start) * table.dlon_deg, south + table.dlat_deg))
    return rings


def _box(west: float, south: float, east: float, north: float) -> list[list[float]]:
    """A closed counter-clockwise ring."""
    return [[west, south], [east, south], [east, north], [west, north], [west, south]]


def _ring(vertices: list[tuple[float, float]]) -> list[list[float]]:
    """A closed ring of the vertices, counter-clockwise (RFC 7946's right-hand rule for exteriors)."""
    points = [[float(lon), float(lat)] for lon, lat in vertices]
    if points[0] == points[-1]:
        points.pop()
    twice_area = sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(points, points[1:] + points[:1], strict=True))
    if twice_area < 0:
        points.reverse()
    return points + [points[0]]


def _feature(geometry: Json, properties: Json) -> Json:
    return {"type": "Feature", "geometry": geometry, "properties": properties}


def _collection(features: list[Json]) -> Json:
    return {"type": "FeatureCollection", "features": features}
