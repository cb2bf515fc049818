"""Vehicle physics: one pure step of a holonomic, neutrally buoyant LRAUV in a current.

The vehicle moves at its through-water velocity plus the current (the planner's model, spec
section 2): horizontal velocity through the water accelerates toward the command at
``accel_m_s2`` and never exceeds ``max_speed_m_s``; heading slews toward its target at
``yaw_rate_deg_s`` independently of the direction of travel (like ArduSub's vectored
frame); depth changes at most at ``glide_rate_m_s`` (a buoyancy engine) and never above
0 m. Energy integrates hotel + propulsion + buoyancy power.

Plain Python floats only (no numpy): ``step`` runs every 0.1 s of simulated time, and an
in-process Monte Carlo can call it millions of times. Metres <-> degrees use a flat earth
with R = 6371000 m (spec section 1). Sensor noise is applied to *reported* values only
(``observe``), with a ``random.Random`` the caller seeds, so the truth is deterministic.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from enum import Enum, unique
from typing import NamedTuple

from planner.contract.geodesy import M_PER_DEG_LAT
from planner.contract.vehicle import VehicleParams, power_draw_w



class Body(NamedTuple):
    """True state of the vehicle. A NamedTuple: immutable and cheap to build every step.

    Velocities are NED: ``water_*`` through the water, ``ground_*`` over ground (water plus
    current), ``down_m_s`` positive when descending. Heading is compass degrees in [0, 360).
    """

    time_s: float = 0.0
    lat_deg: float = 0.0
    lon_deg: float = 0.0
    depth_m: float = 0.0
    heading_deg: float = 0.0
    water_north_m_s: float = 0.0
    water_east_m_s: float = 0.0
    down_m_s: float = 0.0
    ground_north_m_s: float = 0.0
    ground_east_m_s: float = 0.0
    yaw_rate_deg_s: float = 0.0
    energy_used_wh: float = 0.0

    @property
    def water_speed_m_s(self) -> float:
        return math.hypot(self.water_north_m_s, self.water_east_m_s)

    @property
    def ground_speed_m_s(self) -> float:
        return math.hypot(self.ground_north_m_s, self.ground_east_m_s)


@unique
class SetpointKind(Enum):
    """What the autopilot asks the vehicle for."""

    NONE = "none"  # no thrust: drift with the current (disarmed, MANUAL without a pilot)
    VELOCITY = "velocity"  # through-water velocity (NED); depth held when vertical speed is 0
    POSITION = "position"  # go to and hold a point against the current
    DEPTH = "depth"  # hold a depth, no horizontal thrust (ALT_HOLD, SURFACE at depth 0)


@unique
class TurnDirection(Enum):
    SHORTEST = 0
    CLOCKWISE = 1
    COUNTER_CLOCKWISE = -1


@dataclass(frozen=True, slots=True, kw_only=True)
class Setpoint:
    """A command for ``step``.

    ``yaw_deg`` (in [0, 360)) is a heading target reached at ``yaw_rate_deg_s`` (capped by the
    vehicle's rate; None = the vehicle's rate) turning ``turn``; without ``yaw_deg`` a non-zero
    ``yaw_rate_deg_s`` turns continuously (signed, clockwise positive) and None keeps the heading.
    ``depth_m`` is a depth target for every kind (None: hold depth, or follow ``down_m_s``).
    """

    kind: SetpointKind = SetpointKind.NONE
    north_m_s: float = 0.0
    east_m_s: float = 0.0
    down_m_s: float = 0.0
    yaw_deg: float | None = None
    yaw_rate_deg_s: float | None = None
    turn: TurnDirection = TurnDirection.SHORTEST
    lat_deg: float | None = None
    lon_deg: float | None = None
    depth_m: float | None = None


IDLE = Setpoint()


def step(body: Body, sp: Setpoint, current: tuple[float, float], params: VehicleParams, dt_s: float) -> Body:
    """The vehicle ``dt_s`` seconds later under setpoint ``sp`` in current ``(east, north)`` m/s."""
    cur_e, cur_n = current
    kind = sp.kind
    lat = body.lat_deg
    cos_lat = math.cos(math.radians(lat)) or 1e-12

    # Horizontal command, through the water.
    if kind is SetpointKind.VELOCITY:
        cmd_n, cmd_e = sp.north_m_s, sp.east_m_s
    elif kind is SetpointKind.POSITION and sp.lat_deg is not None and sp.lon_deg is not None:
        # Proportional controller over ground, minus the current: station keeping.
        err_n = (sp.lat_deg - lat) * M_PER_DEG_LAT
        err_e = (sp.lon_deg - body.lon_deg) * M_PER_DEG_LAT * cos_lat
        want_n, want_e = _cap(err_n * params.position_gain_per_s, err_e * params.position_gain_per_s,
                              params.cruise_speed_m_s)
        cmd_n, cmd_e = want_n - cur_n, want_e - cur_e
    else:
        cmd_n = cmd_e = 0.0
    cmd_n, cmd_e = _cap(cmd_n, cmd_e, params.max_speed_m_s)
    d_n, d_e = _cap(cmd_n - body.water_north_m_s, cmd_e - body.water_east_m_s, params.accel_m_s2 * dt_s)
    wn = body.water_north_m_s + d_n
    we = body.water_east_m_s + d_e

    # Vertical: at most the glide rate, never above the surface.
    glide = params.glide_rate_m_s
    depth = body.depth_m
    if sp.depth_m is not None:
        vz = (sp.depth_m - depth) / dt_s
    elif kind is SetpointKind.VELOCITY:
        vz = sp.down_m_s
    elif kind is SetpointKind.NONE:
        vz = -params.idle_ascent_m_s
    else:
        vz = 0.0
    vz = glide if vz > glide else -glide if vz < -glide else vz  # conditionals: cheaper than min/max here
    new_depth = depth + vz * dt_s
    if new_depth < 0.0:
        new_depth = 0.0
    vz = (new_depth - depth) / dt_s

    # Heading.
    heading = body.heading_deg
    limit = params.yaw_rate_deg_s
    rate = limit if sp.yaw_rate_deg_s is None else min(abs(sp.yaw_rate_deg_s), limit)
    if sp.yaw_deg is not None:
        target = sp.yaw_deg
        if sp.turn is TurnDirection.CLOCKWISE:
            diff = (target - heading) % 360.0
        elif sp.turn is TurnDirection.COUNTER_CLOCKWISE:
            diff = -((heading - target) % 360.0)
        else:
            diff = (target - heading + 180.0) % 360.0 - 180.0
        max_turn = rate * dt_s
        if -max_turn <= diff <= max_turn:
            new_heading = target
        else:
            new_heading = (heading + math.copysign(max_turn, diff)) % 360.0
            diff = math.copysign(max_turn, diff)
        yaw_rate = diff / dt_s
    elif sp.yaw_rate_deg_s:
        yaw_rate = max(-limit, min(limit, sp.yaw_rate_deg_s))
        new_heading = (heading + yaw_rate * dt_s) % 360.0
    else:
        new_heading, yaw_rate = heading, 0.0

    # Position over ground.
    gn = wn + cur_n
    ge = we + cur_e
    new_lat = lat + gn * dt_s / M_PER_DEG_LAT
    new_lon = body.lon_deg + ge * dt_s / (M_PER_DEG_LAT * cos_lat)

    energy = body.energy_used_wh + power_draw_w(params, math.hypot(wn, we), vz != 0.0) * dt_s / 3600.0

    return Body(body.time_s + dt_s, new_lat, new_lon, new_depth, new_heading, wn, we, vz, gn, ge, yaw_rate, energy)


def _cap(n: float, e: float, limit: float) -> tuple[float, float]:
    """The vector (n, e), shortened to length ``limit`` when longer."""
    mag = math.hypot(n, e)
    if mag > limit:
        scale = limit / mag
        return n * scale, e * scale
    return n, e


def power_w(body: Body, params: VehicleParams) -> float:
    """Electrical power drawn in the state ``body`` (for current telemetry)."""
    return float(power_draw_w(params, body.water_speed_m_s, body.down_m_s != 0.0))


def battery_remaining(body: Body, params: VehicleParams) -> float:
    """Fraction of the battery left, 0..1."""
    return min(1.0, max(0.0, 1.0 - body.energy_used_wh / params.battery_wh))


class Reading(NamedTuple):
    """What the navigation sensors report: the truth plus Gaussian noise."""

    lat_deg: float
    lon_deg: float
    depth_m: float
    heading_deg: float


def observe(body: Body, params: VehicleParams, rng: random.Random) -> Reading:
    """A noisy reading of ``body``; the only place noise enters (draws 4 numbers from ``rng``)."""
    gauss = rng.gauss
    dn = gauss(0.0, params.position_noise_m)
    de = gauss(0.0, params.position_noise_m)
    lat = body.lat_deg + dn / M_PER_DEG_LAT
    lon = body.lon_deg + de / (M_PER_DEG_LAT * (math.cos(math.radians(body.lat_deg)) or 1e-12))
    depth = max(0.0, body.depth_m + gauss(0.0, params.depth_noise_m))
    heading = (body.heading_deg + gauss(0.0, params.heading_noise_deg)) % 360.0
    return Reading(lat, lon, depth, heading)
