"""Telemetry checks: every field the helm uses is screened before it reaches a decision.

A sample that cannot be true (a position at 0, 0, which ArduSub reports before its GPS has a
fix; a NaN; a battery outside 0..100 %) is dropped. One that could be true but disagrees with
the last accepted value by more than the vehicle and the current can do (a 50 km jump, a
100 m depth step in half a second, a battery reading of 0 after 80 %) is held in doubt and
dropped; it is believed only when ``persist_samples`` such samples in a row agree with each
other, so one bad sample never decides anything, while a real change (a GPS reset at the
surface, a battery that really failed) is taken after a few samples (docs/executive.md,
"Bad samples"). A position is used only while the EKF's latest EKF_STATUS_REPORT has
EKF_POS_HORIZ_ABS: before the first such report (ArduSub: about 41 s after boot) none is, and
the drops before the first accepted position are counted without a warning each (set-up says
what it waits for). A heading that stays unknown for ``persist_samples`` samples becomes
unknown (None), never a number.

Pure functions on frozen values: the loop and the decision audit run the same ``screen``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal

from executive.state import Event, VehicleState
from planner.contract.geodesy import EARTH_RADIUS_M

Field = Literal["position", "depth", "heading", "battery"]
Metric = Callable[[tuple[float, ...], tuple[float, ...]], float]
TimeVerdict = Literal["take", "drop", "wrapped", "reboot"]

# time_boot_ms is a uint32 of milliseconds: it wraps to 0 after 49.7 days of uptime (MAVLink common.xml).
WRAP_S = 2**32 / 1000.0
_WRAP_WINDOW_S = 600.0  # a step back from this close to the wrap, to this close after 0, is the wrap
_REBOOT_BACKSTEP_S = 5.0  # time_boot_ms going back by more than this is a reboot (once it persists), not reordering


@dataclass(frozen=True, kw_only=True)
class Limits:
    """What the vehicle and the water can do between two samples, and how many samples make a change true."""

    max_ground_speed_m_s: float = 5.0  # vehicle plus the strongest current, with a margin
    position_noise_m: float = 30.0  # GPS and EKF scatter allowed on top of the motion
    max_vertical_speed_m_s: float = 2.0  # ArduSub changes depth at about 1 m/s in ALT_HOLD
    depth_noise_m: float = 2.0
    max_battery_step_pct: float = 5.0  # between two samples; a battery drains over hours
    persist_samples: int = 3
    max_clock_jump_s: float = 60.0  # vehicle seconds ahead of the clock's extrapolation


@dataclass(frozen=True, slots=True)
class Channel:
    """One field's last accepted value and the run of samples held in doubt against it."""

    value: tuple[float, ...] | None = None
    time_s: float | None = None
    doubt: tuple[float, ...] | None = None  # the latest sample held in doubt
    doubt_time_s: float | None = None
    doubts: int = 0  # samples in doubt in a row, each agreeing with the one before
    invalid: int = 0  # impossible samples in a row


@dataclass(frozen=True, slots=True)
class Gate:
    """The checks' state: a channel per field."""

    position: Channel = Channel()
    depth: Channel = Channel()
    heading: Channel = Channel()
    battery: Channel = Channel()
    dropped: int = 0  # samples dropped so far (counted, logged at the first of each run)


@dataclass(frozen=True, slots=True)
class Screened:
    gate: Gate
    vehicle: VehicleState
    events: tuple[Event, ...] = ()


def screen(gate: Gate, before: VehicleState, after: VehicleState, kind: str, limits: Limits,
           time_s: float | None = None) -> Screened:
    """``after`` (the state ``mavlink_bridge.apply`` made from one message of type ``kind``) with bad fields undone.

    ``time_s``: the message's continuous vehicle time (``stamp``), which replaces the raw one across a wrap.
    """
    events: list[Event] = []
    if time_s is not None and kind in ("GLOBAL_POSITION_INT", "ATTITUDE") and after.time_s != time_s:
        after = replace(after, time_s=time_s)  # across a wrap: the copy only when it changes something
    t = after.time_s
    vehicle = after
    if kind == "GLOBAL_POSITION_INT":
        gate, vehicle = _position(gate, before, vehicle, t, limits, events)
        gate, vehicle = _depth(gate, before, vehicle, t, limits, events)
    if kind in ("GLOBAL_POSITION_INT", "ATTITUDE") and (after.heading_deg != before.heading_deg or kind == "ATTITUDE"):
        gate, vehicle = _heading(gate, before, vehicle, t, limits, events)
    if kind in ("BATTERY_STATUS", "SYS_STATUS") and after.battery_pct != before.battery_pct:
        gate, vehicle = _battery(gate, before, vehicle, t, limits, events)
    return Screened(gate, vehicle, tuple(events))


# -- the fields ---------------------------------------------------------------------


