"""The MAVLink mission protocol (executive/mission_protocol.py, planner/shore/mission_client.py).

State machines alone first (a virtual clock, no sockets), then over real UDP
on 127.0.0.1: a MissionReceiver behind a pymavlink connection as system 1,
component 191, and `upload_goals` / `download_items` from another one, direct
and through a relay that drops 20 % of packets both ways.
"""

from __future__ import annotations

import os
import random
import select
import socket
import threading
import time
from collections.abc import Callable

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from executive.mission_protocol import (  # noqa: E402
    Ack,
    Count,
    Item,
    MissionDownloader,
    MissionReceiver,
    MissionResult,
    MissionSender,
    RequestItem,
    RequestList,
    StatusText,
    addressed_to,
    dispatch,
    encode,
    item_from_message,
    status_chunks,
)
from executive.mission_protocol import STATUSTEXT_LEN  # noqa: E402
from planner.contract.mission import MissionGoal  # noqa: E402
from planner.shore.mission_client import (  # noqa: E402
    MissionDownloadError,
    MissionUploadError,
    StatusTexts,
    download_items,
    upload_goals,
)
from planner.contract.settings import Goal  # noqa: E402
from planner.contract.mission import goals_to_items, items_to_goals  # noqa: E402
from planner.contract.waypoints import MissionItem  # noqa: E402

GCS = (255, 190)
EXEC = (1, 191)
GOALS = (
    MissionGoal(goal=Goal(lon_deg=-117.8, lat_deg=33.4, depth_m=0.0, radius_cells=1), on_arrival="hold"),
    MissionGoal(goal=Goal(lon_deg=-117.9876543, lat_deg=33.5123456, depth_m=12.3, radius_cells=2), on_arrival="surface"),
    MissionGoal(goal=Goal(lon_deg=-118.2, lat_deg=33.6, depth_m=15.0, radius_cells=0), on_arrival="next"),
)
ITEMS = goals_to_items(GOALS, home_lat_deg=33.45, home_lon_deg=-118.1)


class Judge:
    """An accept hook that records what it saw and refuses with ``refusal`` when set."""

    def __init__(self, refusal: str | None = None, *, strict: bool = True) -> None:
        self.seen: list[tuple[MissionItem, ...]] = []
        self.refusal = refusal
        self.strict = strict

    def __call__(self, items: tuple[MissionItem, ...]) -> str | None:
        self.seen.append(items)
        if self.refusal is not None:
            return self.refusal
        if self.strict:
            items_to_goals(items)  # WaypointError refuses with its MAV_MISSION_RESULT
        return None


# The receiver alone.

def _upload(rx: MissionReceiver, items, now: float = 0.0):  # type: ignore[no-untyped-def]
    out = rx.on_count(GCS, len(items), 0, now)
    for it in items:
        assert out[-1] == RequestItem(GCS, it.seq)
        out = rx.on_item(GCS, it, now)
    return out


def test_receiver_requests_each_item_then_accepts_and_serves_the_list():
    judge = Judge()
    rx = MissionReceiver(judge)
    assert _upload(rx, ITEMS) == (Ack(GCS, MissionResult.ACCEPTED),)
    assert judge.seen == [ITEMS] and rx.items == ITEMS
    assert rx.on_request_list(GCS, 0, 1.0) == (Count(GCS, len(ITEMS)),)
    assert rx.on_request(GCS, 2, 1.0) == (Item(GCS, ITEMS[2]),)
    assert rx.on_request(GCS, len(ITEMS), 1.0) == (Ack(GCS, MissionResult.INVALID_SEQUENCE),)
    assert rx.on_ack(GCS, 0, 0, 1.0) == ()


def test_receiver_re_requests_out_of_order_items_and_drops_duplicates():
    rx = MissionReceiver(Judge())
    rx.on_count(GCS, 4, 0, 0.0)
    assert rx.on_item(GCS, ITEMS[2], 0.01) == (RequestItem(GCS, 0),)  # ahead: dropped, 0 re-requested
    assert rx.on_item(GCS, ITEMS[0], 0.02) == (RequestItem(GCS, 1),)
    assert rx.on_item(GCS, ITEMS[0], 0.03) == ()  # a duplicate: no double request
    assert rx.on_item((9, 9), ITEMS[1], 0.04) == ()  # another peer's item
    assert rx.on_item(GCS, ITEMS[1], 0.05) == (RequestItem(GCS, 2),)


