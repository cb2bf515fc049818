"""Action codes of the paper model (spec section 5) and the two table-only codes (section 6).

Numpy-free and dependency-free: the executive imports it through ``planner.table``.
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


MOVE_ACTIONS = (Action.DRIFT, Action.FORWARD, Action.ROTATE_LEFT, Action.ROTATE_RIGHT, Action.UP, Action.DOWN)
