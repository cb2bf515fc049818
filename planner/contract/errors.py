"""The project's errors: one root, one branch per domain. The CLI prints the message and exits 2.

Every error is a ``ValueError`` (bad input, not a bug) whose message says what was wrong, what
was expected, what was received and where.
"""

from __future__ import annotations


class LrauvError(ValueError):
    """Root of every error the project raises on bad input."""


class ContractError(LrauvError):
    """The formats shared by shore, vehicle and simulator: settings, missions, tables, waypoints."""


class TableError(ContractError):
    """A policy table that is corrupt, truncated or does not match what was expected."""


class MissionError(ContractError):
    """A mission file that fails validation; the message names file, line and key path."""


class PlannerError(LrauvError):
    """Shore-side planning: forecasts, grids, goals and the models."""


class ForecastError(PlannerError):
    """A forecast file that cannot be read or does not cover what was asked."""


class CoverageError(ForecastError):
    """A planning region (bbox) that lies outside the forecast."""


class GridError(PlannerError):
    """A planning grid that is malformed or does not fit the forecast."""


class GoalError(PlannerError):
    """A goal on land, outside the grid, or otherwise unusable (spec section 6)."""


class ShoreError(LrauvError):
    """Shore-side tools around a dive: uploads, evaluation, replay and reports."""


class ExecutiveError(LrauvError):
    """The onboard executive: its configuration, keys, logs and uploads."""


class SimulatorError(LrauvError):
    """The simulated vehicle and its world."""
