"""What a plan was, in the lines ``lrauv plan`` prints: the table, forecast, grid, model and reach; the time taken.

``lrauv upload`` prints the same lines for each goal it plans on shore.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from planner.pipeline import PlanResult


def summary_lines(result: PlanResult, *, out: Path, size: int) -> list[str]:
    """The table written to ``out`` (``size`` bytes as written), its forecast, grid, model and reachable states."""
    sol = result.solution
    water_states = int(result.model.water.sum()) * 8
    reachable = int(sol.reachable.sum())
    raw = len(result.table.to_bytes(compress=False))
    slices = f" x {result.table.n_slices} time slices" if result.table.time_varying else ""
    lines = [
        f"table      {out}  ({size:,} bytes; {raw:,} uncompressed; {result.grid.n_states:,} states{slices})",
        (f"forecast   {result.table.forecast_source} [{result.table.forecast_identity}] step {result.time_index}"
         f" ({result.table.forecast_time or 'no reference date'})"),
        (f"grid       {result.grid.nx} x {result.grid.ny} cells x {result.grid.n_layers} layers"
         f" ({', '.join(f'{d:g}' for d in result.grid.depth_m)} m) x 8 headings"),
    ]
    lines.extend(model_lines(result))
    lines.append(f"reachable  {reachable:,} of {water_states:,} water states ({reachable / max(water_states, 1):.1%})")
    from planner.pipeline import coverage_fraction  # loaded already: it made the result

    covered = coverage_fraction(result.forecast, result.grid)
    if covered < 1.0:
        lines.append(f"warning    the forecast covers {covered:.1%} of the region's cells; the rest have no current and "
                     "are planned as land: give a region within the forecast (lrauv forecast info)")
    s = result.model.settings
    if s.model == "physical" and reachable < 0.5 * water_states:
        error = s.physical.current_error_m_s
        if result.horizon is not None:  # time is in the state already: what limits it is the horizon's end
            times = result.table.slice_unix_s
            span_h = (times[-1] - times[0]) / 3600.0
            longer = ("a longer horizon (--horizon-h; a tide's whole cycle at least) may reach more"
                      if span_h >= s.horizon_h - 1e-6 else
                      f"the forecast ends there (planning.horizon_h asks {s.horizon_h:g} h): a forecast that runs longer"
                      " may reach more")
            lines.append(f"warning    fewer than half the water states can reach the goal under a forecast error of {error:g}"
                         f" m/s per component within the plan's {span_h:g} h of slices, or by its last slice's"
                         f" stationary plan beyond them: {longer}")
        else:
            lines.append(f"warning    fewer than half the water states can reach the goal under a forecast error of {error:g}"
                         " m/s per component: where the current changes within hours, plan with time in the state"
                         " (planning.time_varying) rather than a larger error")
    return lines


def model_lines(result: PlanResult) -> list[str]:
    """What was planned: the paper model's settings, or the physical model's figures."""
    s = result.model.settings
    if s.model != "physical":
        c = s.costs
        return [f"model      paper, {s.criterion}, {s.uncertainty} uncertainty; costs drift {c.drift}, forward"
                f" {c.forward}, rotate {c.rotate}, glide {c.glide}"]
    from planner.physical.model import PhysicalModel  # loaded already: the pipeline that made the result imports it
    from planner.physical.solve import PhysicalSolution

    m, sol, v = result.model, result.solution, s.vehicle
    if not isinstance(m, PhysicalModel) or not isinstance(sol, PhysicalSolution):
        raise TypeError(f"a physical plan has a {type(m).__name__} and a {type(sol).__name__}")
    lines = [
        (f"model      physical, {s.criterion}; costs in Wh (hotel {v.hotel_w:g} W, propulsion {v.propulsion_w:g} W"
         f" at {v.cruise_speed_m_s:g} m/s, buoyancy {v.buoyancy_w:g} W)"),
        (f"samples    {m.n_pairs:,} state-actions, {m.samples_per_action} samples per action"
         f" ({s.physical.start_points}x{s.physical.start_points} start points x {s.physical.error_members + 1}"
         f" currents{f' x {m.members} forecast members' if m.members > 1 else ''}),"
         f" currents {m.refine}x finer than the grid"),
    ]
    if result.error is not None:
        lines.append(f"error      {result.error.describe()}")
    h = result.horizon
    if h is not None:
        times = result.table.slice_times
        spacing = "the forecast's own steps" if s.slice_h is None else f"every {s.slice_h:g} h"
        lines.append(f"slices     {h.n_slices} slices, {times[0]} to {times[-1]} ({spacing}); past the"
                     f" last, its stationary plan; {sum(h.sweeps):,} Gauss-Seidel sweeps over the earlier slices")
        if result.table.slice_current_m_s is not None:
            k = result.table.current_block_cells
            per = "per layer" if k is None else f"per block of {k} x {k} cells ({result.table.n_current_regions} blocks)"
            lines.append(f"timing     each slice's mean current {per} carried: the vehicle fits the tide's timing to the"
                         " current it meets and looks its slices up that much earlier or later (docs/time-varying.md)")
    elif s.criterion == "expected":
        lines.append(f"solve      value iteration: {sol.sweeps} sweeps, then policy iteration: {sol.iterations} "
                     f"iterations, residual {sol.residual_wh:.2g} Wh")
    return lines


def time_line(result: PlanResult, total_s: float) -> str:
    """How long each stage took, and ``total_s`` in all."""
    t = result.timings_s
    stages = f"load {t['load_s']:.2f} s, resample {t['resample_s']:.2f} s, plan {t['plan_s']:.3f} s"
    if "transitions_s" in t:  # the physical model's plan time: the transitions (sampling them, then assembling), the solve
        sampling = f", of which sampling {t['sampling_s']:.2f} s" if "sampling_s" in t else ""
        stages += (f" (transitions {t['transitions_s']:.2f} s{sampling};"
                   f" solve {t['plan_s'] - t['transitions_s']:.3f} s)")
    return f"time       {stages}, total {total_s:.2f} s"
