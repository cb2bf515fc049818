"""Monte Carlo closed-loop evaluation: plans flown in-process through a truth that differs from the forecast.

docs/evaluation.md. Every run flies ``vehicle_sim.dynamics.step`` (the simulator's own
physics, without the UDP and MAVLink around it) through ``vehicle_sim.world`` currents from a
truth file, from the same start states for every method:

- ``paper``, ``physical-robust``, ``physical-expected``: feedback plans, the table looked up at
  every step as the executive does, each action flown through ``planner.contract.steering``
  as ``executive.helm`` flies it (that module's docstring has the mapping table and says where
  the helm and this pilot realise it differently), ROTATE and UP/DOWN held until done, a cell
  left only 10 % of a spacing past its edge, drifting at the layer's depth where the plan has
  no action (surfacing over a cell it counts as land) until it has one again;
- ``open-loop``: the physical expected plan's nominal action sequence from the start (each
  action for its mean predicted duration), replayed without looking at the position;
- ``naive``: point at the goal and drive at cruise speed, gliding to the goal's depth.

The vehicle's true state is used (no sensor noise), so differences come from the plans and the
forecast's error alone. A run ends when the vehicle reaches the goal cells (the same cells for
every method), touches land, leaves the planning region, runs out of time, or (open loop) its
sequence ends.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, Protocol, get_args

import numpy as np
from numpy.typing import NDArray

from executive import tide_watch
from planner.contract import tide_timing
from planner.contract.actions import Action
from planner.contract.errors import ShoreError
from planner.contract.steering import SteeringKind, is_complete, steer
from planner.contract.table import CELL_MARGIN, PolicyTable
from vehicle_sim.dynamics import Body, Setpoint, SetpointKind, step
from planner.contract.geodesy import M_PER_DEG_LAT
from planner.contract.vehicle import VehicleParams

if TYPE_CHECKING:  # the parser imports this module: no scipy or numba at import time
    from planner.physical.solve import PhysicalStep

# time-varying: the physical plan with time in the state (docs/time-varying.md), planned once;
# replanned: the stationary physical-expected plan made again at every forecast step.
Method = Literal["paper", "physical-robust", "physical-expected", "open-loop", "naive", "time-varying", "replanned"]
METHODS: tuple[str, ...] = get_args(Method)
DEFAULT_METHODS: tuple[str, ...] = METHODS[:5]  # the time-varying comparison is asked for by name
Outcome = Literal["arrived", "stranded", "left_region", "timed_out", "gave_up", "refused"]
OUTCOMES: tuple[str, ...] = get_args(Outcome)


class Truth(Protocol):
    """What a truth field offers (``vehicle_sim.world.World`` / ``TruthSequence``)."""

    def current_at(self, t_s: float, lat_deg: float, lon_deg: float, depth_m: float) -> tuple[float, float]: ...
    def is_water(self, lat_deg: float, lon_deg: float, depth_m: float, t_s: float = 0.0) -> bool: ...


@dataclass(frozen=True, slots=True)
class Start:
    lon_deg: float
    lat_deg: float
    depth_m: float
    heading_deg: float


@dataclass(frozen=True, slots=True)
class RunResult:
    """One closed-loop run. ``predicted_wh`` is NaN where the method predicts no energy."""

    method: str
    start: int
    outcome: str
    time_s: float
    energy_wh: float
    predicted_wh: float
    marked_reachable: bool


@dataclass(frozen=True, eq=False, kw_only=True)
class Referee:
    """The goal cells and the planning region every method is judged by (one table's geometry)."""

    table: PolicyTable
    goal_mask: NDArray[np.bool_] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "goal_mask", self.table.actions[..., 0] == int(Action.AT_GOAL))

    def judge(self, body: Body) -> str | None:
        cell = self.table.locate(body.lat_deg, body.lon_deg, body.depth_m)
        if cell is None:
            return "left_region"
        if self.goal_mask[cell]:
            return "arrived"
        return None


# --------------------------------------------------------------------------- pilots


