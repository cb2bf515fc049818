"""The executive's pure decision step: every action and every situation gives its command.

No sockets here: ``helm.step`` is a pure function of the helm state, the vehicle
state and the table (issue 2, point 2). The same behaviour over real UDP is in
tests/closed_loop/test_closed_loop.py.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from executive.helm import HelmConfig, HelmState, step
from executive.state import (
    Arm,
    DepthTarget,
    Phase,
    PositionTarget,
    SetMessageInterval,
    SetMode,
    Situation,
    SubMode,
    VehicleState,
    VelocityYaw,
)
from planner.contract.actions import Action
from planner.contract.table import PolicyTable

CONFIG = HelmConfig(cruise_speed_m_s=1.2, refresh_s=1.0, retry_s=2.0, link_loss_timeout_s=30.0)


@pytest.fixture(scope="module")
def table(demo_plan) -> PolicyTable:
    return demo_plan.table


def _state_with(table: PolicyTable, action: Action) -> tuple[int, int, int, int]:
    """A state whose table action is ``action`` and whose heading bin is unambiguous."""
    states = np.argwhere(table.actions == int(action))
    assert len(states), f"the demo table has no {action.name} state"
    return tuple(int(x) for x in states[len(states) // 2])  # type: ignore[return-value]


def _vehicle_at(table: PolicyTable, state: tuple[int, int, int, int], **kw) -> VehicleState:
    l, j, i, k = state
    lat, lon = table.cell_centre(j, i)
    base = dict(time_s=100.0, lat_deg=lat, lon_deg=lon, depth_m=table.depth_m[l], heading_deg=table.bearing_deg(j, k),
                mode=int(SubMode.GUIDED), armed=True, position_ok=True, ekf_reported=True, heartbeat_s=100.0,
                interval_acks=len(CONFIG.rates))  # the autopilot accepted every rate asked for
    base.update(kw)
    return VehicleState(**base)  # type: ignore[arg-type]


RUNNING = HelmState(phase=Phase.RUNNING, rates_sent=True, mission_start_s=0.0)


def _run(table, vehicle, *, helm=RUNNING, now_s=100.0, config=CONFIG):
    return step(helm, vehicle, table, config, now_s=now_s, link_ok=True)


def test_forward_streams_velocity_along_the_cells_bearing(table):
    state = _state_with(table, Action.FORWARD)
    l, j, _i, k = state
    tick = _run(table, _vehicle_at(table, state))
    assert tick.decision is not None and tick.decision.action == Action.FORWARD and tick.decision.cell == state
    (cmd,) = tick.commands
    assert isinstance(cmd, VelocityYaw)
    bearing = table.bearing_deg(j, k)
    assert cmd.yaw_deg == pytest.approx(bearing)
    assert math.hypot(cmd.north_m_s, cmd.east_m_s) == pytest.approx(CONFIG.cruise_speed_m_s)
    assert math.degrees(math.atan2(cmd.east_m_s, cmd.north_m_s)) % 360 == pytest.approx(bearing % 360)
    assert cmd.down_m_s == 0.0
    # Re-sent before ArduSub's 3 s expiry: not at +0.5 s, again at +1 s, and held across updates.
    half = _run(table, _vehicle_at(table, state, time_s=100.5), helm=tick.helm, now_s=100.5)
    assert half.commands == ()
    again = _run(table, _vehicle_at(table, state, time_s=101.0), helm=half.helm, now_s=101.0)
    assert again.commands == (cmd,)
    assert not again.decision.changed


@pytest.mark.parametrize(("action", "dk"), [(Action.FORWARD_LEFT, +1), (Action.FORWARD_RIGHT, -1)])
def test_course_offset_forward_streams_velocity_a_third_of_the_way_to_the_neighbouring_bearing(table, action, dk):
    """Physical plans' FORWARD_LEFT/RIGHT (docs/physical-model.md, "Courses")."""
    state = _state_with(table, Action.FORWARD)
    l, j, _i, k = state
    actions = table.actions.copy()
    actions[state] = int(action)
    physical = replace(table, actions=actions, model="physical")
    tick = _run(physical, _vehicle_at(physical, state))
    assert tick.decision.action == action and tick.decision.cell == state
    (sent,) = tick.commands
    cmd = tick.helm.activity.target  # the course; the yaw setpoint turns to it at the plan's rate
    assert isinstance(cmd, VelocityYaw) and isinstance(sent, VelocityYaw)
    bearing, neighbour = table.bearing_deg(j, k), table.bearing_deg(j, (k + dk) % 8)
    assert sent == replace(cmd, yaw_deg=sent.yaw_deg, yaw_rate_deg_s=CONFIG.yaw_rate_deg_s)
    assert sent.yaw_deg == pytest.approx(bearing % 360.0)  # from the heading it is on
    turn = (cmd.yaw_deg - bearing + 180.0) % 360.0 - 180.0
    assert turn == pytest.approx(((neighbour - bearing + 180.0) % 360.0 - 180.0) / 3.0)
    assert turn < 0 if action == Action.FORWARD_LEFT else turn > 0  # left: counter-clockwise
    assert table.heading_index(j, cmd.yaw_deg) == k  # the vehicle's heading stays in heading k
    assert math.hypot(cmd.north_m_s, cmd.east_m_s) == pytest.approx(CONFIG.cruise_speed_m_s)
    assert math.degrees(math.atan2(cmd.east_m_s, cmd.north_m_s)) % 360 == pytest.approx(cmd.yaw_deg % 360)


