"""MAVLink 2 message signing: the key, the clock, and which frames the executive accepts.

A signed MAVLink 2 frame has bit 0x01 of its incompatibility flags set and 13 more bytes
(mavlink.io, "Message Signing"): the sender's link id (1 byte), a timestamp (6 bytes,
little-endian, 10 us units since 2015-01-01 00:00 UTC) and the first 6 bytes of
sha256(secret key + the frame up to and including the timestamp). pymavlink frames and signs
(``executive.mavlink_bridge``, the only pymavlink import); this module says what a frame is
worth, with no socket and no pymavlink:

- ``SigningKey``: 32 bytes, from a key file (32 raw bytes or 64 hex digits) or a passphrase
  (sha256 of its ASCII bytes, MAVProxy's ``signing key PASSPHRASE``).
- ``judge``: one signed frame against the key and its stream's last timestamp, in the MAVLink
  C library's order (``mavlink_signature_check``): the signature first, then the timestamp. A
  stream is (link id, system, component); within it timestamps must increase, and a stream
  not seen before may start at most one minute behind our clock. pymavlink's own
  ``check_signature`` records the timestamp before it compares the signature, so one forged
  frame with a far-future timestamp would shut out the real sender; ``judge`` records nothing.
- ``Streams``: the last timestamp of every stream and our clock, shared by both links as
  ArduPilot shares one ``signing_streams`` table over all channels (GCS_Signing.cpp).
- ``must_be_signed``: everything on the ground-station link; on the autopilot link, the
  uploads and commands a ground station behind the autopilot addresses to us. Telemetry from
  the autopilot, and the radio's RADIO_STATUS, may come unsigned.
- ``RefusalLog``: refusals are counted always and logged at most once per period (per verdict
  and link, in the loop), so a flood of bad frames cannot fill the log.
"""

from __future__ import annotations

import hashlib
import math
import os
import struct
from dataclasses import dataclass, field, replace
from enum import Enum, unique
from pathlib import Path

from executive.mission_protocol import RECEIVER_MESSAGES
from planner.contract.errors import ExecutiveError

KEY_BYTES = 32
EPOCH_UNIX_S = 1_420_070_400  # 2015-01-01T00:00:00Z, the signing epoch
TICKS_PER_S = 100_000  # timestamps count 10 us
NEW_STREAM_MAX_AGE_TICKS = 60 * TICKS_PER_S  # C library: "not more than 1 minute old" (6000*1000)
IFLAG_SIGNED = 0x01
SIGNATURE_BYTES = 13  # link id 1, timestamp 6, signature 6
_MAGIC_V2 = 0xFD
_HEADER_BYTES = 10

# Our own link ids (the C library's rule: the channel number): the signer's id is part of its stream.
LINK_ID_AUTOPILOT = 0
LINK_ID_GROUND_STATION = 1

COMMANDS = frozenset({"COMMAND_LONG", "COMMAND_INT"})
GUARDED_MESSAGES = RECEIVER_MESSAGES | {"FILE_TRANSFER_PROTOCOL"} | COMMANDS
"""What changes the executive's mission: mission-protocol and FTP uploads (``Uploads.MESSAGES``), and commands."""
UNSIGNED_ALLOWED = frozenset({"RADIO_STATUS", "RADIO"})  # a telemetry radio's own (ArduPilot's accept_list, MAVProxy's)


class SigningError(ExecutiveError):
    """A signing key that cannot be used: the message names where it was configured."""


