"""The executive's durable state: what it needs to go on after a crash (``kill -9``, power cut).

A state directory holds ``state.json`` (the goals, which table serves each, the
active goal, the log being written, the safety stop, and the current met with the tide's timing
fitted to it: ``executive.tide_watch``) and the tables themselves under
``tables/policy-CRC.lrpt``. The loop saves it at start, at every plan swap, when the safety stop
fires, when an operator resumes and at every fit of the tide's timing (``executive.state_writer``);
tables are written before the state that names them, each file atomically
(``planner.contract.atomic``), so a kill at any moment leaves the previous state or the
new one, never half of either. ``lrauv exec --resume DIR`` loads it back
(``load``), recovers the killed log up to its last complete record
(``executive.recorder.recover``) and goes on with a new log.

Standard library and the table reader only, like the rest of the executive.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from executive import tide_watch
from executive.goal_tables import MissionPlan
from planner.contract.atomic import write_atomic
from planner.contract.errors import ExecutiveError
from planner.contract.mission import MissionGoal
from planner.contract.settings import Goal
from planner.contract.table import PolicyTable

__all__ = ["STATE_FILE", "Resumed", "load", "save"]

STATE_FILE = "state.json"
_VERSION = 1


@dataclass(frozen=True, kw_only=True)
class Resumed:
    """A plan read back from a state directory, and the log the killed run was writing."""

    plan: MissionPlan
    blobs: Mapping[int, bytes]  # table CRC -> the exact file bytes
    log_path: Path | None
    mission_path: Path | None
    saved_utc: str
    safety_stop: str | None = None  # the limit that fired (helm Situation value): it holds after a restart
    tide: tide_watch.TideWatch | None = None  # the current met and the tide's shift (absent in older states)


def _table_name(table: PolicyTable) -> str:
    return f"policy-{table.crc32:08x}.lrpt"


def save(state_dir: Path, plan: MissionPlan, blobs: Mapping[int, bytes], *, log_path: Path,
         mission_path: Path | None, safety_stop: str | None = None,
         tide: Mapping[str, Any] | None = None) -> Path:
    """Write the tables ``plan`` uses (those not yet there), then ``state.json``; returns its path.
    ``tide``: ``tide_watch.saved``'s record and shift."""
    tables_dir = state_dir / "tables"
    names: list[str | None] = []
    for table in plan.tables:
        if table is None:
            names.append(None)
            continue
        name = _table_name(table)
        if not (tables_dir / name).is_file():
            write_atomic(tables_dir / name, blobs.get(table.crc32) or table.to_bytes())
        names.append(name)
    state = {
        "version": _VERSION,
        "saved_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "goal_index": plan.index,
        "goals": [{"lon_deg": g.goal.lon_deg, "lat_deg": g.goal.lat_deg, "depth_m": g.goal.depth_m,
                   "radius_cells": g.goal.radius_cells, "on_arrival": g.on_arrival} for g in plan.goals],
        "tables": names,
        "log": os.fspath(log_path),
        "mission": None if mission_path is None else os.fspath(mission_path),
        "safety_stop": safety_stop,
    }
    if tide is not None:
        state["tide"] = tide
    return write_atomic(state_dir / STATE_FILE, (json.dumps(state, indent=1) + "\n").encode())


def load(state_dir: Path) -> Resumed:
    """Read a state directory back; ``ExecutiveError`` names the file and what is wrong."""
    path = state_dir / STATE_FILE
    try:
        state = json.loads(path.read_text())
    except FileNotFoundError:
        raise ExecutiveError(f"{path}: no saved state here (was the executive run with --state-dir {state_dir}?)") from None
    except (OSError, ValueError) as exc:
        raise ExecutiveError(f"{path}: cannot read the saved state: {exc}") from None
    try:
        return _parse(state, state_dir, path)
    except (KeyError, TypeError, ValueError) as exc:
        raise ExecutiveError(f"{path}: not a saved executive state ({type(exc).__name__}: {exc})") from None


def _parse(state: Mapping[str, Any], state_dir: Path, path: Path) -> Resumed:
    if state.get("version") != _VERSION:
        raise ExecutiveError(f"{path}: state version {state.get('version')!r}; this executive reads version {_VERSION}")
    goals = tuple(MissionGoal(goal=Goal(lon_deg=float(g["lon_deg"]), lat_deg=float(g["lat_deg"]),
                                        depth_m=float(g["depth_m"]), radius_cells=int(g["radius_cells"])),
                              on_arrival=g["on_arrival"]) for g in state["goals"])
    tables: list[PolicyTable | None] = []
    blobs: dict[int, bytes] = {}
    for name in state["tables"]:
        if name is None:
            tables.append(None)
            continue
        file = state_dir / "tables" / Path(name).name
        try:
            data = file.read_bytes()
        except OSError as exc:
            raise ExecutiveError(f"{file}: a table the saved state names cannot be read: {exc.strerror or exc}") from None
        table = PolicyTable.from_bytes(data, name=str(file))
        if name != _table_name(table):
            raise ExecutiveError(f"{file}: its CRC is {table.crc32:08x}, not the one in its name")
        tables.append(table)
        blobs[table.crc32] = data
    index = int(state["goal_index"])
    if not (0 <= index < len(goals)) or len(tables) != len(goals):
        raise ExecutiveError(f"{path}: goal_index {index} and {len(tables)} tables do not fit {len(goals)} goals")
    if tables[index] is None:
        raise ExecutiveError(f"{path}: the active goal {index} has no table yet; give one with --table")
    return Resumed(plan=MissionPlan(goals=goals, tables=tuple(tables), index=index), blobs=blobs,
                   log_path=Path(state["log"]) if state.get("log") else None,
                   mission_path=Path(state["mission"]) if state.get("mission") else None,
                   saved_utc=str(state.get("saved_utc", "")),
                   safety_stop=str(state["safety_stop"]) if state.get("safety_stop") else None,
                   tide=tide_watch.restored(state["tide"]) if state.get("tide") else None)
