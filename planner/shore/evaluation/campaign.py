"""An evaluation campaign: the compared plans, the start states, and every closed-loop run.

``lrauv evaluate`` (docs/evaluation.md) builds a ``Campaign`` from a mission, a planning
forecast and a truth: it plans each method once per forecast step it needs (``replan_s``:
replanning at forecast steps, the project's answer to time-varying currents; see
docs/physical-model.md), picks seeded start states, and flies every method from every start
with ``planner.shore.evaluation.runs.fly``. ``run_one`` is the unit of work: it needs only the plans, the
truth and one start, so runs can go to other processes.
"""

from __future__ import annotations

import math
import time
from bisect import bisect_right
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from planner.contract.actions import Action
from planner.cluster import InProcess, Runner, chunks
from planner.contract.errors import ShoreError
from planner.contract.progress import SILENT, Progress
from planner.shore.evaluation.runs import (
    DEFAULT_METHODS,
    METHODS,
    FeedbackPilot,
    NaivePilot,
    OpenLoopPilot,
    Referee,
    RunResult,
    Start,
    Truth,
    fly,
    pick_starts,
)
from planner.forecast import Forecast, open_forecast
from planner.contract.mission import Mission
from planner.physical.solve import PhysicalSolution
from planner.pipeline import PlanRequest, PlanResult, make_plan
from planner.contract.settings import Goal, PlanSettings
from planner.contract.table import PolicyTable
from planner.contract.vehicle import VehicleParams


@dataclass(frozen=True, kw_only=True)
class CampaignSpec:
    """Everything a campaign depends on; same spec, same runs."""

    mission: Mission
    forecast_path: Path
    truth: Truth
    methods: tuple[str, ...] = DEFAULT_METHODS
    n_starts: int = 100
    seed: int = 0
    dt_s: float = 2.0
    max_time_s: float = 24 * 3600.0
    replan_s: float | None = None  # None: plan once, at the first step
    time_index: int = 0
    grid_scale: int = 1  # 2: every cell halved (nx -> 2 nx - 1), the goal radius doubled

    def __post_init__(self) -> None:
        unknown = [m for m in self.methods if m not in METHODS]
        if unknown or not self.methods:
            raise ShoreError(f"--methods: expected some of {', '.join(METHODS)}; got {', '.join(self.methods) or 'none'}")
        if not (math.isfinite(self.dt_s) and self.dt_s > 0):
            raise ShoreError(f"--dt-s: expected a step in seconds > 0; got {self.dt_s!r}")
        if not (math.isfinite(self.max_time_s) and self.max_time_s > 0):
            raise ShoreError(f"--max-hours: expected hours > 0; got {self.max_time_s / 3600.0!r}")
        if self.dt_s >= self.max_time_s:
            raise ShoreError(f"--dt-s: a step of {self.dt_s:g} s is not shorter than a run ({self.max_time_s / 3600.0:g} h, "
                             "--max-hours); expected a physics step of seconds (default 2)")
        if self.seed < 0:
            raise ShoreError(f"--seed: expected an integer >= 0; got {self.seed}")
        if self.replan_s is not None and not (math.isfinite(self.replan_s) and self.replan_s > 0):
            raise ShoreError(f"--replan-h: expected hours > 0; got {self.replan_s / 3600.0!r}")
        if self.n_starts < 1:
            raise ShoreError(f"--starts: expected at least 1; got {self.n_starts}")

    @property
    def vehicle(self) -> VehicleParams:
        return self.mission.settings.vehicle


@dataclass(frozen=True, eq=False, kw_only=True)
class MethodPlan:
    """A method's plans: ``schedule`` lists (vehicle time from which it holds, table)."""

    method: str
    schedule: tuple[tuple[float, PolicyTable], ...]
    first: PlanResult | None  # the plan at the start (None for naive)

    @cached_property
    def _starts_s(self) -> tuple[float, ...]:
        return tuple(t for t, _ in self.schedule)

    def table_at(self, t_s: float) -> PolicyTable:
        """The table in use at vehicle time ``t_s`` (looked up every physics step); of a time-varying
        table, the slice of the UTC time ``t_s`` after its first slice, as the executive looks it up."""
        n = bisect_right(self._starts_s, t_s) - 1
        table = self.schedule[max(n, 0)][1]
        if table.time_varying:
            return table.slice_at(table.slice_unix_s[0] + t_s).table
        return table


