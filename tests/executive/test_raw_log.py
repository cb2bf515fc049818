"""The raw MAVLink log keeps what the executive reads; ArduSub's other default streams are only counted.

A scripted autopilot over real UDP sends ArduSub's default telemetry (36 message types at their
SITL rates, ``tests.support.ardusub_streams``) to a deterministic executive; the MCAP log it writes
is read back.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from executive.raw_log import READ_KINDS, REPORT_PERIOD_S, RawFilter
from executive.recorder import read_messages
from tests.support.ardusub_streams import RATES_HZ, frames
from tests.support.scripted_autopilot import Stepped

SECONDS = 150.0  # vehicle seconds of telemetry: two count reports


def test_the_filter_keeps_what_is_read_and_reports_counts_each_period():
    raw = RawFilter(asked=("VFR_HUD",))
    assert raw.keep("GLOBAL_POSITION_INT") and raw.keep("VFR_HUD") and raw.keep("STATUSTEXT")
    assert raw.report(0.0) is None  # the first call starts the period
    for _ in range(3):
        assert not raw.keep("AHRS2")
    assert not raw.keep("NAMED_VALUE_FLOAT")
    assert raw.report(REPORT_PERIOD_S - 1) is None
    assert raw.report(REPORT_PERIOD_S) == "not logged raw (unused autopilot messages) in the last 60 s: AHRS2 3, NAMED_VALUE_FLOAT 1"
    assert raw.report(2 * REPORT_PERIOD_S) is None  # nothing new to report
    assert raw.skipped_total == 4


def test_ardusubs_default_streams_are_counted_not_logged(tmp_path: Path):
    rig = Stepped(None, tmp_path / "raw.mcap")
    try:
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        for n, (_, frame) in enumerate(frames(mav, 10_000, SECONDS)):
            rig.ap.conn.write(frame)
            if n % 20 == 0:  # a datagram at a time through the executive: no socket buffer overflows
                rig.pump()
        rig.pump()
        summary = rig.executive._summary(0.0)
    finally:
        rig.close()
    logged = Counter(p["name"] for _, _, p in read_messages(tmp_path / "raw.mcap", ["/mavlink/rx"]))
    unused = set(RATES_HZ) - READ_KINDS - {name for name, _ in rig.executive.config.helm.rates}
    assert {"NAMED_VALUE_FLOAT", "AHRS2", "SIMSTATE", "RAW_IMU"} <= unused
    assert not unused & set(logged)  # none of the unused streams is in the raw log
    assert logged["GLOBAL_POSITION_INT"] > 0 and logged["ATTITUDE"] > 0 and logged["HEARTBEAT"] > 0
    lines = [p["message"] for _, _, p in read_messages(tmp_path / "raw.mcap", ["/log"])
             if p["message"].startswith("not logged raw")]
    assert len(lines) == 2 and "NAMED_VALUE_FLOAT" in lines[0] and "AHRS2" in lines[0]
    expected = SECONDS * sum(RATES_HZ[k] for k in unused)
    assert 0.9 * expected < summary.messages_not_logged <= expected + len(unused)
