"""``lrauv`` as a user runs it: real processes, real files, exit codes and messages."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.support import REPO

LRAUV = str(Path(sys.executable).parent / "lrauv")
GRID = ["--bbox=-118.26,33.30,-117.70,33.70", "--nx=29", "--ny=21", "--depths=0,5,10,15"]


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([LRAUV, *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def test_plan_with_flags_writes_table_values_and_pictures(synthetic_forecast, tmp_path):
    out = tmp_path / "t.lrpt"
    proc = run("plan", f"--forecast={synthetic_forecast}", *GRID, "--time-index=3", "--goal=-117.80,33.40,0",
               "--goal-radius=1", "--criterion=robust", "--uncertainty=lateral", f"--out={out}",
               f"--export-values={tmp_path / 'v.npz'}", f"--plot={tmp_path / 'pics'}")
    assert proc.returncode == 0, proc.stderr
    from planner.contract.table import PolicyTable

    table = PolicyTable.load(out)
    assert (table.nx, table.ny, table.depth_m) == (29, 21, (0.0, 5.0, 10.0, 15.0))
    assert table.forecast_time == "2026-01-15T03:00:00Z"
    v = np.load(tmp_path / "v.npz")
    assert v["cost"].shape == (4, 21, 29, 8) and v["cost"].dtype == np.float64
    assert v["steps"].dtype == np.int64 and v["action"].dtype == np.uint8 and v["flow_dir"].dtype == np.int8
    assert np.array_equal(v["action"], table.actions)
    assert np.all(np.isinf(v["cost"]) == (v["steps"] == -1))
    assert sorted(p.name for p in (tmp_path / "pics").iterdir())
    assert "reachable" in proc.stdout


def test_plan_from_the_demo_mission_file(synthetic_forecast, tmp_path):
    proc = run("plan", str(REPO / "missions" / "demo.yaml"), f"--forecast={synthetic_forecast}",
               f"--out={tmp_path / 'd.lrpt'}", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "d.lrpt").stat().st_size > 0


def test_optimistic_and_robust_differ_and_agree_on_goal(synthetic_forecast, tmp_path):
    tables = {}
    for crit in ("robust", "optimistic"):
        out = tmp_path / f"{crit}.lrpt"
        assert run("plan", f"--forecast={synthetic_forecast}", *GRID, "--goal=-117.80,33.40,0",
                   f"--criterion={crit}", f"--out={out}", "--quiet").returncode == 0
        from planner.contract.table import PolicyTable

        tables[crit] = PolicyTable.load(out)
    r, o = tables["robust"].actions, tables["optimistic"].actions
    assert np.array_equal(r == 6, o == 6)
    # optimistic reaches at least every state robust reaches
    assert np.all((o != 7) | (r == 7))


def nan_file(path: Path) -> Path:
    import xarray as xr

    lon = np.linspace(-118.26, -117.70, 5)
    lat = np.linspace(33.3, 33.7, 4)
    nan = np.full((1, 4, 5), np.nan, dtype=np.float32)
    ds = xr.Dataset(
        {
            "u": (("time", "lat", "lon"), nan, {"standard_name": "eastward_sea_water_velocity", "units": "m s-1"}),
            "v": (("time", "lat", "lon"), nan, {"standard_name": "northward_sea_water_velocity", "units": "m s-1"}),
        },
        coords={"time": ("time", [0.0], {"units": "hours since 2026-01-01"}),
                "lat": ("lat", lat, {"units": "degrees_north"}), "lon": ("lon", lon, {"units": "degrees_east"})},
    )
    ds.to_netcdf(path)
    return path


@pytest.mark.parametrize(
    "case, args, expect",
    [
        ("unknown variables", ["--variables=foo,bar", "--goal=-117.80,33.40,0"], "foo"),
        ("goal on land", ["--goal=-117.75,33.65,0"], "on land"),
        ("goal outside the grid", ["--goal=-119.5,33.40,0"], "outside the planning grid"),
        ("all-land layer", ["--depths=0,5,10,20", "--goal=-117.80,33.40,0"], "all land"),
        ("non-integer costs", ["--costs=forward=4.5", "--goal=-117.80,33.40,0"], "integer"),
        ("negative cost", ["--costs=rotate=-1", "--goal=-117.80,33.40,0"], "non-negative"),
        ("time index out of range", ["--time-index=999", "--goal=-117.80,33.40,0"], "out of range"),
    ],
)
def test_bad_input_exits_2_with_one_clear_line(synthetic_forecast, tmp_path, case, args, expect):
    base = [f"--forecast={synthetic_forecast}", *GRID]
    # later flags win: --depths in args replaces the grid's
    proc = run("plan", *base, *args, f"--out={tmp_path / 'x.lrpt'}", "--quiet")
    assert proc.returncode == 2, (case, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("lrauv: error:")]
    assert len(lines) == 1 and expect in lines[0], proc.stderr
    assert not (tmp_path / "x.lrpt").exists()


def test_bbox_outside_the_forecast(synthetic_forecast, tmp_path):
    proc = run("plan", f"--forecast={synthetic_forecast}", "--bbox=10,50,11,51", "--nx=5", "--ny=5",
               "--depths=0", "--goal=10.5,50.5,0", f"--out={tmp_path / 'x.lrpt'}")
    assert proc.returncode == 2 and "outside the forecast" in proc.stderr and "Traceback" not in proc.stderr


def test_nan_only_file(tmp_path):
    path = nan_file(tmp_path / "nan.nc")
    proc = run("plan", f"--forecast={path}", "--depths=0", "--goal=-118.0,33.5,0", f"--out={tmp_path / 'x.lrpt'}")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert str(path.name) in proc.stderr


def test_not_a_netcdf_file_and_missing_file(tmp_path):
    bad = tmp_path / "notes.nc"
    bad.write_text("not a forecast\n")
    for path in (bad, tmp_path / "missing.nc"):
        proc = run("forecast", "info", str(path))
        assert proc.returncode == 2 and "Traceback" not in proc.stderr and path.name in proc.stderr


def test_forecast_info_and_synth(tmp_path):
    out = tmp_path / "f.nc"
    assert run("forecast", "synth", str(out), "--hours=6", "--seed=3").returncode == 0
    proc = run("forecast", "info", str(out))
    assert proc.returncode == 0 and "regular lon/lat" in proc.stdout and "7 steps" in proc.stdout


def test_negative_longitudes_as_separate_arguments(synthetic_forecast, tmp_path):
    # West longitudes are negative; `--goal -117.80,33.40,0` must not read as an option.
    out = tmp_path / "t.lrpt"
    proc = run("plan", "--forecast", str(synthetic_forecast), "--bbox", "-118.26,33.30,-117.70,33.70", "--nx", "29",
               "--ny", "21", "--depths", "0,5,10,15", "--goal", "-117.80,33.40,0", "--start", "-118.0,33.5,0,90",
               "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert out.is_file()


def test_the_subcommand_table_lists_what_the_modules_register():
    import argparse

    from planner.cli import TABLE, build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert list(sub.choices) == [c.name for c in TABLE]
    assert {a.dest: a.help for a in sub._choices_actions} == {c.name: c.help for c in TABLE}


def test_only_the_named_subcommand_module_is_imported():
    probe = ("import sys\nfrom planner.cli import main\n"
             "try:\n    main(['exec', '--help'])\nexcept SystemExit:\n    pass\n"
             "print('loaded:', ','.join(sorted(m for m in sys.modules if m.startswith(('planner.cli.', 'vehicle_sim', 'planner.shore'))"
             " and m != 'planner.cli.help_text')))")  # the help table: argparse only
    proc = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=REPO, check=True)
    assert proc.stdout.splitlines()[-1] == "loaded: ", proc.stdout


def test_a_plan_from_a_start_carries_its_nominal_path_to_the_vehicle(synthetic_forecast, tmp_path):
    """``--start`` puts the nominal path in the table: from the real start to the goal's cell, in lon, lat."""
    from planner.contract.table import PolicyTable

    out, bare = tmp_path / "t.lrpt", tmp_path / "bare.lrpt"
    common = ["plan", "--forecast", str(synthetic_forecast), "--bbox", "-118.26,33.30,-117.70,33.70", "--nx", "29",
              "--ny", "21", "--depths", "0,5,10,15", "--goal", "-117.80,33.40,0"]
    assert run(*common, "--start", "-118.0,33.51,0,90", "--out", str(out)).returncode == 0
    assert run(*common, "--out", str(bare)).returncode == 0
    table, plain = PolicyTable.load(out), PolicyTable.load(bare)
    path = table.nominal_path
    assert plain.nominal_path == () and "nominal_path" not in plain.header()
    assert len(path) >= 3 and path[0] == (-118.0, 33.51)  # the real start, not its cell's centre
    goal = table.locate(table.goal_lat_deg, table.goal_lon_deg, 0.0)
    assert goal is not None
    lat, lon = table.cell_centre(goal[1], goal[2])
    assert abs(path[-1][0] - lon) <= table.dlon_deg * (table.goal_radius_cells + 0.5)
    assert abs(path[-1][1] - lat) <= table.dlat_deg * (table.goal_radius_cells + 0.5)
    # Each leg after the first joins two cell centres; the actions are the same table's.
    assert all(abs((a - table.lon0_deg) / table.dlon_deg - round((a - table.lon0_deg) / table.dlon_deg)) < 1e-3
               for a, _ in path[1:])
    assert (table.actions == plain.actions).all()
