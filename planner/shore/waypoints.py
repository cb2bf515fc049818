"""A mission's goals as QGC WPL 110 waypoint files (QGroundControl, MAVProxy), and back (docs/missions.md).

``export_waypoints`` writes home and the goals (planner/contract/waypoints.py);
``import_waypoints`` writes a base mission's YAML with its ``goals:`` list replaced by
a file's goals. The rest of the base's text is kept as it is, except that relative
forecast paths are rewritten when the new file lies in another folder; the result is
checked with ``load_mission`` before it replaces anything.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from planner.contract.atomic import atomic_target
from planner.contract.errors import MissionError
from planner.contract.mission import goals_to_items, items_to_goals
from planner.contract.waypoints import WaypointError, read_wpl, write_wpl
from planner.grid import Grid, vehicle_longitudes


def export_waypoints(mission_path: Path, out: Path, *, home: tuple[float, float] | None = None) -> tuple[Path, int]:
    """Write the mission's goals as a WPL file; home is ``(lon, lat)`` or the first goal. Returns (path, goals)."""
    from planner.contract.mission import load_mission

    mission = load_mission(mission_path)
    lon, lat = home if home is not None else (mission.goals[0].goal.lon_deg, mission.goals[0].goal.lat_deg)
    items = goals_to_items(mission.goals, home_lat_deg=lat, home_lon_deg=lon)
    return write_wpl(out, items), len(mission.goals)


def import_waypoints(wpl_path: Path, base_path: Path, out: Path) -> tuple[Path, int]:
    """Write BASE with its goals replaced by the WPL file's; checked with load_mission first. Returns (path, goals)."""
    from planner.contract.mission import load_mission

    items = read_wpl(wpl_path)
    try:
        goals = items_to_goals(items)
    except WaypointError as exc:
        raise WaypointError(f"{wpl_path}: {exc}", exc.result) from None
    base = load_mission(base_path)
    deepest = base.region.depths_m[-1]
    box, nx, ny = base.region.bbox, base.region.nx, base.region.ny
    # The planning grid the mission's plans will have, in the vehicle's longitudes (a box written on 0..360
    # holds a waypoint's -180..180 longitude), and the planner's own rule for a goal on it: at most half a
    # cell beyond the outermost centres.
    grid = (Grid.from_bbox(vehicle_longitudes(box), nx=nx, ny=ny, depths_m=list(base.region.depths_m))
            if box is not None and nx and ny else None)
    for n, mg in enumerate(goals, start=1):
        if mg.goal.depth_m > deepest + 1e-9:
            raise WaypointError(f"{wpl_path}: item {n}: depth {mg.goal.depth_m:g} m is deeper than the deepest layer "
                                f"{deepest:g} m of {base_path}")
        g = mg.goal
        if grid is not None and box is not None and grid.nearest_cell(g.lon_deg, g.lat_deg)[2] > 0.5:
            raise WaypointError(f"{wpl_path}: item {n}: ({g.lon_deg:g}, {g.lat_deg:g}) lies outside the region "
                                f"{box.west_deg:g},{box.south_deg:g},{box.east_deg:g},{box.north_deg:g} of "
                                f"{base_path}: no plan could reach it")
    text = replace_goals(base_path.read_text(encoding="utf-8"), goals, base_dir=base_path.parent, out_dir=out.parent)
    with atomic_target(out) as tmp:
        tmp.write_text(text, encoding="utf-8")
        try:
            load_mission(tmp)
        except MissionError as exc:  # name the file being written, not its temporary
            raise MissionError(str(exc).replace(str(tmp), str(out))) from None
    return out, len(goals)


def _yaml_number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() and abs(value) < 1e15 else repr(float(value))


def goals_yaml(goals: Sequence[Any], *, indent: str = "  ") -> str:
    """The ``goals:`` block, one flow mapping per goal, as in missions/demo.yaml."""
    lines = ["goals:"]
    for mg in goals:
        g = mg.goal
        lines.append(f"{indent}- {{lat_deg: {_yaml_number(g.lat_deg)}, lon_deg: {_yaml_number(g.lon_deg)}, "
                     f"depth_m: {_yaml_number(g.depth_m)}, radius_cells: {g.radius_cells}, on_arrival: {mg.on_arrival}}}")
    return "\n".join(lines)


def replace_goals(text: str, goals: Sequence[Any], *, base_dir: Path | None = None, out_dir: Path | None = None) -> str:
    """Mission YAML text with the top-level ``goals`` replaced; relative forecast paths re-based onto ``out_dir``."""
    import yaml

    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        raise MissionError(f"not valid YAML: {exc}") from None
    if not isinstance(root, yaml.MappingNode):
        raise MissionError("expected a mission mapping")
    edits: list[tuple[int, int, str]] = []  # (start, end, new text), non-overlapping
    found = False
    for key, value in root.value:
        if key.value == "goals":
            found = True
            start, end = key.start_mark.index, value.end_mark.index
            new = goals_yaml(goals)
            edits.append((start, end, new + "\n" if text[start:end].endswith("\n") else new))
        elif key.value == "forecast" and isinstance(value, yaml.MappingNode) and base_dir is not None and out_dir is not None:
            edits.extend(_rebased_paths(value, base_dir, out_dir))
    if not found:
        raise MissionError("no top-level goals: key to replace")
    for start, end, new in sorted(edits, reverse=True):
        text = text[:start] + new + text[end:]
    return text


def _rebased_paths(forecast: Any, base_dir: Path, out_dir: Path) -> list[tuple[int, int, str]]:
    """Edits that keep relative ``file``/``directory``/``grid_file`` paths pointing at the same files."""
    if base_dir.resolve() == out_dir.resolve():
        return []
    edits = []
    for key, value in forecast.value:
        if key.value in ("file", "directory", "grid_file") and isinstance(value.value, str) and value.value:
            p = Path(value.value)
            if not p.is_absolute():
                new = os.path.relpath((base_dir / p).resolve(), out_dir.resolve())
                edits.append((value.start_mark.index, value.end_mark.index, json.dumps(new)))
    return edits

