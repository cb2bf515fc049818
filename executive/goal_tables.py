"""The onboard mission plan: the goal list, one policy table per goal, and which goal is active.

Pure values and functions; the loop (``executive.loop``) owns the one ``MissionPlan`` in use
and replaces it whole, between two decisions, so a decision never sees half a change.

Every table that arrives (uploaded over MAVLink FTP, planned onboard after a new forecast,
or given on the command line) goes through ``check_table`` first: a table whose bytes fail
their CRC or version never gets this far (``PolicyTable.from_bytes`` refuses it), and one
whose goal matches no goal of the mission, or whose grid differs from the table it would
replace, is refused with a reason. A refused table never replaces the running plan.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace

from planner.contract.errors import ExecutiveError, LrauvError
from planner.contract.mission import MissionGoal, goals_to_items, items_to_goals
from planner.contract.waypoints import MissionItem
from planner.contract.settings import Goal, OnArrival
from planner.contract.table import PolicyTable

_GOAL_TOLERANCE_DEG = 1.5e-7  # MISSION_ITEM_INT carries degE7: a goal survives the trip to within 1e-7 deg
_GOAL_TOLERANCE_M = 1e-3


@dataclass(frozen=True, slots=True)
class MissionPlan:
    """Goals in order, a table (or None, not yet planned) for each, and the active goal."""

    goals: tuple[MissionGoal, ...]
    tables: tuple[PolicyTable | None, ...]
    index: int = 0

    def __post_init__(self) -> None:
        if len(self.tables) != len(self.goals):
            raise ValueError(f"{len(self.goals)} goals but {len(self.tables)} tables")

    @property
    def goal(self) -> MissionGoal | None:
        return self.goals[self.index] if self.index < len(self.goals) else None

    @property
    def table(self) -> PolicyTable | None:
        return self.tables[self.index] if self.index < len(self.tables) else None

    @property
    def has_next(self) -> bool:
        return self.index + 1 < len(self.goals)


@dataclass(frozen=True, slots=True)
class Verdict:
    """The outcome of checking a table: the goal it serves, or why it is refused."""

    goal_index: int | None
    reason: str | None = None

    @property
    def accepted(self) -> bool:
        return self.reason is None


def single(table: PolicyTable, *, on_arrival: OnArrival = "hold") -> MissionPlan:
    """A one-goal plan around one table, its goal taken from the table."""
    goal = MissionGoal(goal=Goal(lon_deg=table.goal_lon_deg, lat_deg=table.goal_lat_deg, depth_m=table.goal_depth_m,
                                 radius_cells=table.goal_radius_cells), on_arrival=on_arrival)
    return MissionPlan(goals=(goal,), tables=(table,))


def goal_matches(table: PolicyTable, goal: Goal) -> bool:
    return (abs(table.goal_lat_deg - goal.lat_deg) <= _GOAL_TOLERANCE_DEG
            and abs(table.goal_lon_deg - goal.lon_deg) <= _GOAL_TOLERANCE_DEG
            and abs(table.goal_depth_m - goal.depth_m) <= _GOAL_TOLERANCE_M
            and table.goal_radius_cells == goal.radius_cells)


def check_table(table: PolicyTable, plan: MissionPlan) -> Verdict:
    """Which goal of ``plan`` the table serves (the active goal first, then later ones), or why not."""
    order = [*range(plan.index, len(plan.goals)), *range(plan.index)]
    for n in order:
        if not goal_matches(table, plan.goals[n].goal):
            continue
        old = plan.tables[n]
        if old is not None:
            if "grid" in old.matches(table):
                return Verdict(n, f"its grid differs from the running table's for goal {n}")
        return Verdict(n)
    g = table
    return Verdict(None, f"its goal ({g.goal_lon_deg:.6f}, {g.goal_lat_deg:.6f}, {g.goal_depth_m:g} m,"
                         f" radius {g.goal_radius_cells}) matches no goal of the mission")


def assign(goals: tuple[MissionGoal, ...], named: Iterable[tuple[str, PolicyTable]], mission: str) -> MissionPlan:
    """The goals with each named table in its goal's place; ExecutiveError naming a table that fits no goal."""
    plan = MissionPlan(goals=goals, tables=(None,) * len(goals))
    for name, table in named:
        verdict = check_table(table, plan)
        if verdict.goal_index is None or not verdict.accepted:
            raise ExecutiveError(f"{name}: {verdict.reason} in {mission}: plan the table for this mission")
        plan = with_table(plan, verdict.goal_index, table)
    return plan


def with_table(plan: MissionPlan, index: int, table: PolicyTable) -> MissionPlan:
    tables = list(plan.tables)
    tables[index] = table
    return replace(plan, tables=tuple(tables))


def adopt(goals: tuple[MissionGoal, ...], current: MissionPlan) -> MissionPlan:
    """A new goal list, keeping the current tables of goals that did not change.

    A list that keeps the goals up to the active one (a mission extended mid-dive) keeps the
    active goal: the goals already reached are not flown again. Any other list starts at goal 0.
    """
    tables = []
    for g in goals:
        found = next((t for t in current.tables if t is not None and goal_matches(t, g.goal)), None)
        tables.append(found)
    n = current.index
    index = n if 0 < n < len(goals) and goals[:n + 1] == current.goals[:n + 1] else 0
    return MissionPlan(goals=goals, tables=tuple(tables), index=index)


def flown_items(plan: MissionPlan | None, accepted: tuple[MissionItem, ...]) -> tuple[MissionItem, ...]:
    """The mission items of the goals ``plan`` flies: the ``accepted`` upload when it is that list, else made here."""
    if plan is None or not plan.goals:
        return ()
    try:
        if accepted and items_to_goals(accepted) == plan.goals:
            return accepted  # as the ground station sent it, with its own home item
    except LrauvError:
        pass
    home = plan.goals[0].goal  # no launch point is known onboard: item 0 (home) is the first goal's position
    return goals_to_items(plan.goals, home_lat_deg=home.lat_deg, home_lon_deg=home.lon_deg)


def identity(table: PolicyTable | None) -> dict[str, str | None]:
    """How the log names a table: its CRC and the forecast it was planned on."""
    if table is None:
        return {"table_crc32": None, "forecast_identity": None, "forecast_time": None}
    return {"table_crc32": f"{table.crc32:08x}", "forecast_identity": table.forecast_identity,
            "forecast_time": table.forecast_time}