class FeedbackPilot:
    """The table's action for the current state, as the executive realises it.

    Like ``executive.helm``: an action is held until the state changes, turns and glides until
    done, and a cell counts as left only ``cell_margin`` of a spacing beyond its edge.
    """

    def __init__(self, table_at: Callable[[float], PolicyTable], params: VehicleParams,
                 cell_margin: float = CELL_MARGIN, timing: PolicyTable | None = None) -> None:
        self._table_at = table_at
        # A time-varying table with its slices' currents: fit the tide's timing to the current met, as the
        # executive does (planner.contract.tide_timing), and look its slices up that much earlier or later.
        self._timing = timing if timing is not None and timing.slice_current_m_s is not None else None
        self._clock = tide_timing.TideClock()
        self._next_measure_s = 0.0
        self._water: tuple[float, float] | None = None  # the through-water velocity last commanded (north, east)
        self._since_s = 0.0
        self._params = params
        self._margin = cell_margin
        self._held: tuple[Setpoint, Callable[[Body], bool]] | None = None
        self._state: tuple[int, int, int, int] | None = None
        self._cell: tuple[int, int] | None = None  # (j, i) of the last decision, for the hysteresis
        self._setpoint: Setpoint | None = None
        self._table: PolicyTable | None = None

    def command(self, body: Body) -> Setpoint | str:
        shift_s = self._clock.shift_s  # as in the executive: a shift fitted now holds from the next decision
        if self._timing is not None and body.time_s >= self._next_measure_s:
            self._measure(body)
        out = self._decide(body, shift_s)
        if self._timing is not None and isinstance(out, Setpoint):
            self._commanded(out, body.time_s)
        return out

    def _decide(self, body: Body, shift_s: float) -> Setpoint | str:
        table = self._table_at(body.time_s + shift_s)
        if table is not self._table:
            # The next slice of a time-varying plan (the same file): decide again now, as the helm does on
            # every update, keeping the held cell and manoeuvre. A new plan: decide afresh, as the helm
            # does on a swap (no held cell or manoeuvre).
            if self._table is None or table.crc32 != self._table.crc32:
                self._cell, self._held = None, None
            self._table, self._state = table, None
        if self._held is not None:
            sp, done = self._held
            if not done(body):
                return sp
            self._held = None
            self._state = None
        look = table.lookup_held(body.lat_deg, body.lon_deg, body.depth_m, body.heading_deg, self._cell, self._margin)
        if look.reason == "at_goal":
            return "arrived"
        if look.state is None:  # outside the grid (the referee ends such runs first)
            return "gave_up"
        if look.state == self._state and self._setpoint is not None:
            return self._setpoint
        self._state, self._cell = look.state, look.state[1:3]
        if look.reason != "ok":  # executive.helm: drift at the layer's depth where no action reaches the goal,
            # surface over a cell the plan counts as land; the plan resumes wherever it has an action again
            depth = table.depth_m[look.state[0]] if look.reason == "unreachable" else 0.0
            self._setpoint = Setpoint(kind=SetpointKind.DEPTH, depth_m=depth)
            return self._setpoint
        sp, completed = realise(look.action, look.state, table, body, self._params)
        self._setpoint = sp
        if completed is not None:
            self._held = (sp, completed)
        return sp


    def _commanded(self, sp: Setpoint, t_s: float) -> None:
        """As ``executive.tide_watch.commanded``: a velocity, none in a depth hold, unknown in a position hold."""
        water = ((sp.north_m_s, sp.east_m_s) if sp.kind is SetpointKind.VELOCITY
                 else None if sp.kind is SetpointKind.POSITION else (0.0, 0.0))
        if not tide_watch.same_velocity(water, self._water):
            self._water, self._since_s = water, t_s

    def _measure(self, body: Body) -> None:
        """One measurement of the current every ``MEASURE_S``, as the executive makes it: the ground velocity
        less the through-water velocity last commanded, once held ``tide_watch.SETTLE_S``."""
        timing = self._timing
        assert timing is not None and timing.slice_current_m_s is not None
        self._next_measure_s = body.time_s + MEASURE_S
        cell = timing.locate(body.lat_deg, body.lon_deg, body.depth_m)
        if cell is None or self._water is None or body.time_s - self._since_s < tide_watch.SETTLE_S:
            return
        north, east = self._water
        self._clock = tide_timing.advance(
            self._clock, timing.slice_unix_s[0] + body.time_s, timing.current_region(cell), body.ground_east_m_s - east,
            body.ground_north_m_s - north, timing.slice_unix_s, timing.slice_current_m_s)


MEASURE_S = 10.0  # the evaluation's pilot measures the current every 10 s of vehicle time


