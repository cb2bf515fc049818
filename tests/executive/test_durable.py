"""The executive's durable state (``executive.durable``): saved whole, read back exactly, refused clearly."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from executive import durable
from executive.goal_tables import MissionPlan
from planner.contract.errors import LrauvError
from planner.contract.mission import MissionGoal
from planner.contract.settings import Goal


@pytest.fixture()
def plan(demo_plan):
    table = demo_plan.table
    first = MissionGoal(goal=Goal(lon_deg=table.goal_lon_deg, lat_deg=table.goal_lat_deg, depth_m=table.goal_depth_m,
                                  radius_cells=table.goal_radius_cells), on_arrival="next")
    second = MissionGoal(goal=Goal(lon_deg=-117.9, lat_deg=33.4, depth_m=5.0, radius_cells=2), on_arrival="surface")
    return MissionPlan(goals=(first, second), tables=(table, None))


def test_a_saved_state_reads_back_the_same_plan_and_table_bytes(plan, demo_plan, tmp_path):
    data = demo_plan.table.to_bytes()
    path = durable.save(tmp_path, plan, {demo_plan.table.crc32: data}, log_path=tmp_path / "run.mcap",
                        mission_path=tmp_path / "m.yaml")
    assert path == tmp_path / durable.STATE_FILE
    back = durable.load(tmp_path)
    assert back.plan.goals == plan.goals and back.plan.index == 0
    assert back.plan.tables[1] is None
    assert back.plan.tables[0].crc32 == demo_plan.table.crc32
    assert back.blobs[demo_plan.table.crc32] == data
    assert back.log_path == tmp_path / "run.mcap" and back.mission_path == tmp_path / "m.yaml"
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == [
        "policy-%08x.lrpt" % demo_plan.table.crc32, "state.json"]  # no temporary files left


def test_the_active_goal_index_is_kept(plan, demo_plan, tmp_path):
    both = replace(plan, tables=(demo_plan.table, demo_plan.table), index=1)
    durable.save(tmp_path, both, {}, log_path=tmp_path / "run.mcap", mission_path=None)
    back = durable.load(tmp_path)
    assert back.plan.index == 1 and back.mission_path is None


@pytest.mark.parametrize("damage, words", [
    (lambda d: (d / "state.json").unlink(), "no saved state here"),
    (lambda d: (d / "state.json").write_text("{not json"), "cannot read the saved state"),
    (lambda d: _edit(d, version=99), "state version 99"),
    (lambda d: _edit(d, goal_index=5), "goal_index 5"),
    (lambda d: _edit(d, goals="x"), "not a saved executive state"),
    (lambda d: _edit(d, goal_index=1), "the active goal 1 has no table"),
    (lambda d: next((d / "tables").iterdir()).unlink(), "cannot be read"),
    (lambda d: _flip(next((d / "tables").iterdir())), "CRC"),
    (lambda d: _edit(d, tide={"table_crc32": None, "shift_s": 0.0, "observations": [[1.0, 0, 0.1]]}),
     "not a saved executive state .*tide observation"),
    (lambda d: _edit(d, tide={"table_crc32": "zz", "shift_s": 0.0, "observations": []}), "not a saved executive state"),
])
def test_a_damaged_state_is_refused_naming_the_file(plan, tmp_path, damage, words):
    durable.save(tmp_path, plan, {}, log_path=tmp_path / "run.mcap", mission_path=None)
    damage(tmp_path)
    with pytest.raises(LrauvError, match=words) as err:
        durable.load(tmp_path)
    assert str(tmp_path) in str(err.value)


def _edit(d, **changes):  # type: ignore[no-untyped-def]
    state = json.loads((d / "state.json").read_text())
    state.update(changes)
    (d / "state.json").write_text(json.dumps(state))


def _flip(path):  # type: ignore[no-untyped-def]
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def test_a_state_that_cannot_be_saved_is_announced_and_control_goes_on(demo_plan, tmp_path):
    """The saves run on a thread of their own (executive.state_writer): a failing one never stops a decision."""
    from executive.recorder import Topic
    from executive.state import Phase
    from planner.shore.replay.divelog import open_dive
    from tests.support.scripted_autopilot import Stepped

    blocker = tmp_path / "not-a-directory"
    blocker.write_text("a file where the state directory should go\n")
    rig = Stepped(demo_plan.table, tmp_path / "exec.mcap", state_dir=blocker / "state")
    try:
        lat, lon = demo_plan.table.cell_centre(demo_plan.table.ny // 2, 2)
        for _ in range(6):
            rig.ap.heartbeat()
            rig.ap.position(lat, lon, 0.0, 90.0, dt_ms=500)
            rig.pump()
        assert rig.executive._counts["decisions"] >= 5 and rig.executive.helm.phase is not Phase.WAIT_LINK
    finally:
        rig.close()
    texts = [m.payload["message"] for m in open_dive(rig.log_path).messages([Topic.LOG])]
    assert any(t.startswith(f"cannot save the state to {blocker / 'state'}") for t in texts), texts
