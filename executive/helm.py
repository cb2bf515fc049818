"""The executive's decision logic: one pure ``step`` per telemetry update, no I/O.

``step(helm, vehicle, table, config, now_s=..., link_ok=...) -> Tick`` takes the
helm's previous state, the latest ``VehicleState`` and the policy table, and
returns the next helm state, the commands to send and the events to log. The
loop (``executive.loop``) does all sockets, clocks and files around it, so the
same function runs live, in tests without sockets, and in replay.

Table actions are realised through ``planner.contract.steering`` (the mapping table is in its
docstring, shared with the evaluation's pilot): a VELOCITY steering is a through-water velocity
and yaw in GUIDED with zero vertical velocity, re-sent every ``refresh_s`` because ArduSub drops
a velocity target after 3 s; ROTATE is zero velocity and the yaw in GUIDED; DEPTH (DRIFT, UP,
DOWN) is a depth target in ALT_HOLD. On ArduSub GUIDED with zero velocity is station keeping, not
drifting; that is why DRIFT and the glides (which drift along ``w``, spec section 5) use ALT_HOLD.
Turns and glides are held until ``is_complete``, or until their ``timeout_s`` passes.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

from executive.state import (
    Arm,
    Command,
    DepthTarget,
    Event,
    Phase,
    PositionTarget,
    SetMessageInterval,
    SetMode,
    Situation,
    SubMode,
    VehicleState,
    VelocityYaw,
)
from executive.geofence import inside
from executive.mode_requests import Progress, progress
from executive.plausibility import Limits
from executive.setpoints import Ramp, target_at
from planner.contract.actions import Action
from planner.contract.settings import BreachAction, OnArrival
from planner.contract.steering import DEPTH_TOLERANCE_M, Steering, SteeringKind, is_complete, steer
from planner.contract.table import CELL_MARGIN, PolicyTable

# The mode for each on_breach action (ArduSub: SURFACE ascends, ALT_HOLD holds depth without
# horizontal thrust, GUIDED holds a position).
BREACH_MODE: dict[str, SubMode] = {"surface": SubMode.SURFACE, "drift": SubMode.ALT_HOLD, "hold": SubMode.GUIDED}
# Phases in which an autopilot HEARTBEAT runs the helm too: set-up needs no position message
# to go on. Once the policy is followed, position and attitude alone drive decisions; overridden,
# the helm commands nothing, and position messages keep its picture of the autopilot's mode current.
HEARTBEAT_PHASES = frozenset({Phase.WAIT_LINK, Phase.SETUP, Phase.LINK_LOST})
# Phases in which the autopilot's mode, arming and failsafes are the executive's to watch (docs/executive.md, "Authority").
_WATCHED = frozenset({Phase.SETUP, Phase.RUNNING, Phase.ARRIVED, Phase.SAFE})
# Limits that are persistent by construction fire at once; the others must hold for breach_window_s.
_AT_ONCE = frozenset({Situation.MISSION_TIME, Situation.POSITION_LOST, Situation.LINK_LOST})
_RATE_TRIES = 10  # rate requests sent at most this often per set-up (an autopilot may never acknowledge)

# Telemetry the executive asks for (message, interval in vehicle seconds); position and
# attitude drive decisions, the rest is health. Intervals <= 0 disable a stream.
DEFAULT_RATES: tuple[tuple[str, float], ...] = (
    ("GLOBAL_POSITION_INT", 0.5),
    ("ATTITUDE", 0.5),
    ("SYSTEM_TIME", 5.0),
    ("EKF_STATUS_REPORT", 5.0),
    ("BATTERY_STATUS", 5.0),
    ("SYS_STATUS", 5.0),
    ("VFR_HUD", 5.0),
)


@dataclass(frozen=True, kw_only=True)
class HelmConfig:
    """Parameters of the helm; vehicle figures come from the mission's ``vehicle`` section."""

    cruise_speed_m_s: float = 1.0
    yaw_rate_deg_s: float = 10.0
    glide_rate_m_s: float = 0.2
    on_arrival: OnArrival = "hold"
    refresh_s: float = 1.0  # re-send the active target (velocity targets expire after 3 s)
    retry_s: float = 2.0  # mode and arming requests
    link_loss_timeout_s: float = 30.0
    depth_tolerance_m: float = DEPTH_TOLERANCE_M
    # A cell is left only once the vehicle is this fraction of a cell beyond its edge, so that
    # noise and the current cannot make the decision chatter on a boundary.
    cell_margin: float = CELL_MARGIN
    max_mission_time_s: float | None = None
    min_battery_pct: float | None = None
    max_depth_m: float | None = None
    geofence: tuple[tuple[float, float], ...] | None = None  # (lon_deg, lat_deg) vertices
    on_breach: BreachAction = "surface"  # for every safety limit and link loss (docs/missions.md)
    rates: tuple[tuple[str, float], ...] = DEFAULT_RATES
    # Battery, depth and geofence limits fire only when exceeded for this long (vehicle seconds).
    breach_window_s: float = 5.0
    position_timeout_s: float = 60.0  # no plausible position this long while following: on_breach
    # A mode the vehicle enters within this long of the executive asking for it is the executive's own.
    authority_window_s: float = 10.0
    limits: Limits = field(default_factory=Limits)  # telemetry checks (executive.plausibility)

    def to_json(self) -> str:
        """The settings as JSON, for the log (the decision audit runs the helm again with them)."""
        return json.dumps(asdict(self), separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> HelmConfig:
        """Inverse of ``to_json``; keys this version does not know are ignored, missing ones defaulted."""
        data = json.loads(text)
        known = {f.name for f in fields(cls)}
        values = {k: v for k, v in data.items() if k in known}
        for key in ("geofence", "rates"):  # JSON arrays back to the tuples the dataclass holds
            if values.get(key) is not None:
                values[key] = tuple(tuple(p) for p in values[key])
        if isinstance(values.get("limits"), dict):
            known_limits = {f.name for f in fields(Limits)}
            values["limits"] = Limits(**{k: v for k, v in values["limits"].items() if k in known_limits})
        return cls(**values)


@dataclass(frozen=True, slots=True)
class Activity:
    """What the vehicle is being made to do, and why."""

    situation: Situation
    action: Action | None  # the table's action when following it
    cell: tuple[int, int, int, int] | None  # (l, j, i, k) when inside the grid
    mode: SubMode
    target: Command | None  # streamed while this activity lasts
    started_s: float
    steering: Steering | None = None  # the table action's, when following it
    ramp: Ramp | None = None  # where its yaw and depth setpoints start: set when its target is first sent

    @property
    def key(self) -> tuple[object, ...]:
        return (self.situation, self.action, self.cell)

    @property
    def completes(self) -> bool:
        """ROTATE/UP/DOWN: held until done, not only until the state changes."""
        return self.steering is not None and self.steering.held

    @property
    def timeout_s(self) -> float | None:
        return self.steering.timeout_s if self.steering is not None else None

    def target_at(self, now_s: float) -> Command | None:
        """What to send at ``now_s``: ``target`` with its yaw and depth moved at the plan's rates (executive.setpoints)."""
        return None if self.target is None else target_at(self.target, self.steering, self.ramp, now_s)


@dataclass(frozen=True, slots=True)
class HelmState:
    phase: Phase = Phase.WAIT_LINK
    activity: Activity | None = None
    target_sent_s: float | None = None
    mode_request_s: float | None = None
    mode_requested: int | None = None  # the mode last asked for (at mode_request_s)
    mode_progress: Progress | None = None  # the activity's mode request at the last update (executive.mode_requests)
    arm_request_s: float | None = None
    rates_sent: bool = False  # the rate requests went out in this set-up
    rates_sent_s: float | None = None
    rates_acks: int = 0  # the vehicle's count of accepted interval requests when they last went out
    rates_tries: int = 0
    mission_start_s: float | None = None
    # Authority: what the autopilot reported at the last update, and the modes asked for (mode, vehicle time).
    seen_mode: int | None = None
    seen_armed: bool = False
    seen_failsafe: bool = False
    asked_modes: tuple[tuple[int, float], ...] = ()
    overridden: str | None = None  # why the executive yielded (phase OVERRIDDEN); None when it has not
    silent: bool = False  # the link was lost while overridden (the override stands through it)
    # The safety stop: the limit that fired. It holds for the run (reboots, restarts, uploads) until an operator clears it.
    stop: Situation | None = None
    breach: Situation | None = None  # a limit exceeded, not yet for breach_window_s
    breach_since_s: float | None = None
    # Set-up: what it waits for before arming and GUIDED (announced once), since when, and whether it warned.
    waiting: str | None = None
    waiting_since_s: float | None = None
    waiting_warned: bool = False


@dataclass(frozen=True, slots=True)
class Decision:
    """One consultation of the table: the audit record of the decision channel."""

    time_s: float
    lat_deg: float
    lon_deg: float
    depth_m: float
    heading_deg: float | None
    cell: tuple[int, int, int, int] | None
    situation: Situation
    action: Action | None
    mode: SubMode
    changed: bool  # a new activity started on this update

    def to_record(self) -> dict[str, Any]:
        """The ``/executive/decision`` payload (enums by name or value, as JSON holds them)."""
        return {
            "time_s": self.time_s, "lat_deg": self.lat_deg, "lon_deg": self.lon_deg, "depth_m": self.depth_m,
            "heading_deg": self.heading_deg, "cell": list(self.cell) if self.cell is not None else None,
            "situation": self.situation.value, "action": self.action.name if self.action is not None else None,
            "mode": self.mode.name, "changed": self.changed,
        }


@dataclass(frozen=True, slots=True)
class Tick:
    helm: HelmState
    commands: tuple[Command, ...] = ()
    events: tuple[Event, ...] = ()
    decision: Decision | None = None


@dataclass(slots=True)
class _Out:
    commands: list[Command] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)


