"""``--scheduler`` and ``--workers``: where a command's parallel work runs (``planner.cluster.open_runner``)."""

from __future__ import annotations

import argparse

from planner.cluster import IN_PROCESS
from planner.contract.arguments import count


def add_cluster_arguments(parser: argparse.ArgumentParser) -> None:
    """``--scheduler`` and ``--workers``, for every command with parallel work."""
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help=f"Dask scheduler to run the work on (tcp://HOST:PORT); {IN_PROCESS}: no Dask, "
                             "one task after another here; default: a local Dask cluster, one worker per core")
    parser.add_argument("--workers", type=count, help="workers of the local cluster (default: one per core)")
