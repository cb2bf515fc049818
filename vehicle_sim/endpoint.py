"""The simulated vehicle on the network: MAVLink 2 over UDP, paced like ArduPilot SITL's ``--speedup``.

With ``streams``, the only modules of the simulator that import pymavlink. A ``Simulator`` binds one UDP
socket, learns its peers from the datagrams it receives and sends everything to every peer
heard in the last ``peer_timeout_s`` wall seconds (as ArduPilot routes). It speaks as
system 1, component 1, a SUBMARINE with ArduPilot custom modes, and streams telemetry at
ArduSub's default rates (as observed on ArduSub SITL), changeable with
MAV_CMD_SET_MESSAGE_INTERVAL (interval -1 stops a stream, 0 restores its default, as
ArduPilot does). Every time field (``time_boot_ms``) is *simulated* time. By default it
streams the eight messages the executive reads; ``SimConfig.ardusub_streams`` adds ArduSub's
nineteen other default streams (``vehicle_sim.streams``): 110 messages per vehicle second
instead of 35, so off by default (at a speedup of 1000 that is 110,000 messages per wall
second for every closed loop to parse). Positions carry an EKF-like error
(``dynamics.drift_error``, stepped every physics step, so the noise does not depend on which
streams are on), and read lat = lon = 0 until the GPS is found.

The main loop steps the physics every ``dt_s`` of simulated time (telemetry can therefore
stream at most at 1 / dt_s = 10 Hz by default), polls the socket without blocking, sends
what is due, and sleeps so that simulated time runs at ``speedup`` x wall time; when it
cannot keep up it runs flat out. Behaviour lives in ``autopilot``, physics in ``dynamics``,
currents in ``world``; this module only moves bytes and clocks.

Lockstep (``SimConfig.lockstep_slack_s`` not None), in the spirit of ArduPilot's lockstep
SITL, where the physics waits for the autopilot's output for each frame: here the vehicle
waits for its companion computer. The executive reports, with a TIMESYNC request (tc1 = 0,
ts1 = vehicle time in ns) from a component of this system other than the autopilot, the
vehicle time up to which it has handled the telemetry; it starts to once the vehicle has
asked with a TIMESYNC request of its own, which the vehicle sends (with its newest step
again, in case that was lost) whenever it has waited 0.1 s of wall time for a report.
The loop steps the physics only
while that report covers the newest timestamped message sent (GLOBAL_POSITION_INT,
ATTITUDE, SYSTEM_TIME), or while the next step stays within ``lockstep_slack_s`` of it.
So the executive's commands for a message are in force from the same step on any
machine, quiet or busy, and the vehicle never outruns the executive's heartbeat. With
slack 0 a dive is the same from the same seed; a slack of a few seconds keeps a lossy
link (lost telemetry or reports) from stalling the loop, at the price of that exactness.
Each step's frames then go out as one datagram per peer (a step's messages arrive
together), and a stream whose interval is changed starts on a multiple of its interval
(the 1 Hz HEARTBEAT always shares a datagram with the 2 Hz position). Without a report
(before the executive starts: ``lockstep_first_wait_wall_s``; when its report stops
advancing, as when it stops, restarts or the uplink is cut: ``lockstep_wait_wall_s``)
the loop waits that many wall seconds and then runs free at its speedup until a report
advances again.
"""

from __future__ import annotations

import math
import random
import select
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from vehicle_sim.autopilot import (
    ARDUSUB_EXTRA_INTERVALS_S,
    DEFAULT_INTERVALS_S,
    Ack,
    Autopilot,
    AutopilotSettings,
    Interval,
    Msg,
    SendOnce,
    SubMode,
    Text,
    clip_text,
)
from vehicle_sim.dynamics import (
    Body,
    Reading,
    battery_remaining,
    drift_error,
    initial_error,
    observe,
    power_w,
    step,
)
from planner.contract.vehicle import VehicleParams
from vehicle_sim.streams import send_extra
from vehicle_sim.world import Truth

SYSTEM_ID = 1
COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1  # 1
TRACK_COLUMNS = ("time_s", "lat_deg", "lon_deg", "depth_m", "heading_deg", "mode", "armed", "energy_used_wh")

