"""What a table action asks of the vehicle: one mapping for the executive's helm and the evaluation's pilot.

``steer(action, state, table, ...)`` turns a table action in state ``(l, j, i, k)`` into a
``Steering``; ``is_complete`` says when a held manoeuvre is done. ``executive.helm`` realises a
``Steering`` as an ArduSub mode and MAVLink target, ``planner.shore.evaluation.runs`` as a
simulator setpoint, so ``lrauv evaluate`` flies what the executive flies.

| action | kind | course / yaw | speed | depth target | held until complete |
|---|---|---|---|---|---|
| FORWARD | VELOCITY | ``bearing_k(j)`` | cruise | the layer's | no |
| FORWARD_LEFT/RIGHT | VELOCITY | a third of the way to ``bearing_{k+1}(j)`` / ``bearing_{k-1}(j)`` (physical plans) | cruise | the layer's | no |
| ROTATE_LEFT/RIGHT | ROTATE | ``bearing_{k+-1}(j)`` | 0 (hold position) | the current depth | yes: heading within 3 deg of the yaw |
| DRIFT | DEPTH | none | 0 (no thrust: the current carries the vehicle) | the layer's | no |
| UP / DOWN | DEPTH | none | 0 (no thrust, drifting along ``w``) | the neighbouring layer's | yes: depth within the tolerance |

How each side realises a kind, and where the two differ:

- VELOCITY: the helm streams a through-water velocity and yaw in GUIDED with zero vertical
  velocity (ArduSub holds the depth it is at; velocity targets expire after 3 s, so the helm
  re-sends them); the pilot's setpoint carries the layer's depth as its depth target.
- ROTATE: the helm sends zero velocity and the yaw in GUIDED (on ArduSub a zero velocity target
  is station keeping, not drifting); the pilot holds position and depth where the turn began.
- DEPTH: ALT_HOLD with a depth target on the helm (no horizontal thrust); a depth setpoint in
  the pilot.
- Held manoeuvres: the helm gives up after ``timeout_s`` and decides again; the pilot holds
  until ``is_complete`` (its runs end on their own time limit).
- Rates: a steering carries the rates the plan priced (``yaw_rate_deg_s``, ``glide_rate_m_s``).
  The helm moves its yaw and depth setpoints toward ``yaw_deg`` and ``depth_m`` at them
  (``executive.setpoints``), so an autopilot with faster slews of its own still turns and glides
  at the priced rate; the pilot's simulator flies them as its own limits. Completion is judged on
  the measured heading and depth against the final ``yaw_deg`` and ``goal_depth_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum, unique

from planner.contract.actions import FORWARD_ACTIONS, Action
from planner.contract.errors import ContractError
from planner.contract.table import PolicyTable

# A rotation is complete within this of its target bearing: on the new bearing itself, not on
# entering its 45-degree bin, where a vehicle left on the bin's edge would flip between headings
# with every wobble.
HEADING_TOLERANCE_DEG = 3.0
DEPTH_TOLERANCE_M = 0.5  # a glide is complete within this of the neighbouring layer's depth (the helm's default)


@unique
class SteeringKind(Enum):
    VELOCITY = "velocity"  # forward through the water on a course, at a speed
    ROTATE = "rotate"  # hold position, turn to a yaw
    DEPTH = "depth"  # no horizontal thrust; hold or seek a depth


@dataclass(frozen=True, slots=True, kw_only=True)
class Steering:
    """What the vehicle is asked to do for one table action (the table in the module docstring)."""

    kind: SteeringKind
    yaw_deg: float | None = None  # VELOCITY: the course; ROTATE: the yaw to turn to; DEPTH: none
    speed_m_s: float = 0.0  # through the water along ``yaw_deg``
    depth_m: float | None = None  # depth target; None: the depth the vehicle is at (ROTATE)
    held: bool = False  # ROTATE/UP/DOWN: held until complete, not only until the state changes
    goal_k: int | None = None  # ROTATE: the heading index turned to
    goal_depth_m: float | None = None  # UP/DOWN: the neighbouring layer's depth
    timeout_s: float | None = None  # held manoeuvres: the helm decides again after this long
    yaw_rate_deg_s: float | None = None  # the plan's turn rate: the helm's yaw setpoint moves toward yaw_deg at it
    glide_rate_m_s: float | None = None  # the plan's glide rate: the helm's depth setpoint moves toward depth_m at it
    heading_tolerance_deg: float = HEADING_TOLERANCE_DEG
    depth_tolerance_m: float = DEPTH_TOLERANCE_M

    @property
    def velocity_ne_m_s(self) -> tuple[float, float]:
        """``(north, east)`` through-water velocity, m/s: ``speed_m_s`` along ``yaw_deg``, zero otherwise."""
        if self.kind is not SteeringKind.VELOCITY or self.yaw_deg is None:
            return 0.0, 0.0
        rad = math.radians(self.yaw_deg)
        return self.speed_m_s * math.cos(rad), self.speed_m_s * math.sin(rad)


def steer(
    action: Action,
    state: tuple[int, int, int, int],
    table: PolicyTable,
    *,
    cruise_speed_m_s: float,
    yaw_rate_deg_s: float,
    glide_rate_m_s: float,
    depth_tolerance_m: float = DEPTH_TOLERANCE_M,
) -> Steering:
    """The steering for a flyable table ``action`` in ``state = (l, j, i, k)``.

    ``yaw_rate_deg_s`` and ``glide_rate_m_s`` are the rates the plan priced: the steering carries
    them for the helm's setpoints, and they size the timeouts of turns and glides: three times the
    nominal time (90 deg, one layer spacing) plus a margin, so a setpoint moved at the priced rate
    from wherever in its state the vehicle starts (a heading within its bin, a depth within half a
    spacing of its layer) arrives well inside it.
    """
    l, j, _i, k = state
    if action in FORWARD_ACTIONS:
        # spec section 2: steer along bearing_k(j) of this cell; FORWARD_LEFT/RIGHT (physical plans) a
        # third of the way to the neighbouring heading's bearing (docs/physical-model.md, "Courses")
        return Steering(kind=SteeringKind.VELOCITY, yaw_deg=table.course_deg(j, k, action), speed_m_s=cruise_speed_m_s,
                        depth_m=table.depth_m[l], depth_tolerance_m=depth_tolerance_m,
                        yaw_rate_deg_s=yaw_rate_deg_s, glide_rate_m_s=glide_rate_m_s)
    if action in (Action.ROTATE_LEFT, Action.ROTATE_RIGHT):
        # spec section 5: a turn to the neighbouring heading, left counter-clockwise (k + 1); its
        # yaw is that heading's bearing in this row (spec section 2)
        goal_k = (k + 1) % 8 if action == Action.ROTATE_LEFT else (k - 1) % 8
        return Steering(kind=SteeringKind.ROTATE, yaw_deg=table.bearing_deg(j, goal_k), held=True, goal_k=goal_k,
                        timeout_s=3.0 * 90.0 / yaw_rate_deg_s + 10.0, depth_tolerance_m=depth_tolerance_m,
                        yaw_rate_deg_s=yaw_rate_deg_s, glide_rate_m_s=glide_rate_m_s)
    if action in (Action.UP, Action.DOWN):
        # spec section 5: a glide to the neighbouring layer, drifting with the current on the way
        goal_depth = table.depth_m[l - 1 if action == Action.UP else l + 1]
        return Steering(kind=SteeringKind.DEPTH, depth_m=goal_depth, held=True, goal_depth_m=goal_depth,
                        timeout_s=3.0 * abs(goal_depth - table.depth_m[l]) / glide_rate_m_s + 30.0,
                        depth_tolerance_m=depth_tolerance_m, yaw_rate_deg_s=yaw_rate_deg_s, glide_rate_m_s=glide_rate_m_s)
    if action == Action.DRIFT:
        return Steering(kind=SteeringKind.DEPTH, depth_m=table.depth_m[l], depth_tolerance_m=depth_tolerance_m,
                        yaw_rate_deg_s=yaw_rate_deg_s, glide_rate_m_s=glide_rate_m_s)
    # AT_GOAL and UNREACHABLE are table codes, not manoeuvres (spec section 6): callers handle them
    raise ContractError(f"steer: {action.name} is a table code, not an action the vehicle can fly")


def is_complete(steering: Steering, *, heading_deg: float | None, depth_m: float) -> bool:
    """Whether a held manoeuvre is done at this heading and depth (always, for one that is not held).

    A turn is never complete without a heading (None or NaN).
    """
    if steering.goal_k is not None:
        if heading_deg is None or steering.yaw_deg is None:
            return False
        error = (heading_deg - steering.yaw_deg + 180.0) % 360.0 - 180.0
        return abs(error) <= steering.heading_tolerance_deg
    if steering.goal_depth_m is not None:
        return abs(depth_m - steering.goal_depth_m) <= steering.depth_tolerance_m
    return True
