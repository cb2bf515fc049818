"""Compiles the planners' numba kernels into their on-disk cache before the suite runs.

``make test`` runs this beside the type check (a core each). Every test process, each
pytest-xdist worker among them, then loads the kernels from ``__pycache__`` instead of
compiling them itself: on a fresh clone that is about 90 s of each worker's first physical
plan. It makes tiny plans of every kind the suite plans: the paper's model (robust and
optimistic), the physical model (robust and expected) and the physical model with time in the
state. Nothing is asserted here; the suite checks the plans. Prints one line.
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

from planner.cli import main
from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, write_gyre

_GRID = ("--bbox", "-118.15,33.32,-117.85,33.45", "--nx", "7", "--ny", "4", "--depths", "0,5",
         "--goal", "-117.9,33.4,0", "--quiet")
_PLANS = (
    ("--model", "paper", "--criterion", "robust"),
    ("--model", "paper", "--criterion", "optimistic"),
    ("--model", "physical", "--criterion", "robust"),
    ("--model", "physical", "--criterion", "expected"),
    ("--model", "physical", "--criterion", "expected", "--time-varying", "--horizon-h", "2"),
    ("--model", "physical", "--criterion", "robust", "--time-varying", "--horizon-h", "2"),
)


def warm(work: Path) -> int:
    """Plans each of ``_PLANS`` on a small double-gyre forecast in ``work``; the first failing status, else 0."""
    gyre = write_gyre(work / "gyre.nc", DoubleGyreSettings(eps=0.25, hours=3.0, step_h=1.0, depths_m=(0.0, 5.0)))
    for n, args in enumerate(_PLANS):
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            status = main(["plan", "--forecast", str(gyre), *_GRID, *args, "--out", str(work / f"warm{n}.lrpt")])
        if status != 0:
            print(printed.getvalue(), end="")
            return status
    return 0


if __name__ == "__main__":
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        status = warm(Path(tmp))
    print(f"planner kernels compiled or loaded from their cache in {time.monotonic() - t0:.0f} s", flush=True)
    sys.exit(status)
