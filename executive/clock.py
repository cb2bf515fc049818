"""The vehicle's clock, as the executive sees it.

All executive timing (heartbeat pacing, target refresh, timeouts, link loss)
runs on the autopilot's ``time_boot_ms``, so the executive works unchanged at
any simulator speedup (ArduPilot SITL's time_boot_ms scales with its
``--speedup``). Between two timestamps, and through a link silence, vehicle time
is extrapolated from wall time at real time (``SILENCE_RATE``: one vehicle second
per wall second), never at the speedup measured so far.

Why real time: during a silence the executive cannot tell a vehicle that goes on
(the link is down) from an autopilot process that has stopped (ArduSub SITL,
stalled for 3 s of wall time by its own log writes, then went on where it had
stopped); the vehicle's own clock has advanced by anything from nothing to the
speedup times the wall time. A vehicle runs at real time, so for it the two are
the same and the link is lost after ``link_loss_timeout_s`` of its time, as ever.
A simulator's silence counts as wall time: a stalled process is not a silent
vehicle unless it stays stalled for the whole timeout, and a dead one is still
noticed, after the timeout in wall seconds. The price: a simulator that dies at
1000x is noticed after 30 s of wall time (30,000 of its seconds), not 30 ms; one
slower than real time is declared lost after fewer of its own seconds.

At a simulator's speedup (a measured rate of 2x or more, or before any rate is measured)
vehicle time does not run on at all during the first ``SILENCE_GRACE_WALL_S`` of wall time
after the last timestamp: a simulator in lockstep (``vehicle_sim``) waits for the executive,
and a simulator on a busy machine may be descheduled for milliseconds that are seconds of
vehicle time at 1000x; neither is a silent link, and the executive's heartbeats and lockstep
reports must not run ahead of the vehicle. At real time (a vehicle, rate near 1) there is no grace.

Never back: ``now_s`` does not decrease between reboots. A timestamp older than what was
already extrapolated (a message late on the link, or a stalled simulator that went on)
holds the clock where it is until the vehicle's time passes it; a timer due at the
extrapolated time never fires twice. Only a reboot (``time_boot_ms`` back by more than
5 s) starts the clock afresh.
"""

from __future__ import annotations

from dataclasses import dataclass

# Smoothing of the observed rate (vehicle seconds per wall second).
_RATE_GAIN = 0.2
# Rate estimates use spans of at least this much wall time (scheduling jitter dominates below).
_MIN_SPAN_WALL_S = 0.02
# The first estimate replaces the 1x guess outright, from a shorter span: at a simulator speedup the
# vehicle is set up within milliseconds, and its grace must hold from then on.
_FIRST_SPAN_WALL_S = 0.005
# time_boot_ms going back by more than this is a reboot of the autopilot, not reordering.
_REBOOT_BACKSTEP_S = 5.0
# Wall seconds of silence during which a simulator's time is not extrapolated (see the module docstring).
SILENCE_GRACE_WALL_S = 1.0
# Vehicle seconds per wall second between timestamps and through a silence (see the module docstring).
SILENCE_RATE = 1.0
# Rates from this up are a simulator's speedup (a vehicle runs at 1x).
_SIMULATOR_RATE = 2.0


@dataclass(slots=True)
class VehicleClock:
    """Maps wall time to vehicle time; fed with every ``time_boot_ms`` seen."""

    rate: float = 1.0  # measured vehicle seconds per wall second (the simulator's speedup)
    max_rate: float = 1e5
    _vehicle_s: float | None = None
    _wall_s: float = 0.0
    _anchor_vehicle_s: float | None = None
    _anchor_wall_s: float = 0.0
    _rated: bool = False  # a rate has been measured (until then ``rate`` is the 1x guess)
    _floor_s: float = 0.0  # the latest time ``now_s`` gave: it never goes below (until a reboot)
    reboots: int = 0

    @property
    def synced(self) -> bool:
        return self._vehicle_s is not None

    def observe(self, time_boot_s: float, wall_s: float) -> bool:
        """Record a vehicle timestamp; returns True when it reveals an autopilot reboot."""
        if self._vehicle_s is None or time_boot_s < self._vehicle_s - _REBOOT_BACKSTEP_S:
            rebooted = self._vehicle_s is not None
            if rebooted:
                self.reboots += 1
            self._vehicle_s, self._wall_s = time_boot_s, wall_s
            self._anchor_vehicle_s, self._anchor_wall_s = time_boot_s, wall_s
            self._floor_s = time_boot_s
            return rebooted
        if time_boot_s <= self._vehicle_s:
            return False  # duplicate or reordered datagram: keep the newest time
        self._vehicle_s, self._wall_s = time_boot_s, wall_s
        assert self._anchor_vehicle_s is not None
        span_wall = wall_s - self._anchor_wall_s
        if span_wall >= (_MIN_SPAN_WALL_S if self._rated else _FIRST_SPAN_WALL_S):
            observed = (time_boot_s - self._anchor_vehicle_s) / span_wall
            observed = min(max(observed, 0.0), self.max_rate)
            self.rate = self.rate + _RATE_GAIN * (observed - self.rate) if self._rated else observed
            self._rated = True
            self._anchor_vehicle_s, self._anchor_wall_s = time_boot_s, wall_s
        return False

    @property
    def last_s(self) -> float | None:
        """The newest vehicle timestamp seen (None before the first)."""
        return self._vehicle_s

    def _grace_s(self) -> float:
        """Wall seconds of silence not extrapolated: the grace at a simulator's speedup, else none."""
        return SILENCE_GRACE_WALL_S if (not self._rated or self.rate >= _SIMULATOR_RATE) else 0.0

    def now_s(self, wall_s: float) -> float:
        """Vehicle time now: the last timestamp plus the time extrapolated since it arrived, never less than before."""
        if self._vehicle_s is None:
            return 0.0
        extrapolated = self._vehicle_s + max(0.0, wall_s - self._wall_s - self._grace_s()) * SILENCE_RATE
        self._floor_s = max(self._floor_s, extrapolated)
        return self._floor_s

    def latest_s(self, wall_s: float) -> float:
        """The latest vehicle time the autopilot can have reached: extrapolated at the measured rate (after
        the grace). A bound for judging the next timestamp after a silence (a simulator that ran on at its
        speedup is no clock jump), never for timing."""
        if self._vehicle_s is None:
            return 0.0
        return max(self.now_s(wall_s),
                   self._vehicle_s + max(0.0, wall_s - self._wall_s - self._grace_s()) * max(self.rate, SILENCE_RATE))

    def wall_until(self, vehicle_s: float, wall_s: float) -> float:
        """Wall seconds until vehicle time reaches ``vehicle_s`` (0 when already past)."""
        if self._vehicle_s is None:
            return max(0.0, vehicle_s / SILENCE_RATE)
        if vehicle_s <= self.now_s(wall_s):
            return 0.0
        due_wall = self._wall_s + self._grace_s() + (vehicle_s - self._vehicle_s) / SILENCE_RATE
        return max(0.0, due_wall - wall_s)
