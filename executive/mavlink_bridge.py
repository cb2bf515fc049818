"""The bridge between MAVLink and the executive's value objects: the only place with MAVLink units.

Telemetry from the autopilot becomes ``VehicleState`` updates (degE7, mm, cdeg,
cm/s converted here and nowhere else), and ``Command`` objects become MAVLink
messages with ArduSub's conventions (MAVLink common.xml and ArduSub's GCS_MAVLink
handlers, as observed on ArduSub SITL). This is the executive's only
pymavlink import. With a signing key, ``new_mav`` gives a ``SigningMAVLink``: it
signs what it sends and gives every message it decodes a ``signature`` verdict
(``executive.signing``).
"""

from __future__ import annotations

import base64
import math
import socket
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any
from weakref import WeakKeyDictionary

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from executive import mission_protocol as mp
from executive.signing import Streams, Verdict, is_signed, timestamp_at
from planner.contract.errors import ExecutiveError
from executive.state import (
    Arm,
    Command,
    DepthTarget,
    Event,
    PositionTarget,
    SetMessageInterval,
    SetMode,
    VehicleState,
    VelocityYaw,
)

# Our identity (section 2.1): the onboard computer beside the autopilot.
EXECUTIVE_SYSTEM = 1
EXECUTIVE_COMPONENT = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER  # 191
AUTOPILOT_SYSTEM = 1
AUTOPILOT_COMPONENT = mavlink.MAV_COMP_ID_AUTOPILOT1  # 1

# POSITION_TARGET_TYPEMASK (section 2.3, verified masks); 1 = ignore.
MASK_VELOCITY_YAW = 2503  # vx, vy, vz, yaw
# vx, vy, vz, yaw and yaw rate: ArduSub's GUIDED slews toward the yaw at min(yaw rate, 60 deg/s)
# (GCS_MAVLINK_Sub::handle_message -> ModeGuided::guided_set_velocity -> guided_set_yaw_state).
MASK_VELOCITY_YAW_RATE = 455
MASK_DEPTH_ONLY = 3579  # z only (ALT_HOLD depth target)
MASK_POSITION_ONLY = 3576  # x, y, z

# Messages that carry time_boot_ms and drive decisions.
DECISION_MESSAGES = frozenset({"GLOBAL_POSITION_INT", "ATTITUDE"})
_UNKNOWN_HDG = 65535
# A warning longer than one STATUSTEXT goes out in MAVLink 2 chunks (common.xml STATUSTEXT ``id`` and
# ``chunk_seq``), at most this many: 4 x 50 bytes holds every refusal the executive words, and a
# longer text ends in "..." rather than flooding a slow link.
MAX_STATUSTEXT_CHUNKS = 4
_SEVERITY = {"debug": mavlink.MAV_SEVERITY_DEBUG, "info": mavlink.MAV_SEVERITY_INFO,
             "warning": mavlink.MAV_SEVERITY_WARNING, "error": mavlink.MAV_SEVERITY_ERROR}