def test_forward_waits_for_guided_before_streaming(table):
    state = _state_with(table, Action.FORWARD)
    tick = _run(table, _vehicle_at(table, state, mode=int(SubMode.ALT_HOLD)))
    assert tick.commands == (SetMode(SubMode.GUIDED),)
    retry = _run(table, _vehicle_at(table, state, mode=int(SubMode.ALT_HOLD)), helm=tick.helm, now_s=101.0)
    assert retry.commands == ()  # retried every retry_s, not on every message
    later = _run(table, _vehicle_at(table, state, mode=int(SubMode.ALT_HOLD)), helm=tick.helm, now_s=102.0)
    assert later.commands == (SetMode(SubMode.GUIDED),)


@pytest.mark.parametrize(("action", "dk"), [(Action.ROTATE_LEFT, +1), (Action.ROTATE_RIGHT, -1)])
def test_rotate_turns_45_degrees_and_holds_until_on_the_new_bearing(table, action, dk):
    state = _state_with(table, action)
    l, j, i, k = state
    tick = _run(table, _vehicle_at(table, state))
    (cmd,) = tick.commands
    goal = table.bearing_deg(j, (k + dk) % 8)
    assert tick.helm.activity.target == VelocityYaw(0.0, 0.0, 0.0, goal)
    # The yaw setpoint starts on the heading and turns at the plan's rate (executive.setpoints).
    assert cmd == VelocityYaw(0.0, 0.0, 0.0, table.bearing_deg(j, k) % 360.0, CONFIG.yaw_rate_deg_s)
    # Left is counter-clockwise (k + 1): the compass bearing decreases by about 45 degrees.
    turn = (goal - table.bearing_deg(j, k) + 180.0) % 360.0 - 180.0
    assert turn == pytest.approx(-45.0 * dk, abs=10.0)
    # Half-way round (still nearer the old bin) the rotation is held, even in another cell.
    halfway = table.bearing_deg(j, k) + 0.3 * turn
    moved = _vehicle_at(table, state, time_s=101.0, heading_deg=halfway, lat_deg=table.cell_centre(j, i)[0] + 0.3 * table.dlat_deg)
    held = _run(table, moved, helm=tick.helm, now_s=101.0)
    assert held.decision.action == action and not held.decision.changed
    # In the new bin but short of the new bearing: still turning, so it does not stop on the bin's edge.
    short = _vehicle_at(table, state, time_s=102.0, heading_deg=table.bearing_deg(j, k) + 0.8 * turn)
    assert table.heading_index(j, short.heading_deg) == (k + dk) % 8
    still = _run(table, short, helm=held.helm, now_s=102.0)
    assert still.decision.action == action and not still.decision.changed
    # On the new bearing (within 3 degrees) the table is consulted again.
    done = _run(table, _vehicle_at(table, state, time_s=104.0, heading_deg=goal - 2.0), helm=still.helm, now_s=104.0)
    assert done.decision.changed and done.decision.cell == (l, j, i, (k + dk) % 8)


