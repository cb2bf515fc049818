"""The autopilot's own failsafes and warnings in ``lrauv replay``: STATUSTEXT by severity, HEARTBEAT alarm states.

Logs are written by the real ``Recorder`` with the autopilot's messages as the executive logs
them (``/mavlink/rx``, component 1), and replayed by the real ``lrauv replay``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from executive.recorder import Recorder, Topic
from planner.cli import main as lrauv
from planner.shore.replay.autopilot import AutopilotReader, FailsafeKind, failsafe_kind
from planner.shore.replay.dive import load_dive
from planner.shore.replay.divelog import open_dive

LOST = "GCS Failsafe: heartbeat lost from 1/191"  # vehicle_sim/autopilot.py
CLEARED = "GCS Failsafe cleared: heartbeat regained"


@pytest.mark.parametrize(("text", "expected"), [
    # ArduSub/failsafe.cpp and AP_BattMonitor, as ArduPilot words them
    ("MYGCS: 255, heartbeat lost", (FailsafeKind.GCS, False)),
    (LOST, (FailsafeKind.GCS, False)),
    (CLEARED, (FailsafeKind.GCS, True)),
    ("Battery 1 is low 14.10V used 9800 mAh", (FailsafeKind.BATTERY, False)),
    ("Battery 2 is critical 13.20V used 12000 mAh", (FailsafeKind.BATTERY, False)),
    ("EKF bad", (FailsafeKind.EKF, False)),
    ("Leak Detected", (FailsafeKind.LEAK, False)),
    ("Lost manual control", (FailsafeKind.PILOT_INPUT, False)),
    ("Internal pressure critical!", (FailsafeKind.INTERNAL_PRESSURE, False)),
    ("Internal temperature critical!", (FailsafeKind.INTERNAL_TEMPERATURE, False)),
    ("Depth sensor error!", (FailsafeKind.DEPTH_SENSOR, False)),
    ("Crash detected", (FailsafeKind.CRASH, False)),
    ("Failsafe terrain triggered", (FailsafeKind.TERRAIN, False)),
    ("Radio Failsafe", (FailsafeKind.RADIO, False)),
    ("Some new failsafe", (FailsafeKind.OTHER, False)),
    ("ArduSub V4.5.0 (abcdef12)", None),
    ("Arming motors", None),
])
def test_failsafe_texts_ardupilot_sends_are_recognised(text, expected):
    assert failsafe_kind(text) == expected


def _decision(t: float) -> dict:
    return {"time_s": t, "lat_deg": 33.4 + 1e-5 * t, "lon_deg": -117.9, "depth_m": 0.0, "heading_deg": 0.0,
            "cell": [0, 3, 4, 0], "situation": "following", "action": "FORWARD", "mode": "GUIDED", "changed": False}


def _rx(name: str, msg_id: int, fields: dict, component: int = 1) -> dict:
    return {"msg_id": msg_id, "name": name, "src_system": 1, "src_component": component, "fields": fields}


def _heartbeat(status: int, *, autopilot: int = 12) -> dict:  # MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_TYPE_SUBMARINE
    return _rx("HEARTBEAT", 0, {"type": 12, "autopilot": autopilot, "base_mode": 209, "custom_mode": 4,
                                "system_status": status, "mavlink_version": 3})


def _text(severity: int, text: str, *, chunk_id: int = 0, seq: int = 0, component: int = 1) -> dict:
    return _rx("STATUSTEXT", 253, {"severity": severity, "text": text, "id": chunk_id, "chunk_seq": seq}, component)


@pytest.fixture()
def noisy_autopilot_log(tmp_path) -> Path:
    """100 s of decisions; the autopilot loses the GCS twice, warns of its battery in two chunks, goes CRITICAL."""
    path = tmp_path / "autopilot.mcap"
    long_text = "Battery 1 is low 14.10V used 9800 mAh; surfacing now " + "and holding at the surface"
    with Recorder(path, metadata={"helm": {"goal_index": "0"}}) as rec:
        for t in range(100):
            status = 5 if 20 <= t < 26 or 60 <= t < 63 else 4  # MAV_STATE_CRITICAL, ACTIVE
            rec.write(Topic.MAVLINK_RX, float(t), _heartbeat(status))
            rec.write(Topic.DECISION, t + 0.5, _decision(t + 0.5))
            if t in (20, 60):
                rec.write(Topic.MAVLINK_RX, t + 0.1, _text(2, LOST))
            if t in (26, 63):
                rec.write(Topic.MAVLINK_RX, t + 0.1, _text(6, CLEARED))
            if t == 40:  # MAVLink 2 chunks: 50 characters, then a shorter last one
                rec.write(Topic.MAVLINK_RX, 40.1, _text(4, long_text[:50], chunk_id=7, seq=0))
                rec.write(Topic.MAVLINK_RX, 40.2, _text(4, long_text[50:], chunk_id=7, seq=1))
            if t == 50:
                rec.write(Topic.MAVLINK_RX, 50.1, _text(6, "ArduSub V4.5.0 (abcdef12)"))
                rec.write(Topic.MAVLINK_RX, 50.2, _text(2, "Leak Detected", component=191))  # not the autopilot
                rec.write(Topic.MAVLINK_RX, 50.3, _heartbeat(6, autopilot=8))  # a companion's: ignored
        rec.write(Topic.MAVLINK_RX, 99.5, _heartbeat(6))  # ends in EMERGENCY
    return path


def test_the_autopilot_log_counts_texts_by_severity_failsafes_and_alarm_states(noisy_autopilot_log):
    a = load_dive(open_dive(noisy_autopilot_log)).autopilot
    assert a.heartbeats == 101
    assert a.by_severity() == {"CRITICAL": 2, "WARNING": 1, "INFO": 3}
    failsafes = a.failsafes()
    assert list(failsafes) == [FailsafeKind.GCS, FailsafeKind.BATTERY]
    assert [t.time_s for t in failsafes[FailsafeKind.GCS]] == pytest.approx([20.1, 60.1])
    assert failsafes[FailsafeKind.BATTERY][0].text.endswith("holding at the surface")  # the chunks joined
    assert a.cleared() == {FailsafeKind.GCS: 2} and a.failsafe_count() == 3
    assert [(p.state, p.start_s, p.end_s, p.ended) for p in a.periods] == [
        ("CRITICAL", 20.0, 26.0, True), ("CRITICAL", 60.0, 63.0, True), ("EMERGENCY", 99.5, 99.5, False)]


def test_replay_summary_and_report_show_the_autopilots_failsafes(noisy_autopilot_log, tmp_path, capsys):
    code = lrauv(["replay", str(noisy_autopilot_log), "--no-audit", "--report", str(tmp_path / "report")])
    out = capsys.readouterr().out
    assert code == 0, out
    words = " ".join(out.split())  # lines over 100 columns wrap under their value
    assert "failsafes 3 from the autopilot, 0 by the executive" in words
    assert "autopilot GCS heartbeat lost: 2 time(s), first at 20.1 s, last at 60.1 s; 2 text(s) said it cleared" in words
    assert "autopilot battery low or critical: 1 time(s), first at 40.2 s" in words
    assert "autopilot HEARTBEAT state CRITICAL: 2 time(s), 9 s in all, the longest 6 s from 20.0 s" in words
    assert "autopilot HEARTBEAT state EMERGENCY: 1 time(s), 0 s in all" in words and "the log ends in it" in words
    assert "autopilot 6 status text(s): CRITICAL 2, WARNING 1, INFO 3" in words
    assert f"       2  CRITICAL  {LOST}" in out
    assert "Leak" not in out  # another component's text is not the autopilot's
    page = (tmp_path / "report" / "index.html").read_text(encoding="utf-8")
    section = page[page.index("Failsafes and autopilot messages"):page.index("<h2>Map</h2>")]
    assert "failsafes  3 from the autopilot, 0 by the executive" in section
    assert f'<tr class="sev2"><td>CRITICAL</td><td>2</td><td>20.1</td><td>60.1</td><td>{LOST}</td></tr>' in section
    assert "6 status texts from the autopilot (STATUSTEXT): CRITICAL 2, WARNING 1, INFO 3" in section


def test_a_cut_chunked_text_is_kept_and_a_log_without_autopilot_messages_says_so(tmp_path):
    reader = AutopilotReader()
    reader.feed(1.0, _text(4, "x" * 50, chunk_id=3))
    assert [t.text for t in reader.result().texts] == ["x" * 50]
    path = tmp_path / "quiet.mcap"
    with Recorder(path) as rec:
        rec.write(Topic.DECISION, 1.0, _decision(1.0))
    a = load_dive(open_dive(path)).autopilot
    assert a.texts == () and a.periods == () and a.heartbeats == 0
