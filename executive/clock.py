"""The vehicle's clock, as the executive sees it.

All executive timing (heartbeat pacing, target refresh, timeouts, link loss)
runs on the autopilot's ``time_boot_ms``, so the executive works unchanged at
any simulator speedup (ArduPilot SITL's time_boot_ms scales with its
``--speedup``). Between messages, and during a link
silence, vehicle time is extrapolated from wall time at the rate observed so
far, so the heartbeat keeps its 1 Hz in vehicle time and a silent link is
noticed after the right number of vehicle seconds.

At a simulator speedup (a measured rate of 2x or more, or before any rate is measured)
vehicle time does not run on during the first ``SILENCE_GRACE_WALL_S`` of wall time
after the last timestamp: a simulator in lockstep (``vehicle_sim``) waits for the
executive, and a simulator on a busy machine may be descheduled for milliseconds that
are seconds of vehicle time at 1000x; neither is a silent link. After the grace, time
runs on at the measured rate from the last timestamp, so a real silence is still
noticed, one grace late. At real time (a vehicle, rate near 1) nothing changes.
"""

from __future__ import annotations

from dataclasses import dataclass

# Smoothing of the observed rate (vehicle seconds per wall second).
_RATE_GAIN = 0.2
# Rate estimates use spans of at least this much wall time (scheduling jitter dominates below).
_MIN_SPAN_WALL_S = 0.02
# The first estimate replaces the 1x guess outright, from a shorter span: at a simulator speedup the
# vehicle is set up within milliseconds, and a link silence right then must be timed at the real rate.
_FIRST_SPAN_WALL_S = 0.005
# time_boot_ms going back by more than this is a reboot of the autopilot, not reordering.
_REBOOT_BACKSTEP_S = 5.0
# Wall seconds of silence during which a simulator's time is not extrapolated (see the module docstring).
SILENCE_GRACE_WALL_S = 1.0
# Rates from this up are a simulator's speedup (a vehicle runs at 1x).
_SIMULATOR_RATE = 2.0


@dataclass(slots=True)
class VehicleClock:
    """Maps wall time to vehicle time; fed with every ``time_boot_ms`` seen."""

    rate: float = 1.0  # vehicle seconds per wall second (the simulator's speedup)
    max_rate: float = 1e5
    _vehicle_s: float | None = None
    _wall_s: float = 0.0
    _anchor_vehicle_s: float | None = None
    _anchor_wall_s: float = 0.0
    _rated: bool = False  # a rate has been measured (until then ``rate`` is the 1x guess)
    reboots: int = 0

    @property
    def synced(self) -> bool:
        return self._vehicle_s is not None

    def observe(self, time_boot_s: float, wall_s: float) -> bool:
        """Record a vehicle timestamp; returns True when it reveals an autopilot reboot."""
        if self._vehicle_s is None:
            self._vehicle_s, self._wall_s = time_boot_s, wall_s
            self._anchor_vehicle_s, self._anchor_wall_s = time_boot_s, wall_s
            return False
        if time_boot_s < self._vehicle_s - _REBOOT_BACKSTEP_S:
            self.reboots += 1
            self._vehicle_s, self._wall_s = time_boot_s, wall_s
            self._anchor_vehicle_s, self._anchor_wall_s = time_boot_s, wall_s
            return True
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
        """Vehicle time now: the last timestamp plus the extrapolated time since it arrived."""
        if self._vehicle_s is None:
            return 0.0
        return self._vehicle_s + max(0.0, wall_s - self._wall_s - self._grace_s()) * self.rate

    def wall_until(self, vehicle_s: float, wall_s: float) -> float:
        """Wall seconds until vehicle time reaches ``vehicle_s`` (0 when already past)."""
        if self._vehicle_s is None:
            return max(0.0, vehicle_s / max(self.rate, 1e-9))
        if vehicle_s <= self.now_s(wall_s):
            return 0.0
        due_wall = self._wall_s + self._grace_s() + (vehicle_s - self._vehicle_s) / max(self.rate, 1e-9)
        return max(0.0, due_wall - wall_s)
