"""Re-streaming a dive to a listener on a real UDP socket on 127.0.0.1, parsed with pymavlink's MAVLink 2 parser.

The dive is the shared real closed-loop log (``dive_log`` in conftest.py);
edge cases use small logs written by the real ``Recorder``. No assertion is
about wall time: pacing is checked through the vehicle time the stream covers.
"""

from __future__ import annotations

import json
import math
import os
import re
import socket
import threading
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from executive import mavlink_bridge as bridge
from planner.shore.replay.divelog import DiveLog, LogMessage, open_dive
from executive.recorder import LogError, Recorder, Topic
from planner.shore.replay.restream import rebuild, restream

FAST = 1e4  # vehicle seconds per wall second: the short dive in well under a second
IN_FLIGHT = 32  # datagrams the sender may be ahead of the listener (far below the socket's buffer)


class Listener:
    """A ground station's UDP port: one MAVLink frame per datagram, parsed (CRC checked) by pymavlink."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.address = f"udpout:127.0.0.1:{self.sock.getsockname()[1]}"
        self.messages: list = []
        self.datagrams = 0
        self.errors: list[str] = []
        self._parser = mavlink.MAVLink(None)  # not robust: a bad CRC raises, and is recorded
        self._seen = threading.Condition()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            try:
                msgs = self._parser.parse_buffer(data) or []
                if len(msgs) != 1:
                    self.errors.append(f"{len(msgs)} messages in one datagram")
                self.messages += msgs
            except mavlink.MAVError as exc:
                self.errors.append(str(exc))
            with self._seen:
                self.datagrams += 1
                self._seen.notify_all()

    def keep_up(self, sent: int) -> None:
        """Back-pressure for the sender (``on_message``): wait while it is more than IN_FLIGHT ahead."""
        with self._seen:
            assert self._seen.wait_for(lambda: self.datagrams >= sent - IN_FLIGHT, timeout=10), "datagrams lost"

    def wait_for(self, n: int) -> None:
        with self._seen:
            assert self._seen.wait_for(lambda: self.datagrams >= n, timeout=10), (self.datagrams, n)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.sock.close()


@pytest.fixture()
def listener():
    lst = Listener()
    yield lst
    lst.close()


@pytest.fixture(scope="module")
def real_log(dive_log) -> DiveLog:
    return open_dive(dive_log)


def _stream(log: DiveLog, listener: Listener, **options):  # type: ignore[no-untyped-def]
    """``restream`` to the listener, never more than IN_FLIGHT datagrams ahead of it; returns (result, sent)."""
    sent: list[LogMessage] = []

    def on_message(m: LogMessage) -> None:
        sent.append(m)
        listener.keep_up(len(sent))

    result = restream(log, listener.address, on_message=on_message, **{"speed": FAST, **options})
    listener.wait_for(result.messages_sent)
    return result, sent


def _telemetry(log: DiveLog, *, executive: bool = True) -> list[LogMessage]:
    """What a ground station should get: the autopilot's messages, and the executive's heartbeat and texts."""
    out = []
    for m in log.messages((Topic.MAVLINK_RX, Topic.MAVLINK_TX)):
        comp, name = m.payload["src_component"], m.payload["name"]
        if (m.topic is Topic.MAVLINK_RX and comp == 1) or (
                executive and comp == 191 and name in ("HEARTBEAT", "STATUSTEXT")):
            out.append(m)
    return out


def _timed(m: LogMessage) -> bool:
    return m.log_time_s != 0.0


def _decoded(record: dict) -> dict:
    """A record less its wire bytes: the re-stream numbers each source's frames again (a new sequence, CRC)."""
    return {k: v for k, v in record.items() if k != "frame"}


# -- the real dive ---------------------------------------------------------------------------------


@pytest.mark.slow
def test_every_message_arrives_as_logged_from_its_source(real_log, listener):
    expected = _telemetry(real_log)
    names = {m.payload["name"] for m in expected}
    assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "SYS_STATUS", "BATTERY_STATUS", "SYSTEM_TIME"} <= names
    result, sent = _stream(real_log, listener)
    assert result.skipped == {} and listener.errors == []
    assert result.messages_sent == len(expected) == len(listener.messages) == len(sent)
    # Each message, rebuilt from the log and parsed off the wire, reads back as the very record it was
    # (fields, float bits, text, arrays, extension fields, source system and component), in file order.
    assert [_decoded(bridge.describe(msg)) for msg in listener.messages] == [_decoded(m.payload) for m in expected]
    for kind in ("GLOBAL_POSITION_INT", "ATTITUDE"):
        got = [msg for msg in listener.messages if msg.get_type() == kind]
        assert len(got) == sum(m.payload["name"] == kind for m in expected) > 10
        assert {(msg.get_srcSystem(), msg.get_srcComponent()) for msg in got} == {(1, 1)}
    # One sequence counter per source: 0, 1, 2, ... modulo 256 for the autopilot and for the executive.
    for source in ((1, 1), (1, 191)):
        seqs = [msg.get_seq() for msg in listener.messages if (msg.get_srcSystem(), msg.get_srcComponent()) == source]
        assert seqs == [n % 256 for n in range(len(seqs))], source
    # Paced on log time: the stream covered the dive's span of vehicle time (no reboot in this dive).
    times = [m.log_time_s for m in expected if _timed(m)]
    assert result.vehicle_s == pytest.approx(max(times) - times[0])