# SYS_STATUS sensor bits: IMU, compass, pressure (depth), AHRS, battery, pre-arm.
_SENSORS = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | mavlink.MAV_SYS_STATUS_AHRS | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY | mavlink.MAV_SYS_STATUS_PREARM_CHECK)
# EKF_STATUS_REPORT flags before and after the EKF has an absolute position (SITL: ~41 s after boot).
_EKF_NO_POSITION = (mavlink.EKF_ATTITUDE | mavlink.EKF_VELOCITY_VERT | mavlink.EKF_POS_VERT_ABS
                    | mavlink.EKF_CONST_POS_MODE)
_EKF_POSITION = (mavlink.EKF_ATTITUDE | mavlink.EKF_VELOCITY_HORIZ | mavlink.EKF_VELOCITY_VERT
                 | mavlink.EKF_POS_HORIZ_REL | mavlink.EKF_POS_HORIZ_ABS | mavlink.EKF_POS_VERT_ABS
                 | mavlink.EKF_PRED_POS_HORIZ_REL | mavlink.EKF_PRED_POS_HORIZ_ABS)
_CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                 | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                 | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT)
_NEEDS_READING = frozenset({Msg.GLOBAL_POSITION_INT, Msg.ATTITUDE, Msg.VFR_HUD, Msg.AHRS2, Msg.TERRAIN_REPORT,
                            Msg.GPS_RAW_INT, Msg.LOCAL_POSITION_NED, Msg.SCALED_PRESSURE2})
_MAX_LAG_WALL_S = 0.25  # behind by more than this: stop trying to catch up (run flat out from here)
_MIN_SLEEP_S = 0.0005
_LOCKSTEP_POLL_WALL_S = 0.05  # longest select while waiting for a lockstep report
_RESEND_WALL_S = 0.1  # waiting this long for a report: send the newest step again, and a TIMESYNC request
_TIMED = frozenset({Msg.GLOBAL_POSITION_INT, Msg.ATTITUDE, Msg.SYSTEM_TIME})  # messages with time_boot_ms
_MAX_BATCH_BYTES = 8192  # one datagram per step, well under UDP's 65507


@dataclass(frozen=True, kw_only=True)
class SimConfig:
    """Everything a run needs besides the world; the CLI builds one from its flags."""

    start_lat_deg: float
    start_lon_deg: float
    start_depth_m: float = 0.0
    start_heading_deg: float = 0.0
    start_offset_s: float = 0.0  # world (forecast) time at boot, seconds after the forecast's first time
    speedup: float = 1.0  # simulated seconds per wall second (SITL --speedup)
    host: str = "127.0.0.1"
    port: int = 14560  # 0: ephemeral
    seed: int = 0  # sensor noise
    # Time constant of the position estimate's error (standard deviation: params.position_noise_m).
    position_error_tau_s: float = 30.0
    ardusub_streams: bool = False  # also ArduSub's 19 other default streams (module docstring)
    dt_s: float = 0.1  # physics step (simulated)
    params: VehicleParams = field(default_factory=VehicleParams)
    autopilot: AutopilotSettings = field(default_factory=AutopilotSettings)
    track_path: Path | None = None
    track_interval_s: float = 1.0
    peer_timeout_s: float = 10.0  # wall seconds without a datagram before a peer stops getting output
    # Lockstep with the executive (module docstring): None runs free; else the vehicle seconds the
    # physics may run beyond the executive's report (0: never past the newest timestamp it has not handled).
    lockstep_slack_s: float | None = None
    lockstep_first_wait_wall_s: float = 30.0  # wall s to wait for the first report before running free
    # Wall s without the report advancing before running free: the executive's own grace before its clock
    # runs on through a silence (executive.clock), so that with the link cut both go on together.
    lockstep_wait_wall_s: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speedup) and self.speedup > 0):
            raise ValueError(f"SimConfig.speedup: expected a number > 0; got {self.speedup!r}")
        if not (math.isfinite(self.position_error_tau_s) and self.position_error_tau_s > 0):
            raise ValueError(f"SimConfig.position_error_tau_s: expected seconds > 0; got {self.position_error_tau_s!r}")
        if not (0.001 <= self.dt_s <= 1.0):
            raise ValueError(f"SimConfig.dt_s: expected 0.001..1 s; got {self.dt_s!r}")
        if self.lockstep_slack_s is not None and not (math.isfinite(self.lockstep_slack_s)
                                                      and self.lockstep_slack_s >= 0):
            raise ValueError(f"SimConfig.lockstep_slack_s: expected seconds >= 0 or None; got {self.lockstep_slack_s!r}")
        for name in ("lockstep_first_wait_wall_s", "lockstep_wait_wall_s"):
            if not (getattr(self, name) > 0):
                raise ValueError(f"SimConfig.{name}: expected wall seconds > 0; got {getattr(self, name)!r}")


