"""The physical model's plumbing: mission keys, ``lrauv plan`` flags and summary, the table header, replanning.

The model itself (transitions, solvers) is tested elsewhere; here only that its settings travel
from the mission file to the plan, into the table's header and back out (``plan_again``).
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import zlib
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest

from planner.contract.actions import Action
from planner.contract.errors import MissionError, TableError
from planner.contract.mission import Vehicle, load_mission
from planner.contract.settings import PhysicalSettings
from planner.contract.table import PolicyTable
from tests.support import REPO
from planner.contract.vehicle import VehicleParams

LRAUV = str(Path(sys.executable).parent / "lrauv")
PHYSICAL_MISSION = REPO / "missions" / "demo-physical.yaml"
START = "--start=-118.10,33.45,0,90"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([LRAUV, *args], capture_output=True, text=True, timeout=300)


def edit(tmp_path: Path, old: str, new: str) -> Path:
    text = PHYSICAL_MISSION.read_text()
    assert old in text, old
    out = tmp_path / "m.yaml"
    out.write_text(text.replace(old, new))
    return out


def line_of(path: Path, needle: str) -> int:
    return next(n for n, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


# --------------------------------------------------------------------------- the mission


def test_physical_mission_loads_into_the_settings(tmp_path):
    m = load_mission(PHYSICAL_MISSION)
    s = m.settings
    assert (s.model, s.criterion) == ("physical", "expected")
    assert s.physical == PhysicalSettings()  # the file spells out the defaults
    timed = edit(tmp_path, "max_transition_s: null ", "max_transition_s: 1800 ")
    assert load_mission(timed).settings.physical.max_transition_s == 1800.0
    assert s.vehicle == VehicleParams() == m.vehicle.params()  # the demo's figures are VehicleParams' defaults
    # Every figure of the vehicle section reaches VehicleParams; the speed limit follows the cruise speed.
    path = edit(tmp_path, "cruise_speed_m_s: 1.0", "cruise_speed_m_s: 2.0")
    text = path.read_text().replace("hotel_w: 8,", "hotel_w: 9.5,").replace("start_points: 3 ", "start_points: 5 ")
    path.write_text(text.replace("criterion: expected ", "criterion: robust "))
    s = load_mission(path).settings
    assert (s.criterion, s.physical.start_points, s.physical.error_members) == ("robust", 5, 8)
    assert (s.vehicle.cruise_speed_m_s, s.vehicle.max_speed_m_s, s.vehicle.hotel_w) == (2.0, 3.0, 9.5)
    slow = Vehicle(cruise_speed_m_s=0.5).params()
    assert slow.max_speed_m_s == VehicleParams().max_speed_m_s >= slow.cruise_speed_m_s


def test_paper_mission_keeps_its_settings_and_defaults_come_from_vehicle_params():
    m = load_mission(REPO / "missions" / "demo.yaml")
    assert (m.settings.model, m.settings.criterion) == ("paper", "robust")
    d, v = VehicleParams(), Vehicle()
    assert (v.cruise_speed_m_s, v.yaw_rate_deg_s, v.glide_rate_m_s) == (d.cruise_speed_m_s, d.yaw_rate_deg_s,
                                                                         d.glide_rate_m_s)
    assert (v.energy.hotel_w, v.energy.propulsion_w, v.energy.buoyancy_w, v.energy.battery_wh) == (
        d.hotel_w, d.propulsion_w, d.buoyancy_w, d.battery_wh)


@pytest.mark.parametrize(
    "old, new, key, message",
    [
        ("criterion: expected ", "criterion: optimistic ", "planning.criterion",
         "the physical model has robust and expected; got 'optimistic'"),
        ("model: physical", "model: paper", "planning.criterion", "the paper model has robust and optimistic; got 'expected'"),
        ("criterion: expected ", "criterion: safest ", "planning.criterion", "expected one of robust, expected"),
        ("error_members: 8 ", "error_members: 2 ", "planning.physical.error_members", "3..64"),
        ("start_points: 3 ", "start_points: 3.5 ", "planning.physical.start_points", "expected a whole number"),
        ("max_transition_s: null ", "max_transition_s: 0 ", "planning.physical.max_transition_s", "> 0"),
        ("min_cost_wh: 1.0e-6 ", "min_cost_wh: tiny ", "planning.physical.min_cost_wh", "expected a number in Wh"),
        ("rk4_steps: 8 ", "rk4_stepz: 8 ", "planning.physical.rk4_stepz", "unknown key"),
        ("course_offsets: true ", "course_offsets: 1 ", "planning.physical.course_offsets", "expected true or false; got 1"),
    ],
)
def test_bad_planning_keys_name_file_line_and_key(tmp_path, old, new, key, message):
    path = edit(tmp_path, old, new)
    with pytest.raises(MissionError) as err:
        load_mission(path)
    text = str(err.value)
    assert text.startswith(f"{path}:{line_of(path, '  ' + key.split('.')[-1] + ':')} {key}:"), text
    assert message in text, text


@pytest.mark.parametrize(
    "old, new, flags, needle",
    [
        ("criterion: expected ", "criterion: optimistic ", [], "planning.criterion: the physical model has robust and expected"),
        ("error_members: 8 ", "error_members: 70 ", [], "planning.physical.error_members:"),
        ("tolerance_wh: 1.0e-9 ", "tolerance_wh: -1 ", [], "planning.physical.tolerance_wh:"),
        ("name: scb-demo-physical", "name: scb-demo-physical", ["--model=paper"], "--criterion: the paper model has"),
        ("name: scb-demo-physical", "name: scb-demo-physical", ["--criterion=optimistic"], "--criterion: the physical model"),
    ],
)
def test_lrauv_plan_refuses_bad_combinations_with_one_line(tmp_path, synthetic_forecast, old, new, flags, needle):
    path = edit(tmp_path, old, new)
    proc = run("plan", str(path), f"--forecast={synthetic_forecast}", f"--out={tmp_path / 't.lrpt'}", *flags)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith("lrauv: error: ") and needle in lines[0], lines[0]
    if not flags:
        key = needle.split(":")[0]
        assert lines[0].startswith(f"lrauv: error: {path}:{line_of(path, '  ' + key.split('.')[-1] + ':')} {key}:")
    assert not (tmp_path / "t.lrpt").exists()


# --------------------------------------------------------------------------- lrauv plan, the table, plan_again


@pytest.fixture(scope="module")
def physical_plan(synthetic_forecast, tmp_path_factory):
    """``lrauv plan missions/demo-physical.yaml`` with every output: (process, table path, values, pictures)."""
    out = tmp_path_factory.mktemp("physical")
    table, values, pictures = out / "T.lrpt", out / "V.npz", out / "pics"
    proc = run("plan", str(PHYSICAL_MISSION), f"--forecast={synthetic_forecast}", f"--out={table}",
               f"--plot={pictures}", f"--export-values={values}", START)
    assert proc.returncode == 0, proc.stderr
    return proc, table, values, pictures


def test_lrauv_plan_physical_writes_table_values_pictures_and_a_summary(physical_plan):
    proc, table_path, values, pictures = physical_plan
    table = PolicyTable.load(table_path)
    assert (table.model, table.criterion) == ("physical", "expected")
    v = np.load(values)
    assert np.array_equal(v["action"], table.actions)
    assert v["time_s"].shape == v["cost"].shape == (4, 21, 29, 8)
    assert np.array_equal(np.isfinite(v["time_s"]), np.isfinite(v["cost"]))
    assert sorted(p.name for p in pictures.iterdir()) == ["flow_fields.png", "nominal_path.png", "policy_k0_l0.png"]
    out = proc.stdout
    assert "model      physical, expected; costs in Wh" in out
    words = " ".join(out.split())  # lines over 100 columns wrap under their value
    assert "state-actions" in words and "samples per action" in words and "finer than the grid" in words
    assert "policy iteration:" in words and "iterations, residual" in words
    start = words.split(" start (", 1)[1].split(" time ", 1)[0]
    assert " Wh, " in start and " h to go (expected)" in start, start


def test_physical_header_round_trips_the_settings(physical_plan):
    from planner.shore.replay.nominal import table_settings

    _, table_path, _, _ = physical_plan
    data = table_path.read_bytes()
    (header_len,) = struct.unpack_from("<I", data, 12)
    header = json.loads(data[16:16 + header_len])
    mission = load_mission(PHYSICAL_MISSION).settings
    assert header["model"] == "physical" and header["criterion"] == "expected" and header["costs"] == {}
    assert header["physical"]["sampling"] == asdict(PhysicalSettings())  # the mission spells out the defaults
    assert set(header["physical"]["sampling"]) == {
        "start_points", "current_error_m_s", "error_members", "max_transition_s", "rk4_steps", "min_cost_wh",
        "tolerance_wh", "max_iterations", "course_offsets"}
    assert header["physical"]["sampling"]["course_offsets"] is True
    assert header["physical"]["vehicle"] == {
        "cruise_speed_m_s": 1.0, "max_speed_m_s": 1.5, "yaw_rate_deg_s": 10.0, "glide_rate_m_s": 0.2,
        "hotel_w": 8.0, "propulsion_w": 12.0, "buoyancy_w": 15.0, "battery_wh": 3000.0}
    table = PolicyTable.from_bytes(data)
    assert table.header() == header and table.to_bytes() == data
    assert table_settings(table) == mission
    assert isinstance(table.physical["sampling"]["start_points"], int)  # type: ignore[index]


def test_plan_again_gives_the_same_actions_and_a_nominal_path_in_wh(physical_plan, synthetic_forecast):
    from planner.shore.replay.nominal import nominal_from, plan_again

    _, table_path, _, _ = physical_plan
    table = PolicyTable.load(table_path)
    result = plan_again(table, synthetic_forecast)
    assert np.array_equal(result.table.actions, table.actions)
    assert result.table.header() == table.header()
    k = table.heading_index(9, 90.0)
    start = next((0, 9, i, k) for i in range(table.nx) if table.actions[0, 9, i, k] < 6)
    path = nominal_from(result, start)
    assert path.cost_unit == "Wh" and np.isfinite(path.cost) and path.cost > 0
    assert path.time_s is not None and path.time_s > 0
    assert len(path.actions) >= 2 and path.lon_deg.size == len(path.actions)


def _pack(header: dict, water: np.ndarray, actions: np.ndarray) -> bytes:
    """A version-1 table file with a given header, written without PolicyTable (as an older planner did)."""
    from planner.contract.table import _pack_payload

    head = json.dumps(header, sort_keys=True, separators=(",", ":")).encode()
    raw = _pack_payload(water, actions)
    body = b"LRAUVPT\x00" + struct.pack("<HHI", 1, 0, len(head)) + head + struct.pack("<II", len(raw), len(raw)) + raw
    return body + struct.pack("<I", zlib.crc32(body))


def test_old_paper_tables_still_load_and_bad_physical_headers_are_refused(physical_plan):
    _, table_path, _, _ = physical_plan
    table = PolicyTable.load(table_path)
    old = {k: v for k, v in table.header().items() if k != "physical"}
    old.update(model="paper", criterion="robust", costs={"drift": 0, "forward": 4, "rotate": 10, "glide": 2})
    courses = (table.actions == Action.FORWARD_LEFT) | (table.actions == Action.FORWARD_RIGHT)
    assert courses.any()
    with pytest.raises(TableError, match="course offsets.*paper-model table"):  # codes 8, 9 are physical only
        PolicyTable.from_bytes(_pack(old, table.water, table.actions))
    paper_actions = np.where(courses, np.uint8(Action.FORWARD), table.actions)
    paper = PolicyTable.from_bytes(_pack(old, table.water, paper_actions))
    assert paper.physical is None and paper.model == "paper" and paper.costs["rotate"] == 10
    assert "physical" not in paper.header() and paper.header() == old
    # A paper table written now has the bytes it always had: no "physical" key.
    again = replace(paper, physical=None)
    assert b'"physical"' not in again.to_bytes(compress=False)
    # A physical table without the key (written before it existed) loads too.
    bare = dict(table.header())
    del bare["physical"]
    assert PolicyTable.from_bytes(_pack(bare, table.water, table.actions)).physical is None
    # Codes above 9 are refused; 8 and 9 too where the header says the plan had no course offsets.
    too_high = table.actions.copy()
    too_high[np.nonzero(table.water)[0][0], np.nonzero(table.water)[1][0], np.nonzero(table.water)[2][0], 0] = 10
    with pytest.raises(TableError, match="action codes above 9"):
        PolicyTable.from_bytes(_pack(table.header(), table.water, too_high))
    off = json.loads(json.dumps(table.header()))
    off["physical"]["sampling"]["course_offsets"] = False
    with pytest.raises(TableError, match="course_offsets false"):
        PolicyTable.from_bytes(_pack(off, table.water, table.actions))
    assert PolicyTable.from_bytes(_pack(off, table.water, paper_actions)).physical["sampling"]["course_offsets"] is False
    for broken, message in (
        ({"vehicle": {}, "sampling": {"course_offsets": 1}}, "physical.sampling.course_offsets: expected true or false"),
        ({"vehicle": {}, "sampling": {"min_cost_wh": True}}, "physical.sampling.min_cost_wh: expected a finite number"),
        ({"vehicle": {}}, "physical.sampling"),
        ({"vehicle": {}, "sampling": []}, "physical.sampling: expected a JSON object"),
        ({"vehicle": {"hotel_w": "8"}, "sampling": {}}, "physical.vehicle.hotel_w: expected a finite number"),
    ):
        with pytest.raises(TableError, match=message):
            PolicyTable.from_bytes(_pack({**table.header(), "physical": broken}, table.water, table.actions))


# --------------------------------------------------------------------------- compiled kernels

_ONE_SIGNATURE = r"""
import sys, tempfile
from pathlib import Path
from tests.support.warm_kernels import warm
import planner.physical.expected as expected, planner.physical.sampling as sampling
with tempfile.TemporaryDirectory() as tmp:
    assert warm(Path(tmp)) == 0
print(len(sampling.ENTRY_KERNEL.signatures), len(expected._solve_components.signatures))
"""


def test_a_plan_compiles_and_loads_each_large_kernel_once():
    """numba compiles a kernel, and loads it from its cache in every process, once per signature, and a
    read-only array is another type than a writable one: the goal patch's mask and the time's rotation
    costs must arrive as the whole grid's mask and the energies do, or the kernel compiles twice."""
    out = subprocess.run([sys.executable, "-c", _ONE_SIGNATURE], cwd=REPO, capture_output=True, text=True,
                         timeout=600, check=True).stdout
    assert out.split() == ["1", "1"], out
