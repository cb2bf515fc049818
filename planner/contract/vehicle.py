"""The vehicle's figures and its one energy law, shared by the planner, the executive and the simulator.

Standard library only (``power_draw_w`` also takes numpy arrays): the planner prices transitions
with the same law the simulator integrates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, kw_only=True)
class VehicleParams:
    """Performance, power and sensor figures of the simulated vehicle (SI units)."""

    cruise_speed_m_s: float = 1.0
    max_speed_m_s: float = 1.5
    yaw_rate_deg_s: float = 10.0
    glide_rate_m_s: float = 0.2
    accel_m_s2: float = 0.2
    # Position targets: desired speed over ground = gain * distance, at most cruise speed.
    position_gain_per_s: float = 0.2
    # Without thrust (disarmed, MANUAL without a pilot) the vehicle is neutrally trimmed and
    # keeps its depth; set > 0 to make it float up (ArduSub SITL's frame rises ~0.1 m/s).
    idle_ascent_m_s: float = 0.0
    hotel_w: float = 8.0
    propulsion_w: float = 12.0  # at cruise speed, scaling with (speed / cruise)^3
    buoyancy_w: float = 15.0  # while the depth is changing
    battery_wh: float = 3000.0
    battery_voltage_v: float = 16.0  # nominal pack voltage, for mA/mAh telemetry
    # One-sigma noise on reported (not true) values.
    position_noise_m: float = 0.5
    heading_noise_deg: float = 0.5
    depth_noise_m: float = 0.05

    def __post_init__(self) -> None:
        for name in ("cruise_speed_m_s", "max_speed_m_s", "yaw_rate_deg_s", "glide_rate_m_s", "accel_m_s2",
                     "position_gain_per_s", "battery_wh", "battery_voltage_v"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"VehicleParams.{name}: expected a number > 0; got {value!r}")
        for name in ("idle_ascent_m_s", "hotel_w", "propulsion_w", "buoyancy_w", "position_noise_m",
                     "heading_noise_deg", "depth_noise_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"VehicleParams.{name}: expected a number >= 0; got {value!r}")
        if self.max_speed_m_s < self.cruise_speed_m_s:
            raise ValueError(
                f"VehicleParams: max_speed_m_s ({self.max_speed_m_s}) must be >= cruise_speed_m_s "
                f"({self.cruise_speed_m_s})"
            )


def power_draw_w(params: VehicleParams, water_speed_m_s: Any, gliding: Any) -> Any:
    """Electrical power, W: hotel + propulsion (cubic in speed through water) + buoyancy engine while gliding.

    The one energy law of the project: the simulator integrates it every step and the physical
    planning model (``planner.physical.model``) charges it per transition. Floats or numpy arrays.
    """
    ratio = water_speed_m_s / params.cruise_speed_m_s
    return params.hotel_w + params.propulsion_w * ratio * ratio * ratio + params.buoyancy_w * gliding