def step(
    helm: HelmState,
    vehicle: VehicleState,
    table: PolicyTable | None,
    config: HelmConfig,
    *,
    now_s: float,
    link_ok: bool,
) -> Tick:
    """Advance the helm by one update at vehicle time ``now_s``."""
    out = _Out()
    if not link_ok:
        return _link_lost(helm, config, now_s, out)
    if helm.silent:
        out.events.append(Event("info", "link regained; still overridden: commanding nothing until an operator resumes"))
        helm = replace(helm, silent=False)
    if helm.phase in (Phase.WAIT_LINK, Phase.LINK_LOST):
        regained = helm.phase is Phase.LINK_LOST
        text = "link regained: setting up again" if regained else "autopilot heartbeat received"
        out.events.append(Event("info", text))
        # After a silence the executive cannot tell a failsafe that came and went from its own on_breach
        # request: a failsafe still on is taken as the state it comes back to, not as a new override, and
        # the on_breach mode counts as asked for (it was, every retry_s, however long the silence lasted).
        # Requests start afresh, so the decision audit, which runs one tick of the silence, agrees.
        seen = helm if not regained else replace(
            helm, seen_failsafe=vehicle.autopilot_failsafe, mode_request_s=None, arm_request_s=None,
            asked_modes=(*helm.asked_modes[-7:], (int(BREACH_MODE[config.on_breach]), now_s)))
        helm = replace(seen, phase=Phase.SETUP, rates_sent=False, rates_tries=0, activity=None, target_sent_s=None)
    helm = _authority(helm, vehicle, config, now_s, out)
    if helm.phase is Phase.OVERRIDDEN:
        return Tick(helm, tuple(out.commands), tuple(out.events))  # commands nothing: a person or a failsafe has it
    helm = _rates(helm, vehicle, config, now_s, out)
    if helm.phase is Phase.SETUP:
        helm = _setup(helm, vehicle, table, config, now_s, out)
        if helm.phase is Phase.SETUP:
            return Tick(helm, tuple(out.commands), tuple(out.events))
    if not vehicle.has_position:
        if helm.phase is Phase.SAFE and BREACH_MODE[config.on_breach] is SubMode.SURFACE:  # a stop surfaces blind
            helm, _ = _choose(helm, vehicle, table, config, now_s, out)
            helm = _realise(helm, vehicle, config, now_s, out)
        return Tick(helm, tuple(out.commands), tuple(out.events))
    lat, lon, depth = _position(vehicle)
    helm, changed = _choose(helm, vehicle, table, config, now_s, out)
    helm = _realise(helm, vehicle, config, now_s, out)
    act = helm.activity
    assert act is not None
    decision = Decision(
        time_s=now_s,
        lat_deg=lat,
        lon_deg=lon,
        depth_m=depth,
        heading_deg=vehicle.heading_deg,
        cell=act.cell,
        situation=act.situation,
        action=act.action,
        mode=act.mode,
        changed=changed,
    )
    return Tick(helm, tuple(out.commands), tuple(out.events), decision)


