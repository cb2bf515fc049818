"""Simulator profiles: one switch for every ArduSub-faithful choice that is not the default.

The simulator's defaults already behave as ArduSub SITL does wherever the executive can tell
(rates, modes, start-up, GCS failsafe, position error: docs/simulator.md). A few choices stay
LRAUV-friendly by default, and ``Profile.ARDUSUB`` (``lrauv sim --profile ardusub``) sets them
as ArduSub SITL with its default parameters (``sub.parm``) has them, for a parity test:

- ArduSub's other default streams on (``SimConfig.ardusub_streams``);
- the GCS failsafe disarms (FS_GCS_ENABLE's default; the simulator's default surfaces);
- without thrust the vehicle floats up at 0.1 m/s (SITL's frame: from 3.0 to 1.1 m in 20 s).
"""

from __future__ import annotations

from dataclasses import replace
from enum import Enum, unique

from vehicle_sim.autopilot import FailsafeAction
from vehicle_sim.endpoint import SimConfig

SITL_IDLE_ASCENT_M_S = 0.1


@unique
class Profile(Enum):
    LRAUV = "lrauv"  # the defaults
    ARDUSUB = "ardusub"  # every ArduSub-faithful choice


def with_profile(config: SimConfig, profile: Profile) -> SimConfig:
    """``config`` with the profile's choices applied (LRAUV: unchanged)."""
    if profile is Profile.LRAUV:
        return config
    return replace(config, ardusub_streams=True,
                   autopilot=replace(config.autopilot, failsafe=FailsafeAction.DISARM),
                   params=replace(config.params, idle_ascent_m_s=SITL_IDLE_ASCENT_M_S))
