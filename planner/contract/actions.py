"""Action codes of the paper model (spec section 5), the two table-only codes (section 6), and the
physical model's two course-offset FORWARDs (docs/physical-model.md, "Courses").

Numpy-free and dependency-free: the executive imports it through ``planner.contract.table``.
"""

from __future__ import annotations

from enum import IntEnum, unique


@unique
class Action(IntEnum):
    """Action codes; the order also breaks ties (spec section 7)."""

    DRIFT = 0
    FORWARD = 1
    ROTATE_LEFT = 2
    ROTATE_RIGHT = 3
    UP = 4
    DOWN = 5
    AT_GOAL = 6
    UNREACHABLE = 7
    # Physical model only: FORWARD on a course a third of the way from bearing_k towards the
    # bearing of ROTATE_LEFT's (k + 1) or ROTATE_RIGHT's (k - 1) heading; the vehicle's heading
    # stays in heading k's sector (planner.contract.headings.courses_deg).
    FORWARD_LEFT = 8
    FORWARD_RIGHT = 9


MOVE_ACTIONS = (Action.DRIFT, Action.FORWARD, Action.ROTATE_LEFT, Action.ROTATE_RIGHT, Action.UP, Action.DOWN)
FORWARD_ACTIONS = (Action.FORWARD, Action.FORWARD_LEFT, Action.FORWARD_RIGHT)