def test_receiver_retries_after_a_timeout_then_cancels():
    judge = Judge()
    rx = MissionReceiver(judge, item_timeout_s=0.25, retries=2)
    rx.on_count(GCS, 4, 0, 0.0)
    rx.on_item(GCS, ITEMS[0], 0.1)
    assert rx.tick(0.3) == ()
    assert rx.tick(0.35) == (RequestItem(GCS, 1),)
    assert rx.tick(0.5) == ()
    assert rx.tick(0.6) == (RequestItem(GCS, 1),)
    out = rx.tick(0.85)
    assert out[-1] == Ack(GCS, MissionResult.OPERATION_CANCELLED)
    assert rx.tick(5.0) == () and rx.on_item(GCS, ITEMS[1], 5.0) == ()  # no upload any more
    assert "no item 1 after 3 requests" in "".join(o.text for o in out[:-1])  # type: ignore[union-attr]
    assert judge.seen == [] and rx.items == ()


def test_receiver_refuses_fence_and_rally_as_unsupported():
    rx = MissionReceiver(Judge())
    out = rx.on_count(GCS, 5, 1, 0.0)
    assert out[-1] == Ack(GCS, MissionResult.UNSUPPORTED, 1)
    assert isinstance(out[0], StatusText) and "mission_type 1" in out[0].text
    assert rx.on_request_list(GCS, 2, 0.0) == (Ack(GCS, MissionResult.UNSUPPORTED, 2),)
    assert rx.on_request(GCS, 0, 0.0, 1) == (Ack(GCS, MissionResult.UNSUPPORTED, 1),)
    assert rx.on_item(GCS, ITEMS[0], 0.0) == ()  # no upload started


def test_a_new_count_restarts_the_upload():
    judge = Judge()
    rx = MissionReceiver(judge)
    rx.on_count(GCS, 4, 0, 0.0)
    rx.on_item(GCS, ITEMS[0], 0.0)
    rx.on_item(GCS, ITEMS[1], 0.0)
    assert rx.on_count(GCS, 2, 0, 0.1) == (RequestItem(GCS, 0),)
    assert _upload(rx, ITEMS[:2], 0.2) == (Ack(GCS, MissionResult.ACCEPTED),)
    assert judge.seen == [ITEMS[:2]]


def test_another_peer_is_denied_while_an_upload_runs_and_too_many_items_is_no_space():
    rx = MissionReceiver(Judge(), max_items=10)
    rx.on_count(GCS, 4, 0, 0.0)
    assert rx.on_count((250, 1), 4, 0, 0.0) == (Ack((250, 1), MissionResult.DENIED),)
    assert rx.on_item(GCS, ITEMS[0], 0.0) == (RequestItem(GCS, 1),)  # GCS's upload goes on
    out = rx.on_count(GCS, 11, 0, 0.1)
    assert out == (StatusText("mission refused: 11 items: at most 10"), Ack(GCS, MissionResult.NO_SPACE))


def test_count_zero_and_clear_all_ask_accept_with_nothing():
    judge = Judge(strict=False)
    rx = MissionReceiver(judge, items=ITEMS)
    assert rx.on_count(GCS, 0, 0, 0.0) == (Ack(GCS, MissionResult.ACCEPTED),)
    assert judge.seen == [()] and rx.items == ()
    judge.refusal = "cannot clear while executing"
    out = rx.on_clear_all(GCS, 0, 0.1)
    assert out == (StatusText("mission refused: cannot clear while executing"), Ack(GCS, MissionResult.ERROR))


def test_wp_clear_is_refused_saying_what_happened_and_what_to_do():
    rx = MissionReceiver(Judge(), items=ITEMS)  # the executive's hook: goals as items_to_goals reads them
    out = rx.on_clear_all(GCS, 0, 0.0)
    text = "".join(o.text for o in out if isinstance(o, StatusText))
    assert text.startswith("mission refused: clearing the goals is not supported: the vehicle keeps its current goals")
    assert "upload a new mission" in text and "to stop, change the autopilot's mode" in text
    assert out[-1] == Ack(GCS, MissionResult.UNSUPPORTED) and rx.items == ITEMS


