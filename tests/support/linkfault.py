"""A UDP proxy between the executive and the simulated vehicle that damages the link on purpose.

::

    executive --udpout--> [front]  LinkFaultProxy  [back] --> simulator (127.0.0.1:sim_port)
              <---------- down (telemetry)          <----------
              ----------> up (commands, heartbeats) ---------->

Both sockets are bound to 127.0.0.1 on ephemeral ports; the executive connects to
``proxy.port`` instead of the simulator's. One thread moves the datagrams. Each
direction has its own ``Faults`` and its own seeded ``random.Random``, so a run's
fault sequence depends only on the seed and on the order of that direction's
datagrams. Every datagram goes through, in this order:

1. outage: a cut direction drops everything (``cut``, or ``outage`` for a span of time);
2. filter: a datagram carrying a MAVLink message named in ``drop_types`` is dropped;
3. loss: dropped with probability ``loss``;
4. duplication: sent twice with probability ``duplicate``;
5. latency: while a latency spike is on, the datagram is held for ``spike_s`` more;
   a direction is a FIFO queue, so a datagram never overtakes an earlier one and the
   backlog of a spike drains in order when it ends;
6. reordering: with probability ``reorder`` the datagram is held back and sent right
   after the next datagram that gets through, so those two arrive swapped.

Time base: vehicle time. The executive's timeouts (link loss 30 s), ArduSub's (GCS
heartbeat failsafe 5 s, velocity targets 3 s) and the executive's refresh periods are
all in vehicle seconds, and the simulator runs at a speedup over wall time. A "2 s
latency spike" means 2 s of the vehicle's clock, so every time here (spike delay,
spike duration, time between spikes, outages, the times stamped on what the proxy
overhears) is in vehicle seconds. The proxy reads the vehicle's clock from the
``time_boot_ms`` of the simulator's telemetry as it arrives, before any fault is
applied (the proxy stands next to the vehicle), and extrapolates between two
timestamps at the nominal ``speedup`` (never going back), by at most ``AHEAD_S`` (3 s)
past the newest, or as far as the latest due time of a datagram it holds: a simulator
in lockstep stops its clock while it waits for the executive, and the proxy's clock
must not run on without it (what a latency spike holds is still released). So a fault lasts the
vehicle time asked for even when the simulator falls behind its speedup on a loaded
machine; converting with the nominal speedup alone would shorten it. Before the
first timestamp, vehicle time is wall time since the proxy started times
``speedup``. What the clock cannot remove is the proxy thread's own scheduling
delay on a busy machine: at a speedup of 400, 5 ms of wall time is 2 s of vehicle
time, so tests whose outcome hinges on a short outage's length use a lower speedup.

The proxy also listens, as a ground station would: the simulator's HEARTBEAT modes
and STATUSTEXTs (``modes``, ``texts``), and the executive's heartbeat status, commands
and mode requests (``exec_status``, ``commands``, ``mode_requests``), each stamped with
vehicle time, and counts every message type each way (``heard``), whether or not the
datagram is then dropped. ``close()`` stops the thread and closes both sockets.
"""

from __future__ import annotations

import math
import os
import random
import select
import socket
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, fields
from typing import Literal, Self

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

Direction = Literal["up", "down"]  # up: executive -> vehicle; down: vehicle -> executive
_POLL_WALL_S = 0.02  # longest select wait (wall); also the resolution of spikes and outages when idle
_VEHICLE_COMPONENT = 1  # the autopilot (MAV_COMP_ID_AUTOPILOT1)
_EXECUTIVE_COMPONENT = 191  # MAV_COMP_ID_ONBOARD_COMPUTER
_DO_SET_MODE = 176
AHEAD_S = 3.0  # vehicle seconds the clock may run past the newest timestamp while nothing is held


