"""ArduSub's flight modes, as the executive commands them and the simulator runs them."""

from __future__ import annotations

from enum import IntEnum, unique


@unique
class SubMode(IntEnum):
    """ArduSub flight modes (HEARTBEAT.custom_mode), as observed on ArduSub SITL."""

    ALT_HOLD = 2
    GUIDED = 4
    SURFACE = 9
    MANUAL = 19
