"""Bad input at the command line: refused with one ``lrauv: error:`` line and status 2, before the work
and before an earlier output is replaced. Through ``planner.cli.main`` as a user types it, on real files."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr

from planner.cli import main
from tests.support import REPO
from tests.support.helpers import error_line

DEMO = str(REPO / "missions" / "demo.yaml")


@pytest.fixture()
def good_table(tmp_path: Path) -> Path:
    """A file standing for an earlier plan's table at the output path: a failed command must keep it."""
    path = tmp_path / "keep.lrpt"
    path.write_bytes(b"an earlier plan's table")
    return path


@pytest.mark.parametrize(("options", "words"), [
    (["--plot-heading", "99"], "--plot-heading: expected 0..7"),
    (["--plot-layer", "9"], "--plot-layer: expected 0..3"),
])
def test_plot_options_are_checked_before_the_plan_and_the_old_table_is_kept(
        synthetic_forecast, tmp_path, capsys, good_table, options, words):
    line = error_line(capsys, ["plan", DEMO, f"--forecast={synthetic_forecast}", f"--out={good_table}",
                               f"--plot={tmp_path / 'pictures'}", *options, "--quiet"])
    assert words in line, line
    assert good_table.read_bytes() == b"an earlier plan's table"
    assert not (tmp_path / "pictures").exists()


def test_a_plot_folder_that_is_a_file_is_refused_before_the_plan(synthetic_forecast, tmp_path, capsys, good_table):
    line = error_line(capsys, ["plan", DEMO, f"--forecast={synthetic_forecast}", f"--out={good_table}",
                               f"--plot={synthetic_forecast}", "--quiet"])
    assert f"--plot: {synthetic_forecast} is a file: expected a folder" in line, line
    assert good_table.read_bytes() == b"an earlier plan's table"


def test_an_output_that_is_a_folder_is_named_not_a_temporary_file(synthetic_forecast, tmp_path, capsys):
    line = error_line(capsys, ["plan", DEMO, f"--forecast={synthetic_forecast}", f"--out={tmp_path}", "--quiet"])
    assert line == f"lrauv: error: {tmp_path}: is a folder: expected a file name", line
    assert ".tmp" not in line


@pytest.mark.parametrize("flag", ["--nx", "--ny"])
def test_a_zero_grid_size_is_refused_not_replaced_by_the_missions(synthetic_forecast, tmp_path, capsys, flag):
    line = error_line(capsys, ["plan", DEMO, f"--forecast={synthetic_forecast}", flag, "0",
                               f"--out={tmp_path / 'x.lrpt'}", "--quiet"])
    assert "expected nx >= 2 and ny >= 2" in line, line
    assert not (tmp_path / "x.lrpt").exists()


def test_a_grid_beyond_the_tables_states_is_refused_before_resampling(synthetic_forecast, tmp_path, capsys):
    line = error_line(capsys, ["plan", DEMO, f"--forecast={synthetic_forecast}", "--nx", "100000", "--ny", "100000",
                               f"--out={tmp_path / 'x.lrpt'}", "--quiet"])
    assert "4 layers x 100000 x 100000 cells x 8 headings = 320,000,000,000 states" in line, line
    assert "a plan holds at most 2,147,483,647" in line


@pytest.fixture(scope="module")
def west_half(synthetic_forecast, tmp_path_factory) -> Path:
    """The synthetic forecast cut to its 20 westernmost columns: it covers a third of the demo's region."""
    path = tmp_path_factory.mktemp("west") / "west.nc"
    with xr.open_dataset(synthetic_forecast) as ds:
        ds.isel(lon=slice(0, 20)).to_netcdf(path)
    return path


