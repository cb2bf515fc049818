"""The onboard plan store: which goal a table serves, and why a table is refused (executive.goal_tables)."""

from __future__ import annotations

from dataclasses import replace

from executive import goal_tables
from planner.contract.mission import MissionGoal


def _goal_of(table, **kw) -> MissionGoal:  # type: ignore[no-untyped-def]
    """The table's own goal, changed by ``kw``, with ``on_arrival: next``."""
    return MissionGoal(goal=replace(goal_tables.single(table).goals[0].goal, **kw), on_arrival="next")


def test_a_table_serves_the_goal_it_was_planned_for(demo_plan):
    table = demo_plan.table
    other = _goal_of(table, lat_deg=table.goal_lat_deg + 0.05)
    plan = goal_tables.MissionPlan(goals=(other, _goal_of(table)), tables=(None, None))
    verdict = goal_tables.check_table(table, plan)
    assert verdict.accepted and verdict.goal_index == 1
    plan = goal_tables.with_table(plan, 1, table)
    assert plan.table is None and plan.tables[1] is table and plan.has_next


def test_goals_survive_the_degE7_round_trip_but_not_more(demo_plan):
    table = demo_plan.table
    rounded = _goal_of(table, lat_deg=round(table.goal_lat_deg * 1e7) / 1e7, lon_deg=round(table.goal_lon_deg * 1e7) / 1e7)
    assert goal_tables.goal_matches(table, rounded.goal)
    assert not goal_tables.goal_matches(table, _goal_of(table, lat_deg=table.goal_lat_deg + 1e-5).goal)
    assert not goal_tables.goal_matches(table, _goal_of(table, radius_cells=table.goal_radius_cells + 1).goal)
    assert not goal_tables.goal_matches(table, _goal_of(table, depth_m=table.goal_depth_m + 5).goal)


def test_a_table_for_no_goal_or_another_grid_is_refused_with_a_reason(demo_plan):
    table = demo_plan.table
    elsewhere = goal_tables.MissionPlan(goals=(_goal_of(table, lon_deg=table.goal_lon_deg + 0.1),), tables=(None,))
    verdict = goal_tables.check_table(table, elsewhere)
    assert not verdict.accepted and "matches no goal" in verdict.reason
    coarse = replace(table, dlon_deg=table.dlon_deg * 2)  # same goal, another grid
    running = goal_tables.single(table)
    verdict = goal_tables.check_table(coarse, running)
    assert not verdict.accepted and "grid differs" in verdict.reason


def test_a_new_goal_list_keeps_the_tables_of_unchanged_goals(demo_plan):
    table = demo_plan.table
    running = goal_tables.single(table)
    new_goal = _goal_of(table, lat_deg=table.goal_lat_deg - 0.05)
    adopted = goal_tables.adopt((new_goal, _goal_of(table)), running)
    assert adopted.tables == (None, table) and adopted.index == 0
    assert goal_tables.identity(table)["table_crc32"] == f"{table.crc32:08x}"