@pytest.mark.slow
def test_the_executives_messages_can_be_left_out(real_log, listener):
    result, _ = _stream(real_log, listener, executive=False)
    assert result.messages_sent == len(_telemetry(real_log, executive=False)) == len(listener.messages)
    assert {msg.get_srcComponent() for msg in listener.messages} == {1}


@pytest.mark.slow
def test_stop_ends_the_stream(real_log, listener):
    stop = threading.Event()
    sent: list[LogMessage] = []

    def on_message(m: LogMessage) -> None:
        sent.append(m)
        if len(sent) == 25:
            stop.set()

    result = restream(real_log, listener.address, speed=FAST, stop=stop, on_message=on_message)
    listener.wait_for(25)
    assert result.messages_sent == 25 == len(sent)
    expected = [_decoded(m.payload) for m in _telemetry(real_log)[:25]]
    assert [_decoded(bridge.describe(msg)) for msg in listener.messages] == expected


@pytest.mark.slow
def test_a_stop_set_before_the_start_sends_nothing(real_log, listener):
    stop = threading.Event()
    stop.set()
    result = restream(real_log, listener.address, speed=1.0, stop=stop)
    assert result.messages_sent == 0 and result.vehicle_s == 0.0


# -- small logs ------------------------------------------------------------------------------------


def _record(msg, *, system: int = 1, component: int = 1) -> dict:  # type: ignore[no-untyped-def]
    """The ``/mavlink/*`` record of a pymavlink message from (system, component), as the executive logs it."""
    mav = mavlink.MAVLink(None, srcSystem=system, srcComponent=component)
    parsed = mavlink.MAVLink(None).parse_buffer(msg.pack(mav))[0]
    return bridge.describe(parsed)


def _position(t_ms: int, lat: int = 334_000_000) -> dict:
    return _record(mavlink.MAVLink_global_position_int_message(t_ms, lat, -1_178_000_000, -2500, -2500, 10, -5, 0,
                                                               9000))


def _heartbeat(component: int = 1) -> dict:
    return _record(mavlink.MAVLink_heartbeat_message(12, 3, 1, 19, 4, 3), component=component)


def _write_log(path: Path, records: list[tuple[Topic, float, dict]]) -> DiveLog:
    with Recorder(path) as rec:
        for topic, t, payload in records:
            rec.write(topic, t, payload)
    return open_dive(path)


@pytest.mark.slow
def test_log_time_going_back_is_sent_at_once_and_a_reboot_restarts_the_pace(tmp_path, listener):
    rx, tx = Topic.MAVLINK_RX, Topic.MAVLINK_TX
    log = _write_log(tmp_path / "reboot.mcap", [
        (tx, 0.0, _heartbeat(191)),  # before the executive's clock knew vehicle time
        (rx, 100.0, _position(100_000)),
        (rx, 101.0, _position(101_000)),
        (rx, 100.5, _heartbeat()),  # behind the newest time (clock extrapolation): due at once
        (rx, 102.0, _position(102_000)),
        (rx, 1.0, _position(1_000)),  # the autopilot rebooted
        (rx, 2.0, _position(2_000)),
        (rx, 3.0, _record(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), system=255, component=190)),  # a GCS
        (tx, 3.0, _record(mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0), component=191)),
    ])
    result, sent = _stream(log, listener, speed=1000.0)
    assert [m.log_time_s for m in sent] == [0.0, 100.0, 101.0, 100.5, 102.0, 1.0, 2.0]  # file order; no GCS, no command
    assert result.vehicle_s == pytest.approx((102.0 - 100.0) + (2.0 - 1.0))
    assert [_decoded(bridge.describe(msg)) for msg in listener.messages] == [_decoded(m.payload) for m in sent]