@dataclass(frozen=True, eq=False, kw_only=True)
class Campaign:
    spec: CampaignSpec
    plans: dict[str, MethodPlan]
    referee: Referee
    starts: tuple[Start, ...]
    time_offset_s: float  # truth time at the start of every run
    results: tuple[RunResult, ...] = ()
    timings_s: dict[str, float] = field(default_factory=dict)


def settings_for(method: str, base: PlanSettings) -> PlanSettings:
    """The mission's settings with the method's model and criterion."""
    if method == "paper":
        return replace(base, model="paper", criterion="robust" if base.model != "paper" else base.criterion)
    if method == "physical-robust":
        return replace(base, model="physical", criterion="robust")
    if method == "time-varying":
        return replace(base, model="physical", criterion="expected", time_varying=True)
    return replace(base, model="physical", criterion="expected", time_varying=False)  # physical-expected, open-loop, replanned


def request_for(spec: CampaignSpec, settings: PlanSettings, time_index: int) -> PlanRequest:
    request = replace(PlanRequest.for_mission(spec.mission, spec.forecast_path), settings=settings,
                      time_index=time_index, time_iso=None)
    if spec.grid_scale == 1:
        return request
    if request.nx is None or request.ny is None:
        raise ShoreError("a finer grid needs the mission's region.nx and region.ny")
    s, goal = spec.grid_scale, request.goal
    return replace(request, nx=(request.nx - 1) * s + 1, ny=(request.ny - 1) * s + 1,
                   goal=Goal(lon_deg=goal.lon_deg, lat_deg=goal.lat_deg, depth_m=goal.depth_m,
                             radius_cells=goal.radius_cells * s))


def make_plans(spec: CampaignSpec, forecast: Forecast, *, note: Callable[[str], None] = lambda _: None,
               meter: Progress = SILENT) -> dict[str, MethodPlan]:
    """Plan every method at the first step and, with ``replan_s``, at the steps nearest each replan time."""
    t0 = float(forecast.time_s[spec.time_index])
    times = [0.0]
    if spec.replan_s is not None:
        times = list(np.arange(0.0, spec.max_time_s, spec.replan_s))
    steps = [int(np.argmin(np.abs(forecast.time_s - (t0 + t)))) for t in times]
    # replanned: every forecast step from the start to the runs' end
    every = [n for n in range(spec.time_index, forecast.time_s.size) if forecast.time_s[n] - t0 < spec.max_time_s]
    cache: dict[tuple[str, int], PlanResult] = {}
    plans: dict[str, MethodPlan] = {}
    for method in spec.methods:
        if method == "naive":
            plans[method] = MethodPlan(method=method, schedule=(), first=None)
            continue
        settings = settings_for(method, spec.mission.settings)
        if method == "time-varying":  # slices to the runs' end, no further (nor past the mission's horizon)
            settings = replace(settings, horizon_h=min(settings.horizon_h, spec.max_time_s / 3600.0))
        key_model = "physical-expected" if method in ("open-loop", "replanned") else method
        schedule: list[tuple[float, PolicyTable]] = []
        method_times, method_steps = times, steps
        if method == "replanned":
            method_times, method_steps = [float(forecast.time_s[n] - t0) for n in every], every
        elif method == "time-varying":
            method_times, method_steps = [0.0], [spec.time_index]
        for t, index in zip(method_times, method_steps):
            key = (key_model, index)
            if key not in cache:
                started = time.perf_counter()
                cache[key] = make_plan(request_for(spec, settings, index), forecast=forecast, meter=meter)
                note(f"planned {key_model} at forecast step {index} in {time.perf_counter() - started:.1f} s")
            if not schedule or schedule[-1][1] is not cache[key].table:
                schedule.append((t, cache[key].table))
        first = cache[(key_model, method_steps[0])]
        if method == "open-loop":
            schedule = [(0.0, first.table)]
        plans[method] = MethodPlan(method=method, schedule=tuple(schedule), first=first)
    return plans