def realise(action: Action, state: tuple[int, int, int, int], table: PolicyTable, body: Body,
            params: VehicleParams) -> tuple[Setpoint, Callable[[Body], bool] | None]:
    """The setpoint for an action in a state, and for ROTATE/UP/DOWN the test that it is done.

    ``planner.contract.steering`` decides; here it becomes a simulator setpoint. A held manoeuvre
    has no timeout here: it lasts until done, or until the run's own time limit.
    """
    steering = steer(action, state, table, cruise_speed_m_s=params.cruise_speed_m_s,
                     yaw_rate_deg_s=params.yaw_rate_deg_s, glide_rate_m_s=params.glide_rate_m_s)
    done = (lambda b: is_complete(steering, heading_deg=b.heading_deg, depth_m=b.depth_m)) if steering.held else None
    if steering.kind is SteeringKind.VELOCITY:
        north, east = steering.velocity_ne_m_s
        return Setpoint(kind=SetpointKind.VELOCITY, north_m_s=north, east_m_s=east, yaw_deg=steering.yaw_deg,
                        depth_m=steering.depth_m), done
    if steering.kind is SteeringKind.ROTATE:
        # Hold the position and depth where the turn began: what ArduSub's GUIDED mode does with the
        # helm's zero velocity target.
        return Setpoint(kind=SetpointKind.POSITION, lat_deg=body.lat_deg, lon_deg=body.lon_deg, depth_m=body.depth_m,
                        yaw_deg=steering.yaw_deg), done
    return Setpoint(kind=SetpointKind.DEPTH, depth_m=steering.depth_m), done  # DRIFT, UP, DOWN


class OpenLoopPilot:
    """A fixed action sequence, each action for its duration, whatever happens."""

    def __init__(self, steps: Sequence[PhysicalStep], table: PolicyTable, params: VehicleParams) -> None:
        self._steps = list(steps)
        self._table = table
        self._params = params
        self._n = -1
        self._until_s = -math.inf
        self._sp: Setpoint | None = None

    def command(self, body: Body) -> Setpoint | str:
        if body.time_s >= self._until_s:
            self._n += 1
            if self._n >= len(self._steps):
                return "gave_up"  # the sequence is spent without arriving
            s = self._steps[self._n]
            self._until_s = body.time_s + s.duration_s
            self._sp, _ = realise(s.action, (s.l, s.j, 0, s.k), self._table, body, self._params)
        assert self._sp is not None
        return self._sp


class NaivePilot:
    """Point at the goal and drive at cruise speed; glide to the goal's depth on the way."""

    def __init__(self, goal_lon_deg: float, goal_lat_deg: float, goal_depth_m: float, params: VehicleParams) -> None:
        self._goal = (goal_lon_deg, goal_lat_deg, goal_depth_m)
        self._speed = params.cruise_speed_m_s

    def command(self, body: Body) -> Setpoint | str:
        lon, lat, depth = self._goal
        north = (lat - body.lat_deg) * M_PER_DEG_LAT
        east = (lon - body.lon_deg) * M_PER_DEG_LAT * math.cos(math.radians(body.lat_deg))
        dist = math.hypot(north, east) or 1.0
        yaw = math.degrees(math.atan2(east, north)) % 360.0
        return Setpoint(kind=SetpointKind.VELOCITY, north_m_s=self._speed * north / dist,
                        east_m_s=self._speed * east / dist, yaw_deg=yaw, depth_m=depth)


# --------------------------------------------------------------------------- one run


def fly(pilot: FeedbackPilot | OpenLoopPilot | NaivePilot, truth: Truth, start: Start, params: VehicleParams,
        referee: Referee, *, dt_s: float, max_time_s: float, time_offset_s: float = 0.0) -> tuple[str, float, float]:
    """Fly one run; returns (outcome, time s, energy Wh). ``time_offset_s``: truth time at the start."""
    body = Body(lat_deg=start.lat_deg, lon_deg=start.lon_deg, depth_m=start.depth_m, heading_deg=start.heading_deg)
    current_at, is_water = truth.current_at, truth.is_water
    while True:
        verdict = referee.judge(body)
        if verdict is not None:
            return verdict, body.time_s, body.energy_used_wh
        t = time_offset_s + body.time_s
        if not is_water(body.lat_deg, body.lon_deg, body.depth_m, t):
            return "stranded", body.time_s, body.energy_used_wh
        if body.time_s >= max_time_s:
            return "timed_out", body.time_s, body.energy_used_wh
        sp = pilot.command(body)
        if isinstance(sp, str):
            return ("arrived" if sp == "arrived" else "gave_up"), body.time_s, body.energy_used_wh
        body = step(body, sp, current_at(t, body.lat_deg, body.lon_deg, body.depth_m), params, dt_s)


