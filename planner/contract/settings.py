"""Planning settings: criterion, uncertainty, action costs and goal (spec sections 5 to 7)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, TypeVar, get_args

from planner.contract.actions import MOVE_ACTIONS, Action
from planner.contract.errors import GoalError, ContractError
from planner.contract.vehicle import VehicleParams

Criterion = Literal["robust", "optimistic", "expected"]
Uncertainty = Literal["lateral", "none"]
Model = Literal["paper", "physical"]
OnArrival = Literal["hold", "surface", "drift", "next"]  # at a goal (docs/missions.md); the executive's too
BreachAction = Literal["surface", "drift", "hold"]  # when a safety limit is breached (docs/missions.md)
# Each Literal's options as a typed tuple, so that check_choice returns the Literal, not a bare str.
CRITERION_OPTIONS: tuple[Criterion, ...] = get_args(Criterion)
UNCERTAINTY_OPTIONS: tuple[Uncertainty, ...] = get_args(Uncertainty)
MODEL_OPTIONS: tuple[Model, ...] = get_args(Model)
ON_ARRIVAL_OPTIONS: tuple[OnArrival, ...] = get_args(OnArrival)
BREACH_ACTION_OPTIONS: tuple[BreachAction, ...] = get_args(BreachAction)
# Which criteria each model has (docs/physical-model.md): the paper's graph has no probabilities.
CRITERIA: dict[str, tuple[Criterion, ...]] = {"paper": ("robust", "optimistic"), "physical": ("robust", "expected")}

DEFAULT_CALM_SPEED_M_S = 0.01  # spec section 3

ChoiceT = TypeVar("ChoiceT", bound=str)


def check_choice(name: str, value: str, options: tuple[ChoiceT, ...]) -> ChoiceT:
    """``value`` as the one of ``options`` it equals (typed as their Literal), else raise naming the key."""
    for option in options:
        if option == value:
            return option
    raise ContractError(f"{name}: expected one of {', '.join(options)}; got {value!r}")


DEFAULT_TIMING_BLOCK_CELLS = 4  # PlanSettings.timing_block_cells


@dataclass(frozen=True, kw_only=True)
class Costs:
    """Cost of each action (spec section 5: the paper's drift 0, glide 2, forward 4, rotate 10)."""

    drift: int = 0
    forward: int = 4
    rotate: int = 10
    glide: int = 2

    def __post_init__(self) -> None:
        for name in ("drift", "forward", "rotate", "glide"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ContractError(f"costs.{name}: expected a non-negative integer; got {value!r}")
            if value != int(value) or value < 0:
                raise ContractError(
                    f"costs.{name}: the paper model needs non-negative integer costs (spec section 7); got {value!r}"
                )
            object.__setattr__(self, name, int(value))
        if self.max_cost > 1_000_000:
            raise ContractError(f"costs: expected costs up to 1000000; got {self.max_cost}")

    def of(self, action: Action) -> int:
        """Cost of a move action."""
        return {
            Action.DRIFT: self.drift,
            Action.FORWARD: self.forward,
            Action.ROTATE_LEFT: self.rotate,
            Action.ROTATE_RIGHT: self.rotate,
            Action.UP: self.glide,
            Action.DOWN: self.glide,
        }[Action(action)]

    def as_list(self) -> list[int]:
        """Costs indexed by action code 0..5."""
        return [self.of(a) for a in MOVE_ACTIONS]

    @property
    def max_cost(self) -> int:
        return max(self.drift, self.forward, self.rotate, self.glide)


@dataclass(frozen=True, kw_only=True)
class Goal:
    """The goal point and radius (spec section 6)."""

    lon_deg: float
    lat_deg: float
    depth_m: float
    radius_cells: int = 1

    def __post_init__(self) -> None:
        for name in ("lon_deg", "lat_deg", "depth_m"):
            if not math.isfinite(float(getattr(self, name))):
                raise GoalError(f"goal.{name}: expected a finite number; got {getattr(self, name)!r}")
        if int(self.radius_cells) != self.radius_cells or self.radius_cells < 0:
            raise GoalError(f"goal_radius: expected a non-negative whole number of cells; got {self.radius_cells!r}")


@dataclass(frozen=True, kw_only=True)
class PhysicalSettings:
    """How the physical model samples a transition (docs/physical-model.md).

    Outcomes come from ``start_points`` x ``start_points`` start points spread over the cell
    times the forecast itself plus ``error_members`` perturbed currents: uniform offsets of
    equal size in evenly spaced directions, sized so that each current component's
    standard deviation over the members is ``current_error_m_s``.
    """

    start_points: int = 3
    current_error_m_s: float = 0.03
    error_members: int = 8
    max_transition_s: float | None = None  # None: 4 cell crossings at cruise speed (docs/physical-model.md)
    rk4_steps: int = 8  # RK4 steps per cell crossing (per glide)
    min_cost_wh: float = 1e-6  # cost floor: no zero-cost cycles in the expected criterion
    tolerance_wh: float = 1e-9  # policy iteration switches an action only when better by more (< the floor)
    max_iterations: int = 500  # policy iteration's guard
    # FORWARD_LEFT/RIGHT besides FORWARD: courses a third of the way to the neighbouring headings
    # (docs/physical-model.md, "Courses"); False plans with the eight grid bearings only.
    course_offsets: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.course_offsets, bool):
            raise ContractError(f"physical.course_offsets: expected true or false; got {self.course_offsets!r}")
        for name in ("start_points", "error_members", "rk4_steps", "max_iterations"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < (0 if name == "error_members" else 1):
                raise ContractError(f"physical.{name}: expected a whole number >= {0 if name == 'error_members' else 1}; got {value!r}")
        if self.start_points > 9:
            raise ContractError(f"physical.start_points: expected at most 9 per axis; got {self.start_points}")
        if self.error_members in (1, 2) or self.error_members > 64:
            raise ContractError("physical.error_members: expected 0 (no forecast error) or 3..64 evenly spaced "
                               f"directions; got {self.error_members}")
        for name in ("current_error_m_s", "min_cost_wh", "tolerance_wh"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ContractError(f"physical.{name}: expected a number >= 0; got {value!r}")
        if self.max_transition_s is not None and not (
                isinstance(self.max_transition_s, int | float) and math.isfinite(self.max_transition_s)
                and self.max_transition_s > 0):
            raise ContractError(f"physical.max_transition_s: expected a number of seconds > 0; got {self.max_transition_s!r}")
        if self.min_cost_wh <= 0:
            raise ContractError(f"physical.min_cost_wh: expected a number > 0; got {self.min_cost_wh!r}")


@dataclass(frozen=True, kw_only=True)
class PlanSettings:
    """How to plan: model, criterion, uncertainty, costs and the calm threshold."""

    model: Model = "paper"
    criterion: Criterion = "robust"
    uncertainty: Uncertainty = "lateral"
    costs: Costs = field(default_factory=Costs)
    calm_speed_m_s: float = DEFAULT_CALM_SPEED_M_S
    # The physical model's sampling and the vehicle it plans for (unused by the paper model).
    physical: PhysicalSettings = field(default_factory=PhysicalSettings)
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    # A time-varying physical plan (docs/time-varying.md): a slice per forecast step over the next
    # ``horizon_h`` hours; False plans on one forecast step and assumes its current lasts.
    time_varying: bool = False
    horizon_h: float = 72.0
    slice_h: float | None = None  # hours between slices, a multiple of the forecast's step; None: every step
    # A time-varying table that carries each slice's mean current, so that the vehicle fits the tide's
    # timing to the current it meets and looks its slices up that much earlier or later
    # (planner.contract.tide_timing); False: slices at the vehicle's own UTC time. A stationary plan has no
    # slices to shift: there it changes nothing.
    timing_correction: bool = False
    # The reference current of that fit: the mean per block of this many cells a side in each layer, as
    # the tide's phase varies across a coastal region; a block as large as the grid is one mean per layer.
    # Blocks of 4 by default: on NorKyst-800 they turned the fit from no gain into 0.7 % less energy, and
    # elsewhere did as well as the layer's mean (docs/evaluation.md, "A reference current per block").
    timing_block_cells: int = DEFAULT_TIMING_BLOCK_CELLS
    # ``physical.current_error_m_s`` measured from the data (planner.forecast.error) rather than given.
    error_measured: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.time_varying, bool):
            raise ContractError(f"time_varying: expected true or false; got {self.time_varying!r}")
        if not isinstance(self.timing_correction, bool):
            raise ContractError(f"timing_correction: expected true or false; got {self.timing_correction!r}")
        if (isinstance(self.timing_block_cells, bool) or not isinstance(self.timing_block_cells, int)
                or self.timing_block_cells < 1):
            raise ContractError(f"timing_block_cells: expected a whole number of cells >= 1; got {self.timing_block_cells!r}")
        if self.time_varying and self.model != "physical":
            raise ContractError(f"time_varying: needs the physical model (its transitions carry durations); got model {self.model!r}")
        if isinstance(self.horizon_h, bool) or not (isinstance(self.horizon_h, int | float) and math.isfinite(self.horizon_h)
                                                    and self.horizon_h > 0):
            raise ContractError(f"horizon_h: expected a number of hours > 0; got {self.horizon_h!r}")
        if self.slice_h is not None and (isinstance(self.slice_h, bool) or not isinstance(self.slice_h, int | float)
                                         or not math.isfinite(self.slice_h) or self.slice_h <= 0):
            raise ContractError(f"slice_h: expected a number of hours > 0; got {self.slice_h!r}")
        check_choice("model", self.model, MODEL_OPTIONS)
        check_choice("criterion", self.criterion, CRITERION_OPTIONS)
        if self.criterion not in CRITERIA[self.model]:
            raise ContractError(f"criterion: the {self.model} model has {' and '.join(CRITERIA[self.model])}; "
                               f"got {self.criterion!r}")
        check_choice("uncertainty", self.uncertainty, UNCERTAINTY_OPTIONS)
        if not (math.isfinite(self.calm_speed_m_s) and self.calm_speed_m_s >= 0):
            raise ContractError(f"calm_speed: expected a non-negative speed in m/s; got {self.calm_speed_m_s!r}")
