"""``lrauv holdout``: an ensemble plan against single-member plans, each flown in a member it did not see
(``planner.shore.evaluation.holdout``)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from planner.cli.cluster_options import add_cluster_arguments
from planner.contract.arguments import Subcommands
from planner.contract.columns import say
from planner.contract.errors import ShoreError


def add_parser(sub: Subcommands) -> None:
    p = sub.add_parser("holdout", help="ensemble plan against single-member plans, each flown in a member it did not see")
    p.add_argument("mission", type=Path, help="mission YAML (region, vehicle, physical settings, first goal)")
    p.add_argument("--ensemble", type=Path, required=True, help="forecast file with a member dimension (>= 3 members)")
    p.add_argument("--starts", type=int, default=50, help="start states per held-out member (default 50)")
    p.add_argument("--seed", type=int, default=0, help="seed of the start states (default 0)")
    p.add_argument("--dt-s", type=float, default=5.0, help="physics step in seconds (default 5)")
    p.add_argument("--max-hours", type=float, default=24.0, help="a run times out after this (default 24)")
    add_cluster_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")


def run(args: argparse.Namespace) -> int:
    from planner.shore.evaluation.holdout import run_holdout

    if args.starts < 1:
        raise ShoreError(f"--starts: expected at least 1; got {args.starts}")
    if not (math.isfinite(args.dt_s) and args.dt_s > 0 and math.isfinite(args.max_hours) and args.max_hours > 0):
        raise ShoreError("--dt-s and --max-hours: expected numbers > 0")
    note = None if args.quiet else (lambda text: print(f"  {text}", file=sys.stderr, flush=True))
    rows = run_holdout(args.mission, args.ensemble, starts=args.starts, seed=args.seed, dt_s=args.dt_s,
                       max_time_s=args.max_hours * 3600.0, scheduler=args.scheduler, workers=args.workers, note=note)
    say(f"{'held out':>8} {'starts':>6} {'ensemble':>9} {'best single':>11} {'mean single':>11} {'worst single':>12}")
    for r in rows:
        say(f"{r.held_out:>8} {r.starts:>6} {r.ensemble_success:>9.1%} {r.best_single:>11.1%} {r.mean_single:>11.1%}"
            f" {min(r.single_success.values()):>12.1%}")
    per_member: dict[int, list[float]] = {}
    for r in rows:
        for j, v in r.single_success.items():
            per_member.setdefault(j, []).append(v)
    say("single     " + ", ".join(f"member {j} {sum(v) / len(v):.1%}" for j, v in sorted(per_member.items()))
        + " (each plan's mean over the members it did not see)")
    ens = sum(r.ensemble_success for r in rows) / len(rows)
    single = sum(r.mean_single for r in rows) / len(rows)
    beaten = sum(1 for r in rows for v in r.single_success.values() if r.ensemble_success > v)
    ties = sum(1 for r in rows for v in r.single_success.values() if r.ensemble_success == v)
    total = sum(len(r.single_success) for r in rows)
    say(f"mean       ensemble {ens:.1%}, single-member plans {single:.1%}; the ensemble plan did better than "
        f"{beaten} and as well as {ties} of {total} single-member plans in the member they did not see")
    return 0
