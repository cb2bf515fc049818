"""The policy table: round trips, O(1) lookups, and refusal of corrupt or mismatched files."""

from __future__ import annotations

import subprocess
import sys
import zlib

import numpy as np
import pytest

from planner.contract.actions import Action
from planner.contract.errors import TableError
from planner.contract.table import PolicyTable


def test_round_trip_is_bit_exact(demo_plan, tmp_path):
    table = demo_plan.table
    for compress in (True, False):
        path = table.save(tmp_path / f"t{compress}.lrpt", compress=compress)
        back = PolicyTable.load(path)
        assert np.array_equal(back.actions, np.ascontiguousarray(demo_plan.solution.action))
        assert np.array_equal(back.water, demo_plan.model.water)
        assert back.header() == table.header()
        assert back.to_bytes(compress=compress) == path.read_bytes()


def test_the_identity_crc_of_a_loaded_table_is_its_files(demo_plan):
    table = demo_plan.table
    data = table.to_bytes()
    loaded = PolicyTable.from_bytes(data)
    assert loaded.crc32 == int.from_bytes(data[-4:], "little") == table.crc32
    raw = PolicyTable.from_bytes(table.to_bytes(compress=False))  # not the named serialisation: recomputed
    assert raw.crc32 == table.crc32


def test_four_bits_per_state_and_compression(demo_plan):
    """The payload holds 4 bits per state plus 1 bit per cell, read back from the file's own lengths."""
    import struct

    raw = demo_plan.table.to_bytes(compress=False)
    packed = demo_plan.table.to_bytes(compress=True)
    header_len = struct.unpack_from("<I", raw, 12)[0]
    stored_len, raw_len = struct.unpack_from("<II", raw, 16 + header_len)
    n_states = demo_plan.grid.n_states
    n_cells = n_states // 8
    assert stored_len == raw_len == (n_cells + 7) // 8 + (n_states + 1) // 2
    assert raw_len * 8 <= 4 * n_states + n_cells + 8
    assert len(packed) < len(raw)


def test_lookup_at_every_cell_centre_matches_the_solution(demo_plan):
    table, sol, grid = demo_plan.table, demo_plan.solution, demo_plan.grid
    bearings = grid.bearings_deg()
    for l in range(grid.n_layers):
        for j in range(0, grid.ny, 3):
            for i in range(0, grid.nx, 2):
                for k in range(8):
                    got = table.lookup(grid.lat_deg[j], grid.lon_deg[i], grid.depth_m[l], bearings[j, k])
                    assert got.state == (l, j, i, k)
                    assert got.action == sol.action[l, j, i, k]
                    if not demo_plan.model.water[l, j, i]:
                        assert got.reason == "land"


def test_lookup_outside_and_reasons(demo_plan):
    table = demo_plan.table
    lat, lon = table.cell_centre(5, 5)
    assert table.lookup(lat, table.lon0_deg - table.dlon_deg, 0.0, 90.0).reason == "outside_grid"
    assert table.lookup(lat, lon, 100.0, 90.0).reason == "outside_grid"
    assert table.lookup(float("nan"), lon, 0.0, 90.0).reason == "outside_grid"
    # half a cell outside still belongs to the edge cell (cells span half a spacing around centres)
    edge = table.lookup(lat, table.lon0_deg - 0.49 * table.dlon_deg, 0.0, 90.0)
    assert edge.state is not None and edge.state[2] == 0
    g = demo_plan.solution.goal_cells
    glat, glon = table.cell_centre(g.j, g.i)
    at_goal = table.lookup(glat, glon, table.depth_m[g.l], 0.0)
    assert at_goal.action == Action.AT_GOAL and at_goal.reason == "at_goal"
    land = np.argwhere(~table.water[0])
    j, i = land[0]
    assert table.lookup(*table.cell_centre(j, i), 0.0, 0.0).reason == "land"


def test_heading_ties_go_to_the_lower_k(demo_plan):
    table = demo_plan.table
    j = 0
    b0, b1 = table.bearing_deg(j, 0), table.bearing_deg(j, 1)  # E and NE
    mid = (b0 + b1) / 2  # bearings decrease from E (90) to NE (~45)
    assert table.heading_index(j, mid) == 0
    assert table.heading_index(j, mid - 0.01) == 1
    assert table.heading_index(j, 359.999) == 2  # nearest to north


def corrupt(data: bytes, at: int) -> bytes:
    b = bytearray(data)
    b[at] ^= 0x10
    return bytes(b)


@pytest.mark.parametrize("compress", [True, False])
def test_corrupt_truncated_and_foreign_files_are_refused(demo_plan, compress):
    data = demo_plan.table.to_bytes(compress=compress)
    with pytest.raises(TableError, match="CRC32 mismatch"):
        PolicyTable.from_bytes(corrupt(data, len(data) // 2))
    with pytest.raises(TableError, match="truncated"):
        PolicyTable.from_bytes(data[:-10])
    with pytest.raises(TableError, match="truncated"):
        PolicyTable.from_bytes(data[:20])
    with pytest.raises(TableError, match="trailing bytes"):
        PolicyTable.from_bytes(data + b"\0")
    with pytest.raises(TableError, match="not a policy table"):
        PolicyTable.from_bytes(b"CDF\x01" + data[4:])
    with pytest.raises(TableError, match="version 9"):
        PolicyTable.from_bytes(data[:8] + (9).to_bytes(2, "little") + data[10:])


def test_a_consistent_table_with_a_wrong_grid_is_refused(demo_plan):
    """Re-sign a table whose header claims a different grid: the CRC passes, the size check does not."""
    data = demo_plan.table.to_bytes(compress=False)
    forged = data[:-4].replace(b'"nx":29', b'"nx":30')
    forged += zlib.crc32(forged).to_bytes(4, "little")
    with pytest.raises(TableError, match="needs"):
        PolicyTable.from_bytes(forged)


def test_mismatch_against_an_expected_table(demo_plan):
    t = demo_plan.table
    other = PolicyTable.from_bytes(t.to_bytes())
    assert t.matches(other) == []
    import dataclasses

    moved = dataclasses.replace(t, goal_lat_deg=t.goal_lat_deg + 0.01)
    assert t.matches(moved) == ["goal"]


def test_reader_needs_only_numpy():
    """The executive's import path: planner.contract.table must not pull in xarray, scipy, numba or netCDF4."""
    code = (
        "import sys, planner.contract.table; "
        "bad = [m for m in ('xarray', 'scipy', 'numba', 'netCDF4', 'matplotlib') if m in sys.modules]; "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_heading_index_equals_the_vectorised_nearest_bearing(demo_plan, rng):
    """The per-message loop in plain floats agrees with argmin over all eight bearings (spec section 2)."""
    table = demo_plan.table
    headings = np.concatenate([rng.uniform(-720, 720, 2000), np.arange(0, 360, 0.5)])
    for j in (0, table.ny // 2, table.ny - 1):
        row = np.array([table.bearing_deg(j, k) for k in range(8)])
        for h in headings:
            expected = int(np.argmin(np.abs(np.mod(h - row + 180.0, 360.0) - 180.0)))
            assert table.heading_index(j, h) == expected, (j, h)