def test_drift_holds_the_layer_depth_in_alt_hold(table):
    state = _state_with(table, Action.DRIFT)
    tick = _run(table, _vehicle_at(table, state))
    assert tick.commands == (SetMode(SubMode.ALT_HOLD),)
    tick2 = _run(table, _vehicle_at(table, state, mode=int(SubMode.ALT_HOLD)), helm=tick.helm, now_s=100.2)
    assert tick2.commands == (DepthTarget(table.depth_m[state[0]]),)
    assert tick2.decision.mode == SubMode.ALT_HOLD


@pytest.mark.parametrize(("action", "dl"), [(Action.UP, -1), (Action.DOWN, +1)])
def test_glide_goes_to_the_neighbouring_layer_and_holds_until_there(table, action, dl):
    state = _state_with(table, action)
    l = state[0]
    target = table.depth_m[l + dl]
    alt = _vehicle_at(table, state, mode=int(SubMode.ALT_HOLD))
    tick = _run(table, alt)
    assert tick.helm.activity.target == DepthTarget(target)
    # The depth setpoint starts at the vehicle's depth and moves at the plan's glide rate (executive.setpoints).
    assert tick.commands == (DepthTarget(table.depth_m[l]),)
    # Half-way the glide continues although the nearest layer may already be the new one.
    mid = (table.depth_m[l] + target) / 2 + 0.1 * dl
    held = _run(table, replace(alt, time_s=110.0, depth_m=mid), helm=tick.helm, now_s=110.0)
    assert held.decision.action == action and not held.decision.changed
    assert held.commands == (DepthTarget(table.depth_m[l] + dl * 10.0 * CONFIG.glide_rate_m_s),)
    done = _run(table, replace(alt, time_s=130.0, depth_m=target), helm=held.helm, now_s=130.0)
    assert done.decision.changed


def test_arrival_holds_station_or_surfaces_as_configured(table):
    state = _state_with(table, Action.AT_GOAL)
    vehicle = _vehicle_at(table, state)
    hold = _run(table, vehicle)
    assert hold.helm.phase is Phase.ARRIVED and hold.decision.situation is Situation.AT_GOAL
    (cmd,) = hold.commands
    assert cmd == PositionTarget(vehicle.lat_deg, vehicle.lon_deg, table.goal_depth_m)
    assert any("goal reached" in e.text for e in hold.events)
    # It stays arrived even when the current pushes it out of the goal region.
    pushed = _run(table, replace(vehicle, lat_deg=vehicle.lat_deg + 5 * table.dlat_deg, time_s=150.0), helm=hold.helm, now_s=150.0)
    assert pushed.helm.phase is Phase.ARRIVED and not pushed.decision.changed
    surface = _run(table, vehicle, config=replace(CONFIG, on_arrival="surface"))
    assert surface.commands == (SetMode(SubMode.SURFACE),)


@pytest.mark.parametrize(
    ("where", "situation", "mode"),
    [("outside", Situation.OUTSIDE_GRID, SubMode.SURFACE), ("land", Situation.LAND, SubMode.SURFACE),
     ("unreachable", Situation.UNREACHABLE, SubMode.ALT_HOLD)],
)
def test_off_plan_positions_get_a_logged_safe_behaviour(table, where, situation, mode):
    if where == "outside":
        vehicle = _vehicle_at(table, _state_with(table, Action.FORWARD), lat_deg=table.lat0_deg - 1.0)
    elif where == "land":
        l, j, i = (int(x) for x in np.argwhere(~table.water)[0])
        vehicle = _vehicle_at(table, (l, j, i, 0))
    else:
        vehicle = _vehicle_at(table, _state_with(table, Action.UNREACHABLE))
    tick = _run(table, vehicle)
    assert tick.decision.situation is situation
    assert tick.commands == (SetMode(mode),)
    assert [e.level for e in tick.events] == ["warning"]
    again = _run(table, replace(vehicle, time_s=100.5), helm=tick.helm, now_s=100.5)
    assert again.events == ()  # logged once per change, not per message