def swapped(helm: HelmState) -> HelmState:
    """The helm as a new table takes over: no activity, so the next decision starts afresh."""
    phase = Phase.RUNNING if helm.phase is Phase.ARRIVED else helm.phase
    return replace(helm, phase=phase, activity=None, target_sent_s=None, mode_progress=None)


def rebooted(helm: HelmState) -> HelmState:
    """The helm after an autopilot reboot: set up again from scratch, but a safety stop or an override holds."""
    fresh = HelmState(stop=helm.stop, overridden=helm.overridden, mission_start_s=helm.mission_start_s)
    return replace(fresh, phase=Phase.OVERRIDDEN) if helm.overridden is not None else fresh


def resumed(helm: HelmState, *, clear_stop: bool) -> HelmState:
    """An operator's explicit go: the override ends; with ``clear_stop`` the safety stop too (docs/executive.md)."""
    stop = None if clear_stop else helm.stop
    if helm.overridden is None and stop is helm.stop:
        return helm
    phase = Phase.SETUP if helm.phase in (Phase.OVERRIDDEN, Phase.SAFE) else helm.phase
    return replace(helm, phase=phase, overridden=None, stop=stop, activity=None, target_sent_s=None,
                   mode_request_s=None, arm_request_s=None, rates_sent=False, rates_tries=0, breach=None,
                   breach_since_s=None)


