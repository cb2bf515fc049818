"""A corpus of broken input files: each is refused with one clear line and exit status 2 (issue 5, point 5).

Every file here is real: netCDF written with netCDF4/xarray from a small synthetic forecast and then
damaged, YAML missions as text, policy tables as bytes with their CRC recomputed where the damage
must get past it. Each command must print exactly one line ``lrauv: error: ...`` that names the file
(and the key, line or value where there is one), exit with status 2, print no traceback, and leave
nothing behind: no output file, no temporary file, an existing output untouched.

Most cases call ``planner.cli.main`` in-process; a few run ``python -m planner.cli`` as a real process
to prove the exit status and the absence of a traceback end to end.
"""

from __future__ import annotations

import json
import os
import re
import signal
import struct
import subprocess
import sys
import tracemalloc
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from planner.cli import main
from planner.forecast.synthetic.scb import write_synthetic
from planner.contract.table import PolicyTable
from tests.support import REPO
from tests.support.broken_netcdf import NETCDF_CASES, SMALL, coord, cut, rewrite

GOAL = "--goal=-117.9,33.4,0"


# --------------------------------------------------------------------------------------
# Running the command and judging its answer
# --------------------------------------------------------------------------------------


def lrauv(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str]:
    """``lrauv ARGS`` in this process: (exit status, stderr)."""
    capsys.readouterr()
    try:
        rc = main([str(a) for a in args])
    except SystemExit as exc:  # argparse
        rc = int(exc.code or 0)
    return rc, capsys.readouterr().err