def time_offset_s(forecast: Forecast, index: int, truth: Truth) -> float:
    """Truth time (s from the truth's first time) of forecast step ``index``: both dated, by date."""
    start_unix = getattr(truth, "start_unix_s", 0.0)
    times = forecast.times
    if times is not None and getattr(truth, "dated", False):
        return float(times[index].astype("datetime64[ms]").astype(np.int64)) / 1000.0 - start_unix
    return float(forecast.time_s[index] - forecast.time_s[0])


def referee_for(plans: dict[str, MethodPlan], spec: CampaignSpec, forecast: Forecast) -> Referee:
    """Goal cells and region: from any plan's table (they share the grid), else a paper plan's."""
    for plan in plans.values():
        if plan.first is not None:
            return Referee(table=plan.first.table)
    result = make_plan(request_for(spec, settings_for("paper", spec.mission.settings), spec.time_index), forecast=forecast)
    return Referee(table=result.table)


def prepare(spec: CampaignSpec, *, note: Callable[[str], None] = lambda _: None, meter: Progress = SILENT) -> Campaign:
    """Plans, referee and start states; no runs yet. ``meter`` hears each plan's sampling and solving."""
    t = time.perf_counter()
    forecast = open_forecast(spec.forecast_path, variables=spec.mission.forecast.variables,
                             grid_file=spec.mission.forecast.grid_file)
    if not 0 <= spec.time_index < forecast.time_s.size:
        raise ShoreError(f"{spec.forecast_path}: time index {spec.time_index} is out of range (0..{forecast.time_s.size - 1})")
    plans = make_plans(spec, forecast, note=note, meter=meter)
    referee = referee_for(plans, spec, forecast)
    offset = time_offset_s(forecast, spec.time_index, spec.truth)
    starts = pick_starts(referee, spec.truth, spec.n_starts, seed=spec.seed, time_offset_s=offset)
    return Campaign(spec=spec, plans=plans, referee=referee, starts=tuple(starts), time_offset_s=offset,
                    timings_s={"plan_s": time.perf_counter() - t})


def start_state(table: PolicyTable, start: Start) -> tuple[int, int, int, int] | None:
    cell = table.locate(start.lat_deg, start.lon_deg, start.depth_m)
    if cell is None:
        return None
    return (*cell, table.heading_index(cell[1], start.heading_deg))


def run_one(campaign: Campaign, method: str, index: int) -> RunResult:
    """Fly ``method`` from start ``index``."""
    spec = campaign.spec
    start = campaign.starts[index]
    params = spec.vehicle
    plan = campaign.plans[method]
    predicted, marked = math.nan, True
    if method == "naive":
        goal = spec.mission.goals[0].goal
        pilot: FeedbackPilot | OpenLoopPilot | NaivePilot = NaivePilot(goal.lon_deg, goal.lat_deg, goal.depth_m, params)
    else:
        assert plan.first is not None
        table = plan.first.table
        state = start_state(table, start)
        marked = state is not None and Action(int(table.actions[state])) not in (Action.UNREACHABLE,)
        sol = plan.first.solution
        if isinstance(sol, PhysicalSolution) and state is not None:
            predicted = float(sol.value_wh[state])
        if not marked:
            return RunResult(method=method, start=index, outcome="refused", time_s=0.0, energy_wh=0.0,
                             predicted_wh=predicted, marked_reachable=False)
        if method == "open-loop":
            assert isinstance(sol, PhysicalSolution) and state is not None
            steps = [s for s in sol.nominal(state) if s.action not in (Action.AT_GOAL, Action.UNREACHABLE)]
            pilot = OpenLoopPilot(steps, table, params)
        else:
            pilot = FeedbackPilot(plan.table_at, params, timing=plan.schedule[0][1] if method == "time-varying" else None)
    outcome, t, energy = fly(pilot, spec.truth, start, params, campaign.referee, dt_s=spec.dt_s,
                             max_time_s=spec.max_time_s, time_offset_s=campaign.time_offset_s)
    return RunResult(method=method, start=index, outcome=outcome, time_s=t, energy_wh=energy, predicted_wh=predicted,
                     marked_reachable=marked)


