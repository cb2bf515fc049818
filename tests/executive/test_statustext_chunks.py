"""The executive's warnings as STATUSTEXT: MAVLink 2 chunks (common.xml STATUSTEXT ``id``, ``chunk_seq``) for long
texts, one message with id 0 for short ones, read by a pymavlink ground station over a real UDP socket."""

from __future__ import annotations

import os
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from executive import mavlink_bridge as bridge  # noqa: E402
from executive.state import Event  # noqa: E402
from planner.shore.mission_client import StatusTexts  # noqa: E402

REFUSAL = ("refused /tables/goal-0.lrpt: /tables/goal-0.lrpt: CRC32 mismatch: stored 0x1c2d3e4f, computed "
           "0x5a6b7c8d; the file is corrupt; the running plan goes on")


class Link:
    """A ground station listening on an ephemeral port, and the executive's encoder sending to it."""

    def __init__(self) -> None:
        self.gcs = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, source_component=190)
        port = self.gcs.port.getsockname()[1]
        self.vehicle = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=191)

    def send(self, event: Event) -> list[Any]:
        msgs = bridge.statustexts(self.vehicle.mav, event)
        for msg in msgs:
            self.vehicle.mav.send(msg)
        return msgs

    def receive(self, n: int) -> list[Any]:
        got = []
        while len(got) < n:
            msg = self.gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=5.0)
            assert msg is not None, f"{len(got)} of {n} STATUSTEXT arrived"
            got.append(msg)
        return got

    def close(self) -> None:
        self.vehicle.close()
        self.gcs.close()


def test_a_long_refusal_arrives_whole_in_chunks_and_a_short_text_in_one_message():
    link = Link()
    try:
        sent = link.send(Event("warning", REFUSAL))
        assert len(REFUSAL) == 151 and len(sent) == 4  # 50 + 50 + 50 + 1 bytes
        texts = StatusTexts()
        for msg in link.receive(4):
            texts.add(msg)
        assert texts.lines == [REFUSAL]
        assert len({c.id for c in sent}) == 1 and sent[0].id != 0
        assert [c.chunk_seq for c in sent] == [0, 1, 2, 3]
        assert all(c.severity == bridge.mavlink.MAV_SEVERITY_WARNING for c in sent)

        link.send(Event("error", "link lost: no autopilot heartbeat"))
        (got,) = link.receive(1)
        assert (got.id, got.chunk_seq, got.text) == (0, 0, "link lost: no autopilot heartbeat")
        assert got.severity == bridge.mavlink.MAV_SEVERITY_ERROR
    finally:
        link.close()


def test_chunk_ids_count_per_link_and_a_text_beyond_four_chunks_is_cut():
    one, other = Link(), Link()
    try:
        first = [m.id for m in one.send(Event("warning", REFUSAL))]
        second = [m.id for m in one.send(Event("warning", REFUSAL))]
        elsewhere = [m.id for m in other.send(Event("warning", REFUSAL))]
        assert len(set(first)) == len(set(second)) == 1 and first[0] != second[0]  # a new text, a new id
        assert elsewhere[0] == first[0]  # the other link counts its own ids

        long = "refused table 0badf00d: " + "the goal is 3.2 km from the running goal; " * 8
        msgs = one.send(Event("warning", long))
        assert len(msgs) == bridge.MAX_STATUSTEXT_CHUNKS
        texts = StatusTexts()
        for msg in one.receive(2 * 4 + len(msgs))[2 * 4:]:  # after the two refusals
            texts.add(msg)
        (joined,) = texts.lines
        assert joined.endswith("...") and long.startswith(joined[:-3]) and len(joined.encode()) < 200
    finally:
        one.close()
        other.close()