def open_link(address: str, *, source_system: int, source_component: int,
              client_timeout_s: float | None = None, flag: str = "--link") -> Any:
    """A pymavlink connection (``mavutil.mavlink_connection``) that speaks MAVLink 2 from its first frame.

    mavutil picks its dialect module from the ``MAVLINK20`` environment variable when it is
    imported; instead of setting that for the whole process, the connection gets a MAVLink 2
    encoder/parser of its own, and is marked as already switched so that mavutil's protocol
    auto-detection leaves it (and the environment) alone. UDP addresses (``udpin:``, ``udp:``,
    ``udpout:``) give a ``UdpLink``: it knows each datagram's source, can be locked to one
    peer, and (listening) replies only to clients heard within ``client_timeout_s`` wall seconds.
    TCP addresses (``tcp:``, ``tcpin:``) give a ``TcpLink``: read in whole buffers, and
    ``closed`` once the peer has closed the connection. ``flag`` names the option in an error.
    """
    from pymavlink import mavutil

    kind, _, rest = address.partition(":")
    if kind in _NETWORK_KINDS:
        check_address(address, flag=flag)
        try:
            if kind in ("udpin", "udp", "udpout"):
                conn: Any = _udp_link_class()(rest, listen=kind != "udpout", source_system=source_system,
                                              source_component=source_component, client_timeout_s=client_timeout_s)
            else:
                conn = _tcp_link_classes()[kind == "tcpin"](rest, source_system=source_system,
                                                             source_component=source_component)
        except (OSError, ValueError) as exc:  # no such host, a port in use, nobody listening (tcp:)
            raise ExecutiveError(f"{flag} {address}: cannot open: {exc}") from None
    else:  # a serial device, DEVICE or DEVICE,BAUD (ArduPilot's SERIALn_BAUD: 115200 unless set)
        device, _, baud = address.partition(",")
        if baud and not baud.isdigit():
            raise ExecutiveError(f"{flag} {address!r}: expected a serial DEVICE,BAUD with a whole baud rate"
                                 " (e.g. /dev/ttyAMA0,921600), or udpin:/udpout:/tcp:/tcpin: HOST:PORT")
        try:
            conn = mavutil.mavlink_connection(device, baud=int(baud or SERIAL_BAUD), source_system=source_system,
                                              source_component=source_component)
        except OSError as exc:  # pyserial's SerialException is one: no such device, no permission
            raise ExecutiveError(f"{flag} {address!r}: cannot open the serial device: {exc}") from None
        except ValueError as exc:  # mavutil read an unknown KIND:REST as one of its own forms and failed
            raise ExecutiveError(f"{flag} {address!r}: cannot open it ({exc}); expected udpin:/udpout:/tcp:/tcpin:"
                                 "HOST:PORT or a serial DEVICE[,BAUD]") from None
    conn.mav = mavlink.MAVLink(conn, srcSystem=source_system, srcComponent=source_component)
    conn.mav.robust_parsing = True
    conn.WIRE_PROTOCOL_VERSION = mavlink.WIRE_PROTOCOL_VERSION
    conn.first_byte = False
    return conn


_NETWORK_KINDS = ("udpin", "udp", "udpout", "tcp", "tcpin")


def check_address(address: str, *, flag: str = "--link") -> None:
    """A network address's HOST:PORT: a port 0..65535 and, where the host is written as numbers, an IPv4
    address (pymavlink would fail on it with a traceback, or send to nowhere). A serial device is only
    known when it is opened. ``flag`` names the option in the error; checked before any work."""
    kind, _, rest = address.partition(":")
    if kind not in _NETWORK_KINDS:
        return
    host, sep, port = rest.rpartition(":")
    listens = kind in ("udpin", "udp", "tcpin")  # an empty host listens on every interface (udpin::14550)
    if not sep or (not host and not listens) or not port.isdigit() or int(port) > 65535:
        raise ExecutiveError(f"{flag} {address!r}: expected {kind}:HOST:PORT, a port 0..65535 "
                             f"(e.g. {kind}:127.0.0.1:14550)")
    if host.replace(".", "").isdigit() and not _is_ipv4(host):
        raise ExecutiveError(f"{flag} {address!r}: the host {host} is not an IPv4 address (four numbers 0..255)")


def _is_ipv4(host: str) -> bool:
    parts = host.split(".")
    return len(parts) == 4 and all(p.isdigit() and int(p) <= 255 for p in parts)