def lrauv_process(*args: object) -> tuple[int, str]:
    """``python -m planner.cli ARGS`` as a real process: (exit status, stderr)."""
    proc = subprocess.run([sys.executable, "-m", "planner.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=REPO, timeout=120, check=False)
    return proc.returncode, proc.stderr


class _TookTooLong(BaseException):
    """Raised by ``deadline``; a BaseException, so that no ``except Exception`` on the way swallows it."""


@contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Interrupt the block (Python code: the YAML parser) after ``seconds`` with ``_TookTooLong``."""
    def on_alarm(signum: int, frame: object) -> None:
        raise _TookTooLong

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def assert_refused(result: tuple[int, str], *expected: str | re.Pattern[str]) -> str:
    """Exit status 2 and exactly one line ``lrauv: error: ...`` holding every expected text; returns the line."""
    rc, err = result
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert rc == 2, (rc, err)
    assert len(lines) == 1 and lines[0].startswith("lrauv: error: "), err
    for want in expected:
        if isinstance(want, re.Pattern):
            assert want.search(lines[0]), (want.pattern, lines[0])
        else:
            assert want in lines[0], (want, lines[0])
    return lines[0]


def only_files(folder: Path, *names: str) -> None:
    """``folder`` holds exactly these files: nothing half-written, no temporary file left behind."""
    assert sorted(p.name for p in folder.iterdir()) == sorted(names)


# --------------------------------------------------------------------------------------
# netCDF forecasts
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def base_nc(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_synthetic(tmp_path_factory.mktemp("base") / "small.nc", SMALL)


@pytest.fixture(params=NETCDF_CASES, ids=[c[0] for c in NETCDF_CASES])
def broken_nc(request: pytest.FixtureRequest, base_nc: Path, tmp_path: Path) -> tuple[Path, tuple[str, ...]]:
    _, build, expected = request.param
    folder = tmp_path / "in"
    folder.mkdir()
    path = folder / "forecast.nc"
    build(base_nc, path)
    return path, expected


def test_forecast_info_refuses_a_broken_netcdf(capsys, broken_nc):
    path, expected = broken_nc
    assert_refused(lrauv(capsys, "forecast", "info", path), f"{path}: ", *expected)


def test_plan_refuses_a_broken_netcdf_and_writes_nothing(capsys, broken_nc, tmp_path):
    path, expected = broken_nc
    out = tmp_path / "out"
    out.mkdir()
    table = out / "plan.lrpt"
    assert_refused(lrauv(capsys, "plan", "--forecast", path, "--depths=0,5", GOAL, "--out", table, "--quiet"),
                   f"{path}: ", *expected)
    only_files(out)
    only_files(path.parent, path.name)


@pytest.mark.parametrize("case, command", [
    ("cut at 50%", "forecast info"),
    ("cut at 50%", "plan"),
    ("zero bytes", "forecast info"),
    ("u as strings", "forecast info"),
    ("time of 2^31 steps (netCDF-4, sparse)", "forecast info"),
])
def test_a_real_process_exits_2_without_a_traceback(case, command, base_nc, tmp_path):
    build, expected = next((b, e) for name, b, e in NETCDF_CASES if name == case)
    path = tmp_path / "forecast.nc"
    build(base_nc, path)
    args = (["forecast", "info", path] if command == "forecast info"
            else ["plan", "--forecast", path, "--depths=0", GOAL, "--out", tmp_path / "t.lrpt", "--quiet"])
    assert_refused(lrauv_process(*args), f"{path}: ", *expected)
    only_files(tmp_path, "forecast.nc")


def test_elevation_without_a_positive_attribute_is_read_as_height(capsys, base_nc, tmp_path):
    """Depths 0, -5, -10, -15 and no ``positive``: heights (ROMS z-levels), negated, with a note; not an error."""
    path = tmp_path / "up.nc"
    coord("depth", lambda d: -d, drop=("positive", "axis", "standard_name"))(base_nc, path)
    capsys.readouterr()
    assert main(["forecast", "info", str(path)]) == 0
    text = capsys.readouterr().out
    assert "4 level(s): 0, 5, 10, 15 m" in text and "elevation (positive up): negated" in text


def test_a_time_without_units_has_no_date_and_a_dated_plan_says_so(capsys, base_nc, tmp_path):
    """No ``units`` on time: seconds without a reference date (as CROCO writes them); --time is refused."""
    path = tmp_path / "nounits.nc"
    rewrite(base_nc, path, lambda ds: ds.assign_coords(time=("time", ds["time"].values, {"standard_name": "time"})))
    assert main(["forecast", "info", str(path)]) == 0
    assert "no reference date" in capsys.readouterr().out
    assert_refused(lrauv(capsys, "plan", "--forecast", path, "--depths=0,5", GOAL, "--time=2026-01-15T01:00",
                         "--out", tmp_path / "t.lrpt", "--quiet"), f"{path}: ", "no reference date", "--time-index")
    assert not (tmp_path / "t.lrpt").exists()


def test_a_truncated_grid_file_is_named(capsys, base_nc, tmp_path):
    grid = tmp_path / "grid.nc"
    cut(0.5)(base_nc, grid)
    assert_refused(lrauv(capsys, "forecast", "info", base_nc, "--grid-file", grid), f"{grid}: truncated grid file")


# --------------------------------------------------------------------------------------
# Policy tables
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def table_bytes(base_nc: Path, tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """A real table planned on the small forecast (15 x 11 cells x 2 layers, zlib payload)."""
    out = tmp_path_factory.mktemp("table") / "good.lrpt"
    assert main(["plan", "--forecast", str(base_nc), "--depths=0,5", GOAL, "--out", str(out), "--quiet"]) == 0
    return out.read_bytes()


def _parts(data: bytes) -> tuple[dict, int, int, bytes]:
    """(header, flags, raw_len, stored payload) of a table's bytes."""
    _, _, flags, header_len = struct.unpack_from("<8sHHI", data)
    pos = 16 + header_len
    stored_len, raw_len = struct.unpack_from("<II", data, pos)
    return json.loads(data[16:pos]), flags, raw_len, data[pos + 8 : pos + 8 + stored_len]


def _table(header: bytes, flags: int, raw_len: int, stored: bytes) -> bytes:
    """Table bytes with a correct CRC-32, so the damage inside reaches the reader's later checks."""
    body = (struct.pack("<8sHHI", b"LRAUVPT\x00", 1, flags, len(header)) + header
            + struct.pack("<II", len(stored), raw_len) + stored)
    return body + struct.pack("<I", zlib.crc32(body))


def _header_edit(edit: Callable[[dict], object]) -> Callable[[bytes], bytes]:
    def damage(data: bytes) -> bytes:
        header, flags, raw_len, stored = _parts(data)
        edit(header)
        return _table(json.dumps(header).encode(), flags, raw_len, stored)
    return damage


def _grid(**fields: object) -> Callable[[bytes], bytes]:
    return _header_edit(lambda h: h["grid"].update(fields))


def _raw_header(text: bytes) -> Callable[[bytes], bytes]:
    def damage(data: bytes) -> bytes:
        _, flags, raw_len, stored = _parts(data)
        return _table(text, flags, raw_len, stored)
    return damage


def _payload(edit: Callable[[np.ndarray], None]) -> Callable[[bytes], bytes]:
    """Edit the uncompressed payload's bytes (water bits, then action nibbles) and store it uncompressed."""
    def damage(data: bytes) -> bytes:
        header, flags, raw_len, stored = _parts(data)
        raw = np.frombuffer(zlib.decompress(stored), dtype=np.uint8).copy()
        edit(raw)
        return _table(json.dumps(header).encode(), 0, raw_len, raw.tobytes())
    return damage


def _n_mask(header: dict) -> int:
    g = header["grid"]
    return (len(g["depth_m"]) * g["ny"] * g["nx"] + 7) // 8


def _land_cell_with_an_action(data: bytes) -> bytes:
    header, _, _, stored = _parts(data)
    raw = np.frombuffer(zlib.decompress(stored), dtype=np.uint8)
    water = np.unpackbits(raw[: _n_mask(header)], bitorder="little")
    land = int(np.flatnonzero(water == 0)[0])
    return _payload(lambda r: r.__setitem__(_n_mask(header) + land * 4, 0x11))(data)


def _bomb(raw_len_ok: bool) -> Callable[[bytes], bytes]:
    """A zlib stream of 64 MiB of zeros (65 kB stored) where the grid needs 1,362 bytes."""
    def damage(data: bytes) -> bytes:
        header, flags, raw_len, _ = _parts(data)
        stored = zlib.compress(bytes(64 << 20), 9)
        return _table(json.dumps(header).encode(), flags, raw_len if raw_len_ok else 64 << 20, stored)
    return damage


def _flip(offset: int) -> Callable[[bytes], bytes]:
    return lambda d: d[:offset] + bytes([d[offset] ^ 0x10]) + d[offset + 1 :]


# (case, damage(good bytes) -> bad bytes, texts the error line must hold besides the file name)
TABLE_CASES: list[tuple[str, Callable[[bytes], bytes], tuple[str, ...]]] = [
    ("zero bytes", lambda d: b"", ("truncated: 0 bytes",)),
    ("cut in the preamble", lambda d: d[:10], ("truncated: 10 bytes",)),
    ("cut in the header", lambda d: d[:100], ("truncated: the header says", "the file has 100 bytes")),
    ("cut in the payload", lambda d: d[: len(d) - 200], ("truncated: expected",)),
    ("cut by one byte", lambda d: d[:-1], ("truncated: expected",)),
    ("trailing bytes", lambda d: d + b"\x00\x00\x00", ("has trailing bytes",)),
    ("a flipped payload byte", lambda d: _flip(len(d) - 40)(d), ("CRC32 mismatch", "corrupt")),
    ("a flipped header byte", _flip(40), ("CRC32 mismatch",)),
    ("wrong magic", lambda d: b"NOTATABL" + d[8:], ("not a policy table: magic b'NOTATABL'",)),
    ("future version", lambda d: d[:8] + struct.pack("<H", 3) + d[10:], ("format version 3 is not supported",)),
    ("unknown flag", lambda d: d[:10] + struct.pack("<H", 0x0005) + d[12:], ("unknown flags 0x0005",)),
    ("actions by cell in version 1", lambda d: d[:10] + struct.pack("<H", 0x0009) + d[12:],
     ("actions by cell (0x0008) are version 2's alone",)),
    ("xz in version 1", lambda d: d[:10] + struct.pack("<H", 0x0002) + d[12:], ("an xz payload (0x0002) is version 2's alone",)),
    ("header not JSON", _raw_header(b"{grid: 1"), ("header is not valid JSON",)),
    ("header not UTF-8", _raw_header(b"\xff\xfe{}"), ("header is not valid JSON",)),
    ("header nested 100,000 deep", _raw_header(b"[" * 100_000 + b"]" * 100_000), ("header is not valid JSON: nested too deeply",)),
    ("header a list", _raw_header(b"[1, 2, 3]"), ("header is not a JSON object; got list",)),
    ("nx as a string", _grid(nx="15"), ("header grid.nx: expected an integer; got '15'",)),
    ("negative ny", _grid(ny=-3), ("header grid.ny: expected at least 2 cells; got -3",)),
    ("depth_m not a list", _grid(depth_m=5.0), ("header grid.depth_m: expected a non-empty list", "got 5.0")),
    ("depth_m unsorted", _grid(depth_m=[5.0, 0.0]), ("header grid.depth_m: expected depths >= 0, strictly increasing",)),
    ("depth_m with text", _grid(depth_m=[0.0, "5"]), ("header grid.depth_m[1]: expected a finite number; got '5'",)),
    ("grid a list", _header_edit(lambda h: h.update(grid=[1, 2])), ("header grid: expected a JSON object; got list",)),
    ("costs a list", _header_edit(lambda h: h.update(costs=[4])), ("header costs: expected a JSON object",)),
    ("no grid.nx", _header_edit(lambda h: h["grid"].pop("nx")), ("header lacks the key 'grid.nx'",)),
    ("latitude beyond the pole", _grid(lat0_deg=95.0), ("header grid: rows span latitudes 95..95.4", "[-90, 90]")),
    ("10^9 columns", _grid(nx=10**9), ("176,000,000,000 states exceeds the limit of 2,147,483,648",)),
    ("2 x 10^9 states, within the limit", _grid(nx=16_000, ny=8_000, dlat_deg=0.001),
     ("payload declared as 1,362 bytes", "2 x 8000 x 16000 x 8 needs 1,056,000,000")),
    ("raw length off by one", lambda d: _table(*_header_and(d, raw_delta=1)), ("payload declared as 1,363 bytes", "needs 1,362")),
    ("zlib bomb, raw length claimed", _bomb(False), ("payload declared as 67,108,864 bytes", "needs 1,362")),
    ("zlib bomb, raw length right", _bomb(True), ("inflates to more than the 1,362 bytes",)),
    ("zlib stream corrupt", lambda d: _table(*_header_and(d, stored=b"x\x9c\xff\xff\xff")), ("compressed payload is corrupt",)),
    ("action code 9", _payload(lambda r: r.__setitem__(-1, 0x99)), ("action codes above 7",)),
    ("land cell with an action", _land_cell_with_an_action, ("land cells must carry UNREACHABLE",)),
]


def _header_and(data: bytes, *, raw_delta: int = 0, stored: bytes | None = None) -> tuple[bytes, int, int, bytes]:
    header, flags, raw_len, old = _parts(data)
    return json.dumps(header).encode(), flags, raw_len + raw_delta, old if stored is None else stored


@pytest.fixture(scope="module")
def exec_imported(tmp_path_factory: pytest.TempPathFactory) -> None:
    """``lrauv exec`` refused once, so its imports are not counted in the allocations measured below."""
    bad = tmp_path_factory.mktemp("warm") / "empty.lrpt"
    bad.write_bytes(b"")
    assert main(["exec", "--table", str(bad), "--link", "udpout:127.0.0.1:9", "--quiet"]) == 2


@pytest.mark.parametrize("case, damage, expected", TABLE_CASES, ids=[c[0] for c in TABLE_CASES])
def test_exec_refuses_a_broken_table_before_opening_anything(capsys, exec_imported, table_bytes, tmp_path, case, damage,
                                                             expected):
    bad = tmp_path / "bad.lrpt"
    bad.write_bytes(damage(table_bytes))
    log = tmp_path / "logs" / "run.mcap"
    tracemalloc.start()
    try:
        result = lrauv(capsys, "exec", "--table", bad, "--link", "udpout:127.0.0.1:9", "--max-wall-s", "0.1",
                       "--log", log, "--quiet")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert_refused(result, f"{bad}: ", *expected)
    assert peak < 16 << 20, f"{peak:,} bytes allocated to refuse {case}"
    assert not log.parent.exists()  # refused before the log, the link or the ground station was opened
    only_files(tmp_path, "bad.lrpt")


def test_the_good_table_is_accepted(table_bytes):
    table = PolicyTable.from_bytes(table_bytes, name="good")
    assert (table.nx, table.ny, table.depth_m) == (15, 11, (0.0, 5.0))
    uncompressed = table.to_bytes(compress=False)
    assert PolicyTable.from_bytes(uncompressed).to_bytes(compress=False) == uncompressed


@pytest.mark.parametrize("case", ["cut in the payload", "zlib bomb, raw length right"])
def test_a_broken_table_in_a_real_process(table_bytes, tmp_path, case):
    damage, expected = next((d, e) for name, d, e in TABLE_CASES if name == case)
    bad = tmp_path / "bad.lrpt"
    bad.write_bytes(damage(table_bytes))
    assert_refused(lrauv_process("exec", "--table", bad, "--link", "udpout:127.0.0.1:9", "--max-wall-s", "0.1",
                                 "--log", tmp_path / "run.mcap", "--quiet"), f"{bad}: ", *expected)
    only_files(tmp_path, "bad.lrpt")


# --------------------------------------------------------------------------------------
# Mission YAML
# --------------------------------------------------------------------------------------


def _mission_text(forecast: Path) -> str:
    """missions/demo.yaml on the small forecast: 15 x 11 cells, its forecast file named."""
    text = (REPO / "missions" / "demo.yaml").read_text(encoding="utf-8")
    for old, new in (("synthetic: {seed: 0, hours: 72}", f"file: {forecast}"), ("nx: 29", "nx: 15"), ("ny: 21", "ny: 11")):
        assert old in text
        text = text.replace(old, new, 1)
    return text


def _line_of(text: str, fragment: str) -> int:
    return text[: text.index(fragment)].count("\n") + 1


def _replace(old: str, new: str) -> Callable[[str], str]:
    def damage(text: str) -> str:
        assert old in text
        return text.replace(old, new, 1)
    return damage


_GOAL = "{lat_deg: 33.40, lon_deg: -117.80, depth_m: 0, radius_cells: 1, on_arrival: hold}"

# (case, damage(text) -> text, (fragment to find the line of, or None), texts the error line must hold)
YAML_CASES: list[tuple[str, Callable[[str], str], str | None, tuple[str | re.Pattern[str], ...]]] = [
    ("cut in half", lambda t: t[: len(t) // 2], None, (re.compile(r"\.yaml:\d+: not valid YAML"),)),
    ("cut inside a flow mapping", lambda t: t[: t.index("costs: {") + 20], None,
     (re.compile(r"\.yaml:\d+: not valid YAML"),)),
    ("a tab for indentation", _replace("  nx: 15", "\tnx: 15"), "\tnx: 15", ("not valid YAML",)),
    ("an unclosed bracket", _replace("name: scb-demo", "name: [scb-demo"), None,
     (re.compile(r"\.yaml:\d+: not valid YAML"),)),
    ("depth as a word", _replace("depth_m: 0, radius", "depth_m: deep, radius"), "depth_m: deep",
     ("goals[0].depth_m: expected a number in m; got 'deep'",)),
    ("a fractional cost", _replace("forward: 4", "forward: 4.5"), "forward: 4.5",
     ("planning.costs.forward", "integer costs", "got 4.5")),
    ("a negative cost", _replace("rotate: 10", "rotate: -10"), "rotate: -10", ("planning.costs.rotate", "got -10")),
    ("goals as a mapping", _replace("  - {lat_deg", "  first: {lat_deg"), "goals:",
     ("goals: expected a list of one or more goals",)),
    ("a negative goal depth", _replace("depth_m: 0, radius", "depth_m: -5, radius"), "depth_m: -5",
     ("goals[0].depth_m: expected at least 0 m; got -5",)),
    ("negative layer depths", _replace("depths_m: [0, 5, 10, 15]", "depths_m: [-5, 0, 5]"), "depths_m:",
     ("region.depths_m: expected non-negative depths", "[-5, 0, 5]")),
    ("NaN goal depth", _replace("depth_m: 0, radius", "depth_m: .nan, radius"), "depth_m: .nan",
     ("goals[0].depth_m: expected a number in m; got nan",)),
    ("a goal beyond the pole", _replace("lat_deg: 33.40", "lat_deg: 133.40"), "lat_deg: 133.40",
     ("goals[0].lat_deg: expected a latitude in [-90, 90]; got 133.4",)),
    ("nx as a word", _replace("nx: 15", "nx: fifteen"), "nx: fifteen", ("region.nx: expected a whole number; got 'fifteen'",)),
    ("a short bbox", _replace("bbox: [-118.26, 33.30, -117.70, 33.70]", "bbox: [-118.26, 33.30]"), "bbox:",
     ("region.bbox: expected [WEST, SOUTH, EAST, NORTH]",)),
    ("an unknown key", _replace("  nx: 15", "  nx: 15\n  nz: 4"), "nz: 4",
     ("region.nz: unknown key; expected one of: bbox, depths_m, nx, ny",)),
    ("a duplicate key", _replace("  nx: 15", "  nx: 15\n  nx: 16"), "nx: 16", ("region.nx: duplicate key",)),
    ("an empty file", lambda t: "", None, ("the file is empty; expected a mission mapping",)),
    ("only a comment", lambda t: "# a mission\n", None, ("the file is empty",)),
    ("a list at the top", lambda t: "- a\n- b\n", None, (":1: expected a mapping; got list",)),
    ("10,000 goals", _replace(f"  - {_GOAL}\n", f"  - {_GOAL}\n" * 10_000), "goals:",
     ("goals: expected at most 1000 goals; got 10000",)),
]


@pytest.fixture(scope="module")
def mission_text(base_nc: Path) -> str:
    return _mission_text(base_nc)


def test_the_base_mission_loads(mission_text, tmp_path):
    from planner.contract.mission import load_mission

    path = tmp_path / "mission.yaml"
    path.write_text(mission_text, encoding="utf-8")
    assert load_mission(path).region.nx == 15


# Every case through both commands that parse a mission first, except the 500 kB one (2.5 s to parse).
_YAML_PARAMS = [pytest.param(*case, command, id=f"{case[0]}-{command}") for case in YAML_CASES
                for command in ("plan", "waypoints export") if case[0] != "10,000 goals" or command == "plan"]


@pytest.mark.parametrize("case, damage, line_of, expected, command", _YAML_PARAMS)
def test_a_broken_mission_is_refused_with_its_line(capsys, mission_text, tmp_path, case, damage, line_of, expected,
                                                   command):
    text = damage(mission_text)
    path = tmp_path / "mission.yaml"
    path.write_text(text, encoding="utf-8")
    where = f"{path}:{_line_of(text, line_of)}" if line_of else f"{path}"
    out = tmp_path / ("plan.lrpt" if command == "plan" else "goals.waypoints")
    args = ["plan", path, "--out", out, "--quiet"] if command == "plan" else ["waypoints", "export", path, out]
    assert_refused(lrauv(capsys, *args), where, *expected)
    only_files(tmp_path, "mission.yaml")


def test_a_control_character_is_one_line_naming_its_line(capsys, mission_text, tmp_path):
    path = tmp_path / "mission.yaml"
    path.write_text(mission_text.replace("name: scb-demo", "name: scb\x00demo"), encoding="utf-8")
    assert_refused(lrauv(capsys, "plan", path, "--out", tmp_path / "t.lrpt"), f"{path}:3: not valid YAML")


def test_a_mission_that_is_not_utf8(capsys, tmp_path):
    path = tmp_path / "mission.yaml"
    path.write_bytes(b"name: \xff\xfe\n")
    assert_refused(lrauv(capsys, "plan", path, "--out", tmp_path / "t.lrpt"), f"{path}: not a text file (byte 6 is not UTF-8)", "expected a mission in YAML")


def _billion_laughs() -> str:
    """Nine levels of nine aliases: 387,420,489 strings once expanded, 400 bytes as text."""
    lines = ["l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"l{n}: &l{n} [{', '.join([f'*l{n - 1}'] * 9)}]" for n in range(1, 9)]
    return "\n".join(lines) + "\nname: bomb\n"


def test_a_yaml_bomb_is_refused_quickly(capsys, tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(_billion_laughs(), encoding="utf-8")
    try:
        with deadline(60.0):  # a guard against a hang, not a speed test: refused by its count of values
            result = lrauv(capsys, "plan", path, "--out", tmp_path / "t.lrpt")
    except _TookTooLong:
        pytest.fail("lrauv plan on a 400-byte YAML bomb did not finish")
    assert_refused(result, f"{path}", "aliases are expanded")
    only_files(tmp_path, "bomb.yaml")


def test_a_50_megabyte_mission_is_refused_quickly(capsys, mission_text, tmp_path):
    path = tmp_path / "huge.yaml"
    goal = f"  - {_GOAL}\n"
    path.write_text(mission_text.replace(goal, goal * (50_000_000 // len(goal)), 1), encoding="utf-8")
    assert path.stat().st_size > 50_000_000
    try:
        with deadline(60.0):  # a guard against a hang, not a speed test: refused by its size
            result = lrauv(capsys, "plan", path, "--out", tmp_path / "t.lrpt")
    except _TookTooLong:
        pytest.fail("lrauv plan on a 50 MB mission did not finish")
    assert_refused(result, f"{path}", "a mission file is at most")
    only_files(tmp_path, "huge.yaml")


# --------------------------------------------------------------------------------------
# Nothing half-written
# --------------------------------------------------------------------------------------


def test_a_failed_plan_leaves_an_existing_table_untouched(capsys, base_nc, table_bytes, tmp_path):
    out = tmp_path / "plan.lrpt"
    out.write_bytes(table_bytes)
    before = out.stat().st_mtime_ns
    broken = tmp_path / "broken.nc"
    cut(0.5)(base_nc, broken)
    assert_refused(lrauv(capsys, "plan", "--forecast", broken, "--depths=0,5", GOAL, "--out", out, "--quiet"),
                   f"{broken}: truncated")
    assert out.read_bytes() == table_bytes and out.stat().st_mtime_ns == before
    only_files(tmp_path, "plan.lrpt", "broken.nc")


def test_a_plan_that_fails_late_writes_no_table(capsys, base_nc, tmp_path):
    """The goal is checked after the forecast loaded and resampled: still nothing is written."""
    out = tmp_path / "out" / "plan.lrpt"
    assert_refused(lrauv(capsys, "plan", "--forecast", base_nc, "--depths=0,5", "--goal=-119.5,33.4,0",
                         "--out", out, "--quiet"), "goal (-119.5", "outside the planning grid")
    assert not out.parent.exists()


def _small_log(path: Path) -> None:
    from executive.recorder import Recorder, Topic

    with Recorder(path, metadata={"executive": {"table": "t.lrpt"}}) as rec:
        for n in range(50):
            rec.write(Topic.COMMAND, float(n), {"time_s": float(n), "kind": "DepthTarget", "depth_m": 5.0})


def test_log_recover_that_fails_leaves_no_partial_output(capsys, tmp_path):
    source = tmp_path / "run.mcap"
    _small_log(source)
    os.truncate(source, source.stat().st_size * 2 // 3)  # an executive killed mid-run
    blocker = tmp_path / "out.mcap"
    blocker.mkdir()  # the output path is a folder: the final rename fails
    assert_refused(lrauv(capsys, "log", "recover", source, blocker), f"{blocker}: cannot write the recovered log")
    only_files(tmp_path, "run.mcap", "out.mcap")
    assert not any(blocker.iterdir())


@pytest.mark.parametrize("content", [b"", b"not an MCAP file\n", b"\x89MCAP0\r\n"], ids=["empty", "text", "magic only"])
def test_log_recover_refuses_a_broken_source_and_writes_nothing(capsys, tmp_path, content):
    source = tmp_path / "run.mcap"
    source.write_bytes(content)
    assert_refused(lrauv(capsys, "log", "recover", source, tmp_path / "fixed.mcap"), f"{source}: ")
    only_files(tmp_path, "run.mcap")

