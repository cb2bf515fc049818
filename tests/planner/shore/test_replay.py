"""``lrauv replay``: the dive summary, the decision audit and bad or damaged logs.

The log is a real one, shared with the other replay tests (``dive_log`` in
conftest.py): ``lrauv sim`` and ``lrauv exec`` as processes over UDP to the goal.
Damaged and tampered copies are written record by record with the ``mcap`` library.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcap.records import Message
from mcap.writer import Writer

from planner.shore.replay.audit import audit
from planner.shore.replay.dive import load_dive, path_length_m
from planner.shore.replay.divelog import open_dive
from executive.recorder import LogError, Recorder, Topic, read_messages, recover
from planner.shore.replay.summary import distance_to_polyline_m, summarise
from planner.cli import main as lrauv
from planner.contract.actions import Action

from tests.planner.shore.mcap_logs import rewrite_log
from tests.support.helpers import start_west_of_goal

def _decisions(path: Path) -> list[dict]:
    """The logged decisions in the order they were made (file order)."""
    return [m.payload for m in open_dive(path).messages([Topic.DECISION])]


# -- the summary -------------------------------------------------------------------------


def test_replay_prints_the_dive_summary_and_the_audit_finds_no_difference(dive_log, capsys):
    code = lrauv(["replay", str(dive_log)])
    out = capsys.readouterr().out
    assert code == 0, out
    decisions = _decisions(dive_log)
    assert f"decisions  {len(decisions):,}" in out
    assert f"audit      {len(decisions):,} decisions run again with 1 logged table(s), 0 swap(s): no difference" in out
    assert "goal 0     reached at" in out and "NOT reached" not in out
    assert "failsafes  0 (none from the autopilot or the executive)" in out
    assert "autopilot  no status text" in out
    assert "complete (" in out
    # The planning forecast is found beside the table by its identity: the nominal path is known.
    assert "deviation  largest from the nominal path" in out, out


def test_summary_figures_add_up_to_the_log(dive_log):
    dive = load_dive(open_dive(dive_log))
    s = summarise(dive)
    decisions = _decisions(dive_log)
    assert s.decisions == len(decisions) == sum(s.decisions_by_action.values())
    assert s.action_starts == {a: n for a, n in _starts(decisions).items()}
    # Every second of the dive and every watt-hour is put against exactly one action.
    span_s = max(d["time_s"] for d in decisions) - decisions[0]["time_s"]
    assert math.isclose(sum(s.time_by_action_s.values()), span_s, rel_tol=1e-9) and s.vehicle_s == span_s
    states = [p for _, _, p in read_messages(dive_log, [Topic.STATE.value]) if p["energy_used_wh"] is not None]
    assert s.energy_used_wh is not None and s.energy_used_wh > 0
    assert math.isclose(sum(s.energy_by_action_wh.values()), s.energy_used_wh, rel_tol=1e-9)
    assert s.energy_used_wh <= states[-1]["energy_used_wh"] - states[0]["energy_used_wh"] + 1e-9
    lat = np.array([d["lat_deg"] for d in decisions])
    lon = np.array([d["lon_deg"] for d in decisions])
    assert s.fix_distance_m == pytest.approx(path_length_m(lat, lon)) and s.distance_m > 1000.0
    # Filtered, the distance is at most what summing every fix gives (and here, without noise, about it).
    assert s.distance_m <= s.fix_distance_m and s.distance_m == pytest.approx(s.fix_distance_m, rel=0.01)
    reached = [d for d in decisions if d["situation"] == "at_goal"]
    assert [g.time_s for g in s.goals_reached] == [reached[0]["time_s"]]


def _starts(decisions: list[dict]) -> dict[str, int]:
    out: dict[str, int] = {}
    for d in decisions:
        if d["changed"]:
            label = d["action"] or d["situation"].upper()
            out[label] = out.get(label, 0) + 1
    return out


def test_path_length_and_distance_to_a_polyline_by_hand():
    # One minute of latitude is 1852 m on the sphere of radius 6371 km: 1853.25 m.
    minute_m = 6371000.0 * math.radians(1 / 60)
    assert path_length_m(np.array([33.0, 33.0 + 1 / 60, math.nan, 33.0 + 2 / 60]), np.array([-118.0] * 4)) == \
        pytest.approx(2 * minute_m)
    lat = np.array([33.0, 33.0 + 1 / 60, 33.0])
    lon = np.array([-118.0, -118.0, -118.0 + 2 / 60])
    d = distance_to_polyline_m(lat, lon, np.array([33.0, 33.0]), np.array([-118.0, -118.0 + 1 / 60]))
    assert d[0] == pytest.approx(0.0, abs=1e-6)
    assert d[1] == pytest.approx(minute_m, rel=1e-6)  # straight above the first vertex
    assert d[2] == pytest.approx(minute_m * math.cos(math.radians(33.0)), rel=1e-3)  # beyond the end: to the end


def test_without_the_planning_forecast_the_deviation_says_why(dive_log, tmp_path, capsys):
    wrong = tmp_path / "other.nc"
    wrong.write_bytes(b"not the forecast")
    code = lrauv(["replay", str(dive_log), "--forecast", str(wrong), "--no-audit"])
    out = capsys.readouterr().out
    assert code == 0
    assert "deviation  unknown: the planning forecast sha256:" in out and "other.nc" in out
    assert "audit" not in out


# -- the audit ------------------------------------------------------------------------------


def test_the_audit_reports_a_tampered_decision(dive_log, tmp_path, capsys):
    decisions = _decisions(dive_log)
    victim = next(n for n, d in enumerate(decisions) if d["action"] == "FORWARD" and n > 10)
    seen = {"n": -1}

    def tamper(topic: str, m: Message) -> bytes:
        if topic != Topic.DECISION.value:
            return m.data
        seen["n"] += 1
        if seen["n"] != victim:
            return m.data
        return json.dumps({**json.loads(m.data), "action": "DRIFT"}).encode()

    bad = rewrite_log(dive_log, tmp_path / "tampered.mcap", tamper)
    result = audit(open_dive(bad))
    assert result.decisions == len(decisions)
    assert [m.time_s for m in result.mismatches] == [decisions[victim]["time_s"]]
    assert result.mismatches[0].logged["action"] == "DRIFT" and result.mismatches[0].audited["action"] == "FORWARD"
    assert lrauv(["replay", str(bad)]) == 1
    assert "1 DIFFERENT" in capsys.readouterr().out


def test_the_audit_notices_a_table_that_is_not_the_one_used(dive_log, tmp_path, synthetic_forecast, demo_plan):
    from planner.contract.settings import Goal
    from tests.support.helpers import plan_for

    lon, lat = start_west_of_goal(demo_plan.table, cells=6)  # the same grid, another goal
    other = plan_for(synthetic_forecast, Goal(lon_deg=lon, lat_deg=lat, depth_m=0.0)).table.to_bytes()
    bad = rewrite_log(dive_log, tmp_path / "other-table.mcap", attachments=lambda a: other)
    result = audit(open_dive(bad))
    assert not result.clean and result.decisions == len(_decisions(dive_log))


def test_the_audit_notices_a_dropped_decision(dive_log, tmp_path):
    count = {"n": 0}

    def drop_one(topic: str, m: Message) -> bytes | None:
        if topic == Topic.DECISION.value:
            count["n"] += 1
            if count["n"] == 50:
                return None
        return m.data

    result = audit(open_dive(rewrite_log(dive_log, tmp_path / "dropped.mcap", drop_one)))
    assert result.mismatches  # every decision after the gap is paired with the wrong one
    assert result.mismatches[0].logged is not None and result.mismatches[0].audited is not None


# -- the audit of a time-varying plan ---------------------------------------------------------------

# The simulated vehicle boots at the forecast's first time (2026-01-15T00:00:00Z) and has a position 41 s
# later. Slices: the demo plan, DRIFT everywhere, the demo plan again. The nearest slice: before the first
# until 120 s, the first until 410 s, DRIFT until 800 s, the demo plan until 900 s, then past the horizon.
SLICE_TIMES = ("2026-01-15T00:02:00Z", "2026-01-15T00:11:40Z", "2026-01-15T00:15:00Z")


@pytest.fixture(scope="module")
def timed_table(demo_plan):
    base = demo_plan.table
    drift = np.full(base.actions.shape, int(Action.UNREACHABLE), dtype=np.uint8)
    drift[base.water] = int(Action.DRIFT)
    return base.with_slices(SLICE_TIMES, np.stack([base.actions, drift, base.actions]))


@pytest.fixture(scope="module")
def timed_dive_log(timed_table, demo_plan, synthetic_forecast, tmp_path_factory) -> Path:
    """A dive from two cells west of the goal to the goal under the time-varying table, in lockstep (the same
    dive on any machine: the slices' times fall where the comment above says)."""
    from tests.support.lockstep import fly

    log = tmp_path_factory.mktemp("timed-dive") / "timed.mcap"
    arrived = fly(timed_table, synthetic_forecast, log, start=start_west_of_goal(demo_plan.table, cells=2),
                  max_vehicle_s=6 * 3600.0)
    assert arrived is not None and arrived > 900.0
    return log


def test_each_decision_records_the_slice_of_the_vehicles_utc_time(timed_dive_log, timed_table):
    dive = load_dive(open_dive(timed_dive_log))
    decisions = _decisions(timed_dive_log)
    assert dive.unix_offset_s is not None and decisions
    for d in decisions:
        current = timed_table.slice_at(d["time_s"] + dive.unix_offset_s)
        assert (d["slice"], d["slice_status"]) == (current.index, current.status), d
    seen = {(d["slice"], d["slice_status"]) for d in decisions}
    assert seen == {(0, "before_start"), (0, "in_horizon"), (1, "in_horizon"), (2, "in_horizon"), (2, "past_horizon")}
    assert {d["action"] for d in decisions if d["slice"] == 1 and d["situation"] == "following"} == {"DRIFT"}
    past = [e for e in dive.events if "past the plan's horizon" in e.text]
    assert [(e.level, e.text) for e in past] == [
        ("warning", "past the plan's horizon: using the last slice's plan (last slice 2026-01-15T00:15:00Z)")]


def test_the_audit_checks_the_slices_of_a_time_varying_plan(timed_dive_log, timed_table, capsys):
    result = audit(open_dive(timed_dive_log))
    decisions = _decisions(timed_dive_log)
    assert result.clean, [m.describe() for m in result.mismatches[:5]]
    assert result.decisions == result.timed == len(decisions)
    crc = f"{timed_table.crc32:08x}"
    assert result.time_varying == (f"{crc}: time-varying, 3 slices from 2026-01-15T00:02:00Z to 2026-01-15T00:15:00Z",)
    assert lrauv(["replay", str(timed_dive_log)]) == 0
    out = capsys.readouterr().out
    words = " ".join(out.split())  # lines over 100 columns wrap under their value
    assert (f"loaded goal 0, table {crc}: time-varying, 3 slices from 2026-01-15T00:02:00Z to"
            " 2026-01-15T00:15:00Z") in words, out
    assert f"{len(decisions):,} decisions under a time-varying table, each slice checked" in words, out


def _with_slice(victim: int, slice_index: int) -> Callable[[str, Message], bytes]:
    seen = {"n": -1}

    def tamper(topic: str, m: Message) -> bytes:
        if topic != Topic.DECISION.value:
            return m.data
        seen["n"] += 1
        return m.data if seen["n"] != victim else json.dumps({**json.loads(m.data), "slice": slice_index}).encode()

    return tamper


def test_a_decision_that_records_another_slice_is_a_difference(timed_dive_log, timed_table, tmp_path):
    decisions = _decisions(timed_dive_log)
    # Slices 0 and 2 have the same actions: the slice alone differs, and the audit goes on from the same helm.
    victim = next(n for n, d in enumerate(decisions) if d["slice"] == 2 and d["situation"] == "following")
    result = audit(open_dive(rewrite_log(timed_dive_log, tmp_path / "slice.mcap", _with_slice(victim, 0))))
    assert [m.time_s for m in result.mismatches] == [decisions[victim]["time_s"]]
    mismatch = result.mismatches[0]
    assert mismatch.logged is not None and mismatch.audited is not None
    assert (mismatch.logged["slice"], mismatch.audited["slice"]) == (0, 2)
    assert mismatch.logged["action"] == mismatch.audited["action"]
    assert "slice=0" in mismatch.describe() and "slice=2" in mismatch.describe()
    # A DRIFT decision that claims the first slice: checked against that slice's plan, which is not DRIFT there.
    demo = timed_table.slice_table(0).actions
    drift = next(n for n, d in enumerate(decisions) if d["slice"] == 1 and d["situation"] == "following"
                 and d["action"] == "DRIFT" and demo[tuple(d["cell"])] != Action.DRIFT)
    result = audit(open_dive(rewrite_log(timed_dive_log, tmp_path / "drift.mcap", _with_slice(drift, 0))))
    first = result.mismatches[0]
    assert first.time_s == decisions[drift]["time_s"] and first.audited is not None
    assert first.audited["slice"] == 1 and first.audited["action"] != "DRIFT"


# -- damaged and foreign files ---------------------------------------------------------------------


def test_a_truncated_log_replays_up_to_the_cut_and_says_where_it_ends(dive_log, tmp_path, capsys):
    data = dive_log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    recovered = recover(cut, tmp_path / "recovered.mcap")
    expected = _decisions(tmp_path / "recovered.mcap")
    assert 0 < len(expected) < len(_decisions(dive_log))
    code = lrauv(["replay", str(cut)])
    out = capsys.readouterr().out
    assert code == 0, out
    words = " ".join(out.split())  # lines over 100 columns wrap under their value
    assert f"TRUNCATED: the writer did not finish (killed?); read up to byte {recovered.truncated_at_byte:,}" in words
    assert f"decisions  {len(expected):,}" in out
    assert f"audit      {len(expected):,} decisions run again" in out and "no difference" in out


def test_a_log_cut_inside_the_header_is_refused_clearly(dive_log, tmp_path, capsys):
    cut = tmp_path / "head.mcap"
    cut.write_bytes(dive_log.read_bytes()[:12])
    assert lrauv(["replay", str(cut)]) == 2
    err = capsys.readouterr().err
    assert str(cut) in err and "Traceback" not in err


@pytest.mark.parametrize("content, words", [
    (b"", "empty file"),
    (b"PK\x03\x04 this is a zip file", "not an MCAP file"),
    (b"\x89MCA", "truncated inside the MCAP magic"),
])
def test_a_file_that_is_not_mcap_gets_a_clear_message(tmp_path, capsys, content, words):
    path = tmp_path / "log.mcap"
    path.write_bytes(content)
    assert lrauv(["replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert words in err and str(path) in err and "Traceback" not in err


def test_a_missing_log_gets_a_clear_message(tmp_path, capsys):
    assert lrauv(["replay", str(tmp_path / "nowhere.mcap")]) == 2
    err = capsys.readouterr().err
    assert "nowhere.mcap: cannot read" in err and "Traceback" not in err


def test_unknown_channels_are_named_and_skipped(dive_log, tmp_path, capsys):
    mixed = rewrite_log(dive_log, tmp_path / "mixed.mcap", extra_channel="/payload/ctd")
    log = open_dive(mixed)
    assert log.unknown["/payload/ctd"] > 0
    code = lrauv(["replay", str(mixed), "--no-audit"])
    out = capsys.readouterr().out
    assert code == 0
    assert f"ignored    channels this version does not read: /payload/ctd ({log.unknown['/payload/ctd']:,} messages)" in out


def test_an_mcap_file_of_someone_else_is_refused_clearly(tmp_path, capsys):
    path = tmp_path / "ros.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start("ros2", "someone else")
        channel = w.register_channel("/tf", "cdr", w.register_schema("tf2_msgs/TFMessage", "ros2msg", b""))
        w.add_message(channel, 1, b"\x00\x01", 1)
        w.finish()
    assert lrauv(["replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert "no lrauv executive channel" in err and "/tf (cdr) (1)" in err and "Traceback" not in err


def test_a_log_without_decisions_is_refused_clearly(tmp_path, capsys):
    path = tmp_path / "idle.mcap"
    with Recorder(path) as rec:
        rec.log(1.0, "info", "autopilot heartbeat received")
    assert lrauv(["replay", str(path)]) == 2
    captured = capsys.readouterr()
    assert "holds no decision" in captured.err and "Traceback" not in captured.err


def test_a_log_from_before_the_audit_says_it_cannot_be_audited(dive_log):
    log = open_dive(dive_log)
    old = dataclasses.replace(log, metadata={k: v for k, v in log.metadata.items() if k != "helm"})
    with pytest.raises(LogError, match="no 'helm' metadata"):
        audit(old)