def _udp_link_class() -> type:
    """``UdpLink``, defined on first use: mavutil is imported only when a link is opened (as in the loop),
    after the process has chosen its MAVLink version (mavutil reads ``MAVLINK20`` when imported)."""
    global _UDP_LINK
    if _UDP_LINK is not None:
        return _UDP_LINK
    from pymavlink import mavutil

    class UdpLink(mavutil.mavudp):
        """pymavlink's UDP link with two safeguards for a link anyone on the network can reach.

        * ``source``: the address of the last datagram read, so that the loop can lock the
          autopilot link to the autopilot's address once heard (``lock``); once locked, a
          listening link writes only to that address.
        * Listening without a lock (the ground-station port), pymavlink's ``mavudp`` writes to
          every address that ever sent a byte; here only to clients heard within
          ``client_timeout_s`` wall seconds (None: no time-out), and a silent client is forgotten.
        """

        def __init__(self, device: str, *, listen: bool, source_system: int, source_component: int,
                     client_timeout_s: float | None = None) -> None:
            super().__init__(device, input=listen, source_system=source_system, source_component=source_component)
            self.source: tuple[str, int] | None = None
            self.locked: tuple[str, int] | None = None
            self.client_timeout_s = client_timeout_s
            self.heard: dict[tuple[str, int], float] = {}  # listening: client -> wall time (monotonic) last heard

        def recv(self, n: int | None = None) -> bytes:
            try:
                data, addr = self.port.recvfrom(65535)
            except (BlockingIOError, InterruptedError, ConnectionRefusedError):  # nothing to read (or an ICMP error)
                return b""
            self.source = addr
            if self.udp_server and (self.locked is None or addr == self.locked):
                self.heard[addr] = time.monotonic()
            return data

        def lock(self, address: tuple[str, int]) -> None:
            self.locked = address

        def peek_source(self) -> tuple[str, int] | None:
            """The source address of the next datagram, left unread (None when there is none)."""
            try:
                _, addr = self.port.recvfrom(1, socket.MSG_PEEK)
            except OSError:  # nothing waiting, or an ICMP error to be read by recv
                return None
            return addr

        def recipients(self, wall_s: float) -> list[tuple[str, int]]:
            """Listening: where a write goes now (clients silent longer than the time-out are forgotten)."""
            if self.locked is not None:
                return [self.locked]
            limit = self.client_timeout_s
            if limit is not None:
                self.heard = {a: t for a, t in self.heard.items() if wall_s - t <= limit}
            return list(self.heard)

        def write(self, buf: bytes) -> None:
            if not self.udp_server:
                super().write(buf)
                return
            for addr in self.recipients(time.monotonic()):
                try:
                    self.port.sendto(buf, addr)
                except OSError:  # buffer full or peer gone: UDP may drop
                    pass

    _UDP_LINK = UdpLink
    return UdpLink


_UDP_LINK: type | None = None

# A stream link (TCP, serial) is read in whole buffers: whatever waits, up to this. pymavlink's own
# ``recv()`` reads what its parser says the next frame needs, 8 bytes at a time between frames: at
# ArduSub SITL's 91 messages per vehicle second at 57x, that reader fell 24 vehicle seconds behind.
STREAM_READ_BYTES = 65536
SERIAL_BAUD = 115200  # ArduPilot's default SERIALn_BAUD for a MAVLink port


def _tcp_link_classes() -> tuple[type, type]:
    """``TcpLink`` (connecting) and ``TcpInLink`` (listening), defined on first use as ``UdpLink`` is."""
    global _TCP_LINKS
    if _TCP_LINKS is not None:
        return _TCP_LINKS
    from pymavlink import mavutil

    def read(port: socket.socket, n: int | None) -> bytes | None:
        """Up to ``n`` bytes waiting on ``port`` (b"" when none); None when the peer closed or reset it."""
        try:
            return port.recv(n or STREAM_READ_BYTES) or None
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:  # ECONNRESET, ETIMEDOUT, ...
            return None

    def send(port: socket.socket, buf: bytes) -> bool:
        """Write ``buf``; False when the connection is gone (a full send buffer drops it, as pymavlink does)."""
        try:
            port.send(buf)
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:  # EPIPE, ECONNRESET
            return False
        return True

    class TcpLink(mavutil.mavtcp):
        """pymavlink's TCP client link, read in whole buffers (``STREAM_READ_BYTES``).

        The peer closing the connection (end of stream, or a reset) sets ``closed``: a lost link at
        once (docs/executive.md, "Links"). pymavlink would print and read on, 0 bytes at a time.
        """

        closed = False

        def recv(self, n: int | None = None) -> bytes:
            data = None if self.closed else read(self.port, n)
            if data is None:
                self.closed = True
            return data or b""

        def write(self, buf: bytes) -> None:
            if not self.closed and not send(self.port, buf):
                self.closed = True

    class TcpInLink(mavutil.mavtcpin):
        """pymavlink's listening TCP link, read in whole buffers; ``closed`` from the client's close until
        another client connects (pymavlink would read the closed connection forever)."""

        port: socket.socket | None
        closed = False

        def recv(self, n: int | None = None) -> bytes:
            if self.port is None:
                try:
                    port, _ = self.listen.accept()
                except (BlockingIOError, InterruptedError):
                    return b""
                port.setblocking(False)
                port.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.port, self.fd, self.closed = port, port.fileno(), False
            data = read(self.port, n)
            if data is None:
                self._drop()
            return data or b""

        def write(self, buf: bytes) -> None:
            if self.port is not None and not send(self.port, buf):
                self._drop()

        def _drop(self) -> None:
            assert self.port is not None
            self.port.close()
            self.port, self.fd, self.closed = None, self.listen.fileno(), True

    _TCP_LINKS = (TcpLink, TcpInLink)
    return _TCP_LINKS