@dataclass
class SimStats:
    """Counters of a run (not part of any protocol)."""

    datagrams_in: int = 0
    messages_in: int = 0
    parse_errors: int = 0  # undecodable bytes or frames (bad prefix, CRC, length)
    ignored: int = 0  # addressed to another system/component
    messages_out: int = 0
    send_errors: int = 0
    lag_resets: int = 0  # times the loop fell more than 0.25 s (wall) behind the asked speedup
    lockstep_waits: int = 0  # times the loop waited for the executive's report
    lockstep_expired: int = 0  # times it gave up waiting and ran free (no executive, or its report stopped)
    lockstep_resends: int = 0  # times it sent its newest timestamped step again while waiting


class _Fanout:
    """The file pymavlink writes frames to: one datagram per frame to every live peer."""

    def __init__(self, sock: socket.socket, stats: SimStats, *, batch: bool = False) -> None:
        self.sock = sock
        self.stats = stats
        self.targets: list[tuple[str, int]] = []
        self.batch = batch  # hold frames until ``flush``: a step's frames in one datagram (lockstep)
        self._held = bytearray()
        self.last: bytes | None = None  # the last datagram flushed

    def write(self, buf: bytes) -> None:
        if self.batch:
            if len(self._held) + len(buf) > _MAX_BATCH_BYTES:
                self.flush()
            self._held += buf
            return
        self.sendto_all(buf)

    def flush(self) -> None:
        if self._held:
            buf = bytes(self._held)
            self._held.clear()
            self.sendto_all(buf)
            self.last = buf

    def sendto_all(self, buf: bytes) -> None:
        for addr in self.targets:
            try:
                self.sock.sendto(buf, addr)
            except OSError:  # buffer full, peer gone (ICMP): UDP may drop
                self.stats.send_errors += 1


class _Stream:
    """One periodic message: interval and next due time in simulated milliseconds."""

    __slots__ = ("due_ms", "interval_ms", "msg_id")

    def __init__(self, msg_id: int, interval_ms: int | None) -> None:
        self.msg_id = msg_id
        self.interval_ms = interval_ms
        self.due_ms = 0