def resume_text(helm: HelmState, *, clear_stop: bool, source: str) -> str | None:
    """The log line for ``resumed`` (the decision audit finds operator actions by it); None when nothing changes."""
    parts = []
    if helm.overridden is not None:
        parts.append("override ended")
    if clear_stop and helm.stop is not None:
        parts.append(f"safety stop ({helm.stop.value}) cleared")
    if not parts:
        return None
    return f"{OPERATOR_RESUME}{', '.join(parts)} by {source}: setting up again"


OPERATOR_RESUME = "operator resume: "


# -- phases -------------------------------------------------------------------------


def _position(vehicle: VehicleState) -> tuple[float, float, float]:
    """(lat, lon, depth) of a vehicle that ``has_position``: the helm decides only with one."""
    lat, lon, depth = vehicle.lat_deg, vehicle.lon_deg, vehicle.depth_m
    assert lat is not None and lon is not None and depth is not None
    return lat, lon, depth


def _due(last_s: float | None, now_s: float, period_s: float) -> bool:
    """``period_s`` has passed since ``last_s``. A clock that went back makes nothing due early: a request
    goes out at most once per period, whatever the time handed in does (a reboot starts the helm afresh)."""
    return last_s is None or now_s - last_s >= period_s


def _mode_due(helm: HelmState, mode: SubMode, now_s: float, config: HelmConfig) -> bool:
    """Whether to ask for ``mode`` now: another mode than the last asked for at once, the same again every retry_s."""
    return helm.mode_requested != int(mode) or _due(helm.mode_request_s, now_s, config.retry_s)


def _link_lost(helm: HelmState, config: HelmConfig, now_s: float, out: _Out) -> Tick:
    if helm.phase is Phase.WAIT_LINK:
        return Tick(helm)
    if helm.phase is Phase.OVERRIDDEN:  # a person or a failsafe has the vehicle: a silence changes nothing of that
        if not helm.silent:
            out.events.append(Event("warning", f"link lost while overridden: no autopilot heartbeat for"
                                               f" {config.link_loss_timeout_s:g} s; still commanding nothing"))
        return Tick(replace(helm, silent=True), (), tuple(out.events))
    mode = BREACH_MODE[config.on_breach]
    if helm.phase is not Phase.LINK_LOST:
        out.events.append(Event("error", f"link lost: no autopilot heartbeat for {config.link_loss_timeout_s:g} s;"
                                         f" on_breach {config.on_breach}: asking for {mode.name}"))
        helm = replace(helm, phase=Phase.LINK_LOST, mode_request_s=None)
    # Best effort: if only the downlink is lost the vehicle still hears this. GUIDED with no
    # new target holds station on ArduSub; ALT_HOLD without thrust drifts at depth.
    if _due(helm.mode_request_s, now_s, config.retry_s):
        helm = _ask_mode(helm, mode, now_s, out)
    return Tick(helm, tuple(out.commands), tuple(out.events))


def _authority(helm: HelmState, vehicle: VehicleState, config: HelmConfig, now_s: float, out: _Out) -> HelmState:
    """Yield to a mode, a disarm or a failsafe the executive did not command (docs/executive.md, "Authority").

    ArduSub changes mode by itself in one case the executive causes: SURFACE becomes ALT_HOLD
    once at the surface (mode reason SURFACE_COMPLETE); that is not an override, also when the
    HEARTBEAT that read SURFACE was missed (asked at the surface, it ends at once).
    """
    asked = tuple((m, t) for m, t in helm.asked_modes if now_s - t <= config.authority_window_s and t <= now_s)
    mode, armed, failsafe = vehicle.mode, vehicle.armed, vehicle.autopilot_failsafe
    why = None
    if helm.phase in _WATCHED:
        wanted = helm.activity.mode if helm.activity is not None else None
        if (helm.seen_mode is not None and mode is not None and mode != helm.seen_mode and mode != wanted
                and all(m != mode for m, _ in asked)
                and not (mode == SubMode.ALT_HOLD and (helm.seen_mode == SubMode.SURFACE
                                                        or any(m == SubMode.SURFACE for m, _ in asked)))):
            why = f"the autopilot's mode became {_mode_name(mode)} (from {_mode_name(helm.seen_mode)}), not asked for"
        elif helm.seen_armed and not armed:
            why = "the autopilot was disarmed, not asked for"
        elif failsafe and not helm.seen_failsafe:
            why = "an autopilot failsafe is active (HEARTBEAT MAV_STATE_CRITICAL)"
    if (mode, armed, failsafe, asked) != (helm.seen_mode, helm.seen_armed, helm.seen_failsafe, helm.asked_modes):
        helm = replace(helm, seen_mode=mode, seen_armed=armed, seen_failsafe=failsafe, asked_modes=asked)
    if why is None:
        return helm  # the same object when nothing changed (most decisions): no copy of the whole state
    out.events.append(Event("error", f"overridden: {why}; the executive commands nothing until an operator resumes"
                                     " (MAV_CMD_MISSION_START or a mission upload)"))
    return replace(helm, phase=Phase.OVERRIDDEN, overridden=why, activity=None, target_sent_s=None)