def test_no_table_surfaces(table):
    tick = step(RUNNING, _vehicle_at(table, _state_with(table, Action.FORWARD)), None, CONFIG, now_s=100.0, link_ok=True)
    assert tick.decision.situation is Situation.NO_TABLE
    assert tick.commands == (SetMode(SubMode.SURFACE),)


def test_setup_sets_rates_then_asks_for_guided_and_arming(table):
    state = _state_with(table, Action.FORWARD)
    manual = _vehicle_at(table, state, mode=int(SubMode.MANUAL), armed=False)
    first = step(HelmState(), manual, table, CONFIG, now_s=10.0, link_ok=True)
    assert first.helm.phase is Phase.SETUP
    kinds = [type(c) for c in first.commands]
    assert kinds.count(SetMessageInterval) == len(CONFIG.rates)
    assert SetMode(SubMode.GUIDED) in first.commands and Arm(True) in first.commands
    ready = step(first.helm, replace(manual, mode=int(SubMode.GUIDED), armed=True), table, CONFIG, now_s=12.0, link_ok=True)
    assert ready.helm.phase is Phase.RUNNING and ready.helm.mission_start_s == 12.0
    assert ready.decision is not None


def test_link_loss_asks_for_surface_and_recovers(table):
    vehicle = _vehicle_at(table, _state_with(table, Action.FORWARD))
    running = _run(table, vehicle)
    lost = step(running.helm, vehicle, table, CONFIG, now_s=140.0, link_ok=False)
    assert lost.helm.phase is Phase.LINK_LOST and lost.commands == (SetMode(SubMode.SURFACE),)
    assert lost.events[0].level == "error"
    quiet = step(lost.helm, vehicle, table, CONFIG, now_s=141.0, link_ok=False)
    assert quiet.commands == () and quiet.events == ()
    back = step(quiet.helm, replace(vehicle, time_s=150.0), table, CONFIG, now_s=150.0, link_ok=True)
    assert back.helm.phase is Phase.RUNNING  # already GUIDED and armed: straight back to the plan
    assert any("link regained" in e.text for e in back.events)


@pytest.mark.parametrize(
    ("config", "vehicle_kw", "situation"),
    [(replace(CONFIG, max_mission_time_s=50.0), {}, Situation.MISSION_TIME),
     (replace(CONFIG, min_battery_pct=20.0), {"battery_pct": 15.0}, Situation.LOW_BATTERY),
     (replace(CONFIG, max_depth_m=4.0), {"depth_m": 6.0}, Situation.TOO_DEEP),
     # a fence around a far-away square: the vehicle is outside it
     (replace(CONFIG, geofence=((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0))), {}, Situation.GEOFENCE)],
)
def test_safety_limits_surface_and_suspend_the_plan(table, config, vehicle_kw, situation):
    vehicle = _vehicle_at(table, _state_with(table, Action.FORWARD), **vehicle_kw)
    tick = _run(table, vehicle, config=config)
    if situation is not Situation.MISSION_TIME:  # a reading over a limit fires it only once it lasts the window
        assert tick.helm.phase is Phase.RUNNING and tick.decision.situation is Situation.FOLLOWING
        assert [e.level for e in tick.events] == ["warning"]
        t = 100.0 + config.breach_window_s
        held = _run(table, replace(vehicle, time_s=t - 0.5), helm=tick.helm, now_s=t - 0.5, config=config)
        assert held.helm.phase is Phase.RUNNING
        tick = _run(table, replace(vehicle, time_s=t), helm=held.helm, now_s=t, config=config)
    assert tick.helm.phase is Phase.SAFE and tick.decision.situation is situation
    assert tick.helm.stop is situation
    assert tick.commands == (SetMode(SubMode.SURFACE),)
    later = _run(table, replace(vehicle, mode=int(SubMode.SURFACE), time_s=200.0), helm=tick.helm, now_s=200.0, config=config)
    assert later.helm.phase is Phase.SAFE and later.commands == ()


