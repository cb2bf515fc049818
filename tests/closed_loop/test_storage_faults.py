"""Storage faults on a running executive: control never waits for the log's disk.

The simulator is ``lrauv sim`` (a child process); the executive runs in a thread; a UDP tap
between them forwards everything and parses what the executive sends (heartbeats, targets,
STATUSTEXT). The faults are real, at the OS boundary: the log is a symlink to ``/dev/full``
(every write fails with ENOSPC, as on a full disk) or a named pipe nobody reads (every write
blocks, as on a stalled disk). Uploads go in over the ground-station link as a client sends them.
"""

from __future__ import annotations

import fcntl
import os
import threading
from collections import Counter
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from executive import goal_tables  # noqa: E402
from executive.ftp import ErrorCode, Frame, Opcode  # noqa: E402
from executive.recorder import read_messages  # noqa: E402
from executive.state import Phase  # noqa: E402
from planner.contract.mission import load_mission  # noqa: E402
from planner.shore.ftp_client import put_file  # noqa: E402
from tests.support.helpers import DEMO_MISSION, start_west_of_goal, wait_until  # noqa: E402
from tests.support.live_rig import Live, following  # noqa: E402
from tests.support.loop_rig import ExecThread, Sim  # noqa: E402
from tests.support.udp_relay import LossyRelay  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs Linux /dev/full")]

TARGETS = ("SET_POSITION_TARGET_GLOBAL_INT", "SET_POSITION_TARGET_LOCAL_NED")


class Tap:
    """Forwards UDP between the executive and the simulator; keeps what the executive sent."""

    def __init__(self, sim_port: int) -> None:
        self._mav = mavutil.mavlink.MAVLink(None)
        self._mav.robust_parsing = True
        self.sent: Counter[str] = Counter()
        self.texts: list[tuple[str, Counter[str]]] = []  # each STATUSTEXT, with the counts when it came
        self.relay = LossyRelay(sim_port, heard=self._heard)
        self.port = self.relay.port

    def _heard(self, data: bytes) -> None:
        for msg in self._mav.parse_buffer(data) or []:
            self.sent[msg.get_type()] += 1
            if msg.get_type() == "STATUSTEXT":
                self.texts.append((msg.text, Counter(self.sent)))

    def said(self, start: str) -> Counter[str] | None:
        """The counts of what was sent when a STATUSTEXT starting with ``start`` came; None if none did."""
        return next((counts for text, counts in self.texts if text.startswith(start)), None)


def _fly_with_log(demo_plan, forecast: Path, log: Path, check) -> None:  # type: ignore[no-untyped-def]
    sim = Sim(forecast, start_west_of_goal(demo_plan.table), "--heading-deg", "90")
    tap = Tap(sim.port)
    ex = None
    try:
        ex = ExecThread(demo_plan.table, tap.port, log)
        check(ex.executive, tap)
    finally:
        if ex is not None:
            ex.stop()
            assert not ex.thread.is_alive()  # closing never hangs on the log's disk
        tap.relay.stop()
        sim.stop()


def test_a_full_log_disk_degrades_the_log_and_the_vehicle_keeps_being_commanded(demo_plan, synthetic_forecast,
                                                                                  tmp_path):
    log = tmp_path / "exec.mcap"
    log.symlink_to("/dev/full")  # every write: ENOSPC, "No space left on device"

    def check(executive, tap: Tap) -> None:  # type: ignore[no-untyped-def]
        assert wait_until(lambda: tap.said("log degraded (No space left on device)") is not None, 30), tap.texts
        at = tap.said("log degraded (No space left on device)")
        assert at is not None
        decisions = executive._counts["decisions"]
        # Heartbeats and targets go on after the announcement; the helm keeps deciding.
        assert wait_until(lambda: tap.sent["HEARTBEAT"] >= at["HEARTBEAT"] + 10
                          and sum(tap.sent[t] for t in TARGETS) >= sum(at[t] for t in TARGETS) + 10
                          and executive._counts["decisions"] >= decisions + 20, 30), tap.sent
        assert executive.helm.phase is Phase.RUNNING
        assert executive.recorder.degraded == "No space left on device"
        assert len([t for t, _ in tap.texts if t.startswith("log degraded")]) == 1  # announced once

    _fly_with_log(demo_plan, synthetic_forecast, log, check)