class Simulator:
    """A simulated ArduSub-like LRAUV behind a UDP socket. Use as a context manager or call ``close``."""

    def __init__(self, world: Truth, config: SimConfig) -> None:
        self.world = world
        self.config = config
        self.params = config.params
        self.stats = SimStats()
        self.autopilot = Autopilot(config.autopilot, battery_wh=config.params.battery_wh,
                                   origin_lat_deg=config.start_lat_deg, origin_lon_deg=config.start_lon_deg)
        self._body = Body(0.0, config.start_lat_deg, config.start_lon_deg, config.start_depth_m,
                          config.start_heading_deg % 360.0)
        self._t_ms = 0
        self._dt_ms = max(1, round(config.dt_s * 1000))
        self._dt_s = self._dt_ms / 1000.0
        self._rng = random.Random(config.seed)
        self._error = initial_error(config.params.position_noise_m, config.position_error_tau_s, self._rng)
        self._streams = [_Stream(int(k), round(v * 1000)) for k, v in DEFAULT_INTERVALS_S.items()]
        self._streams += [_Stream(int(k), round(v * 1000) if config.ardusub_streams else None)
                          for k, v in ARDUSUB_EXTRA_INTERVALS_S.items()]

        self._track: TextIO | None = None
        self._track_every_ms = max(self._dt_ms, round(config.track_interval_s * 1000))
        self._track_due_ms = 0
        self._track_last_ms = -1
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((config.host, config.port))
            if config.track_path is not None:
                self._track = open(config.track_path, "w", buffering=1 << 16)  # noqa: SIM115 (closed in close())
                self._track.write(",".join(TRACK_COLUMNS) + "\n")
                self._write_track()  # the state at boot
                self._track_due_ms = self._track_every_ms
        except OSError:
            self._sock.close()
            raise
        self._sock.setblocking(False)
        self.host, self.port = self._sock.getsockname()[:2]
        self._lockstep_ms = None if config.lockstep_slack_s is None else round(config.lockstep_slack_s * 1000)
        self._fanout = _Fanout(self._sock, self.stats, batch=self._lockstep_ms is not None)
        self._reported_ms: int | None = None  # the executive's newest lockstep report
        self._report_wall = time.monotonic()  # when it last advanced (or the run started)
        self._timed_sent_ms: int | None = None  # time_boot_ms of the newest timestamped message sent
        self._timed_batch: bytes | None = None  # the datagram that carried it
        self._resend_wall = 0.0  # when it was sent (again)
        self._free = False  # stepping without the executive (its report is overdue)
        self._waiting = False  # waiting for its report
        self._peers: dict[tuple[str, int], float] = {}  # address -> wall time last heard
        self._wall = time.monotonic()
        self._next_prune_wall = self._wall + 1.0
        self._mav = mavlink.MAVLink(self._fanout, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._handlers = {
            Msg.HEARTBEAT: self._on_heartbeat,
            Msg.SET_MODE: self._on_set_mode,
            mavlink.MAVLINK_MSG_ID_COMMAND_LONG: self._on_command_long,
            mavlink.MAVLINK_MSG_ID_COMMAND_INT: self._on_command_int,
            mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED: self._on_local_ned,
            mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT: self._on_global_int,
        }
        if self._lockstep_ms is not None:
            self._handlers[mavlink.MAVLINK_MSG_ID_TIMESYNC] = self._on_timesync
        self._closed = False

    # -- what tests and the CLI read ---------------------------------------------------------

    @property
    def body(self) -> Body:
        """The true state (no noise)."""
        return self._body

    @property
    def time_s(self) -> float:
        """Simulated seconds since boot (``time_boot_ms`` / 1000)."""
        return self._t_ms / 1000.0

    @property
    def mode(self) -> SubMode:
        return self.autopilot.mode

    @property
    def armed(self) -> bool:
        return self.autopilot.armed

    @property
    def energy_used_wh(self) -> float:
        return self._body.energy_used_wh

    @property
    def peers(self) -> list[tuple[str, int]]:
        return list(self._fanout.targets)

    def route(self, data: bytes) -> None:
        """Send ``data`` as it is to every peer, as the autopilot routes a ground station's frames (for tests)."""
        self._fanout.sendto_all(data)

    @property
    def reported_s(self) -> float | None:
        """Lockstep: the newest vehicle time the executive has reported handled (None before its first report)."""
        return None if self._reported_ms is None else self._reported_ms / 1000.0

    # -- running ---------------------------------------------------------------------------------

    def run(self, duration_s: float | None = None, stop_event: threading.Event | None = None) -> None:
        """Step until ``duration_s`` more simulated seconds have passed or ``stop_event`` is set."""
        end_ms = None if duration_s is None else self._t_ms + round(duration_s * 1000)
        rate_ms = self.config.speedup * 1000.0  # simulated ms per wall second
        max_lag_ms = _MAX_LAG_WALL_S * rate_ms
        wall0 = time.monotonic()
        sim0 = self._t_ms
        sock = self._sock
        self._report_wall = wall0  # a wait for the executive's report counts from here
        while end_ms is None or self._t_ms < end_ms:
            if stop_event is not None and stop_event.is_set():
                break
            wall = time.monotonic()
            if self._lockstep_ms is not None and not self._may_step(wall):
                if wall - self._resend_wall >= _RESEND_WALL_S:  # the step or its report may be lost: ask again
                    self._resend_wall = wall
                    if self._timed_batch is not None:  # the executive drops a repeat
                        self._fanout.sendto_all(self._timed_batch)
                        self.stats.lockstep_resends += 1
                    self._mav.timesync_send(0, self._t_ms * 1_000_000)  # "where are you?": answered by a report
                    self._fanout.flush()
                readable, _, _ = select.select([sock], [], [], _LOCKSTEP_POLL_WALL_S)
                if readable:
                    self._wall = time.monotonic()
                    self._poll()
                wall0, sim0 = time.monotonic(), self._t_ms  # the pace starts afresh after a wait
                continue
            ahead_ms = self._t_ms - sim0 - (wall - wall0) * rate_ms
            if ahead_ms > 0.0:
                wait = ahead_ms / rate_ms
                if wait >= _MIN_SLEEP_S:
                    readable, _, _ = select.select([sock], [], [], min(wait, 0.05))
                    if readable:
                        self._wall = time.monotonic()
                        self._poll()
                    continue
            elif ahead_ms < -max_lag_ms:  # cannot keep up: do not try to catch up later in a burst
                wall0, sim0 = wall, self._t_ms
                self.stats.lag_resets += 1
            self.step_once(wall)

    def step_once(self, wall: float | None = None) -> None:
        """Receive what is waiting, step the physics by ``dt_s`` and send what is due."""
        self._wall = time.monotonic() if wall is None else wall
        if self._wall >= self._next_prune_wall:
            self._prune_peers()
        self._poll()
        ap = self.autopilot
        body = self._body
        now_s = self._t_ms / 1000.0
        events = ap.tick(now_s, body)
        if events:
            self._do(events)
        current = self.world.current_at(self.config.start_offset_s + now_s, body.lat_deg, body.lon_deg, body.depth_m)
        self._body = step(body, ap.setpoint, current, self.params, self._dt_s, self.config.autopilot.tracking)
        self._error = drift_error(self._error, self.params.position_noise_m, self.config.position_error_tau_s,
                                  self._dt_s, self._rng)
        self._t_ms += self._dt_ms
        timed = self._timed_sent_ms
        self._send_due()
        self._fanout.flush()
        if self._timed_sent_ms != timed:
            self._timed_batch, self._resend_wall = self._fanout.last, self._wall
        if self._track is not None and self._t_ms >= self._track_due_ms:
            self._track_due_ms = self._t_ms + self._track_every_ms
            self._write_track()

    def close(self) -> None:
        """Close the socket and flush the track file; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self._sock.close()
        if self._track is not None:
            self._write_track()
            self._track.close()

    def __enter__(self) -> Simulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- receiving ---------------------------------------------------------------------------------

    def _poll(self) -> None:
        sock = self._sock
        while True:
            try:
                data, addr = sock.recvfrom(65536)
            except BlockingIOError:
                return
            except OSError:  # e.g. ICMP port unreachable from a peer that went away
                self.stats.send_errors += 1
                continue
            self.stats.datagrams_in += 1
            if addr not in self._peers:
                self._fanout.targets.append(addr)
            self._peers[addr] = self._wall
            self._receive(data)
            self._fanout.flush()  # replies (COMMAND_ACK, STATUSTEXT) go out at once

    def _receive(self, data: bytes) -> None:
        parser = self._parser
        try:
            msgs = parser.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - nothing a peer sends may stop the vehicle
            self.stats.parse_errors += 1
            msgs = []
        # A datagram holds whole frames: never let a broken one swallow the next datagram.
        parser.buf = bytearray()
        parser.buf_index = 0
        parser.expected_length = mavlink.HEADER_LEN_V1 + 2
        for msg in msgs:
            msg_id = msg.get_msgId()
            if msg_id < 0:  # MAVLink_bad_data
                self.stats.parse_errors += 1
                continue
            self.stats.messages_in += 1
            handler = self._handlers.get(msg_id)
            if handler is None:
                continue
            ts = getattr(msg, "target_system", 0)
            tc = getattr(msg, "target_component", 0)
            if ts not in (0, SYSTEM_ID) or tc not in (0, COMPONENT_ID):
                self.stats.ignored += 1
                continue
            try:
                handler(msg)
            except Exception:  # noqa: BLE001 - a malformed field (NaN, out of range) must not crash the vehicle
                self.stats.parse_errors += 1

    def _source(self, msg: Any) -> tuple[int, int]:
        return msg.get_srcSystem(), msg.get_srcComponent()

    def _may_step(self, wall: float) -> bool:
        """Lockstep: whether the physics may take its next step now (module docstring)."""
        reported = self._reported_ms
        if reported is not None and (self._timed_sent_ms is None or reported >= self._timed_sent_ms
                                     or self._t_ms + self._dt_ms <= reported + (self._lockstep_ms or 0)):
            self._free = self._waiting = False
            return True
        if self._free:
            return True
        limit = self.config.lockstep_first_wait_wall_s if reported is None else self.config.lockstep_wait_wall_s
        if wall - self._report_wall >= limit:
            self._free, self._waiting = True, False
            self.stats.lockstep_expired += 1
            return True
        if not self._waiting:
            self._waiting = True
            self.stats.lockstep_waits += 1
        return False

    def _on_timesync(self, msg: Any) -> None:
        """A lockstep report: a TIMESYNC request (tc1 = 0) from a companion computer of this vehicle."""
        if msg.tc1 != 0 or msg.ts1 < 0 or msg.get_srcSystem() != SYSTEM_ID or msg.get_srcComponent() == COMPONENT_ID:
            return  # an answer, or a ground station's request (ArduSub would answer it; this simulator does not)
        reported = msg.ts1 // 1_000_000
        if self._reported_ms is None or reported > self._reported_ms:
            self._reported_ms = reported
            self._report_wall = self._wall
            self._free = False  # the executive is (back) in step: wait for it again

    def _on_heartbeat(self, msg: Any) -> None:
        self._do(self.autopilot.heartbeat(self.time_s, msg.get_srcSystem(), msg.get_srcComponent()))

    def _on_set_mode(self, msg: Any) -> None:
        self._do(self.autopilot.set_mode_message(self.time_s, self._body, msg.base_mode, msg.custom_mode,
                                                 self._source(msg)))

    def _on_command_long(self, msg: Any) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._do(self.autopilot.command(self.time_s, self._body, msg.command, params, self._source(msg)))

    def _on_command_int(self, msg: Any) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._do(self.autopilot.command(self.time_s, self._body, msg.command, params, self._source(msg)))

    def _on_local_ned(self, msg: Any) -> None:
        self.autopilot.position_target_local(
            self.time_s, self._body, frame=msg.coordinate_frame, type_mask=msg.type_mask, x=msg.x, y=msg.y, z=msg.z,
            vx=msg.vx, vy=msg.vy, vz=msg.vz, yaw_rad=msg.yaw, yaw_rate_rad_s=msg.yaw_rate)

    def _on_global_int(self, msg: Any) -> None:
        self.autopilot.position_target_global(
            self.time_s, self._body, frame=msg.coordinate_frame, type_mask=msg.type_mask, lat_int=msg.lat_int,
            lon_int=msg.lon_int, alt_m=msg.alt, vx=msg.vx, vy=msg.vy, vz=msg.vz)

    def _do(self, outputs: list[Any]) -> None:
        """Carry out what the autopilot returned."""
        mav = self._mav
        for out in outputs:
            if isinstance(out, Ack):
                mav.command_ack_send(out.command, int(out.result), 0, 0, out.target_system, out.target_component)
                self.stats.messages_out += 1
            elif isinstance(out, Text):
                mav.statustext_send(int(out.severity), clip_text(out.text).encode("ascii", "replace"))
                self.stats.messages_out += 1
            elif isinstance(out, Interval):
                for s in self._streams:
                    if s.msg_id == out.message_id:
                        s.interval_ms = None if out.interval_s is None else max(1, round(out.interval_s * 1000))
                        s.due_ms = self._t_ms
                        if self._lockstep_ms is not None and s.interval_ms is not None:  # on a multiple of it
                            s.due_ms = -(-self._t_ms // s.interval_ms) * s.interval_ms
            elif isinstance(out, SendOnce) and self._fanout.targets:
                self._send(out.message_id, self._observe())

    def _prune_peers(self) -> None:
        limit = self._wall - self.config.peer_timeout_s
        for addr, heard in list(self._peers.items()):
            if heard < limit:
                del self._peers[addr]
        self._fanout.targets = list(self._peers)
        self._next_prune_wall = self._wall + 1.0

    # -- sending -------------------------------------------------------------------------------------

    def _send_due(self) -> None:
        """Send the streams that are due. Noise is drawn even with no peer, so runs repeat from a seed."""
        now = self._t_ms
        live = bool(self._fanout.targets)
        reading = None
        for s in self._streams:
            interval = s.interval_ms
            if interval is None or now < s.due_ms:
                continue
            s.due_ms += interval
            if s.due_ms <= now:
                s.due_ms = now + interval
            if s.msg_id in _NEEDS_READING and reading is None:
                reading = self._observe()
            if live:
                self._send(s.msg_id, reading)

    def _observe(self) -> Reading:
        return observe(self._body, self.params, self._rng, self._error)

    def _send(self, msg_id: int, reading: Reading | None) -> None:
        mav = self._mav
        b = self._body
        ap = self.autopilot
        t_ms = self._t_ms
        if reading is None:
            reading = Reading(b.lat_deg, b.lon_deg, b.depth_m, b.heading_deg)
        if msg_id in _TIMED:
            self._timed_sent_ms = t_ms
        if msg_id == Msg.GLOBAL_POSITION_INT:
            alt_mm = round(-reading.depth_m * 1000.0)  # Sub: altitude negative below the surface
            gps = ap.gps_ok(t_ms / 1000.0)  # before the GPS is found ArduSub sends lat = lon = 0
            mav.global_position_int_send(
                t_ms, round(reading.lat_deg * 1e7) if gps else 0, round(reading.lon_deg * 1e7) if gps else 0,
                alt_mm, alt_mm,
                _i16(b.ground_north_m_s * 100.0), _i16(b.ground_east_m_s * 100.0), _i16(b.down_m_s * 100.0),
                round(reading.heading_deg * 100.0) % 36000)
        elif msg_id == Msg.ATTITUDE:
            yaw = math.radians(reading.heading_deg)
            if yaw > math.pi:
                yaw -= 2.0 * math.pi
            mav.attitude_send(t_ms, 0.0, 0.0, yaw, 0.0, 0.0, math.radians(b.yaw_rate_deg_s))
        elif msg_id == Msg.VFR_HUD:
            throttle = min(100, round(100.0 * b.water_speed_m_s / self.params.max_speed_m_s))
            mav.vfr_hud_send(b.water_speed_m_s, b.ground_speed_m_s, round(reading.heading_deg) % 360, throttle,
                             -reading.depth_m, -b.down_m_s)
        elif msg_id == Msg.HEARTBEAT:
            base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            if ap.armed:
                base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            if ap.mode is SubMode.GUIDED:
                base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
            if ap.failsafe_active or ap.battery_failsafe:
                status = mavlink.MAV_STATE_CRITICAL
            else:
                status = mavlink.MAV_STATE_ACTIVE if ap.armed else mavlink.MAV_STATE_STANDBY
            mav.heartbeat_send(mavlink.MAV_TYPE_SUBMARINE, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base, int(ap.mode),
                               status)
        elif msg_id == Msg.SYSTEM_TIME:
            unix_s = self.world.start_unix_s + self.config.start_offset_s + t_ms / 1000.0
            mav.system_time_send(max(0, round(unix_s * 1e6)), t_ms)
        elif msg_id == Msg.EKF_STATUS_REPORT:
            flags = _EKF_POSITION if ap.position_ok(t_ms / 1000.0) else _EKF_NO_POSITION
            mav.ekf_status_report_send(flags, 0.02, 0.02, 0.01, 0.02, 0.0)
        elif msg_id in (Msg.SYS_STATUS, Msg.BATTERY_STATUS):
            p = self.params
            pct = round(100.0 * battery_remaining(b, p))
            mv = round(p.battery_voltage_v * 1000.0)
            current_ca = min(32767, round(power_w(b, p) / p.battery_voltage_v * 100.0))
            if msg_id == Msg.SYS_STATUS:
                health = _SENSORS if ap.prearm_ok(t_ms / 1000.0) else _SENSORS & ~mavlink.MAV_SYS_STATUS_PREARM_CHECK
                mav.sys_status_send(_SENSORS, _SENSORS, health, 0, mv, current_ca, pct, 0, 0, 0, 0, 0, 0)
            else:
                mah = round(b.energy_used_wh / p.battery_voltage_v * 1000.0)
                mav.battery_status_send(
                    0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LION, 32767,
                    [min(mv, 65534)] + [65535] * 9, current_ca, mah, round(b.energy_used_wh * 36.0), pct)  # hJ
        elif msg_id == Msg.AUTOPILOT_VERSION:
            mav.autopilot_version_send(_CAPABILITIES, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0)
        else:
            self.stats.messages_out += send_extra(mav, msg_id, t_ms, b, reading, ap, self.params)
            return
        self.stats.messages_out += 1

    def _write_track(self) -> None:
        assert self._track is not None
        if self._t_ms == self._track_last_ms:
            return
        self._track_last_ms = self._t_ms
        b = self._body
        ap = self.autopilot
        self._track.write(f"{self._t_ms / 1000.0:.3f},{b.lat_deg:.8f},{b.lon_deg:.8f},{b.depth_m:.3f},"
                          f"{b.heading_deg:.2f},{int(ap.mode)},{int(ap.armed)},{b.energy_used_wh:.5f}\n")


def _i16(x: float) -> int:
    return max(-32768, min(32767, round(x)))