def _position(gate: Gate, before: VehicleState, v: VehicleState, t: float, limits: Limits,
              events: list[Event]) -> tuple[Gate, VehicleState]:
    lat, lon = v.lat_deg, v.lon_deg
    assert lat is not None and lon is not None  # GLOBAL_POSITION_INT always carries both
    reason = None
    if not (math.isfinite(lat) and math.isfinite(lon)) or abs(lat) > 90.0 or abs(lon) > 180.0:
        reason = f"position (lon, lat) {lon}, {lat} is not a position"
    elif lat == 0.0 and lon == 0.0:
        reason = "position 0, 0: no fix"
    elif not v.position_ok:
        reason = ("the EKF reports no absolute horizontal position" if v.ekf_reported
                  else "no EKF_STATUS_REPORT with EKF_POS_HORIZ_ABS yet")
    # Before any position was accepted, no fix and no EKF position are the autopilot starting up, not
    # faults: counted without a warning (set-up announces what it waits for).
    starting = reason is not None and gate.position.value is None and not reason.endswith("is not a position")
    ch, verdict, text = _judge(gate.position, (lat, lon), t, reason, _distance_m, limits.max_ground_speed_m_s,
                               limits.position_noise_m, limits.persist_samples, "m")
    gate = replace(gate, position=ch)
    if verdict == "drop":
        gate = _count(gate, text, "position", events, quiet=starting)
        return gate, replace(v, lat_deg=before.lat_deg, lon_deg=before.lon_deg, position_s=before.position_s)
    if text is not None:
        events.append(Event("warning", f"position: {text}"))
    return gate, replace(v, position_s=t)


def _depth(gate: Gate, before: VehicleState, v: VehicleState, t: float, limits: Limits,
           events: list[Event]) -> tuple[Gate, VehicleState]:
    depth = v.depth_m
    assert depth is not None
    reason = None if math.isfinite(depth) and depth <= 11_000.0 else f"depth {depth} m is not a depth"
    gate, taken = _scalar(gate, "depth", depth, t, reason, limits.max_vertical_speed_m_s, limits.depth_noise_m, "m",
                          limits, events)
    return gate, v if taken else replace(v, depth_m=before.depth_m)


def _heading(gate: Gate, before: VehicleState, v: VehicleState, t: float, limits: Limits,
             events: list[Event]) -> tuple[Gate, VehicleState]:
    heading = v.heading_deg
    if heading is not None and math.isfinite(heading):
        return replace(gate, heading=Channel(value=(heading,), time_s=t)), v
    ch = gate.heading
    ch = replace(ch, invalid=ch.invalid + 1)
    gate = replace(gate, heading=ch)
    if ch.invalid == 1:
        gate = _count(gate, f"heading {heading} is not a heading", "heading", events)
    else:
        gate = replace(gate, dropped=gate.dropped + 1)
    if ch.invalid >= limits.persist_samples:  # a heading that stays unknown is unknown, never a number
        if before.heading_deg is not None:
            events.append(Event("warning", f"heading unknown for {ch.invalid} samples: no steering by heading"))
        return gate, replace(v, heading_deg=None)
    return gate, replace(v, heading_deg=before.heading_deg)


def _battery(gate: Gate, before: VehicleState, v: VehicleState, t: float, limits: Limits,
             events: list[Event]) -> tuple[Gate, VehicleState]:
    pct = v.battery_pct
    assert pct is not None
    reason = None if math.isfinite(pct) and 0.0 <= pct <= 100.0 else f"battery {pct} % is not a charge"
    # A step, not a rate: battery reports come every few seconds and a battery drains over hours.
    gate, taken = _scalar(gate, "battery", pct, t, reason, 0.0, limits.max_battery_step_pct, "%", limits, events)
    return gate, v if taken else replace(v, battery_pct=before.battery_pct)


def _scalar(gate: Gate, what: Literal["depth", "battery"], value: float, t: float, reason: str | None, rate: float,
            noise: float, unit: str, limits: Limits, events: list[Event]) -> tuple[Gate, bool]:
    """Judge a one-number field; whether its sample is taken."""
    ch, verdict, text = _judge(getattr(gate, what), (value,), t, reason, _difference, rate, noise,
                               limits.persist_samples, unit)
    gate = replace(gate, depth=ch) if what == "depth" else replace(gate, battery=ch)
    if verdict == "drop":
        return _count(gate, text, what, events), False
    if text is not None:
        events.append(Event("warning", f"{what}: {text}"))
    return gate, True


# -- the vehicle's clock ----------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class BootTime:
    """``time_boot_ms`` made continuous across the 32-bit wrap, with jumps held in doubt like any field."""

    epoch_s: float = 0.0  # whole wraps so far
    doubt_s: float | None = None  # the latest timestamp held in doubt (a jump, either way)
    doubt_wall_s: float = 0.0
    doubts: int = 0


@dataclass(frozen=True, slots=True)
class Stamped:
    boot: BootTime
    verdict: TimeVerdict
    time_s: float  # the continuous vehicle time of the message (meaningless when dropped)
    text: str | None = None