@dataclass(frozen=True, kw_only=True)
class Faults:
    """What one direction does to its datagrams; probabilities per datagram, times in vehicle seconds."""

    loss: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    spike_s: float = 0.0  # extra delay of every datagram during a latency spike
    spike_every_s: float = 0.0  # mean time from the end of a spike to the start of the next; 0: no spikes
    spike_duration_s: float = 0.0  # how long each spike lasts
    drop_types: frozenset[str] = frozenset()  # MAVLink message names (e.g. "COMMAND_LONG") never let through

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder"):
            value = getattr(self, name)
            if not (0.0 <= value <= 1.0):
                raise ValueError(f"Faults.{name}: expected a probability 0..1; got {value!r}")
        for name in ("spike_s", "spike_every_s", "spike_duration_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"Faults.{name}: expected vehicle seconds >= 0; got {value!r}")
        if self.spike_every_s > 0.0 and not (self.spike_s > 0.0 and self.spike_duration_s > 0.0):
            raise ValueError("Faults: spike_every_s needs spike_s and spike_duration_s > 0; "
                             f"got spike_s={self.spike_s!r}, spike_duration_s={self.spike_duration_s!r}")


@dataclass
class Counters:
    """What one direction did (datagrams)."""

    received: int = 0
    forwarded: int = 0  # sent on, duplicates included
    dropped: int = 0  # by ``loss``
    filtered: int = 0  # by ``drop_types``
    cut: int = 0  # by an outage
    duplicated: int = 0  # extra copies sent
    reordered: int = 0  # held back and sent after the next one
    delayed: int = 0  # held by a latency spike
    spikes: int = 0  # latency spikes started
    send_errors: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class _Lane:
    """One direction: its faults, random numbers, FIFO queue and counters."""

    def __init__(self, faults: Faults, seed: int) -> None:
        self.faults = faults
        self.rng = random.Random(seed)
        self.counters = Counters()
        self.queue: deque[tuple[float, bytes]] = deque()  # (due vehicle time, datagram), due non-decreasing
        self.last_due_s = -math.inf
        self.held: list[bytes] = []  # reordering: the copies of a datagram waiting for the next one
        self.cut = False
        self.outage_until_s: float | None = None
        self.spike_until_s = -math.inf  # the current spike (scheduled or asked for) ends here
        self.spike_delay_s = 0.0
        self.next_spike_s: float | None = None  # start of the next scheduled spike

    def schedule(self, now_s: float) -> None:
        """Start the scheduled spike when due, and draw when the one after starts."""
        f = self.faults
        if f.spike_every_s <= 0.0:
            self.next_spike_s = None
            return
        if self.next_spike_s is None:
            self.next_spike_s = now_s + self.rng.uniform(0.5, 1.5) * f.spike_every_s
        if now_s >= self.next_spike_s:
            self.spike_until_s = now_s + f.spike_duration_s
            self.spike_delay_s = f.spike_s
            self.counters.spikes += 1
            self.next_spike_s = self.spike_until_s + self.rng.uniform(0.5, 1.5) * f.spike_every_s

    def blocked(self, now_s: float) -> bool:
        if self.outage_until_s is not None and now_s >= self.outage_until_s:
            self.outage_until_s = None
        return self.cut or self.outage_until_s is not None


class LinkFaultProxy:
    """UDP proxy executive <-> simulator on 127.0.0.1 with per-direction faults in vehicle time."""

    def __init__(self, sim_port: int, *, speedup: float, seed: int = 0, up: Faults | None = None,
                 down: Faults | None = None, host: str = "127.0.0.1") -> None:
        if not (math.isfinite(speedup) and speedup > 0.0):
            raise ValueError(f"LinkFaultProxy: speedup must be > 0; got {speedup!r}")
        self.speedup = speedup
        self.sim_addr = (host, sim_port)
        self.exec_addr: tuple[str, int] | None = None
        self._lanes = {"up": _Lane(up or Faults(), seed * 2 + 1), "down": _Lane(down or Faults(), seed * 2 + 2)}
        # What the proxy overhears, stamped with vehicle time.
        self.modes: list[tuple[float, int]] = []  # the simulator's HEARTBEAT custom_mode
        self.texts: list[tuple[float, str]] = []  # the simulator's STATUSTEXT
        self.exec_status: list[tuple[float, int]] = []  # the executive's HEARTBEAT system_status
        self.commands: list[tuple[float, int]] = []  # COMMAND_LONG command ids the executive sent
        self.mode_requests: list[tuple[float, int]] = []  # DO_SET_MODE / SET_MODE custom modes the executive sent
        self._heard: dict[str, Counter[str]] = {"up": Counter(), "down": Counter()}
        self.outages: list[list] = []  # [start, end or None while open, up, down], vehicle seconds
        self._lock = threading.Lock()
        self._wall0 = time.monotonic()
        self._clock_s: float | None = None  # last time_boot_ms seen, vehicle seconds
        self._clock_wall = self._wall0
        self._now_s = 0.0  # never goes back
        self._parsers = {d: self._parser() for d in ("up", "down")}
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # the executive talks to this
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # this talks to the simulator
        try:
            self.front.bind((host, 0))
            self.back.bind((host, 0))
        except OSError:
            self.front.close()
            self.back.close()
            raise
        self.port = self.front.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="link-fault-proxy", daemon=True)
        self._thread.start()

    # -- control (any thread) -------------------------------------------------------------------

    def set_faults(self, *, up: Faults | None = None, down: Faults | None = None) -> None:
        """Replace a direction's faults from now on; a new spike schedule is drawn."""
        with self._lock:
            for name, faults in (("up", up), ("down", down)):
                if faults is not None:
                    lane = self._lanes[name]
                    lane.faults = faults
                    lane.next_spike_s = None

    def cut(self, *, up: bool, down: bool) -> None:
        """Cut (True) or restore (False) each direction until told otherwise."""
        with self._lock:
            now = self.vehicle_s()
            for name, on in (("up", up), ("down", down)):
                lane = self._lanes[name]
                if on and not lane.cut:
                    self.outages.append([now, None, name == "up", name == "down"])
                elif lane.cut and not on:
                    for record in self.outages:
                        if record[1] is None and record[2 if name == "up" else 3]:
                            record[1] = now
                lane.cut = on

    def outage(self, duration_s: float, *, up: bool = True, down: bool = True) -> None:
        """Cut the chosen directions for ``duration_s`` vehicle seconds from now."""
        with self._lock:
            now = self.vehicle_s()
            for name, on in (("up", up), ("down", down)):
                if on:
                    self._lanes[name].outage_until_s = now + duration_s
            self.outages.append([now, now + duration_s, up, down])

    def spike(self, duration_s: float, delay_s: float, *, up: bool = True, down: bool = True) -> None:
        """One latency spike now: for ``duration_s`` vehicle seconds, datagrams are held ``delay_s`` more."""
        with self._lock:
            now = self.vehicle_s()
            for name, on in (("up", up), ("down", down)):
                if on:
                    lane = self._lanes[name]
                    lane.spike_until_s = now + duration_s
                    lane.spike_delay_s = delay_s
                    lane.counters.spikes += 1

    # -- what tests read ---------------------------------------------------------------------------

    def counters(self, direction: Direction) -> Counters:
        return self._lanes[direction].counters

    def vehicle_s(self, wall: float | None = None) -> float:
        """Vehicle time now, from the simulator's ``time_boot_ms`` (see the module docstring)."""
        wall = time.monotonic() if wall is None else wall
        if self._clock_s is None:
            now = (wall - self._wall0) * self.speedup
        else:
            limit = AHEAD_S
            for lane in self._lanes.values():
                try:  # the latest due time of what a lane holds (the proxy's thread may empty it meanwhile)
                    limit = max(limit, lane.queue[-1][0] - self._clock_s)
                except IndexError:
                    pass
            now = self._clock_s + min(max(0.0, wall - self._clock_wall) * self.speedup, limit)
        self._now_s = max(self._now_s, now)
        return self._now_s

    def heard(self, direction: Direction) -> Counter[str]:
        """How many messages of each type came in from that direction's sender so far (a copy)."""
        with self._lock:
            return Counter(self._heard[direction])

    def mode(self) -> int | None:
        """The simulator's mode in its latest HEARTBEAT (as sent, before any fault)."""
        return self.modes[-1][1] if self.modes else None

    def close(self) -> None:
        """Stop the thread and close both sockets; datagrams still queued are dropped. Safe to call twice."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self.front.close()
        self.back.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the thread --------------------------------------------------------------------------------

    def _run(self) -> None:
        socks = [self.front, self.back]
        while not self._stop.is_set():
            ready, _, _ = select.select(socks, [], [], self._wait_wall())
            for sock in ready:
                try:
                    data, addr = sock.recvfrom(65536)
                except OSError:  # ICMP port unreachable from a peer that went away
                    continue
                with self._lock:
                    if sock is self.front:
                        self.exec_addr = addr
                        self._enter("up", data, self._overhear("up", data))
                    else:
                        self._enter("down", data, self._overhear("down", data))
            with self._lock:
                self._release()

    def _wait_wall(self) -> float:
        with self._lock:
            now = self.vehicle_s()
            wait = _POLL_WALL_S
            for lane in self._lanes.values():
                if lane.queue:
                    wait = min(wait, max(0.0, (lane.queue[0][0] - now) / self.speedup))
            return wait

    def _enter(self, direction: Direction, data: bytes, types: tuple[str, ...]) -> None:
        lane = self._lanes[direction]
        c = lane.counters
        now = self.vehicle_s()
        c.received += 1
        lane.schedule(now)
        if lane.blocked(now):
            c.cut += 1
            return
        f = lane.faults
        if f.drop_types and not f.drop_types.isdisjoint(types):
            c.filtered += 1
            return
        rng = lane.rng
        if rng.random() < f.loss:
            c.dropped += 1
            return
        copies = 2 if rng.random() < f.duplicate else 1
        c.duplicated += copies - 1
        due = now
        if now < lane.spike_until_s:
            due += lane.spike_delay_s
            c.delayed += 1
        due = max(due, lane.last_due_s)  # FIFO: no overtaking
        lane.last_due_s = due
        if not lane.held and rng.random() < f.reorder:
            lane.held = [data] * copies  # goes out right after the next datagram
            c.reordered += 1
            return
        for packet in [data] * copies + lane.held:
            lane.queue.append((due, packet))
        lane.held = []

    def _release(self) -> None:
        now = self.vehicle_s()
        for direction, lane in self._lanes.items():
            lane.schedule(now)
            queue = lane.queue
            while queue and queue[0][0] <= now:
                _, data = queue.popleft()
                if direction == "up":
                    self._send(lane, self.back, data, self.sim_addr)
                elif self.exec_addr is not None:
                    self._send(lane, self.front, data, self.exec_addr)

    def _send(self, lane: _Lane, sock: socket.socket, data: bytes, addr: tuple[str, int]) -> None:
        try:
            sock.sendto(data, addr)
            lane.counters.forwarded += 1
        except OSError:
            lane.counters.send_errors += 1

    # -- listening in ------------------------------------------------------------------------------

    @staticmethod
    def _parser() -> mavlink.MAVLink:
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        return parser

    def _overhear(self, direction: Direction, data: bytes) -> tuple[str, ...]:
        """Note what the datagram says; returns the types of its messages."""
        parser = self._parsers[direction]
        try:
            msgs = parser.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - a broken frame is the executive's business, not the proxy's
            msgs = []
        parser.buf = bytearray()  # a datagram holds whole frames: start the next one clean
        parser.buf_index = 0
        parser.expected_length = mavlink.HEADER_LEN_V1 + 2
        wall = time.monotonic()
        heard = self._heard[direction]
        for msg in msgs:
            kind = msg.get_type()
            heard[kind] += 1
            if direction == "down":
                if msg.get_srcComponent() != _VEHICLE_COMPONENT:
                    continue
                t_ms = getattr(msg, "time_boot_ms", None)
                if t_ms is not None and (self._clock_s is None or t_ms / 1000.0 > self._clock_s):
                    self._clock_s, self._clock_wall = t_ms / 1000.0, wall
                if kind == "HEARTBEAT":
                    self.modes.append((self.vehicle_s(wall), msg.custom_mode))
                elif kind == "STATUSTEXT":
                    self.texts.append((self.vehicle_s(wall), msg.text))
            elif msg.get_srcComponent() == _EXECUTIVE_COMPONENT:
                if kind == "HEARTBEAT":
                    self.exec_status.append((self.vehicle_s(wall), msg.system_status))
                elif kind == "COMMAND_LONG":
                    self.commands.append((self.vehicle_s(wall), msg.command))
                    if msg.command == _DO_SET_MODE:
                        self.mode_requests.append((self.vehicle_s(wall), int(msg.param2)))
                elif kind == "SET_MODE":
                    self.mode_requests.append((self.vehicle_s(wall), msg.custom_mode))
        return tuple(msg.get_type() for msg in msgs)