def _mode_name(mode: int | None) -> str:
    if mode is None:
        return "no mode yet"
    try:
        return SubMode(mode).name
    except ValueError:
        return f"mode {mode}"


def _ask_mode(helm: HelmState, mode: SubMode, now_s: float, out: _Out) -> HelmState:
    """Send a mode request and remember it, so the change it brings is not taken for an override."""
    out.commands.append(SetMode(mode))
    asked = (*helm.asked_modes[-7:], (int(mode), now_s))
    return replace(helm, mode_request_s=now_s, mode_requested=int(mode), asked_modes=asked)


def _rates(helm: HelmState, vehicle: VehicleState, config: HelmConfig, now_s: float, out: _Out) -> HelmState:
    """Ask for the telemetry rates, and again every ``retry_s`` until each request is acknowledged.

    A lost request would leave its stream at the autopilot's default for the whole run
    (MAV_CMD_SET_MESSAGE_INTERVAL is not retried by MAVLink itself). Its COMMAND_ACK does not
    say which message it was for, so the whole set goes again until as many were accepted.
    """
    if helm.rates_sent:
        if (vehicle.interval_acks - helm.rates_acks >= len(config.rates) or helm.rates_tries >= _RATE_TRIES
                or not _due(helm.rates_sent_s, now_s, config.retry_s)):
            return helm
        if helm.rates_tries + 1 == _RATE_TRIES:
            out.events.append(Event("warning", f"telemetry rates not all acknowledged after {_RATE_TRIES} requests;"
                                               " asking no more"))
    out.commands.extend(SetMessageInterval(name, interval) for name, interval in config.rates)
    return replace(helm, rates_sent=True, rates_sent_s=now_s, rates_acks=vehicle.interval_acks,
                   rates_tries=helm.rates_tries + 1)


def _setup(
    helm: HelmState, vehicle: VehicleState, table: PolicyTable | None, config: HelmConfig, now_s: float, out: _Out
) -> HelmState:
    if helm.stop is not None and BREACH_MODE[config.on_breach] is SubMode.SURFACE:
        # Surfacing needs no position: an autopilot that rebooted underwater during a stop has no GPS to find.
        return replace(helm, phase=Phase.SAFE, activity=None)
    helm = _await_position(helm, vehicle, config, now_s, out)
    if helm.waiting is not None:
        return helm
    if helm.stop is not None:  # a safety stop that outlived a reboot or a restart: straight to it
        return replace(helm, phase=Phase.SAFE, activity=None)
    if table is None:
        return replace(helm, phase=Phase.RUNNING)  # "no table" is handled there: surface
    if vehicle.mode != SubMode.GUIDED and _mode_due(helm, SubMode.GUIDED, now_s, config):
        helm = _ask_mode(helm, SubMode.GUIDED, now_s, out)
    if not vehicle.armed and _due(helm.arm_request_s, now_s, config.retry_s):
        out.commands.append(Arm(True))
        helm = replace(helm, arm_request_s=now_s)
    if progress(SubMode.GUIDED, vehicle, None, surface_depth_m=config.depth_tolerance_m) is Progress.COMPLETE:
        start = helm.mission_start_s if helm.mission_start_s is not None else now_s
        out.events.append(Event("info", "armed in GUIDED: following the policy"))
        helm = replace(helm, phase=Phase.RUNNING, mission_start_s=start, activity=None)
    return helm