def _undoubted(boot: BootTime) -> BootTime:
    """``boot`` with no doubt pending; itself when it has none (every message in order: no copy)."""
    return boot if boot.doubt_s is None and boot.doubts == 0 else replace(boot, doubt_s=None, doubts=0)


def stamp(boot: BootTime, raw_s: float, *, last_s: float | None, expected_s: float | None, rate: float,
          wall_s: float, limits: Limits) -> Stamped:
    """Judge one message's ``time_boot_ms`` (in s) against the newest accepted time and the clock's extrapolation.

    A jump forward beyond ``max_clock_jump_s`` of what the clock expects, or back by more than
    5 s, is dropped until ``persist_samples`` timestamps in a row agree with it: then a jump
    forward is taken and a jump back is an autopilot reboot. One bad timestamp never moves the
    clock or resets the helm.
    """
    t = raw_s + boot.epoch_s
    if last_s is None or expected_s is None:
        return Stamped(_undoubted(boot), "take", t)
    if last_s - boot.epoch_s > WRAP_S - _WRAP_WINDOW_S and raw_s < _WRAP_WINDOW_S:
        epoch = boot.epoch_s + WRAP_S
        return Stamped(BootTime(epoch_s=epoch), "wrapped", raw_s + epoch,
                       f"time_boot_ms wrapped after {WRAP_S / 86400:.1f} days: vehicle time goes on at {raw_s + epoch:,.1f} s")
    forward = t > expected_s + limits.max_clock_jump_s
    back = t < last_s - _REBOOT_BACKSTEP_S
    if not (forward or back):
        return Stamped(_undoubted(boot), "take", t)
    slack = limits.max_clock_jump_s
    agrees = (boot.doubt_s is not None
              and abs(t - (boot.doubt_s + rate * max(0.0, wall_s - boot.doubt_wall_s))) <= slack)
    doubts = boot.doubts + 1 if agrees else 1
    if doubts >= limits.persist_samples:
        verdict: TimeVerdict = "take" if forward else "reboot"
        text = (f"vehicle time jumped {t - expected_s:,.1f} s ahead and held for {doubts} messages: taken" if forward
                else None)
        return Stamped(BootTime(epoch_s=boot.epoch_s), verdict, t, text)
    what = "ahead of" if forward else "behind"
    text = f"time_boot_ms {raw_s:,.3f} s is {abs(t - (expected_s if forward else last_s)):,.1f} s {what} the vehicle clock"
    return Stamped(BootTime(epoch_s=boot.epoch_s, doubt_s=t, doubt_wall_s=wall_s, doubts=doubts), "drop", t, text)


# -- the rule -------------------------------------------------------------------------


def _judge(ch: Channel, sample: tuple[float, ...], t: float, reason: str | None, distance: Metric, rate: float,
           noise: float, persist: int, unit: str) -> tuple[Channel, Literal["take", "drop"], str | None]:
    """Take or drop one sample; the text says why it was dropped, or that a doubted change was believed."""
    if reason is not None:
        return replace(ch, invalid=ch.invalid + 1), "drop", reason
    if ch.value is None or ch.time_s is None:
        return Channel(value=sample, time_s=t), "take", None
    step = distance(ch.value, sample)
    if step <= rate * max(0.0, t - ch.time_s) + noise:
        return Channel(value=sample, time_s=t), "take", None
    # Implausible against the last accepted value: believed only once it persists.
    agrees = (ch.doubt is not None and ch.doubt_time_s is not None
              and distance(ch.doubt, sample) <= rate * max(0.0, t - ch.doubt_time_s) + noise)
    doubts = ch.doubts + 1 if agrees else 1
    if doubts >= persist:
        return Channel(value=sample, time_s=t), "take", (f"a step of {step:,.1f} {unit} held for {doubts} samples:"
                                                          " taken as the new value")
    text = f"a step of {step:,.1f} {unit} from the last accepted value in {max(0.0, t - ch.time_s):.1f} s"
    return replace(ch, doubt=sample, doubt_time_s=t, doubts=doubts, invalid=0), "drop", text


def _count(gate: Gate, text: str | None, what: Field, events: list[Event], *, quiet: bool = False) -> Gate:
    """Count a dropped sample; the first of a run is logged (the rest would flood the log at 2 Hz)."""
    ch: Channel = getattr(gate, what)
    first = ch.invalid + ch.doubts <= 1
    if first and not quiet:
        events.append(Event("warning", f"{what} sample dropped: {text}"))
    return replace(gate, dropped=gate.dropped + 1)


def _distance_m(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """Great-circle distance between two (lat, lon) in degrees (haversine)."""
    lat1, lon1, lat2, lon2 = map(math.radians, (a[0], a[1], b[0], b[1]))
    h = math.sin((lat2 - lat1) / 2) ** 2 + math.cos(lat1) * math.cos(lat2) * math.sin((lon2 - lon1) / 2) ** 2
    return 2.0 * EARTH_RADIUS_M * math.asin(min(1.0, math.sqrt(h)))


def _difference(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    return abs(a[0] - b[0])
