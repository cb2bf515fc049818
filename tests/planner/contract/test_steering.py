"""The executive's helm and the evaluation's pilot fly the same steering for every action.

``executive.helm.step`` (what the vehicle flies) and ``planner.shore.evaluation.runs.realise``
(what ``lrauv evaluate`` flies) both go through ``planner.contract.steering``. Here both are
driven over every flyable action, every heading and the top, a middle and the bottom layer of a
paper table and of a physical one (with course offsets), and must give the same course or yaw,
speed, depth target and hold, and complete a turn or a glide at the same heading or depth errors.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from executive.helm import Activity, HelmConfig, HelmState, step
from executive.state import DepthTarget, Phase, SubMode, VehicleState, VelocityYaw
from planner.contract.actions import FORWARD_ACTIONS, MOVE_ACTIONS, Action
from planner.contract.errors import ContractError
from planner.contract.geodesy import BBox
from planner.contract.settings import Goal, PlanSettings
from planner.contract.steering import SteeringKind, steer
from planner.contract.table import PolicyTable
from planner.contract.vehicle import VehicleParams
from planner.shore.evaluation.runs import realise
from vehicle_sim.dynamics import Body, Setpoint, SetpointKind

# The same figures on both sides, none of them the defaults, so that a side that ignored them shows.
CRUISE_M_S, YAW_RATE_DEG_S, GLIDE_RATE_M_S = 1.3, 12.0, 0.25
CONFIG = HelmConfig(cruise_speed_m_s=CRUISE_M_S, yaw_rate_deg_s=YAW_RATE_DEG_S, glide_rate_m_s=GLIDE_RATE_M_S)
PARAMS = VehicleParams(cruise_speed_m_s=CRUISE_M_S, yaw_rate_deg_s=YAW_RATE_DEG_S, glide_rate_m_s=GLIDE_RATE_M_S)
RUNNING = HelmState(phase=Phase.RUNNING, rates_sent=True, mission_start_s=0.0)
NOW_S = 100.0
# The documented tolerances (docs/executive.md): a turn is done within 3 degrees of its bearing,
# a glide within 0.5 m of the neighbouring layer's depth.
HEADING_TOLERANCE_DEG, DEPTH_TOLERANCE_M = 3.0, 0.5
JUST = 0.01  # just inside (tolerance - JUST) and just outside (tolerance + JUST)
HELD = (Action.ROTATE_LEFT, Action.ROTATE_RIGHT, Action.UP, Action.DOWN)


@pytest.fixture(scope="module")
def physical_table(synthetic_forecast) -> PolicyTable:
    """A small physical plan: 6 x 5 cells, three layers, course offsets on (the default)."""
    from planner.pipeline import PlanRequest, make_plan

    goal = Goal(lat_deg=33.40, lon_deg=-117.80, depth_m=0.0, radius_cells=1)
    box = BBox(west_deg=-118.0, south_deg=33.30, east_deg=-117.70, north_deg=33.50)
    request = PlanRequest(forecast_path=synthetic_forecast, goal=goal, depths_m=(0.0, 5.0, 10.0),
                          settings=PlanSettings(model="physical", criterion="expected"), bbox=box, nx=6, ny=5,
                          time_index=0)
    table = make_plan(request).table
    assert table.model == "physical" and table.physical["sampling"]["course_offsets"] is True
    return table


@pytest.fixture(scope="module", params=["paper", "physical"])
def table(request, demo_plan, physical_table) -> PolicyTable:
    return demo_plan.table if request.param == "paper" else physical_table


def _actions(table: PolicyTable) -> tuple[Action, ...]:
    """Every flyable action of the table's model: FORWARD_LEFT/RIGHT only in physical plans."""
    return MOVE_ACTIONS + (FORWARD_ACTIONS[1:] if table.model == "physical" else ())