def _awaited(vehicle: VehicleState) -> str | None:
    """What set-up still waits for before it asks for GUIDED and arms; None when nothing.

    ArduSub refuses GUIDED ("GUIDED requires position") until its EKF has an absolute horizontal
    position, about 41 s after boot in SITL, and sends lat = lon = 0 before its GPS is found; the
    EKF_POS_HORIZ_ABS flag of EKF_STATUS_REPORT says when (the SYS_STATUS pre-arm bit comes earlier and
    is not enough). An autopilot that never sends EKF_STATUS_REPORT is waited for too, with a warning.
    """
    if not vehicle.ekf_reported:
        return "the EKF's absolute position (no EKF_STATUS_REPORT from the autopilot yet)"
    if not vehicle.position_ok:
        return "the EKF's absolute position (EKF_STATUS_REPORT without EKF_POS_HORIZ_ABS)"
    if not vehicle.has_position:
        return "a position (GLOBAL_POSITION_INT) that passes the checks"
    return None


def _await_position(helm: HelmState, vehicle: VehicleState, config: HelmConfig, now_s: float, out: _Out) -> HelmState:
    """Set-up waits for a position the EKF vouches for: announced once, and a warning once it has waited too long."""
    awaited = _awaited(vehicle)
    if awaited is None:
        if helm.waiting is not None:
            out.events.append(Event("info", "set-up: the EKF has an absolute position: asking for GUIDED and arming"))
            helm = replace(helm, waiting=None, waiting_since_s=None, waiting_warned=False)
        return helm
    if awaited != helm.waiting:
        out.events.append(Event("info", f"set-up: waiting for {awaited} before arming and asking for GUIDED"))
        helm = replace(helm, waiting=awaited)
    if helm.waiting_since_s is None:
        if vehicle.time_s > 0.0:  # timed from the first message with time_boot_ms (a HEARTBEAT before it is at 0 s)
            helm = replace(helm, waiting_since_s=now_s)
        return helm
    if not helm.waiting_warned and now_s - helm.waiting_since_s >= config.position_timeout_s:
        out.events.append(Event("warning", f"not started: waited {now_s - helm.waiting_since_s:.0f} s for {awaited};"
                                           " the executive arms and asks for GUIDED only once the autopilot's EKF"
                                           " reports an absolute horizontal position (EKF_POS_HORIZ_ABS)"))
        helm = replace(helm, waiting_warned=True)
    return helm


def _safety(helm: HelmState, vehicle: VehicleState, config: HelmConfig, now_s: float) -> tuple[Situation, str] | None:
    if (helm.phase is Phase.RUNNING and vehicle.position_s is not None
            and now_s - vehicle.position_s > config.position_timeout_s):
        return Situation.POSITION_LOST, (f"no plausible position for {now_s - vehicle.position_s:.0f} s"
                                         f" (position_timeout_s {config.position_timeout_s:g})")
    if config.max_mission_time_s is not None and helm.mission_start_s is not None:
        elapsed = now_s - helm.mission_start_s
        if elapsed > config.max_mission_time_s:
            return Situation.MISSION_TIME, f"mission time {elapsed / 3600:.2f} h exceeds max_mission_time_h {config.max_mission_time_s / 3600:g}"
    if config.min_battery_pct is not None and vehicle.battery_pct is not None and vehicle.battery_pct < config.min_battery_pct:
        return Situation.LOW_BATTERY, f"battery {vehicle.battery_pct:.0f} % is under min_battery_pct {config.min_battery_pct:g}"
    if config.max_depth_m is not None and vehicle.depth_m is not None and vehicle.depth_m > config.max_depth_m:
        return Situation.TOO_DEEP, f"depth {vehicle.depth_m:.1f} m exceeds max_depth_m {config.max_depth_m:g}"
    if (config.geofence is not None and vehicle.lat_deg is not None and vehicle.lon_deg is not None
            and not inside(vehicle.lon_deg, vehicle.lat_deg, config.geofence)):
        return Situation.GEOFENCE, f"position {vehicle.lon_deg:.5f}, {vehicle.lat_deg:.5f} (lon, lat) is outside the geofence"
    return None


def _persisting(helm: HelmState, breach: tuple[Situation, str] | None, config: HelmConfig, now_s: float,
               out: _Out) -> HelmState:
    """Track how long a limit has been exceeded: one sample over a limit never fires it."""
    if breach is None:
        if helm.breach is not None:
            out.events.append(Event("info", f"{helm.breach.value}: back within the limit before it fired"))
        return replace(helm, breach=None, breach_since_s=None) if helm.breach is not None else helm
    situation, text = breach
    if helm.breach is situation:
        return helm
    if situation not in _AT_ONCE:
        out.events.append(Event("warning", f"{text}: on_breach if it lasts {config.breach_window_s:g} s"))
    return replace(helm, breach=situation, breach_since_s=now_s)