def pick_starts(referee: Referee, truth: Truth, n: int, *, seed: int, time_offset_s: float = 0.0) -> list[Start]:
    """``n`` start states spread at random over the region's water cells, outside the goal cells.

    Positions uniform over the grid's area, a layer at random, a heading uniform in [0, 360);
    kept when the table and the truth both have water there. Seeded: the same starts every time.
    """
    table = referee.table
    rng = np.random.default_rng(seed)
    out: list[Start] = []
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 1000 * max(n, 1):
            raise ShoreError(f"found only {len(out)} of {n} start states in water after {tries - 1} tries: a start "
                             "needs water in the plan's table and in the truth; does the truth cover the mission's region?")
        lon = table.lon0_deg + (rng.uniform(-0.5, table.nx - 0.5)) * table.dlon_deg
        lat = table.lat0_deg + (rng.uniform(-0.5, table.ny - 0.5)) * table.dlat_deg
        depth = float(table.depth_m[int(rng.integers(table.n_layers))])
        heading = float(rng.uniform(0.0, 360.0))
        cell = table.locate(lat, lon, depth)
        if cell is None or not table.water[cell] or referee.goal_mask[cell]:
            continue
        if not truth.is_water(lat, lon, depth, time_offset_s):
            continue
        out.append(Start(lon_deg=float(lon), lat_deg=float(lat), depth_m=depth, heading_deg=heading))
    return out


# --------------------------------------------------------------------------- summary


@dataclass(frozen=True, kw_only=True)
class MethodSummary:
    method: str
    runs: int
    marked_reachable: int
    outcomes: dict[str, int]
    success_rate: float  # arrived / runs
    success_from_reachable: float  # arrived among starts the plan marks reachable / those starts
    coverage: float  # starts marked reachable among those some method arrived from / those
    median_time_h: float  # over arrived runs
    median_energy_wh: float
    median_predicted_wh: float
    energy_error: float  # median over arrived runs of spent / predicted - 1
    energy_vs_naive: float  # mean energy over runs both arrived / naive's mean on them - 1
    both_with_naive: int
    mean_energy_all_arrived_wh: float = math.nan  # mean energy over the starts every method arrived from
    all_arrived: int = 0  # those starts


def summarise(results: Sequence[RunResult], methods: Sequence[str]) -> list[MethodSummary]:
    """Per-method figures of docs/evaluation.md from the runs."""
    by = {m: [r for r in results if r.method == m] for m in methods}
    arrived_any = {r.start for r in results if r.outcome == "arrived"}
    naive = {r.start: r for r in by.get("naive", []) if r.outcome == "arrived"}
    every = set.intersection(*({r.start for r in by[m] if r.outcome == "arrived"} for m in methods)) if methods else set()
    out = []
    for m in methods:
        rs = by[m]
        arrived = [r for r in rs if r.outcome == "arrived"]
        marked = [r for r in rs if r.marked_reachable]
        marked_arrived = [r for r in marked if r.outcome == "arrived"]
        covered = [r for r in rs if r.start in arrived_any]
        ratio = [r.energy_wh / r.predicted_wh - 1.0 for r in arrived if math.isfinite(r.predicted_wh) and r.predicted_wh > 0]
        both = [(r.energy_wh, naive[r.start].energy_wh) for r in arrived if r.start in naive]
        out.append(MethodSummary(
            method=m, runs=len(rs), marked_reachable=len(marked),
            outcomes={o: sum(1 for r in rs if r.outcome == o) for o in OUTCOMES},
            success_rate=_frac(len(arrived), len(rs)),
            success_from_reachable=_frac(len(marked_arrived), len(marked)),
            coverage=_frac(sum(1 for r in covered if r.marked_reachable), len(covered)),
            median_time_h=_median([r.time_s / 3600.0 for r in arrived]),
            median_energy_wh=_median([r.energy_wh for r in arrived]),
            median_predicted_wh=_median([r.predicted_wh for r in arrived if math.isfinite(r.predicted_wh)]),
            energy_error=_median(ratio),
            energy_vs_naive=(float(np.mean([a for a, _ in both]) / np.mean([b for _, b in both]) - 1.0)
                             if both else math.nan),
            both_with_naive=len(both),
            mean_energy_all_arrived_wh=float(np.mean([r.energy_wh for r in arrived if r.start in every])) if every else math.nan,
            all_arrived=len(every),
        ))
    return out


def _frac(a: int, b: int) -> float:
    return a / b if b else math.nan


def _median(values: Sequence[float]) -> float:
    return float(np.median(values)) if len(values) else math.nan