def _column(table: PolicyTable) -> tuple[int, int]:
    """(j, i) of a cell that is water in every layer and nowhere the goal, so every lookup there is "ok"."""
    moves = np.isin(table.actions, [int(a) for a in _actions(table)] + [int(Action.UNREACHABLE)]).all(axis=(0, 3))
    found = np.argwhere(table.water.all(axis=0) & moves)
    assert len(found), "no water column away from the goal"
    j, i = found[len(found) // 2]
    return int(j), int(i)


def _layers(table: PolicyTable) -> tuple[int, ...]:
    assert table.n_layers >= 3
    return 0, table.n_layers // 2, table.n_layers - 1  # top, middle, bottom


def _flyable(action: Action, l: int, table: PolicyTable) -> bool:
    return not (action == Action.UP and l == 0 or action == Action.DOWN and l == table.n_layers - 1)


def _with_action(table: PolicyTable, state: tuple[int, int, int, int], action: Action) -> PolicyTable:
    actions = table.actions.copy()
    actions[state] = int(action)
    return replace(table, actions=actions)


def _vehicle(table: PolicyTable, state: tuple[int, int, int, int], *, heading_deg: float, depth_m: float,
             mode: SubMode = SubMode.GUIDED, time_s: float = NOW_S) -> VehicleState:
    _l, j, i, _k = state
    lat, lon = table.cell_centre(j, i)
    return VehicleState(time_s=time_s, lat_deg=lat, lon_deg=lon, depth_m=depth_m, heading_deg=heading_deg % 360.0,
                        mode=int(mode), armed=True, position_ok=True, heartbeat_s=time_s,
                        interval_acks=len(CONFIG.rates))


def _body(table: PolicyTable, state: tuple[int, int, int, int], *, heading_deg: float, depth_m: float) -> Body:
    _l, j, i, _k = state
    lat, lon = table.cell_centre(j, i)
    return Body(time_s=NOW_S, lat_deg=lat, lon_deg=lon, depth_m=depth_m, heading_deg=heading_deg % 360.0)


def _helm(table: PolicyTable, state: tuple[int, int, int, int]) -> tuple[HelmState, Activity]:
    """The helm's activity for the table's action in ``state``, and that the target it streams is it."""
    l, j, _i, k = state
    at = {"heading_deg": table.bearing_deg(j, k), "depth_m": table.depth_m[l]}
    tick = step(RUNNING, _vehicle(table, state, **at), table, CONFIG, now_s=NOW_S, link_ok=True)
    act = tick.helm.activity
    assert act is not None and tick.decision is not None and tick.decision.cell == state
    if act.mode is not SubMode.GUIDED:  # once the vehicle is in the activity's mode, the target streams
        tick = step(RUNNING, _vehicle(table, state, mode=act.mode, **at), table, CONFIG, now_s=NOW_S, link_ok=True)
        assert replace(tick.helm.activity, ramp=None) == act
        act = tick.helm.activity
    # The setpoint moves toward the target at the plan's rates (executive.setpoints) and ends on it.
    assert tick.commands == (act.target_at(NOW_S),)
    final = act.target_at(NOW_S + 1e4)
    assert final == (replace(act.target, yaw_rate_deg_s=YAW_RATE_DEG_S) if isinstance(act.target, VelocityYaw)
                     else act.target)
    return tick.helm, act


def _helm_view(act: Activity, vehicle_depth_m: float) -> tuple[object, ...]:
    """(kind, yaw, (north, east) m/s, depth target, held) of a helm activity."""
    target = act.target
    if act.mode is SubMode.ALT_HOLD:
        assert isinstance(target, DepthTarget)
        return "depth", None, (0.0, 0.0), target.depth_m, act.completes
    assert act.mode is SubMode.GUIDED and isinstance(target, VelocityYaw)
    assert target.down_m_s == 0.0  # GUIDED with no vertical velocity holds the depth the vehicle is at
    moving = (target.north_m_s, target.east_m_s) != (0.0, 0.0)
    return ("velocity" if moving else "rotate", target.yaw_deg, (target.north_m_s, target.east_m_s), vehicle_depth_m,
            act.completes)


def _pilot_view(sp: Setpoint, held: bool, body: Body) -> tuple[object, ...]:
    """The same of a pilot setpoint."""
    if sp.kind is SetpointKind.DEPTH:
        return "depth", sp.yaw_deg, (sp.north_m_s, sp.east_m_s), sp.depth_m, held
    if sp.kind is SetpointKind.POSITION:  # a turn holds the position where it began
        assert (sp.lat_deg, sp.lon_deg) == (body.lat_deg, body.lon_deg)
        return "rotate", sp.yaw_deg, (sp.north_m_s, sp.east_m_s), sp.depth_m, held
    assert sp.kind is SetpointKind.VELOCITY
    return "velocity", sp.yaw_deg, (sp.north_m_s, sp.east_m_s), sp.depth_m, held


def _expected(action: Action, state: tuple[int, int, int, int], table: PolicyTable) -> tuple[object, ...]:
    """What the mapping asks for, from the table alone (spec sections 2 and 5)."""
    l, j, _i, k = state
    if action in FORWARD_ACTIONS:
        course = table.course_deg(j, k, action)
        rad = math.radians(course)
        return "velocity", course, (CRUISE_M_S * math.cos(rad), CRUISE_M_S * math.sin(rad)), table.depth_m[l], False
    if action in (Action.ROTATE_LEFT, Action.ROTATE_RIGHT):
        goal_k = (k + 1) % 8 if action == Action.ROTATE_LEFT else (k - 1) % 8
        return "rotate", table.bearing_deg(j, goal_k), (0.0, 0.0), table.depth_m[l], True
    if action in (Action.UP, Action.DOWN):
        return "depth", None, (0.0, 0.0), table.depth_m[l - 1 if action == Action.UP else l + 1], True
    return "depth", None, (0.0, 0.0), table.depth_m[l], False


def _errors(act: Activity, table: PolicyTable, state: tuple[int, int, int, int]) -> list[tuple[float, float, bool]]:
    """(heading, depth, complete?) just inside and just outside the tolerance, either side of the goal."""
    l, j, _i, k = state
    steering = act.steering
    assert steering is not None and steering.held
    out = []
    for sign in (1.0, -1.0):
        for off in (-JUST, JUST):
            if steering.goal_k is not None:  # a turn, at the layer's depth
                assert steering.yaw_deg is not None
                out.append((steering.yaw_deg + sign * (HEADING_TOLERANCE_DEG + off), table.depth_m[l], off < 0))
            else:  # a glide, on heading k
                assert steering.goal_depth_m is not None
                out.append((table.bearing_deg(j, k), steering.goal_depth_m + sign * (DEPTH_TOLERANCE_M + off), off < 0))
    return out


def test_helm_and_pilot_fly_the_same_steering_for_every_action_heading_and_layer(table):
    j, i = _column(table)
    actions = _actions(table)
    flown = 0
    for l in _layers(table):
        for k in range(8):
            state = (l, j, i, k)
            at = {"heading_deg": table.bearing_deg(j, k), "depth_m": table.depth_m[l]}
            for action in actions:
                if not _flyable(action, l, table):
                    continue
                where = f"{action.name} in state {state} of the {table.model} table"
                t = _with_action(table, state, action)
                helm, act = _helm(t, state)
                body = _body(t, state, **at)
                sp, done = realise(action, state, t, body, PARAMS)
                helm_view = _helm_view(act, vehicle_depth_m=table.depth_m[l])
                assert helm_view == _pilot_view(sp, done is not None, body), where
                assert helm_view == _expected(action, state, t), where
                assert math.hypot(*helm_view[2]) == pytest.approx(CRUISE_M_S if action in FORWARD_ACTIONS else 0.0)
                if action not in HELD:
                    assert done is None and not act.completes and act.timeout_s is None, where
                    flown += 1
                    continue
                # The helm's timeouts: three times the nominal turn (90 deg) or glide, plus a margin.
                dz = abs(act.steering.goal_depth_m - table.depth_m[l]) if act.steering.goal_depth_m is not None else 0.0
                timeout = (3.0 * 90.0 / YAW_RATE_DEG_S + 10.0 if act.steering.goal_k is not None
                           else 3.0 * dz / GLIDE_RATE_M_S + 30.0)
                assert act.timeout_s == pytest.approx(timeout), where
                for heading, depth, complete in _errors(act, t, state):
                    later = step(helm, _vehicle(t, state, heading_deg=heading, depth_m=depth, mode=act.mode,
                                                time_s=NOW_S + 1.0), t, CONFIG, now_s=NOW_S + 1.0, link_ok=True)
                    assert later.decision is not None
                    helm_done = later.decision.changed  # held while not complete; a new decision once it is
                    assert helm_done == done(_body(t, state, heading_deg=heading, depth_m=depth)) == complete, (
                        f"{where} at heading {heading:.2f}, depth {depth:.2f}")
                flown += 1
    n = len(actions)
    # every action at every heading of three layers, less UP on the top and DOWN on the bottom
    assert flown == 8 * (3 * n - 2)


def test_where_the_helm_and_the_pilot_realise_a_steering_differently(demo_plan):
    """The differences planner.contract.steering's docstring lists, kept on purpose."""
    table = demo_plan.table
    j, i = _column(table)
    l, k = 1, 2
    state = (l, j, i, k)
    off_layer = table.depth_m[l] + 0.3
    heading = table.bearing_deg(j, k)
    # FORWARD: the helm holds the depth it is at (no vertical velocity); the pilot seeks the layer's.
    t = _with_action(table, state, Action.FORWARD)
    tick = step(RUNNING, _vehicle(t, state, heading_deg=heading, depth_m=off_layer), t, CONFIG, now_s=NOW_S, link_ok=True)
    assert isinstance(tick.helm.activity.target, VelocityYaw) and tick.helm.activity.target.down_m_s == 0.0
    sp, _ = realise(Action.FORWARD, state, t, _body(t, state, heading_deg=heading, depth_m=off_layer), PARAMS)
    assert sp.depth_m == table.depth_m[l]
    # ROTATE: the helm asks for zero velocity in GUIDED; the pilot holds the point and depth it began at.
    t = _with_action(table, state, Action.ROTATE_LEFT)
    tick = step(RUNNING, _vehicle(t, state, heading_deg=heading, depth_m=off_layer), t, CONFIG, now_s=NOW_S, link_ok=True)
    assert tick.helm.activity.target == VelocityYaw(0.0, 0.0, 0.0, table.bearing_deg(j, k + 1))
    body = _body(t, state, heading_deg=heading, depth_m=off_layer)
    sp, _ = realise(Action.ROTATE_LEFT, state, t, body, PARAMS)
    assert (sp.kind, sp.lat_deg, sp.lon_deg, sp.depth_m) == (SetpointKind.POSITION, body.lat_deg, body.lon_deg, off_layer)
    # Held manoeuvres: the helm decides again after its timeout; the pilot has none (its runs end on their own).
    steering = steer(Action.ROTATE_LEFT, state, t, cruise_speed_m_s=CRUISE_M_S, yaw_rate_deg_s=YAW_RATE_DEG_S,
                     glide_rate_m_s=GLIDE_RATE_M_S)
    assert steering.kind is SteeringKind.ROTATE and steering.timeout_s == tick.helm.activity.timeout_s
    stuck = step(tick.helm, _vehicle(t, state, heading_deg=heading, depth_m=off_layer, time_s=NOW_S + 1e4), t, CONFIG,
                 now_s=NOW_S + 1e4, link_ok=True)
    assert stuck.decision.changed and [e.level for e in stuck.events] == ["warning"]


@pytest.mark.parametrize("action", [Action.AT_GOAL, Action.UNREACHABLE])
def test_table_codes_are_not_steered(demo_plan, action):
    with pytest.raises(ContractError, match=action.name):
        steer(action, (0, 0, 0, 0), demo_plan.table, cruise_speed_m_s=1.0, yaw_rate_deg_s=10.0, glide_rate_m_s=0.2)