def all_runs(campaign: Campaign) -> list[tuple[str, int]]:
    """Every (method, start index) of a campaign, in a fixed order."""
    return [(m, n) for n in range(len(campaign.starts)) for m in campaign.spec.methods]


def run_chunk(runs: Sequence[tuple[str, int]], campaign: Campaign) -> list[RunResult]:
    """One task: fly some runs of a campaign (docs/scale-out.md: what a worker gets and returns)."""
    return [run_one(campaign, m, n) for m, n in runs]


def run_all(campaign: Campaign, runs: Iterable[tuple[str, int]] | None = None, *, runner: Runner | None = None,
            meter: Progress = SILENT) -> Campaign:
    """Fly the runs, as tasks of ``runner`` (default: here, one after another); results in ``runs`` order.

    Each task flies a contiguous piece of the runs; the campaign (plans, truth, starts) goes to
    every worker once. Runs are deterministic, so any runner gives the same results. ``meter``
    hears the runs flown: after every run here, after every wave of one piece per worker on a cluster.
    """
    t = time.perf_counter()
    todo = list(all_runs(campaign) if runs is None else runs)
    runner = runner or InProcess()
    pieces = [[todo[i] for i in r] for r in chunks(len(todo), runner.workers)]
    if runner.workers == 1:  # nothing to balance: one run a piece, so the meter moves with every run
        pieces = [[run] for run in todo]
    results: list[RunResult] = []
    meter.update("runs", 0, len(todo), unit="runs")
    for wave in range(0, len(pieces), runner.workers):
        results.extend(r for part in runner.map(run_chunk, pieces[wave:wave + runner.workers], campaign=campaign)
                       for r in part)
        meter.update("runs", len(results), len(todo), unit="runs")
    return replace(campaign, results=tuple(results), timings_s={**campaign.timings_s, "runs_s": time.perf_counter() - t})


def resolution_change(campaign: Campaign, methods: Sequence[str] = ("physical-expected", "physical-robust")
                      ) -> dict[str, dict[str, float]]:
    """How the start states' predicted cost changes when the grid spacing halves (docs/evaluation.md).

    Per method: the median, 90th percentile and largest |V_fine / V - 1| over the starts
    reachable on both grids, and how many those are. The coarse plan is the campaign's own
    first plan where it has the method.
    """
    spec = campaign.spec
    forecast = open_forecast(spec.forecast_path, variables=spec.mission.forecast.variables,
                             grid_file=spec.mission.forecast.grid_file)
    fine_spec = replace(spec, grid_scale=2)
    out: dict[str, dict[str, float]] = {}
    for method in methods:
        settings = settings_for(method, spec.mission.settings)
        planned = campaign.plans.get(method)
        coarse = (planned.first if planned is not None and planned.first is not None
                  else make_plan(request_for(spec, settings, spec.time_index), forecast=forecast))
        fine = make_plan(request_for(fine_spec, settings, spec.time_index), forecast=forecast)
        changes = []
        for s in campaign.starts:
            a, b = start_state(coarse.table, s), start_state(fine.table, s)
            if a is None or b is None:
                continue
            coarse_sol, fine_sol = coarse.solution, fine.solution
            assert isinstance(coarse_sol, PhysicalSolution) and isinstance(fine_sol, PhysicalSolution)  # in Wh
            va = float(coarse_sol.value_wh[a])
            vb = float(fine_sol.value_wh[b])
            if math.isfinite(va) and math.isfinite(vb) and va > 0:
                changes.append(abs(vb / va - 1.0))
        arr = np.array(changes) if changes else np.array([math.nan])
        out[method] = {"median": float(np.median(arr)), "p90": float(np.percentile(arr, 90)),
                       "max": float(np.max(arr)), "starts": float(len(changes))}
    return out