def test_duplicated_telemetry_sends_nothing_twice(table):
    vehicle = _vehicle_at(table, _state_with(table, Action.FORWARD))
    first = _run(table, vehicle)
    dup = _run(table, vehicle, helm=first.helm)
    assert first.commands and dup.commands == () and dup.events == ()


def test_an_action_that_never_completes_times_out_once_and_restarts(table):
    state = _state_with(table, Action.ROTATE_LEFT)
    stuck = _vehicle_at(table, state)  # the heading never changes
    tick = _run(table, stuck)
    timeout = tick.helm.activity.timeout_s
    late = _run(table, replace(stuck, time_s=100.0 + timeout + 1), helm=tick.helm, now_s=100.0 + timeout + 1)
    assert [e.level for e in late.events] == ["warning"] and late.decision.changed
    assert late.commands  # the turn is commanded again
    after = _run(table, replace(stuck, time_s=100.0 + timeout + 2), helm=late.helm, now_s=100.0 + timeout + 2)
    assert after.events == () and not after.decision.changed


def test_a_cell_is_left_only_a_margin_beyond_its_edge(table):
    """Hysteresis: noise or the current on a cell boundary cannot make the decision chatter."""
    # A FORWARD state with a water neighbour in the same row whose action at this heading differs.
    found = [(tuple(int(x) for x in s), di) for s in np.argwhere(table.actions == int(Action.FORWARD)) for di in (1, -1)
             if 0 <= s[2] + di < table.nx and table.water[s[0], s[1], s[2] + di]
             and table.actions[s[0], s[1], s[2] + di, s[3]] not in (int(Action.FORWARD), int(Action.AT_GOAL))]
    assert found, "the demo table has no FORWARD state beside another action"
    state, di = found[len(found) // 2]
    l, j, i, k = state
    lat, lon = table.cell_centre(j, i)
    first = _run(table, _vehicle_at(table, state))
    assert first.decision.cell == state

    def at(frac: float, helm, t: float):
        # frac of a cell past the shared edge, into the neighbour
        x = lon + di * (0.5 + frac) * table.dlon_deg
        return _run(table, _vehicle_at(table, state, lon_deg=x, time_s=t), helm=helm, now_s=t)

    inside = at(0.05, first.helm, 101.0)  # 5 % into the neighbour: still this cell's action
    assert table.locate(lat, lon + di * 0.55 * table.dlon_deg, table.depth_m[l])[2] == i + di
    assert inside.decision.cell == state and not inside.decision.changed
    beyond = at(0.15, inside.helm, 102.0)  # beyond the 10 % margin: the neighbour's action
    assert beyond.decision.changed and beyond.decision.cell[:3] == (l, j, i + di)
    back = at(-0.05, beyond.helm, 103.0)  # back over the edge by 5 %: the neighbour is kept
    assert back.decision.cell[:3] == (l, j, i + di) and not back.decision.changed
    # Without a margin the decision follows the raw cell at once.
    raw = _run(table, _vehicle_at(table, state, lon_deg=lon + di * 0.55 * table.dlon_deg, time_s=101.0),
               helm=first.helm, now_s=101.0, config=replace(CONFIG, cell_margin=0.0))
    assert raw.decision.changed and raw.decision.cell[:3] == (l, j, i + di)


@pytest.mark.parametrize(("on_breach", "mode", "target"), [
    ("surface", SubMode.SURFACE, None), ("drift", SubMode.ALT_HOLD, DepthTarget), ("hold", SubMode.GUIDED, PositionTarget)])
def test_a_breach_does_what_on_breach_says(table, on_breach, mode, target):
    vehicle = _vehicle_at(table, _state_with(table, Action.FORWARD), depth_m=6.0)
    config = replace(CONFIG, max_depth_m=4.0, on_breach=on_breach)
    too_deep_since = replace(RUNNING, breach=Situation.TOO_DEEP, breach_since_s=100.0 - config.breach_window_s)
    tick = _run(table, replace(vehicle, mode=int(SubMode.MANUAL)), config=config, helm=too_deep_since)
    assert tick.helm.phase is Phase.SAFE and tick.decision.situation is Situation.TOO_DEEP
    assert tick.commands == (SetMode(mode),) and f"on_breach {on_breach}" in tick.events[0].text
    there = _run(table, replace(vehicle, mode=int(mode), time_s=101.0), helm=tick.helm, now_s=101.0, config=config)
    if target is None:
        assert there.commands == ()
    else:  # the breach position (or its depth) is held, not the plan's next target
        assert len(there.commands) == 1 and isinstance(there.commands[0], target)
        assert there.commands[0].depth_m == pytest.approx(6.0)
        if target is PositionTarget:
            assert there.commands[0].lat_deg == pytest.approx(vehicle.lat_deg)


def test_link_loss_asks_for_the_on_breach_mode(table):
    vehicle = _vehicle_at(table, _state_with(table, Action.FORWARD))
    config = replace(CONFIG, on_breach="hold")
    running = _run(table, vehicle, config=config)
    lost = step(running.helm, vehicle, table, config, now_s=140.0, link_ok=False)
    assert lost.helm.phase is Phase.LINK_LOST and lost.commands == (SetMode(SubMode.GUIDED),)


def test_geofence_inside_and_outside():
    from executive.geofence import inside

    square = ((-118.0, 33.0), (-117.0, 33.0), (-117.0, 34.0), (-118.0, 34.0))
    assert inside(-117.5, 33.5, square) and not inside(-116.9, 33.5, square) and not inside(-117.5, 34.1, square)
    notch = ((0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (2.0, 1.0), (0.0, 4.0))  # concave: the notch is outside
    assert inside(1.0, 0.5, notch) and not inside(2.0, 3.0, notch) and inside(0.5, 3.0, notch)


def test_rate_requests_go_again_until_each_is_acknowledged(table):
    """A lost SET_MESSAGE_INTERVAL would leave its stream at the autopilot's default: ask until all are accepted."""
    n = len(CONFIG.rates)
    vehicle = _vehicle_at(table, _state_with(table, Action.FORWARD), interval_acks=0)
    helm = HelmState(phase=Phase.RUNNING, mission_start_s=0.0)

    def rates(tick):  # type: ignore[no-untyped-def]
        return [c for c in tick.commands if isinstance(c, SetMessageInterval)]

    first = _run(table, vehicle, helm=helm, now_s=100.0)
    assert len(rates(first)) == n
    assert rates(_run(table, vehicle, helm=first.helm, now_s=101.0)) == []  # not before retry_s
    again = _run(table, vehicle, helm=first.helm, now_s=102.0)
    assert len(rates(again)) == n  # no acknowledgement: all again
    partly = replace(vehicle, interval_acks=n - 1)
    assert len(rates(_run(table, partly, helm=again.helm, now_s=104.0))) == n  # one still missing
    done = replace(vehicle, interval_acks=n)
    assert rates(_run(table, done, helm=again.helm, now_s=200.0)) == []  # every one accepted: no more
    # An autopilot that never acknowledges is asked ten times, then told so once.
    tick, asked, warned = first, 1, []
    for t in range(2, 60):
        tick = _run(table, vehicle, helm=tick.helm, now_s=100.0 + 2.0 * t)
        asked += bool(rates(tick))
        warned += [e.text for e in tick.events if "telemetry rates" in e.text]
    assert asked == 10 and len(warned) == 1
