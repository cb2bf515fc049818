"""The vehicle side stays light: the executive never loads xarray, scipy or numba (developers' guide)."""

from __future__ import annotations

import subprocess
import sys

HEAVY = ("xarray", "scipy", "numba", "netCDF4", "pyproj", "matplotlib")


def _heavy_after(code: str) -> str:
    """The heavy packages loaded by ``code`` in a fresh interpreter, comma-separated."""
    probe = f"import sys\n{code}\nprint(','.join(m for m in {HEAVY!r} if m in sys.modules))\n"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.strip()


def test_executive_import_path_has_no_heavy_packages():
    loaded = _heavy_after(
        "import executive.loop, executive.cli, executive.recorder, executive.helm, executive.mavlink_bridge\n"
        "import planner.contract.mission  # read by `lrauv exec --mission`"
    )
    assert loaded == "", f"the executive imported {loaded}"


def test_lrauv_exec_help_loads_nothing_heavy():
    loaded = _heavy_after("from planner.cli import build_parser\nbuild_parser().parse_args(['exec', '--table', 'x.lrpt'])")
    assert loaded == "", f"`lrauv exec` argument parsing imported {loaded}"