_TCP_LINKS: tuple[type, type] | None = None


def new_mav(sink: Any, *, system: int = EXECUTIVE_SYSTEM, component: int = EXECUTIVE_COMPONENT,
            streams: Streams | None = None, link_id: int = 0) -> mavlink.MAVLink:
    """A MAVLink 2 encoder/parser writing frames to ``sink.write(bytes)``; signing with ``streams``' key."""
    if streams is None:
        mav = mavlink.MAVLink(sink, srcSystem=system, srcComponent=component)
    else:
        mav = SigningMAVLink(sink, system=system, component=component, streams=streams, link_id=link_id)
    mav.robust_parsing = True  # skip garbage instead of raising on every bad byte
    return mav


class SigningMAVLink(mavlink.MAVLink):
    """pymavlink's MAVLink, signing everything it sends and judging everything it decodes.

    pymavlink does the framing and ``sign_packet``; the verdict on a received frame is
    ``Streams.admit``'s (signature first, then timestamp), through pymavlink's own hook
    ``check_signature``, called by ``decode`` for signed frames of known types. Nothing is
    dropped here: ``allow_unsigned_callback`` lets every frame through and ``signature(msg)``
    tells the loop what it is worth, so the loop, which knows the link, the sender and the
    addressee, decides and logs.
    """

    def __init__(self, sink: Any, *, system: int, component: int, streams: Streams, link_id: int,
                 wall_unix_s: Callable[[], float] = time.time) -> None:
        super().__init__(sink, srcSystem=system, srcComponent=component)
        self._streams = streams
        self._wall_unix_s = wall_unix_s
        self._verdict: Verdict | None = None
        self.signing.secret_key = streams.key.secret
        self.signing.link_id = link_id
        self.signing.sign_outgoing = True
        self.signing.timestamp = streams.next_send_ticks(0, wall_ticks=timestamp_at(wall_unix_s()))
        self.signing.allow_unsigned_callback = lambda _mav, _msg_id: True  # the loop decides (above)

    def check_signature(self, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:  # noqa: N803 (pymavlink's names)
        self._verdict = self._streams.admit(bytes(msgbuf), wall_ticks=timestamp_at(self._wall_unix_s()))
        return self._verdict is Verdict.SIGNED

    def decode(self, msgbuf: bytearray) -> Any:
        self._verdict = None
        msg = super().decode(msgbuf)
        if self._verdict is None:  # unsigned, or a type pymavlink does not know (decoded before any check)
            frame = bytes(msgbuf)
            self._verdict = (self._streams.admit(frame, wall_ticks=timestamp_at(self._wall_unix_s()))
                             if is_signed(frame) else Verdict.UNSIGNED)
        msg._lrauv_signature = self._verdict
        return msg

    def send(self, mavmsg: Any, force_mavlink1: bool = False) -> None:
        wall = timestamp_at(self._wall_unix_s())
        self.signing.timestamp = self._streams.next_send_ticks(self.signing.timestamp, wall_ticks=wall)
        super().send(mavmsg, force_mavlink1=force_mavlink1)
        self._streams.sent(self.signing.timestamp)  # pymavlink added 1 per frame


def signature(msg: Any) -> Verdict:
    """A decoded message's signing verdict (UNSIGNED when it came through a MAVLink without a key)."""
    return getattr(msg, "_lrauv_signature", Verdict.UNSIGNED)


def end_datagram(mav: mavlink.MAVLink) -> None:
    """Drop what the parser holds of an unfinished frame: a datagram's bytes never join the next one's."""
    mav.buf = bytearray()
    mav.buf_index = 0
    mav.expected_length = mavlink.HEADER_LEN_V1 + 2  # pymavlink's state between frames


def from_autopilot(msg: Any, system: int = AUTOPILOT_SYSTEM) -> bool:
    return msg.get_srcSystem() == system and msg.get_srcComponent() == AUTOPILOT_COMPONENT


def time_boot_s(msg: Any) -> float | None:
    """Vehicle time of a message, when it carries ``time_boot_ms``."""
    ms = getattr(msg, "time_boot_ms", None)
    return None if ms is None else ms / 1000.0


def unix_offset_s(msg: Any) -> float | None:
    """SYSTEM_TIME: unix time minus vehicle time (s), or None while the autopilot has no UTC."""
    if msg.time_unix_usec <= 0:
        return None
    return msg.time_unix_usec / 1e6 - msg.time_boot_ms / 1000.0


def apply(vehicle: VehicleState, msg: Any, now_s: float) -> VehicleState:
    """The vehicle state after one message from the autopilot (unchanged for other messages)."""
    kind = msg.get_type()
    # The two per-decision messages build the state directly: 1 us instead of replace()'s 5 us.
    v = vehicle
    if kind == "GLOBAL_POSITION_INT":
        heading = v.heading_deg if msg.hdg == _UNKNOWN_HDG else (msg.hdg / 100.0) % 360.0
        depth_m = max(0.0, -msg.relative_alt / 1000.0)  # relative_alt is negative below the surface
        return VehicleState(msg.time_boot_ms / 1000.0, msg.lat / 1e7, msg.lon / 1e7, depth_m, heading, v.mode, v.armed,
                            v.position_ok, v.battery_pct, v.energy_used_wh, v.heartbeat_s, v.interval_acks,
                            v.position_s, v.autopilot_failsafe, v.ekf_reported)
    if kind == "ATTITUDE":
        return VehicleState(msg.time_boot_ms / 1000.0, v.lat_deg, v.lon_deg, v.depth_m, math.degrees(msg.yaw) % 360.0,
                            v.mode, v.armed, v.position_ok, v.battery_pct, v.energy_used_wh, v.heartbeat_s,
                            v.interval_acks, v.position_s, v.autopilot_failsafe, v.ekf_reported)
    if kind == "HEARTBEAT":
        armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        # ArduPilot reports MAV_STATE_CRITICAL while one of its failsafes is active (GCS, battery, ...).
        failsafe = msg.system_status == mavlink.MAV_STATE_CRITICAL
        return replace(vehicle, mode=int(msg.custom_mode), armed=armed, heartbeat_s=now_s, autopilot_failsafe=failsafe)
    if kind == "EKF_STATUS_REPORT":
        return replace(vehicle, position_ok=bool(msg.flags & mavlink.EKF_POS_HORIZ_ABS), ekf_reported=True)
    if kind == "BATTERY_STATUS":
        pct = None if msg.battery_remaining < 0 else float(msg.battery_remaining)
        wh = None if msg.energy_consumed < 0 else msg.energy_consumed / 36.0  # hJ -> Wh
        return replace(vehicle, battery_pct=pct if pct is not None else vehicle.battery_pct,
                       energy_used_wh=wh if wh is not None else vehicle.energy_used_wh)
    if (kind == "COMMAND_ACK" and msg.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
            and msg.result == mavlink.MAV_RESULT_ACCEPTED):
        return replace(vehicle, interval_acks=vehicle.interval_acks + 1)
    if kind == "SYS_STATUS" and msg.battery_remaining >= 0:
        return replace(vehicle, battery_pct=float(msg.battery_remaining))
    return vehicle


def encode(mav: mavlink.MAVLink, cmd: Command, *, time_boot_ms: int, target_system: int = AUTOPILOT_SYSTEM,
           target_component: int = AUTOPILOT_COMPONENT) -> Any:
    """The MAVLink message for a helm command, addressed to the autopilot."""
    ts, tc = target_system, target_component
    if isinstance(cmd, VelocityYaw):
        # The yaw rate is a magnitude: ArduSub turns toward the yaw at it, and a negative one would
        # turn it away (AC_AttitudeControl_Sub::input_euler_angle_roll_pitch_slew_yaw_cd).
        rate = cmd.yaw_rate_deg_s
        return mav.set_position_target_local_ned_encode(
            time_boot_ms, ts, tc, mavlink.MAV_FRAME_LOCAL_NED,
            MASK_VELOCITY_YAW if rate is None else MASK_VELOCITY_YAW_RATE,
            0.0, 0.0, 0.0, cmd.north_m_s, cmd.east_m_s, cmd.down_m_s, 0.0, 0.0, 0.0,
            math.radians(_wrap180(cmd.yaw_deg)), 0.0 if rate is None else math.radians(abs(rate)))
    if isinstance(cmd, DepthTarget):
        return mav.set_position_target_global_int_encode(
            time_boot_ms, ts, tc, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, MASK_DEPTH_ONLY,
            0, 0, -cmd.depth_m, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if isinstance(cmd, PositionTarget):
        return mav.set_position_target_global_int_encode(
            time_boot_ms, ts, tc, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, MASK_POSITION_ONLY,
            round(cmd.lat_deg * 1e7), round(cmd.lon_deg * 1e7), -cmd.depth_m,
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if isinstance(cmd, SetMode):
        return _command_long(mav, ts, tc, mavlink.MAV_CMD_DO_SET_MODE,
                             mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, int(cmd.mode))
    if isinstance(cmd, Arm):
        return _command_long(mav, ts, tc, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1 if cmd.arm else 0)
    if isinstance(cmd, SetMessageInterval):
        msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{cmd.message}")
        interval_us = -1 if cmd.interval_s <= 0 else round(cmd.interval_s * 1e6)
        return _command_long(mav, ts, tc, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us)
    raise TypeError(f"not a command: {cmd!r}")


def _command_long(mav: mavlink.MAVLink, ts: int, tc: int, command: int, *params: float) -> Any:
    p = list(params) + [0.0] * (7 - len(params))
    return mav.command_long_encode(ts, tc, command, 0, *p)


def _wrap180(deg: float) -> float:
    return (deg + 180.0) % 360.0 - 180.0


def heartbeat(mav: mavlink.MAVLink, *, healthy: bool) -> Any:
    """Our 1 Hz heartbeat: ONBOARD_CONTROLLER, autopilot INVALID (section 2.1)."""
    status = mavlink.MAV_STATE_ACTIVE if healthy else mavlink.MAV_STATE_CRITICAL
    return mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, status)


def progress_report(mav: mavlink.MAVLink, vehicle_s: float) -> Any:
    """TIMESYNC as a lockstep report: ``ts1`` the vehicle time (ns) up to which we have handled the autopilot.

    A TIMESYNC request (``tc1`` = 0) is harmless to any autopilot: ArduPilot answers it with its
    own clock (which the loop logs and otherwise ignores); ``vehicle_sim`` in lockstep does not step
    its physics past this time plus its slack (docs/executive.md, "Lockstep with the simulator").
    """
    return mav.timesync_encode(0, max(0, round(vehicle_s * 1000.0)) * 1_000_000)


def asks_for_progress(msg: Any, system: int = AUTOPILOT_SYSTEM) -> bool:
    """A TIMESYNC request (``tc1`` = 0) from the autopilot: a lockstep simulator waiting for our report."""
    return msg.get_msgId() == mavlink.MAVLINK_MSG_ID_TIMESYNC and msg.tc1 == 0 and from_autopilot(msg, system)


# The last STATUSTEXT chunk id used on each link (each ``MAVLink`` encoder is one link): ids count 1..65535
# per link, so that a ground station never sees two texts of one id in a row from us.
_TEXT_IDS: WeakKeyDictionary[mavlink.MAVLink, int] = WeakKeyDictionary()


def statustexts(mav: mavlink.MAVLink, event: Event) -> list[Any]:
    """``event`` as STATUSTEXT for the link ``mav`` encodes for: one message (id 0) when it fits in 50 bytes,
    else MAVLink 2 chunks (common.xml STATUSTEXT: one non-zero ``id``, ``chunk_seq`` 0, 1, ..., the last
    chunk shorter than 50 bytes, i.e. NUL-terminated), at most ``MAX_STATUSTEXT_CHUNKS`` of them.

    A text beyond that many chunks is cut, ending in "...". Chunks are UTF-8 and never split a
    character (``mission_protocol.status_chunks``, which the mission protocol's refusals use too).
    """
    severity = _SEVERITY[event.level]
    budget = MAX_STATUSTEXT_CHUNKS * mp.STATUSTEXT_LEN - 1  # bytes: the last chunk must stay shorter than 50
    chunks = mp.status_chunks(_clip(event.text, budget), chunk_id=1, severity=severity)
    while len(chunks) > MAX_STATUSTEXT_CHUNKS:  # characters that straddle chunk boundaries took room
        budget -= 3
        chunks = mp.status_chunks(_clip(event.text, budget), chunk_id=1, severity=severity)
    if len(chunks) > 1:
        text_id = _TEXT_IDS.get(mav, 0) % 65535 + 1
        _TEXT_IDS[mav] = text_id
        chunks = tuple(replace(c, chunk_id=text_id) for c in chunks)
    return [mp.encode(mav, chunk) for chunk in chunks]


def _clip(text: str, max_bytes: int) -> str:
    """``text`` if its UTF-8 takes at most ``max_bytes``, else cut to fit with "..." at the end."""
    data = text.encode("utf-8")
    if len(data) <= max_bytes:
        return text
    return data[: max_bytes - 3].decode("utf-8", "ignore") + "..."  # "ignore": a character the cut split


def describe(msg: Any) -> dict[str, Any]:
    """A JSON-ready record of a message for the log's raw MAVLink channels: decoded fields and the frame (base64)."""
    fields = {}
    for name in msg.get_fieldnames():
        value = getattr(msg, name)
        if isinstance(value, bytes | bytearray):
            value = value.decode("ascii", "replace").rstrip("\x00")
        elif isinstance(value, list):
            value = [v for v in value]
        fields[name] = value
    record = {"msg_id": msg.get_msgId(), "name": msg.get_type(), "src_system": msg.get_srcSystem(),
              "src_component": msg.get_srcComponent(), "fields": fields}
    frame = msg.get_msgbuf()  # the exact bytes on the wire, signature included; empty for a message never packed
    if frame:
        record["frame"] = base64.b64encode(bytes(frame)).decode("ascii")  # what a telemetry log (.tlog) holds
    return record


def command_text(msg: Any) -> str:
    """Short text of a COMMAND_ACK or STATUSTEXT from the autopilot, for the event log."""
    if msg.get_type() == "COMMAND_ACK":
        cmd = mavlink.enums["MAV_CMD"].get(msg.command)
        res = mavlink.enums["MAV_RESULT"].get(msg.result)
        return f"COMMAND_ACK {cmd.name if cmd else msg.command}: {res.name if res else msg.result}"
    text = msg.text if isinstance(msg.text, str) else bytes(msg.text).decode("ascii", "replace")
    return f"autopilot: {text.rstrip(chr(0))}"


# -- commands to the executive (docs/executive.md, "Authority") --------------------------

MAV_CMD_MISSION_START = mavlink.MAV_CMD_MISSION_START  # an operator's explicit go: resume, clear the safety stop
MAV_RESULT_ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
MAV_RESULT_UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED


def command_ack(mav: mavlink.MAVLink, command: int, result: int, peer: tuple[int, int]) -> Any:
    """COMMAND_ACK for a command the executive received from ``peer`` (system, component)."""
    return mav.command_ack_encode(command, result, 0, 0, peer[0], peer[1])


# -- the ground-station link as a router sees it (executive.ground_station) ---------------

def listening(conn: Any) -> bool:
    """Whether a write on ``conn`` reaches anyone now: a listening UDP link only writes to clients heard recently."""
    recipients = getattr(conn, "recipients", None)
    if recipients is not None and getattr(conn, "udp_server", False):
        return bool(recipients(time.monotonic()))
    return not getattr(conn, "closed", False)


def forward(conn: Any, frame: bytes) -> bool:
    """Write another node's frame as it came (never re-packed or re-signed); False when the send failed."""
    try:
        conn.write(frame)
    except Exception:  # a router drops what it cannot send, as UDP may; the loop never stops for it
        return False
    return True


def param_value(mav: mavlink.MAVLink, name: str, value: float, index: int, count: int) -> Any:
    """PARAM_VALUE of one of the executive's parameters (all MAV_PARAM_TYPE_REAL32, executive.parameters)."""
    return mav.param_value_encode(name.encode("ascii"), value, mavlink.MAV_PARAM_TYPE_REAL32, count, index)


# What the executive's component speaks: MAVLink 2, MAVLink FTP, MISSION_ITEM_INT, float parameters.
CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_FTP
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT)


def autopilot_version(mav: mavlink.MAVLink) -> Any:
    """AUTOPILOT_VERSION of the executive's component: its capabilities; versions and ids 0 (not known)."""
    return mav.autopilot_version_encode(CAPABILITIES, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0, [0] * 18)
