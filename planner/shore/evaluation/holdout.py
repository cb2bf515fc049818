"""``lrauv holdout``: does a plan over an ensemble hold in a member it did not see? (docs/scale-out.md)

For each member k of an ensemble file in turn, member k is the truth and is hidden from the
planner. The **ensemble plan** is the physical model planned over all the other members (the
members are its outcomes); each **single-member plan** is the same model planned on one other
member alone. Every plan is flown as a feedback plan (``planner.shore.evaluation.runs``) from the same
seeded start states through member k, and the share of runs that reach the goal is compared.
Runs are tasks of the runner, like ``lrauv evaluate``'s.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from planner.cluster import InProcess, Runner, open_runner
from planner.contract.errors import ShoreError


@dataclass(frozen=True, kw_only=True)
class HoldoutRow:
    """One held-out member: success rates of the ensemble plan and of each single-member plan."""

    held_out: int
    starts: int
    ensemble_success: float
    single_success: dict[int, float]  # member -> success

    @property
    def best_single(self) -> float:
        return max(self.single_success.values())

    @property
    def mean_single(self) -> float:
        return sum(self.single_success.values()) / len(self.single_success)


def holdout(mission_path: Path, ensemble: Path, *, starts: int, seed: int, dt_s: float, max_time_s: float,
            runner: Runner | None = None, held_out: list[int] | None = None) -> list[HoldoutRow]:
    """The rows of the comparison, one per held-out member (default: every member)."""
    from planner.contract.mission import load_mission
    from planner.forecast import ensemble_size, open_forecast
    from planner.pipeline import MemberRef, PlanRequest, make_plan
    from planner.shore.evaluation.campaign import Campaign, CampaignSpec, MethodPlan, run_all, time_offset_s
    from planner.shore.evaluation.runs import Referee, pick_starts
    from vehicle_sim.world import World

    runner = runner or InProcess()
    mission = load_mission(mission_path)
    if mission.settings.model != "physical":
        mission = replace(mission, settings=replace(mission.settings, model="physical", criterion="expected"))
    n = ensemble_size(ensemble)
    if n < 3:
        raise ShoreError(f"{ensemble}: {n} member(s); a hold-out comparison needs at least 3 (one truth, two to plan on)")
    base = replace(PlanRequest.for_mission(mission, ensemble), time_index=mission.forecast.time_index or 0,
                   time_iso=None, variables=None, grid_file=None)
    plans_by_member = {j: make_plan(replace(base, members=(MemberRef(path=ensemble, member=j),))) for j in range(n)}
    rows = []
    for k in (range(n) if held_out is None else held_out):
        others = [j for j in range(n) if j != k]
        truth_fc = open_forecast(ensemble, member=k)
        truth = World.from_forecast(truth_fc)
        ens = make_plan(replace(base, members=tuple(MemberRef(path=ensemble, member=j) for j in others)), runner=runner)
        plans = {"ensemble": MethodPlan(method="ensemble", schedule=((0.0, ens.table),), first=ens)}
        for j in others:
            r = plans_by_member[j]
            plans[f"member {j}"] = MethodPlan(method=f"member {j}", schedule=((0.0, r.table),), first=r)
        referee = Referee(table=ens.table)
        offset = time_offset_s(ens.forecast, base.time_index or 0, truth)
        spec = CampaignSpec(mission=mission, forecast_path=ensemble, truth=truth, methods=("physical-expected",),
                            n_starts=starts, seed=seed, dt_s=dt_s, max_time_s=max_time_s)
        picked = pick_starts(referee, truth, starts, seed=seed, time_offset_s=offset)
        campaign = Campaign(spec=spec, plans=plans, referee=referee, starts=tuple(picked), time_offset_s=offset)
        runs = [(name, s) for s in range(len(picked)) for name in plans]
        done = run_all(campaign, runs, runner=runner).results
        rate = {name: sum(1 for r in done if r.method == name and r.outcome == "arrived") / len(picked) for name in plans}
        rows.append(HoldoutRow(held_out=k, starts=len(picked), ensemble_success=rate["ensemble"],
                               single_success={j: rate[f"member {j}"] for j in others}))
    return rows


def run_holdout(mission_path: Path, ensemble: Path, *, starts: int, seed: int, dt_s: float, max_time_s: float,
                scheduler: str | None = None, workers: int | None = None,
                note: Callable[[str], None] | None = None) -> list[HoldoutRow]:
    """``holdout`` over every member, its runs and member sampling on the runner of ``scheduler``."""
    with open_runner(scheduler, workers=workers) as runner:
        if note is not None:
            note(f"runs and member sampling: {runner.describe()}")
        return holdout(mission_path, ensemble, starts=starts, seed=seed, dt_s=dt_s, max_time_s=max_time_s, runner=runner)
