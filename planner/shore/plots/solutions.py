"""What the plan pictures read from a solution of either model (paper or physical).

A paper plan's nominal outcome is ``planner.paper.solve.nominal_path``'s (spec
section 5); a physical plan follows each action's most likely outcome
(``PhysicalSolution.nominal``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from planner.contract.actions import Action

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.paper.solve import Solution
    from planner.physical.solve import PhysicalSolution

    AnySolution = Solution | PhysicalSolution

__all__ = ["is_physical", "nominal_displacement", "nominal_steps"]


def is_physical(solution: Any) -> bool:
    """Whether ``solution`` is a physical plan (its settings' ``model``; "paper" when absent)."""
    return getattr(solution.model.settings, "model", "paper") == "physical"


def nominal_steps(solution: AnySolution, start: tuple[int, int, int, int]) -> list[Any]:
    """The nominal path: ``planner.paper.solve.nominal_path`` (paper) or ``PhysicalSolution.nominal``."""
    if is_physical(solution):
        return solution.nominal(start)  # type: ignore[union-attr]
    from planner.paper.solve import nominal_path

    return nominal_path(solution, start)  # type: ignore[arg-type]


def nominal_displacement(solution: AnySolution, l: int, j: int, i: int, k: int, a: Action) -> tuple[int, int]:
    """Horizontal displacement ``(di, dj)`` of the action's nominal outcome (spec section 5); for a physical
    plan, of the policy's pair's most likely outcome (ties: the first listed)."""
    model = solution.model
    if is_physical(solution):
        pair = int(solution.policy_pair[model.state_index(l, j, i, k)])  # type: ignore[union-attr]
        if pair < 0:
            return (0, 0)
        (_, jj, ii, _), _, _ = max(model.outcomes(pair), key=lambda o: o[1])  # type: ignore[call-arg, arg-type]
        return (ii - i, jj - j)
    outs = model.outcomes(l, j, i, k, a)  # type: ignore[call-arg]
    if not outs:
        return (0, 0)
    _, jj, ii, _ = outs[0]
    return (ii - i, jj - j)
