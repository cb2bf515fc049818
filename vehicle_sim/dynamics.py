"""Vehicle physics: one pure step of a holonomic, neutrally buoyant LRAUV in a current.

The vehicle moves at its through-water velocity plus the current (the planner's model, spec
section 2): horizontal velocity through the water accelerates toward the command at
``accel_m_s2`` and never exceeds ``max_speed_m_s``; heading turns toward its target
independently of the direction of travel (like ArduSub's vectored frame); depth never goes
above 0 m. Energy integrates hotel + propulsion + buoyancy power (the latter while the
depth changes).

How heading and depth follow their targets is a ``Tracking``: the autopilot's controllers,
roughly as ArduSub's run them, a proportional controller with a rate limit,
``rate = clamp(gain * error, +-max)``, so that a target moved at some rate is followed at that
rate and a step is flown at the autopilot's own speed (``ARDUSUB_TRACKING``: about 30 deg/s of
yaw unless a yaw rate is commanded, about 1 m/s of depth change). Without a ``Tracking`` the
vehicle's own figures apply with an infinite gain: heading at ``yaw_rate_deg_s``, depth at
``glide_rate_m_s`` (the planner's model, flown by the in-process evaluation).

Plain Python floats only (no numpy): ``step`` runs every 0.1 s of simulated time, and an
in-process Monte Carlo can call it millions of times. Metres <-> degrees use a flat earth
with R = 6371000 m (spec section 1). Sensor noise is applied to *reported* values only
(``observe``), with a ``random.Random`` the caller seeds, so the truth is deterministic.
The horizontal position error is an EKF's, not raw jitter: a smooth, correlated error
(``PositionError``, stepped with the simulation's time by ``drift_error``), so that the
distance along the reported track stays close to the true one.
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

    ``yaw_deg`` (in [0, 360)) is a heading target approached at up to ``yaw_rate_deg_s`` (None:
    the ``Tracking``'s own rate) turning ``turn``; without ``yaw_deg`` a non-zero
    ``yaw_rate_deg_s`` turns continuously (signed, clockwise positive) and None keeps the heading.
    ``depth_m`` is a depth target for every kind; without one, VELOCITY and DEPTH follow
    ``down_m_s`` (0: hold the depth), capped at the ``Tracking``'s vertical rate.
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

# Within these of its target a proportional controller has arrived (and draws no more buoyancy power).
YAW_SETTLED_DEG = 0.01
DEPTH_SETTLED_M = 0.001


@dataclass(frozen=True, slots=True, kw_only=True)
class Tracking:
    """How the autopilot's controllers follow a heading and a depth target: rate = clamp(gain * error, +-max).

    ``yaw_rate_deg_s`` is the most a heading target is approached at when no yaw rate is
    commanded; a commanded rate is obeyed up to ``max_yaw_rate_deg_s``. ``depth_rate_m_s`` is
    the most a depth target is approached at, and caps a commanded vertical speed. An infinite
    gain gives a pure rate limit (at the maximum rate until the target is reached).
    """

    yaw_rate_deg_s: float
    yaw_gain_per_s: float
    max_yaw_rate_deg_s: float
    depth_rate_m_s: float
    depth_gain_per_s: float

    def __post_init__(self) -> None:
        for name in ("yaw_rate_deg_s", "yaw_gain_per_s", "max_yaw_rate_deg_s", "depth_rate_m_s", "depth_gain_per_s"):
            value = getattr(self, name)
            if not value > 0:  # inf allowed; NaN and <= 0 not
                raise ValueError(f"Tracking.{name}: expected a number > 0 (or inf); got {value!r}")


# ArduSub SITL as observed (ardusub-sitl-facts.md): with no yaw rate commanded it turned 45 deg in
# 1.3-2.0 s (its own slew, about 30 deg/s, then a short exponential settle: gain 6/s), it obeyed a
# commanded yaw rate (10 deg/s: 52 deg in 6 s), and it went from 0 to 5 m of depth in about 5 s
# (about 1 m/s, then gain 3/s). A commanded yaw rate is obeyed as given.
ARDUSUB_TRACKING = Tracking(yaw_rate_deg_s=30.0, yaw_gain_per_s=6.0, max_yaw_rate_deg_s=math.inf,
                            depth_rate_m_s=1.0, depth_gain_per_s=3.0)


def _approach(error: float, max_rate: float, gain: float, dt_s: float, settled: float) -> float:
    """The change toward a target ``error`` away in ``dt_s``: a P controller with a rate limit.

    Stepped exactly (``error * (1 - exp(-gain dt))`` in the linear part), so it is stable at any
    ``dt_s`` (the evaluation steps 2 s); an infinite gain is a pure rate limit.
    """
    magnitude = abs(error)
    move = max_rate * dt_s
    if gain != math.inf:
        linear = -magnitude * math.expm1(-gain * dt_s)
        if linear < move:
            move = linear
        if magnitude - move <= settled:
            return error
    elif move >= magnitude:
        return error
    return math.copysign(move, error)


def step(body: Body, sp: Setpoint, current: tuple[float, float], params: VehicleParams, dt_s: float,
         tracking: Tracking | None = None) -> Body:
    """The vehicle ``dt_s`` seconds later under setpoint ``sp`` in current ``(east, north)`` m/s.

    ``tracking``: how heading and depth follow their targets (None: the vehicle's own yaw and
    glide rates as pure rate limits, the planner's model).
    """
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

    # Vertical: toward the depth target, or at the commanded vertical speed; never above the surface.
    if tracking is None:
        v_max, v_gain = params.glide_rate_m_s, math.inf
    else:
        v_max, v_gain = tracking.depth_rate_m_s, tracking.depth_gain_per_s
    depth = body.depth_m
    if sp.depth_m is not None:
        new_depth = depth + _approach(sp.depth_m - depth, v_max, v_gain, dt_s, DEPTH_SETTLED_M)
    else:
        if kind is SetpointKind.VELOCITY or kind is SetpointKind.DEPTH:
            vz = sp.down_m_s
        elif kind is SetpointKind.NONE:
            vz = -params.idle_ascent_m_s
        else:
            vz = 0.0
        vz = v_max if vz > v_max else -v_max if vz < -v_max else vz  # conditionals: cheaper than min/max here
        new_depth = depth + vz * dt_s
    if new_depth < 0.0:
        new_depth = 0.0
    vz = (new_depth - depth) / dt_s

    # Heading.
    heading = body.heading_deg
    if tracking is None:
        rate = ceiling = params.yaw_rate_deg_s
        y_gain = math.inf
    else:
        rate, ceiling, y_gain = tracking.yaw_rate_deg_s, tracking.max_yaw_rate_deg_s, tracking.yaw_gain_per_s
    if sp.yaw_rate_deg_s is not None:
        rate = min(abs(sp.yaw_rate_deg_s), ceiling)
    if sp.yaw_deg is not None:
        target = sp.yaw_deg
        if sp.turn is TurnDirection.CLOCKWISE:
            diff = (target - heading) % 360.0
        elif sp.turn is TurnDirection.COUNTER_CLOCKWISE:
            diff = -((heading - target) % 360.0)
        else:
            diff = (target - heading + 180.0) % 360.0 - 180.0
        turn = _approach(diff, rate, y_gain, dt_s, YAW_SETTLED_DEG)
        new_heading = target if turn == diff else (heading + turn) % 360.0
        yaw_rate = turn / dt_s
    elif sp.yaw_rate_deg_s:
        yaw_rate = max(-ceiling, min(ceiling, sp.yaw_rate_deg_s))
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
    """What the navigation sensors report: the truth plus the estimate's error."""

    lat_deg: float
    lon_deg: float
    depth_m: float
    heading_deg: float


class PositionError(NamedTuple):
    """The horizontal error of the position estimate, metres, and its rate of change (m/s)."""

    north_m: float = 0.0
    east_m: float = 0.0
    north_m_s: float = 0.0
    east_m_s: float = 0.0


NO_ERROR = PositionError()
ERROR_RATE_TAU_FRACTION = 1.0 / 3.0  # the error's rate decorrelates three times as fast as the error


def drift_error(error: PositionError, sigma_m: float, tau_s: float, dt_s: float, rng: random.Random) -> PositionError:
    """``error`` ``dt_s`` later: a second-order Gauss-Markov process, as an EKF's position error behaves.

    The error's rate is a first-order Gauss-Markov process (time constant ``tau_s / 3``) and the
    error its leaky integral (time constant ``tau_s``), scaled so that the error's standard
    deviation is ``sigma_m`` per axis: var = s_v^2 tau^2 tau_v / (tau + tau_v). Its track is smooth
    (the error's rate is bounded, about ``sigma_m / tau_s``), so the distance along the reported
    track is close to the true one at any reporting rate; a first-order process alone is rough
    (its steps grow as the square root of the interval): at 10 Hz it still lengthens a 1 m/s
    track by 9 % at 0.5 m and doubles it at 2 m. Draws 2 numbers from ``rng``.
    """
    if sigma_m <= 0.0:
        return NO_ERROR
    tau_v = tau_s * ERROR_RATE_TAU_FRACTION
    sigma_v = sigma_m * math.sqrt((tau_s + tau_v) / (tau_s * tau_s * tau_v))
    a_v = math.exp(-dt_s / tau_v)
    a_e = math.exp(-dt_s / tau_s)
    kick = sigma_v * math.sqrt(1.0 - a_v * a_v)
    gain = tau_s * (1.0 - a_e)  # the leaky integral of a rate held over the step
    vn = a_v * error.north_m_s + kick * rng.gauss(0.0, 1.0)
    ve = a_v * error.east_m_s + kick * rng.gauss(0.0, 1.0)
    return PositionError(a_e * error.north_m + gain * error.north_m_s, a_e * error.east_m + gain * error.east_m_s,
                         vn, ve)


def initial_error(sigma_m: float, tau_s: float, rng: random.Random) -> PositionError:
    """A draw of the error at boot, about its steady spread (draws 4 numbers from ``rng``)."""
    tau_v = tau_s * ERROR_RATE_TAU_FRACTION
    sigma_v = sigma_m * math.sqrt((tau_s + tau_v) / (tau_s * tau_s * tau_v)) if tau_s > 0 else 0.0
    g = rng.gauss
    return PositionError(g(0.0, sigma_m), g(0.0, sigma_m), g(0.0, sigma_v), g(0.0, sigma_v))


def observe(body: Body, params: VehicleParams, rng: random.Random, error: PositionError = NO_ERROR) -> Reading:
    """A reading of ``body``: position off by ``error``; heading and depth with white noise (2 draws from ``rng``)."""
    gauss = rng.gauss
    lat = body.lat_deg + error.north_m / M_PER_DEG_LAT
    lon = body.lon_deg + error.east_m / (M_PER_DEG_LAT * (math.cos(math.radians(body.lat_deg)) or 1e-12))
    depth = max(0.0, body.depth_m + gauss(0.0, params.depth_noise_m))
    heading = (body.heading_deg + gauss(0.0, params.heading_noise_deg)) % 360.0
    return Reading(lat, lon, depth, heading)
