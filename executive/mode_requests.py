"""When a mode the executive asks the autopilot for is complete: the one place that says so.

ArduSub does not always stay in the mode it was asked for: SURFACE ends by itself once the
vehicle is at the surface, in ALT_HOLD with mode reason SURFACE_COMPLETE (ArduSub's
``ModeSurface::run``; seen on ArduSub SITL). An executive that waits for the HEARTBEAT to read
SURFACE asks again for ever. So each mode has a stated completion condition
(docs/executive.md, "Modes the executive asks for"):

| mode asked | in progress | complete |
|---|---|---|
| GUIDED | reads GUIDED, not armed yet | reads GUIDED and armed |
| ALT_HOLD | reads ALT_HOLD, not armed yet | reads ALT_HOLD and armed |
| SURFACE | reads SURFACE (ascending) | at the surface (depth within the helm's depth tolerance of 0) after it read SURFACE, or at the surface reading ALT_HOLD; then complete for as long as the activity lasts, whatever mode the autopilot reports |

Anything else is ``ASK``: the helm asks for the mode, at most once per ``retry_s``. Pure.
"""

from __future__ import annotations

from enum import Enum, unique

from executive.state import VehicleState
from planner.contract.modes import SubMode


@unique
class Progress(Enum):
    ASK = "ask"  # the autopilot is not in the mode (or not yet): ask for it
    UNDERWAY = "underway"  # in the mode, not complete: targets are streamed, nothing asked again
    COMPLETE = "complete"


def progress(mode: SubMode, vehicle: VehicleState, previous: Progress | None, *,
             surface_depth_m: float) -> Progress:
    """Where the request for ``mode`` stands, given the vehicle and where it stood at the last update.

    ``previous``: this function's answer at the activity's last update (None at its first).
    ``surface_depth_m``: the vehicle is at the surface at or above this depth.
    """
    if mode is SubMode.SURFACE:
        if previous is Progress.COMPLETE:
            return Progress.COMPLETE  # the autopilot has left SURFACE by itself: never asked again
        at_surface = vehicle.depth_m is not None and vehicle.depth_m <= surface_depth_m
        if at_surface and (previous is Progress.UNDERWAY or vehicle.mode in (SubMode.SURFACE, SubMode.ALT_HOLD)):
            return Progress.COMPLETE
        return Progress.UNDERWAY if vehicle.mode == SubMode.SURFACE else Progress.ASK
    if vehicle.mode != mode:
        return Progress.ASK
    return Progress.COMPLETE if vehicle.armed else Progress.UNDERWAY
