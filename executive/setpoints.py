"""Setpoints that move at the plan's rates: a turn's yaw and a glide's depth as pure functions of time.

The plan prices a turn at the mission's ``yaw_rate_deg_s`` and a glide at its ``glide_rate_m_s``
(``planner.contract.steering``). An autopilot given the final value flies a step at its own speed:
ArduSub slews toward a GUIDED yaw at ``AUTO_YAW_SLEW_RATE`` (60 deg/s) when no yaw rate comes with it,
and its ALT_HOLD depth target (``pos_control.set_pos_desired_U_cm``) is reached at its vertical speed
limit: 45 deg in 1.3-2 s and about 1 m/s were measured on ArduSub SITL, where the plan priced 4.5 s
and 0.2 m/s. So the helm moves the setpoint itself, from the vehicle's heading and depth when the
activity's target was first sent toward the final value, at the priced rate, and re-sends it every
``refresh_s``: any autopilot that tracks its setpoint then turns and glides at the priced rate on
average, whatever its own slew limits. A yaw goes with the plan's rate in the yaw rate field too:
ArduSub (``ModeGuided::guided_set_yaw_state``, ``ModeAuto::set_auto_yaw_look_at_heading``) slews
toward the yaw at min(that rate, 60 deg/s) until within 5 deg, then holds the angle.

Pure functions of an activity's ``Ramp`` and the vehicle time, so the decision audit, which runs the
helm again from the log, gets the same setpoints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from executive.state import Command, DepthTarget, VelocityYaw
from planner.contract.steering import Steering


@dataclass(frozen=True, slots=True)
class Ramp:
    """Where an activity's setpoint starts: the vehicle when the activity's target was first sent."""

    start_s: float  # vehicle time of that first send
    heading_deg: float | None  # the vehicle's heading then; None (unknown): the final yaw at once
    depth_m: float  # the vehicle's depth then


def yaw_at(start_deg: float, final_deg: float, rate_deg_s: float, elapsed_s: float) -> float:
    """The yaw ``elapsed_s`` into a turn from ``start_deg`` to ``final_deg`` the short way at ``rate_deg_s``.

    ``final_deg`` itself once reached (never beyond); before, in [0, 360). A half turn goes
    counter-clockwise.
    """
    delta = (final_deg - start_deg + 180.0) % 360.0 - 180.0
    moved = rate_deg_s * max(elapsed_s, 0.0)
    if moved >= abs(delta):
        return final_deg
    return (start_deg + math.copysign(moved, delta)) % 360.0


def depth_at(start_m: float, final_m: float, rate_m_s: float, elapsed_s: float) -> float:
    """The depth ``elapsed_s`` into a glide from ``start_m`` to ``final_m`` at ``rate_m_s`` (``final_m`` once reached)."""
    delta = final_m - start_m
    moved = rate_m_s * max(elapsed_s, 0.0)
    if moved >= abs(delta):
        return final_m
    return start_m + math.copysign(moved, delta)


def target_at(target: Command, steering: Steering | None, ramp: Ramp | None, now_s: float) -> Command:
    """The command to send at ``now_s`` for an activity whose final target is ``target``.

    A table action's yaw (ROTATE, and a VELOCITY course the vehicle is not yet on) and depth (UP,
    DOWN, DRIFT) move from the ramp's start at the steering's rates; any other target is sent as it is.
    """
    if steering is None or ramp is None:
        return target
    elapsed_s = now_s - ramp.start_s
    if isinstance(target, VelocityYaw) and steering.yaw_rate_deg_s is not None:
        rate = steering.yaw_rate_deg_s
        yaw = target.yaw_deg if ramp.heading_deg is None else yaw_at(ramp.heading_deg, target.yaw_deg, rate, elapsed_s)
        return replace(target, yaw_deg=yaw, yaw_rate_deg_s=rate)
    if isinstance(target, DepthTarget) and steering.glide_rate_m_s is not None:
        return DepthTarget(depth_at(ramp.depth_m, target.depth_m, steering.glide_rate_m_s, elapsed_s))
    return target
