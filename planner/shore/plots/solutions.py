"""What the plan pictures read from a solution of either model (paper or physical).

A paper plan's nominal outcome is ``planner.paper.solve.nominal_path``'s (spec
section 5); a physical plan follows each action's most likely outcome
(``PhysicalSolution.nominal``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, overload

from planner.contract.actions import Action

if TYPE_CHECKING:  # pragma: no cover - typing only
    from typing_extensions import TypeIs

    from planner.paper.solve import PathStep, Solution
    from planner.physical.solve import PhysicalSolution, PhysicalStep

    AnySolution = Solution | PhysicalSolution

__all__ = ["NominalStep", "is_physical", "nominal_displacement", "nominal_lon_lat", "nominal_steps"]


class NominalStep(Protocol):
    """A step of a nominal path, paper (``PathStep``) or physical (``PhysicalStep``): state and action."""

    @property
    def l(self) -> int: ...

    @property
    def j(self) -> int: ...

    @property
    def i(self) -> int: ...

    @property
    def k(self) -> int: ...

    @property
    def action(self) -> Action: ...


def is_physical(solution: AnySolution) -> TypeIs[PhysicalSolution]:
    """Whether ``solution`` is a physical plan (its settings' ``model``; "paper" when absent).

    The settings name the model that made the solution (``planner.pipeline`` solves with the
    physical model exactly when ``model`` is "physical"), hence the narrowing to either type.
    """
    return getattr(solution.model.settings, "model", "paper") == "physical"


@overload
def nominal_steps(solution: PhysicalSolution, start: tuple[int, int, int, int]) -> list[PhysicalStep]: ...
@overload
def nominal_steps(solution: Solution, start: tuple[int, int, int, int]) -> list[PathStep]: ...
@overload
def nominal_steps(
    solution: AnySolution, start: tuple[int, int, int, int]
) -> list[PathStep] | list[PhysicalStep]: ...
def nominal_steps(
    solution: AnySolution, start: tuple[int, int, int, int]
) -> list[PathStep] | list[PhysicalStep]:
    """The nominal path: ``planner.paper.solve.nominal_path`` (paper) or ``PhysicalSolution.nominal``."""
    if is_physical(solution):
        return solution.nominal(start)
    from planner.paper.solve import nominal_path

    return nominal_path(solution, start)


def nominal_lon_lat(solution: AnySolution, start: tuple[int, int, int, int],
                    start_lon_lat: tuple[float, float] | None = None) -> tuple[tuple[float, float], ...]:
    """The nominal path as (lon, lat) vertices for a map: ``start_lon_lat`` (the real start) or the start
    cell's centre, then the centre of each cell the path enters, the middle vertices of straight runs
    left out; to 1e-6 degrees (about 0.1 m), so that the table carrying it stays small."""
    grid = solution.model.grid
    cells: list[tuple[int, int]] = []
    for step in nominal_steps(solution, start):
        if not cells or cells[-1] != (step.j, step.i):
            cells.append((step.j, step.i))
    points = [(float(grid.lon_deg[i]), float(grid.lat_deg[j])) for j, i in cells]
    if start_lon_lat is not None:
        points[0] = (float(start_lon_lat[0]), float(start_lon_lat[1]))
    kept = points[:1]
    for n in range(1, len(points) - 1):
        straight = (cells[n][0] - cells[n - 1][0], cells[n][1] - cells[n - 1][1]) == (
            cells[n + 1][0] - cells[n][0], cells[n + 1][1] - cells[n][1])
        if not straight or n == 1:  # the first cell's centre stays: the real start is off it
            kept.append(points[n])
    if len(points) > 1:
        kept.append(points[-1])
    return tuple((round(lon, 6), round(lat, 6)) for lon, lat in kept)


def nominal_displacement(solution: AnySolution, l: int, j: int, i: int, k: int, a: Action) -> tuple[int, int]:
    """Horizontal displacement ``(di, dj)`` of the action's nominal outcome (spec section 5); for a physical
    plan, of the policy's pair's most likely outcome (ties: the first listed)."""
    if is_physical(solution):
        model = solution.model
        pair = int(solution.policy_pair[model.state_index(l, j, i, k)])
        if pair < 0:
            return (0, 0)
        (_, jj, ii, _), _, _ = max(model.outcomes(pair), key=lambda o: o[1])
        return (ii - i, jj - j)
    outs = solution.model.outcomes(l, j, i, k, a)
    if not outs:
        return (0, 0)
    _, jj, ii, _ = outs[0]
    return (ii - i, jj - j)
