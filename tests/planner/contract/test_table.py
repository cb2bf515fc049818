"""The policy table: round trips, O(1) lookups, and refusal of corrupt or mismatched files."""

from __future__ import annotations

import json
import lzma
import math
import re
import subprocess
import sys
import zlib

from dataclasses import replace

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


# -- version 2: time-varying tables ----------------------------------------------------------------

HOURS = ("2026-01-15T00:00:00Z", "2026-01-15T01:00:00Z", "2026-01-15T02:00:00Z")
T0 = 1768435200.0  # HOURS[0], Unix s


def _slices(table: PolicyTable, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` slices: the table's actions, then each with some water states changed (land stays UNREACHABLE)."""
    stack = np.repeat(table.actions[None], n, axis=0).copy()
    for s in range(1, n):
        change = table.water[..., None] & (rng.random(table.actions.shape) < 0.05)
        stack[s][change] = rng.integers(0, 6, size=int(change.sum()))
    return stack


def _rewritten(data: bytes, *, version: int | None = None, header=lambda h: h, payload=lambda p: p,  # type: ignore[no-untyped-def]
               new_flags=lambda f: f) -> bytes:
    """A table file with its version, header, raw payload or flags changed, its lengths and CRC made right again."""
    import json
    import struct

    magic, ver, flags, header_len = struct.unpack_from("<8sHHI", data, 0)
    head = json.dumps(header(json.loads(data[16:16 + header_len])), sort_keys=True, separators=(",", ":")).encode()
    stored_len, _raw_len = struct.unpack_from("<II", data, 16 + header_len)
    stored = data[24 + header_len:24 + header_len + stored_len]
    raw = payload(zlib.decompress(stored) if flags & 1 else lzma.decompress(stored) if flags & 2 else stored)
    if flags & 2 and version == 1:  # xz is version 2's alone: a version-1 rewrite stores zlib
        flags = 1
    stored = zlib.compress(raw, 9) if flags & 1 else lzma.compress(raw) if flags & 2 else raw
    body = (struct.pack("<8sHHI", magic, ver if version is None else version, new_flags(flags), len(head)) + head
            + struct.pack("<II", len(stored), len(raw)) + stored)
    return body + zlib.crc32(body).to_bytes(4, "little")


@pytest.fixture(scope="module")
def timed(demo_plan) -> PolicyTable:
    return demo_plan.table.with_slices(HOURS, _slices(demo_plan.table, 3, np.random.default_rng(7)))


@pytest.mark.parametrize("compress", [True, False])
def test_a_time_varying_table_round_trips_as_version_2(timed, compress):
    data = timed.to_bytes(compress=compress)
    assert int.from_bytes(data[8:10], "little") == 2
    back = PolicyTable.from_bytes(data)
    assert back.time_varying and back.n_slices == 3 and back.slice_times == HOURS
    assert back.slices is not None and np.array_equal(back.slices, timed.slices)
    assert np.array_equal(back.actions, timed.slices[0]) and np.array_equal(back.water, timed.water)
    assert back.header()["time"] == {"slices_utc": list(HOURS), "lookup": "nearest"}
    assert back.to_bytes(compress=compress) == data
    assert int.from_bytes(data[10:12], "little") == (0x000A if compress else 0x0008)  # xz; by cell
    assert back.slice_unix_s == (T0, T0 + 3600.0, T0 + 7200.0)
    for n in range(3):  # each slice is a stationary table with the file's identity
        view = back.slice_table(n)
        assert not view.time_varying and np.array_equal(view.actions, timed.slices[n])
        assert view.crc32 == back.crc32 == timed.crc32


def test_a_stationary_table_is_still_version_1_byte_for_byte(demo_plan):
    """The file, built here from docs/policy-table.md's version 1 layout, is what the writer gives."""
    import json
    import struct

    table = demo_plan.table
    head = json.dumps(table.header(), sort_keys=True, separators=(",", ":")).encode()
    assert "time" not in table.header()
    mask = np.packbits(table.water.ravel(), bitorder="little").tobytes()
    flat = table.actions.ravel()
    raw = mask + ((flat[0::2] & 0x0F) | (flat[1::2] << 4)).astype(np.uint8).tobytes()  # an even number of states
    stored = zlib.compress(raw, 9)
    body = struct.pack("<8sHHI", b"LRAUVPT\0", 1, 1, len(head)) + head + struct.pack("<II", len(stored), len(raw)) + stored
    data = table.to_bytes()
    assert data == body + zlib.crc32(body).to_bytes(4, "little")
    assert PolicyTable.from_bytes(data).to_bytes() == data
    assert not table.time_varying and table.n_slices == 1 and table.slice_unix_s == ()
    assert table.slice_at(T0).table is table and table.slice_at(T0).status == "stationary"


@pytest.mark.parametrize(("unix_s", "index", "status"), [
    (None, 0, "time_unknown"), (math.nan, 0, "time_unknown"), (T0 - 1.0, 0, "before_start"),
    (T0, 0, "in_horizon"), (T0 + 1799.0, 0, "in_horizon"), (T0 + 1800.0, 0, "in_horizon"),  # a tie: the earlier
    (T0 + 1801.0, 1, "in_horizon"), (T0 + 5000.0, 1, "in_horizon"), (T0 + 7200.0, 2, "in_horizon"),
    (T0 + 7200.5, 2, "past_horizon"), (T0 + 86400.0, 2, "past_horizon"),
])
def test_slice_at_each_status(timed, unix_s, index, status):
    current = timed.slice_at(unix_s)
    assert (current.index, current.status) == (index, status)
    assert current.table is timed.slice_table(index)
    assert np.array_equal(current.table.actions, timed.slices[index])


def test_refused_time_varying_files_say_why(demo_plan, timed):
    v1, v2 = demo_plan.table.to_bytes(), timed.to_bytes()
    cases = [
        (_rewritten(v1, version=2), "format version 2 needs the header's time.slices_utc"),
        (_rewritten(v2, version=1), "format version 1 has no time slices; the header's time.slices_utc needs version 2"),
        (_rewritten(v2, header=lambda h: {**h, "time": {**h["time"], "slices_utc": [HOURS[0], HOURS[2], HOURS[1]]}}),
         r"time.slices_utc\[2\]: 2026-01-15T01:00:00Z is not after the slice before it \(2026-01-15T02:00:00Z\)"),
        (_rewritten(v2, header=lambda h: {**h, "time": {**h["time"], "slices_utc": [HOURS[0], "2026-01-15T01:00:00+00:00",
                                                                                     HOURS[2]]}}),
         r"time.slices_utc\[1\]: expected an ISO 8601 UTC time like 2026-01-15T03:00:00Z"),
        (_rewritten(v2, header=lambda h: {**h, "time": {**h["time"], "lookup": "linear"}}),
         'time.lookup: expected "nearest"'),
        (_rewritten(v2, header=lambda h: {**h, "time": {**h["time"], "slices_utc": [*HOURS, "2026-01-15T03:00:00Z"]}}),
         "payload declared as .* bytes but the grid 4 x 21 x 29 x 8 needs"),
        (_rewritten(v2, payload=lambda p: p[:-100]), "payload declared as .* bytes but the grid"),
    ]
    for data, message in cases:
        with pytest.raises(TableError, match=message):
            PolicyTable.from_bytes(data, name="t.lrpt")


def test_a_land_cell_with_an_action_in_a_later_slice_is_refused(demo_plan, timed):
    assert timed.slices is not None
    stack = timed.slices.copy()
    l, j, i = (int(x) for x in np.argwhere(~demo_plan.table.water)[0])
    stack[2, l, j, i, 3] = int(Action.FORWARD)
    bad = demo_plan.table.with_slices(HOURS, stack).to_bytes()  # the writer does not check; the reader does
    with pytest.raises(TableError, match=r"t.lrpt: land cells must carry UNREACHABLE"):
        PolicyTable.from_bytes(bad, name="t.lrpt")


def test_the_first_version_2_files_with_each_slice_as_its_change_from_the_one_before_still_read(timed):
    """Without flag 0x0008 a later slice is its XOR with the slice before (the first version 2 files)."""
    for compress in (True, False):
        old = _rewritten(timed.to_bytes(compress=compress), payload=lambda p: _xor_slices(p, timed),
                         new_flags=lambda f: f & ~0x0008)
        back = PolicyTable.from_bytes(old)
        assert back.slices is not None and np.array_equal(back.slices, timed.slices)
    # Read as actions by cell, the XOR file would put other actions on land: the flag is what tells the two apart.
    with pytest.raises(TableError, match="land cells must carry UNREACHABLE"):
        PolicyTable.from_bytes(_rewritten(old, new_flags=lambda f: f | 0x0008))
    with pytest.raises(TableError, match=re.escape("actions by cell (0x0008) are version 2's alone")):
        PolicyTable.from_bytes(_rewritten(timed.slice_table(0).to_bytes(), new_flags=lambda f: f | 0x0008))


def test_slices_that_barely_change_cost_little_more_than_one(demo_plan):
    """xz finds each slice's match in the slice before: unchanged states compress to almost nothing."""
    table = demo_plan.table
    one = len(table.to_bytes())
    same = len(table.with_slices(tuple(f"2026-01-15T{h:02d}:00:00Z" for h in range(10)),
                                 np.repeat(table.actions[None], 10, axis=0)).to_bytes())
    assert same < 1.5 * one, (same, one)
    few = len(table.with_slices(tuple(f"2026-01-15T{h:02d}:00:00Z" for h in range(10)),
                                _slices(table, 10, np.random.default_rng(3))).to_bytes())
    assert same < few  # the changes are what costs


def test_a_nominal_path_round_trips_and_a_bad_one_is_refused(demo_plan):
    from dataclasses import replace

    path = ((-118.0, 33.51), (-117.95, 33.45), (-117.8, 33.4))
    table = replace(demo_plan.table, nominal_path=path)
    again = PolicyTable.from_bytes(table.to_bytes())
    assert again.nominal_path == path and again.to_bytes() == table.to_bytes()
    assert (again.actions == demo_plan.table.actions).all() and again.crc32 != demo_plan.table.crc32
    timed = table.with_slices(("2026-01-15T00:00:00Z", "2026-01-15T01:00:00Z"),
                              np.stack([table.actions, table.actions]))
    assert PolicyTable.from_bytes(timed.to_bytes()).nominal_path == path  # a time-varying table carries it too
    data = table.to_bytes(compress=False)
    for bad, message in (([[-118.0]], r"nominal_path.lon_lat_deg\[0\]: expected \[lon, lat\]"),
                         ([[-118.0, 95.0]], r"nominal_path.lon_lat_deg\[0\]: \(-118, 95\) is not"),
                         ([["a", 33.0]], r"nominal_path.lon_lat_deg\[0\]\[0\]: expected a finite number"),
                         ("path", "nominal_path.lon_lat_deg: expected a list")):
        def header(h, bad=bad):  # type: ignore[no-untyped-def]
            return {**h, "nominal_path": {"lon_lat_deg": bad}}

        with pytest.raises(TableError, match=message):
            PolicyTable.from_bytes(_rewritten(data, header=header), name="t.lrpt")


def test_a_time_varying_table_carries_its_slices_currents_to_the_cm_s(timed):
    L = timed.n_layers
    current = np.linspace(-0.834, 0.917, 3 * L * 2).reshape(3, L, 2)
    table = timed.with_slices(HOURS, timed.slices, current)
    back = PolicyTable.from_bytes(table.to_bytes())
    assert back.slice_current_m_s is not None
    assert np.allclose(back.slice_current_m_s, np.round(current, 2)) and np.allclose(back.slice_current_m_s, current, atol=0.005)
    assert back.header()["time"]["current_cm_s"] == "payload"
    # The payload ends in them: int16 cm/s, the first slice, then each slice less the one before.
    tail = np.frombuffer(lzma.decompress(table.to_bytes()[24 + _header_len(table):-4])[-3 * L * 4:], "<i2")
    cm_s = np.round(current * 100).astype(int)
    assert tail.reshape(3, L, 2).tolist() == np.concatenate([cm_s[:1], np.diff(cm_s, axis=0)]).tolist()
    assert back.to_bytes() == table.to_bytes()
    assert back.slice_table(1).slice_current_m_s is None  # a slice is a stationary plan
    assert "current_cm_s" not in timed.header()["time"]  # without them, the bytes they always had
    assert len(timed.to_bytes(compress=False)) + 3 * L * 4 + len('"current_cm_s":"payload",') == len(table.to_bytes(compress=False))
    assert "current_block_cells" not in back.header()["time"] and back.current_region((1, 5, 7)) == 1


def test_slice_currents_at_the_ends_of_16_bits_round_trip_and_beyond_them_are_refused(timed):
    L = timed.n_layers
    current = np.zeros((3, L, 2))
    current[0, 0, 0], current[1, 0, 0], current[2, 0, 0] = 327.67, -327.67, 327.67  # steps beyond 16 bits wrap back
    back = PolicyTable.from_bytes(timed.with_slices(HOURS, timed.slices, current).to_bytes())
    assert np.array_equal(back.slice_current_m_s, current)
    current[2, 0, 1] = 327.68
    with pytest.raises(TableError, match=re.escape("slice 2, region 0, north: 327.68 m/s; expected a finite current within"
                                                   " +-327.67 m/s")):
        timed.with_slices(HOURS, timed.slices, current)
    current[2, 0, 1] = np.nan
    with pytest.raises(TableError, match=re.escape("slice 2, region 0, north: nan m/s")):
        timed.with_slices(HOURS, timed.slices, current)
    # -32768 cm/s fits the payload's 16 bits but no table carries it: the file is refused by name.
    good = timed.with_slices(HOURS, timed.slices, np.zeros((3, L, 2))).to_bytes()
    low = _rewritten(good, payload=lambda p: p[:-3 * L * 4] + (-32768).to_bytes(2, "little", signed=True) + p[-3 * L * 4 + 2:])
    with pytest.raises(TableError, match=re.escape("t.lrpt: slice currents: slice 0, region 0, east: -327.68 m/s")):
        PolicyTable.from_bytes(low, name="t.lrpt")
    with pytest.raises(TableError, match=re.escape("time.current_cm_s[1][0][1]: expected whole cm/s within +-32767;")):
        PolicyTable.from_bytes(_rewritten(_header_currents(timed.with_slices(HOURS, timed.slices, np.zeros((3, L, 2)))),
                                          header=lambda h: _set_current(h, 1, 0, 1, 10 ** 400)))


def test_slice_currents_beyond_their_limit_are_refused_before_the_payload_is_read(timed):
    from planner.contract.table_header import MAX_CURRENT_PAIRS

    table = timed.with_slices(HOURS, timed.slices, np.zeros((3, timed.n_layers * timed.ny * timed.nx, 2)), block_cells=1)

    def header(h):  # type: ignore[no-untyped-def]
        h["grid"]["nx"] = h["grid"]["ny"] = 2400  # 4 layers of 2400 x 2400 one-cell blocks in 3 slices: 69 M pairs
        return h

    assert 3 * 4 * 2400 * 2400 > MAX_CURRENT_PAIRS
    with pytest.raises(TableError, match=re.escape(f"time.current_cm_s: 3 slices x 23,040,000 regions exceed the limit of"
                                                   f" {MAX_CURRENT_PAIRS:,} pairs")):
        PolicyTable.from_bytes(_rewritten(table.to_bytes(), header=header))


def _set_current(h, n, r, c, value):  # type: ignore[no-untyped-def]
    h["time"]["current_cm_s"][n][r][c] = value
    return h


def test_a_table_with_its_slice_currents_in_the_header_still_reads(timed):
    """The first tables with slice currents carried them as JSON lists in the header (and their slices as XOR changes)."""
    L = timed.n_layers
    current = np.linspace(-0.834, 0.917, 3 * L * 2).reshape(3, L, 2)
    table = timed.with_slices(HOURS, timed.slices, current)
    old = _header_currents(table)
    assert json.loads(old[16:16 + _header_len(table, old)])["time"]["current_cm_s"][1][0] == \
        [round(current[1, 0, 0] * 100), round(current[1, 0, 1] * 100)]
    back = PolicyTable.from_bytes(old)
    assert np.array_equal(back.slice_current_m_s, table.slice_current_m_s) and np.array_equal(back.slices, table.slices)
    assert back.to_bytes() == table.to_bytes()  # written again, the current form
    with pytest.raises(TableError, match=re.escape(f"and {L} regions of slice currents needs")):  # the currents cut off
        PolicyTable.from_bytes(_rewritten(table.to_bytes(), payload=lambda p: p[:-3 * L * 4]))


def _header_len(table: PolicyTable, data: bytes | None = None) -> int:
    return int.from_bytes((table.to_bytes() if data is None else data)[12:16], "little")


def _header_currents(table: PolicyTable) -> bytes:
    """``table``'s file as the first tables with slice currents were written: JSON lists in the header, and
    each slice after the first as its XOR with the slice before (no flag 0x0008)."""
    assert table.slice_current_m_s is not None and table.slices is not None
    cm_s = np.round(table.slice_current_m_s * 100).astype(int).tolist()

    def header(h):  # type: ignore[no-untyped-def]
        h["time"]["current_cm_s"] = cm_s
        return h

    return _rewritten(table.to_bytes(), header=header, new_flags=lambda f: f & ~0x0008,
                      payload=lambda p: _xor_slices(p[:-table.slice_current_m_s.size * 2], table))


def _xor_slices(p: bytes, table: PolicyTable) -> bytes:
    """``table``'s payload (``p``: its water mask, then its actions; no currents) as the first version 2
    files stored it: slice after slice, each after the first as its XOR with the slice before."""
    assert table.slices is not None
    n_mask = (table.water.size + 7) // 8
    assert len(p) == n_mask + table.slices.size // 2
    flat = table.slices.reshape(table.n_slices, -1)
    packed = (flat[:, 0::2] | (flat[:, 1::2] << 4)).astype(np.uint8)
    packed[1:] ^= packed[:-1].copy()  # nibble by nibble, as byte by byte
    return p[:n_mask] + packed.tobytes()


def test_a_time_varying_payload_holds_each_cells_actions_slice_after_slice(timed):
    """Flag bit 3, as docs/policy-table.md lays it out: per cell (l, j, i), its 8 actions in slice 0, then slice 1, ..."""
    assert timed.slices is not None
    data = timed.to_bytes(compress=False)
    n_mask = (timed.water.size + 7) // 8
    payload = data[24 + int.from_bytes(data[12:16], "little"):-4]
    nibbles = np.empty(2 * (len(payload) - n_mask), dtype=np.uint8)
    nibbles[0::2] = np.frombuffer(payload[n_mask:], dtype=np.uint8) & 0x0F
    nibbles[1::2] = np.frombuffer(payload[n_mask:], dtype=np.uint8) >> 4
    cells = nibbles.reshape(timed.n_layers, timed.ny, timed.nx, timed.n_slices, 8)
    l, j, i = 1, 3, 4
    for n in range(timed.n_slices):
        assert cells[l, j, i, n].tolist() == timed.slices[n, l, j, i].tolist()
    assert np.array_equal(np.moveaxis(cells, 3, 0), timed.slices)


def test_slice_currents_per_block_of_cells_read_back_and_say_which_block_a_cell_is_in(timed):
    rows, cols = -(-timed.ny // 4), -(-timed.nx // 4)
    regions = timed.n_layers * rows * cols
    current = np.arange(3 * regions * 2, dtype=np.float64).reshape(3, regions, 2) / 100.0
    back = PolicyTable.from_bytes(timed.with_slices(HOURS, timed.slices, current, block_cells=4).to_bytes())
    assert back.current_block_cells == 4 and back.current_blocks() == (rows, cols) and back.n_current_regions == regions
    assert np.allclose(back.slice_current_m_s, current)
    assert back.current_region((0, 0, 0)) == 0 and back.current_region((0, 3, 4)) == 1
    assert back.current_region((1, 4, 0)) == rows * cols + cols  # the next layer, the second block row
    assert back.current_region((timed.n_layers - 1, timed.ny - 1, timed.nx - 1)) == regions - 1
    assert back.slice_table(0).current_block_cells is None
    huge = PolicyTable.from_bytes(timed.with_slices(HOURS, timed.slices, current[:, :timed.n_layers], block_cells=10_000)
                                  .to_bytes())  # larger than the grid: one block a layer, written and read alike
    assert huge.current_blocks() == (1, 1) and huge.current_region((1, timed.ny - 1, timed.nx - 1)) == 1
    with pytest.raises(TableError, match="slice currents"):  # per layer, where blocks were said
        timed.with_slices(HOURS, timed.slices, np.zeros((3, timed.n_layers, 2)), block_cells=4)

    def header(h):  # type: ignore[no-untyped-def]
        h["time"]["current_block_cells"] = 0
        return h

    with pytest.raises(TableError, match=re.escape("time.current_block_cells: expected a whole number of cells >= 1")):
        PolicyTable.from_bytes(_rewritten(back.to_bytes(), header=header))


@pytest.mark.parametrize("bad, key", [
    (lambda c: c[:2], "time.current_cm_s"),
    (lambda c: [c[0], c[1], c[2][:1]] if len(c[2]) > 1 else [c[0], c[1], []], "time.current_cm_s[2]"),
    (lambda c: [c[0], c[1], [[1.5, 0]] + c[2][1:]], "time.current_cm_s[2][0][0]"),
    (lambda c: [c[0], c[1], [[1]] + c[2][1:]], "time.current_cm_s[2][0]"),
])
def test_bad_slice_currents_are_refused_by_name(timed, bad, key):
    table = timed.with_slices(HOURS, timed.slices, np.zeros((3, timed.n_layers, 2)))

    def header(h):  # type: ignore[no-untyped-def]
        h["time"]["current_cm_s"] = bad(h["time"]["current_cm_s"])
        return h

    with pytest.raises(TableError, match=re.escape(key)):
        PolicyTable.from_bytes(_rewritten(_header_currents(table), header=header))
    with pytest.raises(TableError, match=re.escape('time.current_cm_s: expected "payload" or one entry per slice')):
        PolicyTable.from_bytes(_rewritten(table.to_bytes(), header=lambda h: {**h, "time": {**h["time"], "current_cm_s": "x"}}))


def test_slice_currents_need_a_time_varying_table_of_their_shape(demo_plan, timed):
    with pytest.raises(TableError, match="slice currents"):
        replace(demo_plan.table, slice_current_m_s=np.zeros((1, demo_plan.table.n_layers, 2)))
    with pytest.raises(TableError, match="slice currents"):
        timed.with_slices(HOURS, timed.slices, np.zeros((2, timed.n_layers, 2)))
