"""The current the vehicle meets, measured onboard, and the tide's timing fitted to it.

A time-varying table that carries its slices' currents (``PolicyTable.slice_current_m_s``) lets
the vehicle look its slices up earlier or later than its UTC time, by as much as the current it
meets runs behind or ahead of the forecast (``planner.contract.tide_timing``, docs/time-varying.md).

The current is measured as the ground velocity GLOBAL_POSITION_INT reports less the through-water
velocity the helm commands (``VelocityYaw``; a depth hold, ALT_HOLD, commands none), only once a
command has been held for ``SETTLE_S``, so the vehicle has reached it, and only while the helm runs
the plan (a person, a failsafe or a safety stop that takes over leaves the velocity unknown until
the helm commands one again). While the helm holds a position, nothing is measured. On an autopilot
whose velocity targets are over ground (a real ArduSub's GUIDED mode), only the depth holds (DRIFT)
measure the current; the rest measure zero and the fit then finds nothing it can accept, so the
plan is looked up at UTC itself.

Pure: ``commanded`` and ``measured`` take and return frozen values; the loop (``executive.loop``)
logs the event ``measured`` returns, and the decision audit (``planner.shore.replay.audit``)
applies the shift that event names from the same decision on. ``saved`` and ``restored`` carry the
record and the shift across a restart (``executive.durable``): a restart is then a pause in the
record, not hours of the tide measured again.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from executive.state import Command, DepthTarget, Event, PositionTarget, SetMode, VehicleState, VelocityYaw
from planner.contract import tide_timing
from planner.contract.modes import SubMode
from planner.contract.table import PolicyTable

SETTLE_S = 30.0  # a 0.5 m/s vehicle reaches its commanded velocity within seconds; a turn within tens
SAME_M_S = 0.01  # a command repeated within this is the same command
# The event that says which shift the decisions use from here on, for the audit to read back.
SHIFT_PREFIX = "tide timing: table "


@dataclass(frozen=True, slots=True)
class TideWatch:
    """The tide's clock, the through-water velocity the helm last commanded (None: none, or a position
    hold) and since when, the table the clock's shift was fitted for, and how that table numbers its
    reference regions (``region_layout``: the record's observations are numbered so)."""

    clock: tide_timing.TideClock = tide_timing.TideClock()
    water_ne_m_s: tuple[float, float] | None = None
    since_s: float = 0.0
    table_crc32: int | None = None
    layout: tuple[str | int | float, ...] = ()

    def shift_for(self, table: PolicyTable | None) -> float:
        """The shift (s) at which ``table``'s slices are looked up: the fitted one for that table, else 0."""
        return self.clock.shift_s if table is not None and table.crc32 == self.table_crc32 else 0.0


def commanded(watch: TideWatch, cmd: Command, now_s: float) -> TideWatch:
    """``watch`` after the helm sent ``cmd``."""
    if isinstance(cmd, VelocityYaw):
        water: tuple[float, float] | None = (cmd.north_m_s, cmd.east_m_s)
    elif isinstance(cmd, DepthTarget) or (isinstance(cmd, SetMode) and cmd.mode is SubMode.ALT_HOLD):
        water = (0.0, 0.0)  # a depth hold (DRIFT: ALT_HOLD, no horizontal thrust)
    elif isinstance(cmd, PositionTarget):
        water = None
    elif isinstance(cmd, SetMode) and cmd.mode is not SubMode.GUIDED:
        water = None  # surfacing, or a mode that steers by itself: what the vehicle does through the water is unknown
    else:
        return watch  # modes, arming and message rates say nothing of the velocity
    if same_velocity(water, watch.water_ne_m_s):
        return watch
    return replace(watch, water_ne_m_s=water, since_s=now_s)


def region_layout(table: PolicyTable) -> tuple[str | int | float, ...]:
    """What a region number means in ``table`` (``PolicyTable.current_region``): its layers, and with blocks
    their size and the grid they cut. Two tables with the same layout number the same places alike."""
    if table.current_block_cells is None:  # a table keeps no block as large as the grid (kept_block_cells)
        return ("layers", *table.depth_m)
    return ("blocks", table.current_block_cells, table.ny, table.nx, table.lon0_deg, table.lat0_deg, table.dlon_deg,
            table.dlat_deg, *table.depth_m)


def same_velocity(a: tuple[float, float] | None, b: tuple[float, float] | None) -> bool:
    """Two commanded through-water velocities that are the same command (a repeat): within ``SAME_M_S``."""
    return a is not None and b is not None and abs(a[0] - b[0]) < SAME_M_S and abs(a[1] - b[1]) < SAME_M_S


def measured(watch: TideWatch, table: PolicyTable | None, vehicle: VehicleState, now_s: float, utc_s: float | None,
             ground_north_m_s: float, ground_east_m_s: float, *, fresh: bool,
             running: bool) -> tuple[TideWatch, Event | None]:
    """``watch`` after one ground velocity at vehicle time ``now_s``, and the event that announces a new shift;
    ``fresh``: the message's position passed the telemetry checks (a rejected one measures nothing);
    ``running``: the helm runs the plan (else the velocity through the water is no longer the command's)."""
    if not running:
        if watch.water_ne_m_s is None:
            return watch, None
        return replace(watch, water_ne_m_s=None, since_s=now_s), None
    if (table is None or table.slice_current_m_s is None or utc_s is None or watch.water_ne_m_s is None
            or now_s - watch.since_s < SETTLE_S or not fresh
            or vehicle.lat_deg is None or vehicle.lon_deg is None or vehicle.depth_m is None):
        return watch, None
    cell = table.locate(vehicle.lat_deg, vehicle.lon_deg, vehicle.depth_m)
    if cell is None or not (math.isfinite(ground_north_m_s) and math.isfinite(ground_east_m_s)):
        return watch, None
    clock, layout = watch.clock, watch.layout
    if watch.table_crc32 != table.crc32:  # another plan: its own reference, fitted afresh on the record so far,
        layout = region_layout(table)  # unless it numbers its regions otherwise: then on a record of its own
        clock = tide_timing.TideClock(record=clock.record if layout == watch.layout else tide_timing.CurrentRecord())
    north, east = watch.water_ne_m_s
    after = tide_timing.advance(clock, utc_s, table.current_region(cell), ground_east_m_s - east, ground_north_m_s - north,
                                table.slice_unix_s, table.slice_current_m_s)
    new = replace(watch, clock=after, table_crc32=table.crc32, layout=layout)
    # Logged whenever what the log last said no longer holds: a new shift for this table, or another
    # table while the last logged shift (of the table before) was not none. The audit keeps one
    # (table, shift) as this does, so it looks up the same slices.
    if watch.table_crc32 == table.crc32:
        changed = after.shift_s != watch.clock.shift_s
    else:
        changed = after.shift_s != 0.0 or watch.clock.shift_s != 0.0
    if not changed:
        return new, None
    fit = after.last_fit
    if fit is None or (not fit.accepted and after.shift_s == 0.0 and watch.table_crc32 != table.crc32):
        why = "another plan: none until a fit of its own"
    elif fit.accepted:
        why = fit.describe()
    else:
        why = f"the forecast's current no longer explains the current met ({fit.describe()})"
    return new, Event("info", f"{SHIFT_PREFIX}{table.crc32:08x} looked up at UTC {after.shift_s:+.0f} s: {why}")


def logged_shift(text: str) -> tuple[int, float] | None:
    """(table CRC, shift s) of a logged ``measured`` event, or None for any other text."""
    if not text.startswith(SHIFT_PREFIX):
        return None
    try:
        crc, rest = text[len(SHIFT_PREFIX):].split(" looked up at UTC ", 1)
        return int(crc, 16), float(rest.split(" s:", 1)[0])
    except ValueError:
        return None


def saved(watch: TideWatch) -> dict[str, Any] | None:
    """What a restart needs of ``watch`` (JSON): the table its shift is for, the shift and the record's
    observations; None when there is nothing to keep. The minute being filled and the command are not
    kept: after a restart the helm commands again and measuring waits for the command to settle."""
    clock = watch.clock
    if watch.table_crc32 is None and not clock.record.observations:
        return None
    return {"table_crc32": None if watch.table_crc32 is None else f"{watch.table_crc32:08x}",
            "shift_s": clock.shift_s, "layout": list(watch.layout),
            "observations": [[o.unix_s, o.region, o.east_m_s, o.north_m_s] for o in clock.record.observations]}


def restored(saved_watch: Mapping[str, Any]) -> TideWatch:
    """``saved``'s output read back; ``ValueError`` (or ``KeyError``, ``TypeError``) says what is malformed.
    The shift is refitted at the first measurement, on the kept record and the ones that follow it."""
    crc = saved_watch["table_crc32"]
    shift_s = float(saved_watch["shift_s"])
    if not (math.isfinite(shift_s) and abs(shift_s) <= tide_timing.MAX_SHIFT_S):
        raise ValueError(f"tide shift_s {shift_s} is outside +-{tide_timing.MAX_SHIFT_S:g} s")
    observations = []
    for row in saved_watch["observations"]:
        if not (isinstance(row, list) and len(row) == 4 and isinstance(row[1], int) and row[1] >= 0
                and all(isinstance(x, (int, float)) and math.isfinite(x) for x in row)):
            raise ValueError(f"tide observation {row!r}: expected [unix_s, region >= 0, east_m_s, north_m_s]")
        observations.append(tide_timing.Observation(float(row[0]), row[1], float(row[2]), float(row[3])))
    observations.sort(key=lambda o: o.unix_s)
    layout = saved_watch["layout"]
    if not (isinstance(layout, list) and all(isinstance(x, (str, int, float)) for x in layout)):
        raise ValueError(f"tide layout {layout!r}: expected a list of names and numbers")
    clock = tide_timing.TideClock(record=tide_timing.CurrentRecord(observations=tuple(observations)), shift_s=shift_s)
    return TideWatch(clock=clock, table_crc32=None if crc is None else int(str(crc), 16), layout=tuple(layout))


def kept_text(watch: TideWatch) -> Event | None:
    """The event that says what a restart kept: the shift and its table (for the audit, as ``measured``'s
    events: the loop uses it whenever that table is the active one), else only the record; None when
    nothing was kept."""
    minutes = len(watch.clock.record.observations)
    if watch.table_crc32 is None and not minutes:
        return None
    kept = f"kept from before the restart ({minutes} minutes of the current met)"
    if watch.table_crc32 is not None and watch.clock.shift_s != 0.0:
        return Event("info", f"{SHIFT_PREFIX}{watch.table_crc32:08x} looked up at UTC {watch.clock.shift_s:+.0f} s: {kept}")
    return Event("info", f"tide timing: none in use; {kept}")
