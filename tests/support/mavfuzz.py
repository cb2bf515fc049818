"""MAVLink input fuzzing: corrupt frames, and harnesses that feed them to the executive and the simulator.

Used by tests/closed_loop/test_fuzz_mavlink.py (tens of thousands of frames, and hypothesis)
and bench/bench_fuzz.py (a million). Frames go in as real datagrams over UDP on
127.0.0.1 to the real input paths: ``Executive._drain`` and ``Simulator._poll``,
called in this thread so that a run is deterministic and its effects can be
compared with a run on the clean frames alone.

A frame counts as *invalid* when a fresh MAVLink 2 parser finds no message in it
(bad CRC, cut short, wrong length, garbage). A bit flip that happens to keep the
CRC right (about 1 in 65,536) makes a valid frame with other contents; only
signing can tell it from the original, so such frames are set aside, not counted
as invalid.
"""

from __future__ import annotations

import os
import random
import socket
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from executive.helm import HelmConfig  # noqa: E402
from executive.loop import ExecConfig, Executive  # noqa: E402
from planner.contract.modes import SubMode  # noqa: E402

Corruption = Callable[[bytes, random.Random], bytes]


def flip_bits(frame: bytes, rng: random.Random) -> bytes:
    data = bytearray(frame)
    for _ in range(rng.randint(1, 4)):
        data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    return bytes(data)


def truncate(frame: bytes, rng: random.Random) -> bytes:
    return frame[: rng.randrange(len(frame))]


def extend(frame: bytes, rng: random.Random) -> bytes:
    return frame + rng.randbytes(rng.randint(1, 40))


def garbage(frame: bytes, rng: random.Random) -> bytes:
    data = rng.randbytes(rng.randint(0, 300))
    return b"\xfd" + data if rng.random() < 0.5 else data  # half start like a MAVLink 2 frame


def bad_length(frame: bytes, rng: random.Random) -> bytes:
    data = bytearray(frame)
    if len(data) > 1:
        data[1] = rng.randrange(256)  # payload length field
    return bytes(data)


def splice(frame: bytes, rng: random.Random) -> bytes:
    cut = rng.randrange(1, len(frame))
    return frame[:cut] + frame[rng.randrange(len(frame)):]


CORRUPTIONS: tuple[Corruption, ...] = (flip_bits, truncate, extend, garbage, bad_length, splice)


def parses(data: bytes) -> bool:
    """Whether a fresh parser finds a message in ``data``."""
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    try:
        msgs = parser.parse_buffer(data) or []
    except Exception:  # noqa: BLE001 - pymavlink raises on some garbage even when robust
        return False
    return any(m.get_msgId() >= 0 for m in msgs)


def invalid_frames(valid: Sequence[bytes], rng: random.Random) -> Iterator[bytes]:
    """Endless corrupted copies of ``valid`` frames that no parser accepts."""
    while True:
        data = rng.choice(CORRUPTIONS)(rng.choice(valid), rng)
        if not parses(data):
            yield data


def noisy_stream(valid: Sequence[bytes], rng: random.Random, *, max_noise: int = 3, reorder: float = 0.05,
                 duplicate: float = 0.05) -> tuple[list[bytes], list[bytes]]:
    """``(noisy, clean)``: ``valid`` with invalid copies mixed in, some frames twice or one place late.

    ``clean`` is what ``noisy`` holds of the valid frames, in the same order (a late frame is
    older than the last of its kind, and both runs drop it alike).
    """
    noisy: list[bytes] = []
    clean: list[bytes] = []
    held = None
    for frame in valid:
        for _ in range(rng.randint(0, max_noise)):
            data = rng.choice(CORRUPTIONS)(frame, rng)
            if not parses(data):  # a corruption that kept the CRC right is a valid frame, not noise
                noisy.append(data)
        if held is None and rng.random() < reorder:
            held = frame  # delivered after the next one
            continue
        copies = 2 if rng.random() < duplicate else 1
        noisy.extend([frame] * copies)
        clean.extend([frame] * copies)
        if held is not None:
            noisy.append(held)
            clean.append(held)
            held = None
    return noisy, clean