def test_a_stalled_log_disk_never_stalls_control(demo_plan, synthetic_forecast, tmp_path):
    """The log is a pipe nobody reads: once its buffer is full every write blocks, as on a hung disk."""
    log = tmp_path / "exec.mcap"
    os.mkfifo(log)
    reader = os.open(log, os.O_RDONLY | os.O_NONBLOCK)  # so the writer's open does not wait
    capacity = fcntl.fcntl(reader, fcntl.F_SETPIPE_SZ, 4096)
    drained = bytearray()
    drainer = threading.Thread(target=_drain, args=(reader, drained), daemon=True)

    def check(executive, tap: Tap) -> None:  # type: ignore[no-untyped-def]
        # The writer has more of the log than the pipe takes: it is blocked in write().
        assert wait_until(lambda: executive.recorder.bytes_written > capacity, 30)
        sent, decisions = sum(tap.sent[t] for t in TARGETS), executive._counts["decisions"]
        assert wait_until(lambda: sum(tap.sent[t] for t in TARGETS) >= sent + 20
                          and executive._counts["decisions"] >= decisions + 50, 30), tap.sent
        assert executive.helm.phase is Phase.RUNNING
        drainer.start()  # the disk comes back: the writer goes on where it stopped

    try:
        _fly_with_log(demo_plan, synthetic_forecast, log, check)
    finally:
        drainer.join(timeout=10)
        os.close(reader)
    copy = tmp_path / "drained.mcap"
    copy.write_bytes(bytes(drained))
    decisions = [p for _, _, p in read_messages(copy, ["/executive/decision"])]  # whole, with its footer
    assert len(decisions) >= 50


def _drain(fd: int, into: bytearray) -> None:
    os.set_blocking(fd, True)
    while block := os.read(fd, 65536):
        into += block


# -- uploads ------------------------------------------------------------------------------------


@pytest.fixture()
def live(demo_plan, synthetic_forecast, tmp_path):
    table = demo_plan.table
    plan = goal_tables.MissionPlan(goals=load_mission(DEMO_MISSION).goals, tables=(table,))
    rig = Live(synthetic_forecast, plan, tmp_path / "exec.mcap", start=start_west_of_goal(table))
    with following(rig):
        yield rig


def test_a_sparse_write_is_refused_and_announced_and_superseded_forecasts_are_removed(live, tmp_path):
    gcs, texts = live.ground_station(), []
    try:
        # One WriteFile a long way beyond the end of a new file: it once made a 60 MB file from 1 byte.
        _ftp(gcs, texts, 0, Opcode.CREATE_FILE, session=7, data=b"/forecasts/big.nc")
        nak = _ftp(gcs, texts, 1, Opcode.WRITE_FILE, session=7, offset=60_000_000, data=b"x")
        assert (nak.opcode, nak.data[0], nak.data[1]) == (Opcode.NAK, ErrorCode.FAIL_ERRNO, 22)  # EINVAL
        assert _ftp(gcs, texts, 2, Opcode.TERMINATE_SESSION, session=7).opcode == Opcode.NAK
        assert [t for t in texts if t.startswith("upload refused")] == [  # whole, in STATUSTEXT chunks of 50
            "upload refused: /forecasts/big.nc: a write at byte 60000000, beyond its end (0 bytes); no sparse files"]
        # Forecasts, one after another: each newer one supersedes those before it.
        for n in range(4):
            put_file(gcs, b"CDF\x01" + bytes([n]) * 1000, f"/forecasts/issue-{n}.nc", timeout_s=2.0)
    finally:
        gcs.close()
    forecasts = live.executive.uploads.forecasts.directory
    assert not (forecasts / "big.nc").exists()
    on_disk = sorted(p.name for p in forecasts.glob("*.nc"))
    # Kept: the newest, and at most the one a planner job may still be reading; the others are gone.
    assert "issue-3.nc" in on_disk and len(on_disk) <= 2, on_disk
    held = [p for p in live.executive.uploads.ftp.files if p.startswith("/forecasts/")]
    assert sorted(p.rsplit("/", 1)[-1] for p in held) == on_disk  # the FTP store forgets them too


def _ftp(conn, texts: list[str], seq: int, opcode: int, *, session: int = 0, offset: int = 0, data: bytes = b"") -> Frame:  # type: ignore[no-untyped-def]
    payload = Frame(seq, session, opcode, len(data), 0, 0, offset, data).pack()
    conn.mav.file_transfer_protocol_send(0, 1, 191, payload)
    while (reply := conn.recv_match(type=["FILE_TRANSFER_PROTOCOL", "STATUSTEXT"], blocking=True, timeout=10)):
        if reply.get_type() == "FILE_TRANSFER_PROTOCOL":
            return Frame.parse(bytes(reply.payload))
        # Heard while waiting: kept for the test, a long text's later chunks (MAVLink 2 id, chunk_seq) joined to it.
        if getattr(reply, "id", 0) and getattr(reply, "chunk_seq", 0) and texts:
            texts[-1] += reply.text
        else:
            texts.append(reply.text)
    raise AssertionError(f"no FTP reply to {Opcode(opcode).name}")