def test_refusals_keep_the_old_list_and_carry_a_result():
    rx = MissionReceiver(Judge("not today"), items=ITEMS[:2])
    out = _upload(rx, ITEMS)
    assert out == (StatusText("mission refused: not today"), Ack(GCS, MissionResult.ERROR)) and rx.items == ITEMS[:2]
    rx = MissionReceiver(Judge())  # items_to_goals raises WaypointError with a specific result
    bad = (*ITEMS[:2], MissionItem(2, 6, 16, 0, 1, 0.0, 1.5, 0.0, 0.0, 334000000, -1178000000, -1.0))
    out = _upload(rx, bad)
    assert out[-1] == Ack(GCS, MissionResult.INVALID_PARAM2)
    reason = "item 2: param2 (radius_cells) 1.5 is not a whole number >= 0"
    assert "".join(o.text for o in out[:-1]) == f"mission refused: {reason}"  # type: ignore[union-attr]


def test_any_exception_from_accept_is_a_refusal():
    def broken(items: tuple[MissionItem, ...]) -> str | None:
        raise KeyError("boom")

    rx = MissionReceiver(broken, items=ITEMS[:2])
    out = _upload(rx, ITEMS)
    assert out[-1] == Ack(GCS, MissionResult.ERROR) and rx.items == ITEMS[:2]
    assert "".join(o.text for o in out[:-1]) == "mission refused: KeyError: 'boom'"  # type: ignore[union-attr]


def test_a_lost_ack_is_answered_again_when_the_last_item_is_re_sent():
    judge = Judge()
    rx = MissionReceiver(judge)
    _upload(rx, ITEMS)
    assert rx.on_item(GCS, ITEMS[-1], 1.0) == (Ack(GCS, MissionResult.ACCEPTED),)
    assert rx.on_item(GCS, ITEMS[1], 1.0) == ()
    assert len(judge.seen) == 1


def test_status_chunks_split_long_reasons():
    assert status_chunks("short", chunk_id=3) == (StatusText("short"),)
    chunks = status_chunks("x" * 120, chunk_id=3)
    assert [(c.chunk_id, c.chunk_seq, len(c.text)) for c in chunks] == [(3, 0, 50), (3, 1, 50), (3, 2, 20)]
    assert status_chunks("y" * 100, chunk_id=4)[-1] == StatusText("", chunk_id=4, chunk_seq=2)


def _sizes(chunks) -> list[int]:  # type: ignore[no-untyped-def]
    return [len(c.text.encode("utf-8")) for c in chunks]


def test_status_chunks_count_utf8_bytes_and_never_cut_a_character():
    assert status_chunks("é" * 25, chunk_id=1) == (StatusText("é" * 25),)  # 50 bytes: one chunk
    chunks = status_chunks("é" * 30, chunk_id=1)  # 60 bytes
    assert [c.text for c in chunks] == ["é" * 25, "é" * 5] and _sizes(chunks) == [50, 10]
    assert _sizes(status_chunks("é" * 50, chunk_id=1)) == [50, 50, 0]  # an exact multiple: an empty last chunk
    # "€" is 3 bytes: 16 fit in 48, the 17th would straddle; the chunk is filled to 50 with spaces, so that it
    # does not read as the last one, and every chunk is valid UTF-8 on its own.
    chunks = status_chunks("€" * 20, chunk_id=1)
    assert [c.text for c in chunks] == ["€" * 16 + "  ", "€" * 4] and _sizes(chunks) == [50, 12]
    text = "mission refused: " + "ça ne va pas, 北京 " * 9
    chunks = status_chunks(text, chunk_id=9)
    assert all(n == STATUSTEXT_LEN for n in _sizes(chunks)[:-1]) and _sizes(chunks)[-1] < STATUSTEXT_LEN
    assert "".join(c.text for c in chunks).replace(" ", "") == text.replace(" ", "")