def _breach(situation: Situation, vehicle: VehicleState, config: HelmConfig, now_s: float) -> Activity:
    """The configured ``on_breach`` behaviour where the breach happened."""
    mode = BREACH_MODE[config.on_breach]
    target: Command | None = None
    if config.on_breach == "drift":
        target = DepthTarget(float(vehicle.depth_m or 0.0))
    elif config.on_breach == "hold":
        lat, lon, _ = _position(vehicle)
        target = PositionTarget(float(lat), float(lon), float(vehicle.depth_m or 0.0))
    return Activity(situation=situation, action=None, cell=None, mode=mode, target=target, started_s=now_s)


def _choose(
    helm: HelmState, vehicle: VehicleState, table: PolicyTable | None, config: HelmConfig, now_s: float, out: _Out
) -> tuple[HelmState, bool]:
    """Pick the activity for this update; returns the new helm state and whether it changed."""
    current = helm.activity
    if helm.phase is Phase.SAFE:
        if current is not None:
            return helm, False
        assert helm.stop is not None  # SAFE without an activity: a stop carried over a reboot, restart or resume
        out.events.append(Event("error", f"safety stop ({helm.stop.value}) holds until an operator clears it"
                                         f" (MAV_CMD_MISSION_START): on_breach {config.on_breach}"))
        act = _breach(helm.stop, vehicle, config, now_s)
        return replace(helm, activity=act, target_sent_s=None, mode_progress=None), True
    breach = _safety(helm, vehicle, config, now_s)
    helm = _persisting(helm, breach, config, now_s, out)
    if breach is not None and (breach[0] in _AT_ONCE or helm.breach_since_s is not None
                               and now_s - helm.breach_since_s >= config.breach_window_s):
        situation, text = breach
        out.events.append(Event("error", f"{text}: on_breach {config.on_breach}, plan suspended until an operator"
                                         " clears the safety stop (MAV_CMD_MISSION_START)"))
        act = _breach(situation, vehicle, config, now_s)
        return replace(helm, phase=Phase.SAFE, activity=act, target_sent_s=None, mode_progress=None, stop=situation,
                       breach=None, breach_since_s=None), True
    if helm.phase is Phase.ARRIVED and current is not None:
        return helm, False
    lat, lon, depth = _position(vehicle)
    heading = vehicle.heading_deg if vehicle.heading_deg is not None else math.nan
    if table is not None and not math.isfinite(heading):
        # The table's action depends on the heading: none is decided without one (never a NaN taken as east).
        new = Activity(situation=Situation.NO_HEADING, action=None, cell=None, mode=SubMode.ALT_HOLD,
                       target=DepthTarget(depth), started_s=now_s)
        return _switch(helm, current, new, out, "heading unknown: holding depth without thrust until it is known")
    if table is None:
        new = Activity(situation=Situation.NO_TABLE, action=None, cell=None, mode=SubMode.SURFACE, target=None, started_s=now_s)
        return _switch(helm, current, new, out, "no valid policy table: surfacing")
    held = current.cell[1:3] if current is not None and current.cell is not None else None
    look = table.lookup_held(lat, lon, depth, heading, held, config.cell_margin)
    if current is not None and current.completes and look.reason in ("ok", "unreachable"):
        assert current.steering is not None
        if not is_complete(current.steering, heading_deg=vehicle.heading_deg, depth_m=depth):
            if current.timeout_s is None or now_s - current.started_s <= current.timeout_s:
                return helm, False
            out.events.append(Event("warning", f"{current.action.name if current.action else '?'} not complete after "
                                               f"{now_s - current.started_s:.0f} s: deciding again"))
            current = None  # start afresh, with a new timeout, even if the table gives the same action
    if look.reason == "at_goal":
        new = _arrival(look.state, vehicle, table, config, now_s)
        helm = replace(helm, phase=Phase.ARRIVED)
        return _switch(helm, current, new, out, f"goal reached: {config.on_arrival}")
    if look.reason == "outside_grid":
        new = Activity(situation=Situation.OUTSIDE_GRID, action=None, cell=None, mode=SubMode.SURFACE, target=None, started_s=now_s)
        return _switch(helm, current, new, out, f"outside the planned grid at {lon:.5f}, {lat:.5f}, {depth:.1f} m (lon, lat, depth): surfacing")
    if look.reason == "land":
        new = Activity(situation=Situation.LAND, action=None, cell=look.state, mode=SubMode.SURFACE, target=None, started_s=now_s)
        return _switch(helm, current, new, out, f"position in a land cell {look.state}: surfacing")
    if look.reason == "unreachable":
        assert look.state is not None  # a cell of the grid: only outside_grid has no state
        new = Activity(situation=Situation.UNREACHABLE, action=None, cell=look.state, mode=SubMode.ALT_HOLD,
                       target=DepthTarget(table.depth_m[look.state[0]]), started_s=now_s)
        return _switch(helm, current, new, out, f"no action reaches the goal from {look.state}: drifting at depth")
    assert look.state is not None
    new = _action_activity(look.action, look.state, table, config, now_s)
    return _switch(helm, current, new, out, None)