@dataclass(frozen=True)
class SigningKey:
    """A MAVLink 2 secret key (32 bytes). Never printed: ``fingerprint`` identifies it in logs."""

    secret: bytes = field(repr=False)

    def __post_init__(self) -> None:
        if len(self.secret) != KEY_BYTES:
            raise SigningError(f"a signing key is {KEY_BYTES} bytes; got {len(self.secret)}")
        if not any(self.secret):  # ArduPilot reads an all-zero key as "signing off" (load_signing_key)
            raise SigningError("a signing key of all zeros turns signing off in ArduPilot; generate a random one")

    @property
    def fingerprint(self) -> str:
        """8 hex digits to compare keys by (both ``lrauv exec`` and ``lrauv upload`` print it)."""
        return hashlib.sha256(b"lrauv signing key fingerprint\0" + self.secret).hexdigest()[:8]

    @classmethod
    def from_passphrase(cls, passphrase: str) -> SigningKey:
        """sha256 of the ASCII passphrase: the key MAVProxy's ``signing key PASSPHRASE`` uses."""
        if not passphrase:
            raise SigningError("the passphrase is empty")
        try:
            data = passphrase.encode("ascii")  # MAVProxy encodes ASCII (mavproxy_signing.passphrase_to_key)
        except UnicodeEncodeError:
            raise SigningError("the passphrase must be ASCII, as MAVProxy's `signing key` needs") from None
        return cls(hashlib.sha256(data).digest())

    @classmethod
    def from_file_bytes(cls, data: bytes) -> SigningKey:
        """A key file's content: 32 raw bytes, or 64 hex digits (surrounding whitespace ignored)."""
        if len(data) == KEY_BYTES:
            return cls(data)
        text = data.strip()
        if len(text) == 2 * KEY_BYTES:
            try:
                return cls(bytes.fromhex(text.decode("ascii")))
            except (UnicodeDecodeError, ValueError):
                pass
        raise SigningError(f"expected {KEY_BYTES} raw bytes or {2 * KEY_BYTES} hex digits; got {len(data)} bytes"
                           f" that are neither")


def load_key(*, key_file: Path | None = None, passphrase_env: str | None = None, where: str = "") -> SigningKey:
    """The key from exactly one source; errors start with ``where`` (the mission line, or the flag)."""
    prefix = f"{where}: " if where else ""
    if (key_file is None) == (passphrase_env is None):
        raise SigningError(f"{prefix}expected exactly one of a key file or a passphrase variable")
    if key_file is not None:
        try:
            data = key_file.read_bytes()
        except OSError as exc:
            raise SigningError(f"{prefix}cannot read {key_file}: {exc.strerror or exc}") from None
        try:
            return SigningKey.from_file_bytes(data)
        except SigningError as exc:
            raise SigningError(f"{prefix}{key_file}: {exc}") from None
    assert passphrase_env is not None
    passphrase = os.environ.get(passphrase_env)
    if passphrase is None:
        raise SigningError(f"{prefix}environment variable {passphrase_env} is not set")
    try:
        return SigningKey.from_passphrase(passphrase)
    except SigningError as exc:
        raise SigningError(f"{prefix}${passphrase_env}: {exc}") from None


def timestamp_at(unix_s: float) -> int:
    """The signing timestamp (10 us units since 2015-01-01 UTC) of a Unix time in seconds."""
    return max(0, math.floor((unix_s - EPOCH_UNIX_S) * TICKS_PER_S))


# -- frames ------------------------------------------------------------------------------------

def is_signed(frame: bytes) -> bool:
    """Whether a MAVLink frame says it is signed (MAVLink 2, incompat flag 0x01, room for the block)."""
    return (len(frame) >= _HEADER_BYTES + 2 + SIGNATURE_BYTES and frame[0] == _MAGIC_V2
            and bool(frame[2] & IFLAG_SIGNED))


def frame_stream(frame: bytes) -> tuple[int, int, int]:
    """(link id, system, component) of a signed frame: the stream its timestamps belong to."""
    return frame[-SIGNATURE_BYTES], frame[5], frame[6]


def frame_timestamp(frame: bytes) -> int:
    """The signing timestamp of a signed frame, 10 us ticks."""
    low, high = struct.unpack_from("<IH", frame, len(frame) - 12)
    return low | (high << 32)


def signature_ok(frame: bytes, key: SigningKey) -> bool:
    """Whether the frame's 6 signature bytes are sha256(key + everything before them)[:6]."""
    return hashlib.sha256(key.secret + frame[:-6]).digest()[:6] == frame[-6:]


@unique
class Verdict(Enum):
    """What a frame's signature is worth."""

    SIGNED = "signed"  # by our key, with a fresh timestamp
    UNSIGNED = "unsigned"
    BAD_SIGNATURE = "wrongly signed"  # another key, or altered on the way
    REPLAYED = "replayed"  # a timestamp not after its stream's last
    TOO_OLD = "too old"  # a new stream starting more than a minute behind our clock