def test_chunked_utf8_statustext_is_joined_by_the_ground_side():
    text = "mission refused: " + "ça ne va pas: 12 °C, 北京 " * 5
    for n in (0, 1):  # two texts, through pymavlink's wire format
        texts = StatusTexts()
        for chunk in status_chunks(text if n else text[:33], chunk_id=7):
            texts.add(_through_the_wire(chunk))
        assert texts.lines == [text if n else text[:33]]
    texts = StatusTexts()
    for chunk in status_chunks("x" * 100, chunk_id=8):  # an exact multiple: the empty chunk ends it
        texts.add(_through_the_wire(chunk))
    assert texts.lines == ["x" * 100]


# The ground side alone.

def test_sender_resends_count_on_timeout_then_items_on_request():
    tx = MissionSender(EXEC, timeout_s=1.5, item_timeout_s=0.25, retries=5)
    assert tx.start(ITEMS, 0.0) == (Count(EXEC, len(ITEMS)),)
    assert tx.tick(1.0) == ()
    assert tx.tick(1.6) == (Count(EXEC, len(ITEMS)),)
    assert tx.on_request(0, 2.0) == (Item(EXEC, ITEMS[0]),)
    assert tx.on_request(0, 2.1) == (Item(EXEC, ITEMS[0]),)  # a re-request
    assert tx.on_request(99, 2.1) == ()
    assert tx.on_ack(0, 2.2) == () and not tx.done  # ACCEPTED before every item was asked for: stale
    for it in ITEMS[1:]:
        assert tx.on_request(it.seq, 2.3) == (Item(EXEC, it),)
    tx.on_ack(0, 2.4)
    assert tx.done and tx.result == MissionResult.ACCEPTED and tx.error is None


def test_sender_gives_up_after_retries_and_reports_refusals():
    tx = MissionSender(EXEC, timeout_s=1.0, retries=2)
    tx.start(ITEMS, 0.0)
    sent = [out for t in (1.0, 2.0, 3.0, 4.0) for out in tx.tick(t)]
    assert sent == [Count(EXEC, len(ITEMS))] * 2 and tx.done and tx.result is None
    assert tx.error == "timed out: no MISSION_REQUEST for item 0 after sending it 3 times"
    tx = MissionSender(EXEC)
    tx.start(ITEMS, 0.0)
    tx.on_request(0, 0.1)
    tx.on_ack(int(MissionResult.INVALID_PARAM2), 0.2)
    assert tx.done and tx.result == MissionResult.INVALID_PARAM2
    assert tx.error == "MAV_MISSION_INVALID_PARAM2 (param2 has an invalid value)"


def _run_lossy(seed: int, loss: float) -> tuple[MissionSender, MissionReceiver, MissionDownloader, Judge]:
    """Sender, receiver and downloader exchange value objects over a lossy channel on a virtual clock."""
    rnd = random.Random(seed)
    judge = Judge()
    rx = MissionReceiver(judge, retries=20)
    tx = MissionSender(EXEC, retries=20)
    dl = MissionDownloader(EXEC, retries=20)
    to_rx: list = []  # type: ignore[type-arg]
    to_gcs: list = []  # type: ignore[type-arg]

    def deliver(outs, queue) -> None:  # type: ignore[no-untyped-def]
        queue.extend(o for o in outs if not isinstance(o, StatusText) and rnd.random() >= loss)

    now = 0.0
    deliver(tx.start(ITEMS, now), to_rx)
    for phase, ground in (("upload", tx), ("download", dl)):
        if phase == "download":
            deliver(dl.start(now), to_rx)
        while not ground.done and now < 120:
            now += 0.01
            for o in to_rx:
                handler = {Count: lambda o: rx.on_count(GCS, o.count, 0, now), Item: lambda o: rx.on_item(GCS, o.item, now),
                           RequestList: lambda o: rx.on_request_list(GCS, 0, now),
                           RequestItem: lambda o: rx.on_request(GCS, o.seq, now), Ack: lambda o: rx.on_ack(GCS, o.result, 0, now)}
                deliver(handler[type(o)](o), to_gcs)
            to_rx.clear()
            deliver(rx.tick(now), to_gcs)
            for o in to_gcs:
                if isinstance(o, RequestItem) and ground is tx:
                    deliver(tx.on_request(o.seq, now), to_rx)
                elif isinstance(o, Ack):
                    deliver(ground.on_ack(o.result, now), to_rx)
                elif isinstance(o, Count) and ground is dl:
                    deliver(dl.on_count(o.count, now), to_rx)
                elif isinstance(o, Item) and ground is dl:
                    deliver(dl.on_item(o.item, now), to_rx)
            to_gcs.clear()
            deliver(ground.tick(now), to_rx)
    return tx, rx, dl, judge