@pytest.mark.slow
def test_records_that_cannot_be_rebuilt_are_skipped_by_name(tmp_path, listener):
    broken = _position(2_000)
    broken["fields"]["lat"] = None  # an integer field lost
    too_far = _position(3_000)
    too_far["fields"]["lat"] = 2**40  # does not fit an int32
    log = _write_log(tmp_path / "broken.mcap", [
        (Topic.MAVLINK_RX, 1.0, _position(1_000)),
        (Topic.MAVLINK_RX, 2.0, broken),
        (Topic.MAVLINK_RX, 3.0, too_far),
        (Topic.MAVLINK_RX, 3.5, {"msg_id": 59999, "name": "FROM_ANOTHER_DIALECT", "src_system": 1,
                                 "src_component": 1, "fields": {}}),
        (Topic.MAVLINK_RX, 4.0, _position(4_000)),
    ])
    result, _ = _stream(log, listener)
    assert result.skipped == {"GLOBAL_POSITION_INT": 2, "FROM_ANOTHER_DIALECT": 1}
    assert [msg.time_boot_ms for msg in listener.messages] == [1_000, 4_000]


@pytest.mark.slow
def test_a_status_text_logged_for_both_links_goes_out_once(tmp_path, listener):
    text = _record(mavlink.MAVLink_statustext_message(4, b"link lost: no telemetry for 30 s", 0, 0), component=191)
    log = _write_log(tmp_path / "texts.mcap", [
        (Topic.MAVLINK_TX, 5.0, text),  # to the autopilot
        (Topic.MAVLINK_TX, 5.0, text),  # the same event to the ground station (--gcs)
        (Topic.MAVLINK_TX, 9.0, text),  # said again later: a new event
    ])
    result, sent = _stream(log, listener)
    assert result.messages_sent == 2 and [m.log_time_s for m in sent] == [5.0, 9.0]
    assert [msg.text for msg in listener.messages] == ["link lost: no telemetry for 30 s"] * 2


@pytest.mark.parametrize("speed", [0.0, -10.0, math.nan, math.inf])
def test_a_bad_speed_is_refused_naming_the_option(tmp_path, speed):
    log = _write_log(tmp_path / "one.mcap", [(Topic.MAVLINK_RX, 1.0, _heartbeat())])
    with pytest.raises(LogError, match="--speed"):
        restream(log, "udpout:127.0.0.1:9", speed=speed)


def test_an_address_that_cannot_be_opened_is_refused_naming_it(tmp_path):
    log = _write_log(tmp_path / "one.mcap", [(Topic.MAVLINK_RX, 1.0, _heartbeat())])
    with pytest.raises(LogError, match=re.escape("udpout:127.0.0.1:nope")):
        restream(log, "udpout:127.0.0.1:nope")


@pytest.mark.parametrize("msg", [
    mavlink.MAVLink_statustext_message(4, b"autopilot: depth hold lost", 7, 1),
    mavlink.MAVLink_battery_status_message(0, 1, 3, 32767, [16000] + [65535] * 9, 50, 31, 18, 97, 3600, 1,
                                           [1, 2, 3, 4], 0, 0),
    mavlink.MAVLink_attitude_message(1500, math.nan, 0.1, -3.0, 0.0, 0.0, 0.25),
    mavlink.MAVLink_sys_status_message(1, 2, 3, 500, 16000, 50, 97, 0, 0, 0, 0, 0, 0, 5, 6, 7),
], ids=lambda m: m.get_type())
def test_rebuild_undoes_describe_through_the_log(tmp_path, msg):
    """Packed, parsed, described, written as JSON by the Recorder and read back: rebuilt to the same frame."""
    record = _record(msg)
    log = _write_log(tmp_path / "one.mcap", [(Topic.MAVLINK_RX, 1.5, record)])
    (logged,) = list(log.messages([Topic.MAVLINK_RX]))
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    assert rebuild(logged.payload).pack(mav) == msg.pack(mavlink.MAVLink(None, srcSystem=1, srcComponent=1))


def test_rebuild_gives_extension_fields_their_defaults_when_an_older_log_lacks_them():
    record = _record(mavlink.MAVLink_sys_status_message(1, 2, 3, 500, 16000, 50, 97, 0, 0, 0, 0, 0, 0))
    fields = json.loads(json.dumps(record["fields"]))
    for name in mavlink.MAVLink_sys_status_message.fieldnames[-3:]:  # the *_extended extensions
        del fields[name]
    msg = rebuild({**record, "fields": fields})
    assert msg.onboard_control_sensors_present_extended == 0 and msg.voltage_battery == 16000
