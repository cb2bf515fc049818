"""``lrauv holdout``: does a plan over an ensemble hold in a member it did not see? (docs/scale-out.md)

For each member k of an ensemble file in turn, member k is the truth and is hidden from the
planner. The **ensemble plan** is the physical model planned over all the other members (the
members are its outcomes); each **single-member plan** is the same model planned on one other
member alone. Every plan is flown as a feedback plan (``planner.shore.evaluation.runs``) from the same
seeded start states through member k, and the share of runs that reach the goal is compared.
Runs are tasks of the runner, like ``lrauv evaluate``'s.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, replace
from pathlib import Path

from planner.cluster import InProcess, Runner
from planner.cluster import add_arguments as add_cluster_arguments
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


def add_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("holdout", help="ensemble plan against single-member plans, each flown in a member it did not see")
    p.add_argument("mission", type=Path, help="mission YAML (region, vehicle, physical settings, first goal)")
    p.add_argument("--ensemble", type=Path, required=True, help="forecast file with a member dimension (>= 3 members)")
    p.add_argument("--starts", type=int, default=50, help="start states per held-out member (default 50)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--dt-s", type=float, default=5.0, help="physics step in seconds (default 5)")
    p.add_argument("--max-hours", type=float, default=24.0, help="a run times out after this (default 24)")
    add_cluster_arguments(p)
    p.add_argument("--quiet", action="store_true")


def holdout(mission_path: Path, ensemble: Path, *, starts: int, seed: int, dt_s: float, max_time_s: float,
            runner: Runner | None = None, held_out: list[int] | None = None) -> list[HoldoutRow]:
    """The rows of the comparison, one per held-out member (default: every member)."""
    from planner.shore.evaluation.campaign import Campaign, CampaignSpec, MethodPlan, run_all, time_offset_s
    from planner.shore.evaluation.runs import Referee, pick_starts
    from planner.forecast import ensemble_size, open_forecast
    from planner.contract.mission import load_mission
    from planner.pipeline import MemberRef, PlanRequest, make_plan
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


def run(args: argparse.Namespace) -> int:
    import sys

    from planner.cluster import open_runner

    if args.starts < 1:
        raise ShoreError(f"--starts: expected at least 1; got {args.starts}")
    if not (math.isfinite(args.dt_s) and args.dt_s > 0 and math.isfinite(args.max_hours) and args.max_hours > 0):
        raise ShoreError("--dt-s and --max-hours: expected numbers > 0")
    with open_runner(args.scheduler, workers=args.workers) as runner:
        if not args.quiet:
            print(f"  runs and member sampling: {runner.describe()}", file=sys.stderr, flush=True)
        rows = holdout(args.mission, args.ensemble, starts=args.starts, seed=args.seed, dt_s=args.dt_s,
                       max_time_s=args.max_hours * 3600.0, runner=runner)
    print(f"{'held out':>8} {'starts':>6} {'ensemble':>9} {'best single':>11} {'mean single':>11} {'worst single':>12}")
    for r in rows:
        print(f"{r.held_out:>8} {r.starts:>6} {r.ensemble_success:>9.1%} {r.best_single:>11.1%} {r.mean_single:>11.1%}"
              f" {min(r.single_success.values()):>12.1%}")
    per_member: dict[int, list[float]] = {}
    for r in rows:
        for j, v in r.single_success.items():
            per_member.setdefault(j, []).append(v)
    print("single     " + ", ".join(f"member {j} {sum(v) / len(v):.1%}" for j, v in sorted(per_member.items()))
          + " (each plan's mean over the members it did not see)")
    ens = sum(r.ensemble_success for r in rows) / len(rows)
    single = sum(r.mean_single for r in rows) / len(rows)
    beaten = sum(1 for r in rows for v in r.single_success.values() if r.ensemble_success > v)
    ties = sum(1 for r in rows for v in r.single_success.values() if r.ensemble_success == v)
    total = sum(len(r.single_success) for r in rows)
    print(f"mean       ensemble {ens:.1%}, single-member plans {single:.1%}; the ensemble plan did better than "
          f"{beaten} and as well as {ties} of {total} single-member plans in the member they did not see")
    return 0