@pytest.mark.parametrize("seed", range(40))
def test_upload_and_download_complete_over_a_lossy_channel(seed):  # type: ignore[no-untyped-def]
    tx, rx, dl, judge = _run_lossy(seed, loss=0.3)
    assert tx.result == MissionResult.ACCEPTED, tx.error
    assert judge.seen == [ITEMS] and rx.items == ITEMS
    assert dl.done and dl.error is None and dl.items == ITEMS


# pymavlink encoding.

class _Sink:
    def __init__(self) -> None:
        self.data = b""

    def write(self, data: bytes) -> None:
        self.data += data


def _through_the_wire(out):  # type: ignore[no-untyped-def]
    sink = _Sink()
    tx = mavlink.MAVLink(sink, srcSystem=255, srcComponent=190)
    tx.send(encode(tx, out))
    return mavlink.MAVLink(None).parse_buffer(sink.data)[0]


def test_encode_and_item_from_message_round_trip_through_bytes():
    msg = _through_the_wire(Item(EXEC, ITEMS[2]))
    assert msg.get_type() == "MISSION_ITEM_INT" and (msg.target_system, msg.target_component) == EXEC
    item = item_from_message(msg)
    assert item.z != ITEMS[2].z and item_from_message(msg) == MissionItem(**{**ITEMS[2].__dict__, "z": item.z})
    assert items_to_goals(tuple(item_from_message(_through_the_wire(Item(EXEC, it))) for it in ITEMS)) == GOALS
    assert _through_the_wire(RequestItem(GCS, 4)).get_type() == "MISSION_REQUEST_INT"
    ack = _through_the_wire(Ack(GCS, MissionResult.NO_SPACE, 0))
    assert (ack.get_type(), ack.type) == ("MISSION_ACK", 4)
    assert _through_the_wire(Count(GCS, 7)).count == 7
    assert _through_the_wire(RequestList(EXEC)).get_type() == "MISSION_REQUEST_LIST"
    text = _through_the_wire(StatusText("mission refused: x", chunk_id=2, chunk_seq=1))
    assert (text.text, text.id, text.chunk_seq, text.severity) == ("mission refused: x", 2, 1, 4)


def test_legacy_mission_item_is_accepted_with_float_degrees():
    sink = _Sink()
    gcs = mavlink.MAVLink(sink, srcSystem=255, srcComponent=190)
    it = ITEMS[1]
    gcs.send(gcs.mission_item_encode(1, 191, it.seq, 3, 16, 0, 1, 0, 1, 0, 0, it.lat_deg, it.lon_deg, it.z))
    msg = mavlink.MAVLink(None).parse_buffer(sink.data)[0]
    rx = MissionReceiver(Judge())
    rx.on_count(GCS, 2, 0, 0.0)
    rx.on_item(GCS, ITEMS[0], 0.0)
    assert dispatch(rx, msg, 0.0, system=1, component=191) == (Ack(GCS, MissionResult.ACCEPTED),)
    assert abs(rx.items[1].x_lat_e7 - it.x_lat_e7) < 20 and rx.items[1].frame == 3  # float32 degrees: ~2 m
    assert dispatch(rx, msg, 0.0, system=1, component=1) == ()  # addressed to the autopilot, not us


def test_non_finite_legacy_coordinates_are_refused_not_raised():
    sink = _Sink()
    gcs = mavlink.MAVLink(sink, srcSystem=255, srcComponent=190)
    for lat, lon in ((float("nan"), -117.8), (33.4, float("inf")), (float("-inf"), float("nan")), (3e38, 0.0)):
        gcs.send(gcs.mission_item_encode(1, 191, 1, 3, 16, 0, 1, 0, 1, 0, 0, lat, lon, -1.0))
    rx = MissionReceiver(Judge(), items=ITEMS[:2])
    for msg in mavlink.MAVLink(None).parse_buffer(sink.data):
        item = item_from_message(msg)
        assert -2**31 <= item.x_lat_e7 < 2**31 and -2**31 <= item.y_lon_e7 < 2**31  # still fits MISSION_ITEM_INT
        rx.on_count(GCS, 2, 0, 0.0)
        rx.on_item(GCS, ITEMS[0], 0.0)
        out = dispatch(rx, msg, 0.0, system=1, component=191)
        assert out[-1] in (Ack(GCS, MissionResult.INVALID_PARAM5_X), Ack(GCS, MissionResult.INVALID_PARAM6_Y))
    assert rx.items == ITEMS[:2]