def test_a_forecast_that_covers_part_of_the_region_is_said(west_half, tmp_path, capsys):
    assert main(["plan", DEMO, f"--forecast={west_half}", "--goal=-118.2,33.4,0", f"--out={tmp_path / 'x.lrpt'}",
                 "--quiet"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "warning the forecast covers 34.5% of the region's cells; the rest have no current and are planned as land" \
        in out, out


def test_a_goal_outside_the_forecast_is_said_so_not_called_land(west_half, tmp_path, capsys):
    line = error_line(capsys, ["plan", DEMO, f"--forecast={west_half}", f"--out={tmp_path / 'x.lrpt'}", "--quiet"])
    assert f"goal (-117.8, 33.4) lies outside the forecast {west_half}, which covers lon -118.2600..-118.0700" in line
    assert "on land" not in line


def test_the_whole_forecast_gives_no_coverage_warning(synthetic_forecast, tmp_path, capsys):
    assert main(["plan", DEMO, f"--forecast={synthetic_forecast}", f"--out={tmp_path / 'x.lrpt'}", "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().out


def test_a_forecast_error_for_the_paper_model_is_refused(synthetic_forecast, tmp_path, capsys):
    line = error_line(capsys, ["plan", DEMO, f"--forecast={synthetic_forecast}", "--current-error", "0.1",
                               f"--out={tmp_path / 'x.lrpt'}", "--quiet"])
    assert "--current-error: the paper model has no forecast error to set" in line, line


@pytest.mark.parametrize(("argv", "words"), [
    (["plan", DEMO, "--workers", "0"], "argument --workers: expected a whole number >= 1; got 0"),
    (["upload", DEMO, "--to", "udpout:127.0.0.1:14550", "--target-system", "999"],
     "argument --target-system: expected a MAVLink id 0..255; got 999"),
    (["upload", DEMO, "--to", "udpout:127.0.0.1:14550", "--timeout-s", "0"],
     "argument --timeout-s: expected a number of seconds > 0; got 0"),
])
def test_option_values_out_of_range_are_usage_errors(tmp_path, capsys, argv, words):
    out = ["--out", str(tmp_path / "x.lrpt")] if argv[0] == "plan" else []  # nothing lands in the checkout if it plans
    with pytest.raises(SystemExit) as caught:
        main([*argv, *out])
    assert caught.value.code == 2
    assert words in capsys.readouterr().err


@pytest.mark.parametrize("address", ["bogus", "tcp://host", "127.0.0.1"])
def test_a_scheduler_address_without_a_port_is_refused_before_connecting(address):
    from planner.cluster import open_runner
    from planner.contract.errors import PlannerError

    with pytest.raises(PlannerError, match="expected tcp://HOST:PORT"), open_runner(address):
        pass


def test_a_perturbed_copy_may_not_replace_its_source(synthetic_forecast, tmp_path, capsys):
    source = tmp_path / "f.nc"
    source.write_bytes(synthetic_forecast.read_bytes())
    line = error_line(capsys, ["forecast", "perturb", str(source), str(source), "--phase-error-h", "1"])
    assert "the copy would replace the file it is made from" in line, line
    assert source.read_bytes() == synthetic_forecast.read_bytes()


def test_a_phase_error_beyond_the_files_span_is_refused(synthetic_forecast, tmp_path, capsys):
    line = error_line(capsys, ["forecast", "perturb", str(synthetic_forecast), str(tmp_path / "p.nc"),
                               "--phase-error-h", "1000"])
    assert "(the file spans 24 h)" in line, line
    assert not (tmp_path / "p.nc").exists()


def test_a_replay_forecast_that_is_not_there_is_refused(tmp_path, capsys):
    line = error_line(capsys, ["replay", str(tmp_path / "dive.mcap"), "--forecast", str(tmp_path / "none.nc")])
    assert line == f"lrauv: error: --forecast {tmp_path / 'none.nc'}: no such file", line


def test_a_demo_with_a_table_for_another_goal_starts_nothing_and_writes_nothing(demo_plan, synthetic_forecast,
                                                                              tmp_path, capsys):
    from planner.contract.settings import Goal
    from tests.support.helpers import plan_for

    other = plan_for(synthetic_forecast, goal=Goal(lon_deg=-118.2, lat_deg=33.4, depth_m=0.0, radius_cells=1))
    table = tmp_path / "other.lrpt"
    other.table.save(table)
    out = tmp_path / "demo"
    line = error_line(capsys, ["demo", "--table", str(table), "--mission", DEMO, "--truth", str(synthetic_forecast),
                               "--start=-118.0,33.45", "--out", str(out), "--quiet"])
    assert f"{table}: its goal (-118.200000, 33.400000, 0 m, radius 1) matches no goal of the mission in {DEMO}" \
        in line, line
    assert not out.exists()


def test_a_demo_time_limit_is_named_by_its_own_flag(demo_plan, synthetic_forecast, tmp_path, capsys):
    table = tmp_path / "demo.lrpt"
    demo_plan.table.save(table)
    line = error_line(capsys, ["demo", "--table", str(table), "--mission", DEMO, "--truth", str(synthetic_forecast),
                               "--start=-118.0,33.45", "--out", str(tmp_path / "demo"), "--timeout-s", "-1"])
    assert "--timeout-s: expected seconds of wall time > 0; got -1" in line, line


def test_a_reader_that_stops_reading_is_not_bad_input(synthetic_forecast):
    """``lrauv ... | head``: the write to the closed pipe ends the command quietly, as a shell's SIGPIPE would."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run([sys.executable, "-m", "planner.cli", "forecast", "info", str(synthetic_forecast)],
                              stdout=write_end, stderr=subprocess.PIPE, text=True, cwd=REPO, timeout=120)
    finally:
        os.close(write_end)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""


def test_the_version_is_printed(capsys):
    with pytest.raises(SystemExit) as caught:
        main(["--version"])
    assert caught.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("lrauv ") and out.strip() != "lrauv"


def test_a_truth_that_misses_the_region_is_said_so(synthetic_forecast, tmp_path, capsys):
    far = tmp_path / "far.nc"
    with xr.open_dataset(synthetic_forecast) as ds:
        ds.assign_coords(lon=ds.lon + 5.0).to_netcdf(far)
    line = error_line(capsys, ["evaluate", DEMO, "--forecast", str(synthetic_forecast), "--truth", str(far),
                               "--methods", "paper", "--starts", "2", "--max-hours", "1", "--out", str(tmp_path / "e")])
    assert "found only 0 of 2 start states in water" in line and "does the truth cover the mission's region?" in line


def test_a_physics_step_as_long_as_the_run_is_refused(synthetic_forecast, tmp_path, capsys):
    line = error_line(capsys, ["evaluate", DEMO, "--forecast", str(synthetic_forecast), "--truth",
                               str(synthetic_forecast), "--methods", "paper", "--starts", "2", "--max-hours", "1",
                               "--dt-s", "100000", "--out", str(tmp_path / "e")])
    assert "--dt-s: a step of 100000 s is not shorter than a run (1 h, --max-hours)" in line, line


@pytest.mark.parametrize("command", ["evaluate", "replay"])
def test_an_output_folder_that_is_a_file_is_refused_before_the_work(synthetic_forecast, tmp_path, capsys, command):
    taken = tmp_path / "taken"
    taken.write_bytes(b"kept")
    argv = (["evaluate", DEMO, "--forecast", str(synthetic_forecast), "--truth", str(synthetic_forecast),
             "--methods", "paper", "--starts", "2", "--max-hours", "1", "--out", str(taken / "e")]
            if command == "evaluate" else ["replay", str(tmp_path / "dive.mcap"), "--report", str(taken)])
    line = error_line(capsys, argv)
    assert line == f"lrauv: error: {taken}: is a file: expected a folder", line
    assert taken.read_bytes() == b"kept"


def test_a_replay_export_path_that_is_a_folder_is_refused_before_the_work(tmp_path, capsys):
    line = error_line(capsys, ["replay", str(tmp_path / "dive.mcap"), "--csv", str(tmp_path / "new.csv"),
                               "--gpx", str(tmp_path)])
    assert line == f"lrauv: error: {tmp_path}: is a folder: expected a file name", line
    assert not (tmp_path / "new.csv").exists()


def test_a_forecast_too_large_for_memory_is_one_line(tmp_path):
    """A real allocation that fails: under a 4 GiB address-space limit (the shell's ulimit) it fails at once."""
    command = shlex.join([sys.executable, "-m", "planner.cli", "forecast", "synth", str(tmp_path / "huge.nc"),
                          "--hours", "100000000"])
    proc = subprocess.run(["sh", "-c", f"ulimit -v 4194304 && exec {command}"], capture_output=True, text=True,
                          cwd=REPO, timeout=300)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "lrauv: error: not enough memory: Unable to allocate" in proc.stderr, proc.stderr
    assert not (tmp_path / "huge.nc").exists()


def test_a_goal_half_a_cell_beyond_the_edge_still_plans(synthetic_forecast, tmp_path, capsys):
    """The goal's cell centre is what must have a current, not the point (spec section 6)."""
    assert main(["plan", DEMO, f"--forecast={synthetic_forecast}", "--goal=-118.268,33.4,0",
                 f"--out={tmp_path / 'x.lrpt'}", "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().out


def test_a_forecast_with_float32_axes_covers_its_own_region(synthetic_forecast, tmp_path, capsys):
    narrow = tmp_path / "f32.nc"
    with xr.open_dataset(synthetic_forecast) as ds:
        ds.assign_coords(lat=ds.lat.astype("float32"), lon=ds.lon.astype("float32")).to_netcdf(narrow)
    assert main(["plan", DEMO, f"--forecast={narrow}", f"--out={tmp_path / 'x.lrpt'}", "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().out


def test_the_state_limit_is_the_plans_not_the_sampling_grids():
    """A physical plan's currents are sampled on a grid up to 8 times finer: that grid is not a plan's."""
    from planner.contract.geodesy import BBox
    from planner.grid import Grid
    from planner.physical.model import fine_grid

    grid = Grid.from_bbox(BBox(west_deg=-118.0, south_deg=33.0, east_deg=-117.0, north_deg=34.0), nx=1200, ny=1200,
                          depths_m=[0.0, 5.0, 10.0, 15.0])
    assert fine_grid(grid, 8).nx == 9593