def _switch(helm: HelmState, current: Activity | None, new: Activity, out: _Out, text: str | None) -> tuple[HelmState, bool]:
    if current is not None and current.key == new.key:
        return helm, False
    if text is not None and (current is None or current.situation is not new.situation):
        out.events.append(Event("info" if new.situation is Situation.AT_GOAL else "warning", text))
    elif text is None and current is not None and current.situation is not Situation.FOLLOWING:
        out.events.append(Event("info", f"back on the plan ({current.situation.value} cleared)"))
    return replace(helm, activity=new, target_sent_s=None, mode_progress=None), True


def _action_activity(action: Action, state: tuple[int, int, int, int], table: PolicyTable, config: HelmConfig, now_s: float) -> Activity:
    steering = steer(action, state, table, cruise_speed_m_s=config.cruise_speed_m_s,
                     yaw_rate_deg_s=config.yaw_rate_deg_s, glide_rate_m_s=config.glide_rate_m_s,
                     depth_tolerance_m=config.depth_tolerance_m)
    if steering.kind is SteeringKind.DEPTH:
        # ALT_HOLD: no horizontal thrust, the current carries the vehicle while the depth is held or sought.
        assert steering.depth_m is not None
        return Activity(situation=Situation.FOLLOWING, action=action, cell=state, mode=SubMode.ALT_HOLD,
                        target=DepthTarget(steering.depth_m), started_s=now_s, steering=steering)
    # GUIDED, zero vertical velocity (the depth it is at is held): VELOCITY along the course, ROTATE with
    # zero velocity, which ArduSub flies as station keeping while it turns to the yaw.
    assert steering.yaw_deg is not None
    north, east = steering.velocity_ne_m_s
    return Activity(situation=Situation.FOLLOWING, action=action, cell=state, mode=SubMode.GUIDED,
                    target=VelocityYaw(north, east, 0.0, steering.yaw_deg), started_s=now_s, steering=steering)


def _arrival(state: tuple[int, int, int, int] | None, vehicle: VehicleState, table: PolicyTable, config: HelmConfig, now_s: float) -> Activity:
    mode: SubMode
    target: Command | None
    if config.on_arrival == "surface":
        mode, target = SubMode.SURFACE, None
    elif config.on_arrival == "drift":
        mode, target = SubMode.ALT_HOLD, DepthTarget(float(vehicle.depth_m or 0.0))
    else:  # hold (and "next", until multi-goal missions land): keep station where the goal was reached.
        lat, lon, _ = _position(vehicle)
        mode, target = SubMode.GUIDED, PositionTarget(float(lat), float(lon), table.goal_depth_m)
    return Activity(situation=Situation.AT_GOAL, action=Action.AT_GOAL, cell=state, mode=mode, target=target,
                    started_s=now_s)


def _realise(helm: HelmState, vehicle: VehicleState, config: HelmConfig, now_s: float, out: _Out) -> HelmState:
    """Get the vehicle into the activity's mode, armed, then stream its target."""
    act = helm.activity
    assert act is not None
    if act.mode is not SubMode.SURFACE and not vehicle.armed and _due(helm.arm_request_s, now_s, config.retry_s):
        out.commands.append(Arm(True))
        helm = replace(helm, arm_request_s=now_s)
    done = progress(act.mode, vehicle, helm.mode_progress, surface_depth_m=config.depth_tolerance_m)
    if done is not helm.mode_progress:
        if done is Progress.COMPLETE and act.mode is SubMode.SURFACE:  # never asked again while this activity lasts
            out.events.append(Event("info", "at the surface: SURFACE complete (the autopilot reports"
                                            f" {_mode_name(vehicle.mode)})"))
        helm = replace(helm, mode_progress=done)
    if done is Progress.ASK:
        if _mode_due(helm, act.mode, now_s, config):
            helm = _ask_mode(helm, act.mode, now_s, out)
        return helm
    target = act.target
    if target is not None and _due(helm.target_sent_s, now_s, config.refresh_s):
        if act.steering is not None and act.ramp is None:  # setpoints move from where the vehicle is when first commanded
            heading = vehicle.heading_deg if vehicle.heading_deg is not None and math.isfinite(vehicle.heading_deg) else None
            act = replace(act, ramp=Ramp(now_s, heading, _position(vehicle)[2]))
            helm = replace(helm, activity=act)
        out.commands.append(target_at(target, act.steering, act.ramp, now_s))
        helm = replace(helm, target_sent_s=now_s)
    return helm
