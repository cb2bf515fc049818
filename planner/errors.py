"""Errors raised on bad input. The CLI prints the message and exits with status 2."""

from __future__ import annotations


class PlannerError(ValueError):
    """Bad input to the planner; the message says what, expected, got and where."""


class ForecastError(PlannerError):
    """A forecast file that cannot be read or does not cover what was asked."""


class GridError(PlannerError):
    """A planning grid that is malformed or does not fit the forecast."""


class GoalError(PlannerError):
    """A goal on land, outside the grid, or otherwise unusable (spec section 6)."""


class TableError(PlannerError):
    """A policy table that is corrupt, truncated or does not match what was expected."""


class MissionError(PlannerError):
    """A mission file that fails validation; the message names file, line and key path."""