class _Addressed:
    def __init__(self, **targets: int) -> None:
        self.__dict__.update(targets)


def test_addressed_to_treats_zero_as_broadcast():
    assert addressed_to(_Addressed(target_system=1, target_component=191), 1, 191)
    assert addressed_to(_Addressed(target_system=0, target_component=0), 1, 191)
    assert addressed_to(_Addressed(target_system=1, target_component=0), 1, 191)
    assert addressed_to(_Addressed(target_system=0, target_component=191), 1, 191)
    assert addressed_to(_Addressed(), 1, 191)  # no target fields (STATUSTEXT): everyone's
    assert not addressed_to(_Addressed(target_system=2, target_component=191), 1, 191)
    assert not addressed_to(_Addressed(target_system=1, target_component=1), 1, 191)
    assert not addressed_to(_Addressed(target_system=0, target_component=1), 1, 191)


def test_dispatch_answers_broadcast_mission_messages():
    sink = _Sink()
    gcs = mavlink.MAVLink(sink, srcSystem=255, srcComponent=190)
    gcs.send(gcs.mission_request_list_encode(0, 0))
    gcs.send(gcs.mission_request_list_encode(1, 0))
    gcs.send(gcs.mission_request_list_encode(2, 0))
    rx = MissionReceiver(Judge(), items=ITEMS)
    answers = [dispatch(rx, msg, 0.0, system=1, component=191) for msg in mavlink.MAVLink(None).parse_buffer(sink.data)]
    assert answers == [(Count(GCS, len(ITEMS)),), (Count(GCS, len(ITEMS)),), ()]


# Over real UDP.

class Vehicle:
    """A MissionReceiver behind a pymavlink UDP endpoint (system 1, component 191), served by a thread."""

    def __init__(self, accept: Callable, **receiver) -> None:  # type: ignore[type-arg]
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=1, source_component=191)
        self.port = self.conn.port.getsockname()[1]
        self.receiver = MissionReceiver(accept, **receiver)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="mission-vehicle", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            msg = self.conn.recv_match(blocking=True, timeout=0.01)
            now = time.monotonic()
            outs = () if msg is None or msg.get_type() == "BAD_DATA" else dispatch(
                self.receiver, msg, now, system=1, component=191)
            for out in outs + self.receiver.tick(now):
                self.conn.mav.send(encode(self.conn.mav, out))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        assert not self._thread.is_alive()
        self.conn.close()


class LossyRelay:
    """A UDP relay between the ground and the vehicle that drops ``loss`` of the packets each way (seeded)."""

    def __init__(self, vehicle_port: int, *, loss: float, seed: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.vehicle = ("127.0.0.1", vehicle_port)
        self.loss, self.rnd = loss, random.Random(seed)
        self.dropped = self.passed = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._relay, name="lossy-relay", daemon=True)
        self._thread.start()

    def _relay(self) -> None:
        ground = None
        while not self._stop.is_set():
            if not select.select([self.sock], [], [], 0.01)[0]:
                continue
            data, source = self.sock.recvfrom(65536)
            if source != self.vehicle:
                ground = source
            target = ground if source == self.vehicle else self.vehicle
            if target is None or self.rnd.random() < self.loss:
                self.dropped += 1
                continue
            self.passed += 1
            self.sock.sendto(data, target)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        assert not self._thread.is_alive()
        self.sock.close()


@pytest.fixture()
def ground():  # type: ignore[no-untyped-def]
    conns = []

    def connect(port: int):  # type: ignore[no-untyped-def]
        conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=GCS[0], source_component=GCS[1])
        conns.append(conn)
        return conn

    yield connect
    for conn in conns:
        conn.close()