def judge(frame: bytes, key: SigningKey, *, last_ticks: int | None, now_ticks: int) -> Verdict:
    """One frame's verdict: ``last_ticks`` is its stream's last accepted timestamp (None: a new stream)."""
    if not is_signed(frame):
        return Verdict.UNSIGNED
    if not signature_ok(frame, key):
        return Verdict.BAD_SIGNATURE
    stamp = frame_timestamp(frame)
    if last_ticks is not None:
        return Verdict.SIGNED if stamp > last_ticks else Verdict.REPLAYED
    return Verdict.TOO_OLD if stamp + NEW_STREAM_MAX_AGE_TICKS < now_ticks else Verdict.SIGNED


@dataclass
class Streams:
    """The last accepted timestamp of each stream, and our clock (10 us ticks).

    Mutable, on purpose: the one piece of signing state, shared by the executive's two links.
    Only frames that verify change it, so a sender without the key cannot move it.
    """

    key: SigningKey
    clock_ticks: int = 0  # the newest of: the wall clock, our own last timestamp, any accepted frame's
    last_ticks: dict[tuple[int, int, int], int] = field(default_factory=dict)

    def admit(self, frame: bytes, *, wall_ticks: int) -> Verdict:
        """Judge a frame; a SIGNED one advances its stream and our clock (mavlink.io "Timestamp handling")."""
        self.clock_ticks = max(self.clock_ticks, wall_ticks)
        stream = frame_stream(frame) if is_signed(frame) else None
        verdict = judge(frame, self.key, last_ticks=self.last_ticks.get(stream) if stream else None,
                        now_ticks=self.clock_ticks)
        if verdict is Verdict.SIGNED:
            assert stream is not None
            stamp = frame_timestamp(frame)
            self.last_ticks[stream] = stamp
            self.clock_ticks = max(self.clock_ticks, stamp)
        return verdict

    def next_send_ticks(self, own_ticks: int, *, wall_ticks: int) -> int:
        """The timestamp to sign our next frame with: never behind the wall clock, so a ground station
        that meets our stream for the first time does not find it more than a minute old."""
        self.clock_ticks = max(self.clock_ticks, own_ticks, wall_ticks)
        return self.clock_ticks

    def sent(self, own_ticks: int) -> None:
        """pymavlink adds 1 per frame signed: our clock follows."""
        self.clock_ticks = max(self.clock_ticks, own_ticks)


# -- the executive's rule --------------------------------------------------------------------------

@unique
class Link(Enum):
    AUTOPILOT = "autopilot link"
    GROUND_STATION = "ground-station link"


def must_be_signed(kind: str, *, link: Link, from_autopilot: bool, for_us: bool) -> bool:
    """Whether a message of type ``kind`` is refused unless ``Verdict.SIGNED`` (with a key configured).

    The ground-station link carries nothing but ground-station traffic: all of it. The
    autopilot link carries the autopilot's telemetry (unsigned on ArduSub's own link; not
    protected) and what a ground station behind the autopilot routes to us: its uploads and
    commands addressed to us (system 1, component 191, or broadcast).
    """
    if kind in UNSIGNED_ALLOWED:
        return False
    if link is Link.GROUND_STATION:
        return True
    return not from_autopilot and for_us and kind in GUARDED_MESSAGES


@dataclass(frozen=True)
class RefusalLog:
    """When to log a refusal: the first at once, then at most one line per ``period_s`` of wall time."""

    period_s: float = 10.0
    next_wall_s: float = -math.inf
    held: int = 0  # refusals since the last line


def note_refusal(log: RefusalLog, wall_s: float) -> tuple[RefusalLog, int | None]:
    """The log after one more refusal, and how many refusals a line written now covers (None: stay quiet)."""
    if wall_s < log.next_wall_s:
        return replace(log, held=log.held + 1), None
    return RefusalLog(period_s=log.period_s, next_wall_s=wall_s + log.period_s, held=0), log.held + 1


def refusal_text(verdict: Verdict, kind: str, source: tuple[int, int], link: Link, covers: int) -> str:
    """The warning for a refusal: what, from whom, on which link, and how many since the last line."""
    more = f" (and {covers - 1} more since the last report)" if covers > 1 else ""
    return (f"refused {verdict.value} {kind} from {source[0]}/{source[1]} on the {link.value}:"
            f" signing is required{more}")