def autopilot_frames(table: Any, n: int, *, t0_ms: int = 100_000) -> list[bytes]:
    """A valid autopilot stream: armed in GUIDED with a position fix, crossing the grid east at 1 m/s.

    Alternates GLOBAL_POSITION_INT and ATTITUDE at 10 Hz, a HEARTBEAT, EKF_STATUS_REPORT and
    BATTERY_STATUS every second.
    """
    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    lat = table.lat0_deg + 0.5 * table.ny * table.dlat_deg
    frames = []
    t_ms = t0_ms
    for step in range(n):
        t_ms += 100
        if step % 10 == 0:
            frames.append(ap.heartbeat_encode(12, 3, 1 | 128, int(SubMode.GUIDED), 4).pack(ap))
            frames.append(ap.ekf_status_report_encode(0x3FF, 0.1, 0.1, 0.1, 0.1, 0.1).pack(ap))
            frames.append(ap.battery_status_encode(0, 0, 1, 20, [12000] + [65535] * 9, 100, step * 3, -1, 90)
                          .pack(ap))
        lon = table.lon0_deg + (step * 0.1) / (111_320.0 * 0.83)
        lon = table.lon0_deg + (lon - table.lon0_deg) % ((table.nx - 1) * table.dlon_deg)
        if step % 2 == 0:
            frames.append(ap.global_position_int_encode(t_ms, round(lat * 1e7), round(lon * 1e7), -2000, -2000,
                                                        0, 0, 0, 9000).pack(ap))
        else:
            frames.append(ap.attitude_encode(t_ms, 0.0, 0.0, 1.5708, 0.0, 0.0, 0.0).pack(ap))
    return frames


def executive_frames(n: int) -> list[bytes]:
    """Valid frames an executive or ground station sends to the simulator: heartbeats, modes, arming, targets."""
    ex = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    out = []
    for step in range(n):
        kind = step % 5
        if kind == 0:
            out.append(ex.heartbeat_encode(18, 8, 0, 0, 4).pack(ex))
        elif kind == 1:
            out.append(ex.command_long_encode(1, 1, 176, 0, 1, int(SubMode.GUIDED), 0, 0, 0, 0, 0).pack(ex))
        elif kind == 2:
            out.append(ex.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(ex))
        elif kind == 3:
            out.append(ex.set_position_target_local_ned_encode(step, 1, 1, 1, 2503, 0, 0, 0, 0.5, 0.5, 0, 0, 0, 0,
                                                               0.7, 0).pack(ex))
        else:
            out.append(ex.set_position_target_global_int_encode(step, 1, 1, 6, 3579, 0, 0, -5.0, 0, 0, 0, 0, 0, 0,
                                                                 0, 0).pack(ex))
    return out


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


@dataclass
class ExecutiveHarness:
    """A real ``Executive`` whose autopilot is a socket here; datagrams in, commands counted out."""

    executive: Executive
    sink: socket.socket  # the executive's autopilot peer: what it sends arrives here
    address: tuple[str, int]

    @classmethod
    def start(cls, table: Any, log: Path) -> ExecutiveHarness:
        sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sink.bind(("127.0.0.1", 0))
        sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        ex = Executive(ExecConfig(link=f"udpout:127.0.0.1:{sink.getsockname()[1]}", log_path=log,
                                  helm=HelmConfig()), table)
        ex._heartbeat(time.monotonic())  # binds the executive's socket
        sink.recv(65536)
        return cls(ex, sink, ("127.0.0.1", ex.conn.port.getsockname()[1]))

    def feed(self, data: bytes) -> None:
        """One datagram to the executive, handled at once."""
        self.sink.sendto(data, self.address)
        self.executive._drain(time.monotonic())

    def sent(self) -> list[Any]:
        """The messages the executive sent since the last call."""
        parser = mavlink.MAVLink(None)
        out = []
        self.sink.setblocking(False)
        try:
            while True:
                try:
                    out.extend(parser.parse_buffer(self.sink.recv(65536)) or [])
                except BlockingIOError:
                    break
        finally:
            self.sink.setblocking(True)
        return out

    def run(self, frames: Iterable[bytes], *, every: int = 500,
            on_progress: Callable[[int], None] | None = None) -> list[tuple[str, tuple[Any, ...]]]:
        """Feed every frame; the messages the executive sent, as (name, fields less time_boot_ms).

        Heartbeats are left out: they are paced by time (wall time before the autopilot is heard),
        not by the frames, so how many go out depends on the machine's speed.
        """
        sent = []
        for n, data in enumerate(frames):
            self.feed(data)
            if n % every == 0:
                sent.extend(self.sent())
                if on_progress is not None:
                    on_progress(n)
        sent.extend(self.sent())
        return [(m.get_type(), tuple((k, getattr(m, k)) for k in m.get_fieldnames() if k != "time_boot_ms"))
                for m in sent if m.get_type() != "HEARTBEAT"]

    def close(self) -> None:
        self.executive.close()
        self.sink.close()


def autopilot_state(sim: Any) -> dict[str, Any]:
    """What a ``Simulator``'s autopilot would act on next: mode, arming, setpoint, holds, deadlines, failsafe."""
    ap = sim.autopilot
    return {"mode": ap.mode, "armed": ap.armed, "setpoint": ap.setpoint, "guided": ap._guided,
            "hold": ap._hold_depth_m, "deadline": ap._velocity_deadline_s, "heartbeat": ap._last_heartbeat_s,
            "failsafe": ap.failsafe_active}