@pytest.fixture()
def vehicle():  # type: ignore[no-untyped-def]
    made = []

    def start(accept: Callable, **receiver) -> Vehicle:  # type: ignore[type-arg]
        made.append(Vehicle(accept, **receiver))
        return made[-1]

    yield start
    for v in made:
        v.close()


@pytest.mark.slow
def test_upload_goals_over_udp_reaches_accept_and_downloads_back(vehicle, ground):  # type: ignore[no-untyped-def]
    judge = Judge()
    v = vehicle(judge)
    conn = ground(v.port)
    upload_goals(conn, ITEMS)
    assert len(judge.seen) == 1 and items_to_goals(judge.seen[0]) == GOALS
    assert items_to_goals(download_items(conn)) == GOALS


@pytest.mark.slow
def test_download_by_hand_with_legacy_mission_request(vehicle, ground):  # type: ignore[no-untyped-def]
    v = vehicle(Judge(), items=ITEMS)
    conn = ground(v.port)
    conn.mav.mission_request_list_send(1, 191)
    count = conn.recv_match(type="MISSION_COUNT", blocking=True, timeout=2)
    assert count is not None and count.count == len(ITEMS)
    got = []
    for seq in range(count.count):
        conn.mav.mission_request_send(1, 191, seq)  # deprecated MISSION_REQUEST: answered with MISSION_ITEM_INT
        msg = conn.recv_match(type=["MISSION_ITEM_INT", "MISSION_ITEM"], blocking=True, timeout=2)
        assert msg is not None and msg.get_type() == "MISSION_ITEM_INT"
        got.append(item_from_message(msg))
    conn.mav.mission_ack_send(1, 191, 0)
    assert items_to_goals(tuple(got)) == GOALS


@pytest.mark.slow
def test_a_refusal_raises_with_the_result_name_and_reason(vehicle, ground):  # type: ignore[no-untyped-def]
    judge = Judge("the vehicle is armed")
    v = vehicle(judge)
    conn = ground(v.port)
    with pytest.raises(MissionUploadError) as info:
        upload_goals(conn, ITEMS)
    assert info.value.result == MissionResult.ERROR
    assert "refused the mission: MAV_MISSION_ERROR" in str(info.value)
    assert str(info.value).endswith(": the vehicle is armed")
    bad = (*ITEMS[:2], MissionItem(2, 6, 22, 0, 1, 0.0, 1.0, 0.0, 0.0, 334000000, -1178000000, -1.0))
    judge.refusal = None  # the goal check alone
    with pytest.raises(MissionUploadError, match=r"MAV_MISSION_UNSUPPORTED \(command is not supported\): "
                                                 r"item 2: command 22 \(NAV_TAKEOFF\) is not a goal"):
        upload_goals(conn, bad)
    assert v.receiver.items == ()


@pytest.mark.slow
def test_upload_and_download_survive_a_lossy_relay(vehicle, ground):  # type: ignore[no-untyped-def]
    judge = Judge()
    v = vehicle(judge, item_timeout_s=0.05, retries=40)
    relay = LossyRelay(v.port, loss=0.2, seed=1)
    goals = GOALS * 5
    try:
        conn = ground(relay.port)
        fast = {"count_timeout_s": 0.15, "item_timeout_s": 0.05, "retries": 40}
        upload_goals(conn, goals_to_items(goals, home_lat_deg=33.45, home_lon_deg=-118.1), **fast)
        assert len(judge.seen) == 1 and items_to_goals(judge.seen[0]) == goals and v.receiver.items == judge.seen[0]
        assert items_to_goals(download_items(conn, **fast)) == goals
        assert relay.dropped > 5, "the relay should have dropped packets"
    finally:
        relay.close()


@pytest.mark.slow
def test_silence_times_out(ground):  # type: ignore[no-untyped-def]
    mute = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    mute.bind(("127.0.0.1", 0))
    try:
        conn = ground(mute.getsockname()[1])
        with pytest.raises(MissionUploadError, match="no MISSION_REQUEST for item 0 after sending it 3 times") as info:
            upload_goals(conn, ITEMS, count_timeout_s=0.05, retries=2)
        assert info.value.result is None
        with pytest.raises(MissionDownloadError, match="no MISSION_COUNT after 3 requests"):
            download_items(conn, count_timeout_s=0.05, retries=2)
    finally:
        mute.close()
