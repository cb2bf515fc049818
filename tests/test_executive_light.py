"""The vehicle side stays light: the executive never loads xarray, scipy or numba (developers' guide)."""

from __future__ import annotations

import subprocess
import sys

HEAVY = ("xarray", "scipy", "numba", "netCDF4", "pyproj", "matplotlib")


def test_executive_import_path_has_no_heavy_packages():
    code = (
        "import sys, executive.loop, executive.cli, executive.recorder, executive.helm, executive.mavlink_bridge\n"
        "import planner.mission  # read by `lrauv exec --mission`\n"
        f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"the executive imported {out.stdout.strip()}"


def test_lrauv_exec_help_loads_nothing_heavy():
    code = (
        "import sys\nfrom planner.cli import build_parser\n"
        "build_parser().parse_args(['exec', '--table', 'x.lrpt'])\n"
        f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
