"""``lrauv batch``: a plan for every goal of many missions or fleet files (``planner.shore.batch``)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from planner.cli.cluster_options import add_cluster_arguments
from planner.contract.arguments import Subcommands
from planner.contract.columns import say
from planner.contract.errors import ShoreError


def add_parser(sub: Subcommands) -> None:
    p = sub.add_parser("batch", help="plan every goal of many missions (or a fleet file) as parallel tasks")
    p.add_argument("files", type=Path, nargs="+", help="mission YAML files and/or fleet YAML files")
    p.add_argument("--forecast", type=Path, help="plan every mission on this forecast (default: each mission's)")
    p.add_argument("--out", type=Path, required=True, help="directory for OUT/<vehicle>/goal-<n>.lrpt")
    add_cluster_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")


def run(args: argparse.Namespace) -> int:
    from planner.contract.atomic import check_folder_target
    from planner.shore.batch import run_batch

    check_folder_target(args.out)  # before the plans, not after them
    note = None if args.quiet else (lambda text: print(f"  {text}", file=sys.stderr, flush=True))
    done = run_batch(args.files, out_dir=args.out, forecast=args.forecast, scheduler=args.scheduler,
                     workers=args.workers, note=note)
    for r, path in zip(done.results, done.written):
        if path is None:
            say(f"failed     {r.vehicle} goal {r.goal_index}: {r.error}")
            continue
        assert r.table is not None
        say(f"table      {os.fspath(path)}  ({len(r.table):,} bytes; reachable {r.reachable:,} of "
            f"{r.water_states:,} water states; {r.plan_s:.2f} s)")
    n = len(done.items)
    say(f"batch      {n - done.failed} of {n} goals planned in {done.elapsed_s:.1f} s")
    if done.failed:
        raise ShoreError(f"batch: {done.failed} of {n} goals could not be planned (listed above)")
    return 0
