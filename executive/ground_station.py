"""The ground-station link as a MAVLink router on the companion computer sees it (pure decisions, counted).

The executive sits between the autopilot and the ground station (``lrauv exec --gcs``), where
mavlink-router or BlueOS would sit on a vehicle, and does what they do
(https://mavlink.io/en/guide/routing.html):

* everything the autopilot's system sends goes to the ground station's clients as its exact
  frame (signature included, never re-packed), so a ground station picks the vehicle from the
  autopilot's own HEARTBEAT (type SUBMARINE, ArduSub's modes) and shows its telemetry;
* what the ground station sends goes to the autopilot when it is addressed to the autopilot's
  system (any component but ours) or broadcast (no target, or target 0: its heartbeat, which
  ArduSub's GCS failsafe watches, PARAM_REQUEST_LIST to component 0, ...), and to the
  executive's own component when addressed to it (191) or broadcast; a message for another
  system goes nowhere (counted);
* a command for the autopilot while its link is silent or closed is not sent into the void:
  it is answered COMMAND_ACK MAV_RESULT_TEMPORARILY_REJECTED and announced (rate-limited).

A person taking over always wins: mode changes and arming from the ground station are
forwarded untouched, and the helm sees their effect in the autopilot's heartbeat (``executive.helm``,
"overridden"). The executive's own component answers the commands below (``answer_command``)
and the parameter protocol (``executive.parameters``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from executive import mavlink_bridge as bridge
from executive.signing import RefusalLog, note_refusal

COMMANDS = frozenset({"COMMAND_LONG", "COMMAND_INT"})
MAV = bridge.mavlink
# MAV_CMD_REQUEST_MESSAGE: what the executive's component can give (param1 = message id).
REQUESTABLE = {MAV.MAVLINK_MSG_ID_HEARTBEAT: "HEARTBEAT", MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION: "AUTOPILOT_VERSION"}


def target_of(msg: Any) -> tuple[int, int] | None:
    """(system, component) a message is addressed to; None when it has no target (a broadcast).

    MANUAL_CONTROL names its system ``target`` (common.xml) and has no component.
    """
    system = getattr(msg, "target_system", None)
    if system is None:
        system = getattr(msg, "target", None)
    if system is None:
        return None
    return int(system), int(getattr(msg, "target_component", 0))


@dataclass(frozen=True, slots=True)
class Route:
    autopilot: bool  # the frame goes to the autopilot link
    executive: bool  # the executive's component handles it


def route(target: tuple[int, int] | None, *, autopilot_system: int, executive: tuple[int, int]) -> Route:
    """Where a message from the ground station goes (``target_of``)."""
    if target is None or target[0] == 0:
        return Route(autopilot=True, executive=True)
    system, component = target
    return Route(autopilot=system == autopilot_system and (system, component) != executive,
                 executive=system == executive[0] and component in (0, executive[1]))


def for_executive(msg: Any, executive: tuple[int, int]) -> bool:
    """Whether a message from the autopilot is for the executive: its answers to a ground station
    (COMMAND_ACK, PARAM_VALUE, mission replies with the station as target) are only forwarded."""
    target = target_of(msg)
    return target is None or (target[0] in (0, executive[0]) and target[1] in (0, executive[1]))


def reachable(*, heartbeat_s: float | None, now_s: float, timeout_s: float, closed: bool) -> bool:
    """The autopilot link is worth a command: open, and a heartbeat heard within the link-loss timeout."""
    return not closed and heartbeat_s is not None and now_s - heartbeat_s <= timeout_s


@dataclass(frozen=True, slots=True)
class CommandAnswer:
    """The executive component's answer to a COMMAND_LONG / COMMAND_INT addressed to it."""

    result: int | None  # MAV_RESULT of the COMMAND_ACK; None: not ours to answer (a broadcast the autopilot answers)
    text: str  # for the log
    send: str | None = None  # the message to send after an accepted MAV_CMD_REQUEST_MESSAGE
    resume: bool = False  # MAV_CMD_MISSION_START: an operator's explicit go (docs/executive.md, "Authority")


def command_name(command: int) -> str:
    entry = MAV.enums["MAV_CMD"].get(command)
    return entry.name if entry is not None else str(command)


def answer_command(command: int, param1: float, *, component: int, peer: tuple[int, int]) -> CommandAnswer:
    """What the executive's component answers; ``component`` is the command's target (0 or 191).

    Commands to component 0 are the autopilot's to answer, except MAV_CMD_MISSION_START (the
    executive's resume, as it always was). MAV_CMD_REQUEST_MESSAGE for a message the executive
    cannot give gets MAV_RESULT_FAILED, as ArduPilot answers it (GCS_MAVLINK::handle_command_request_message).
    """
    who = f"{command_name(command)} from {peer[0]}/{peer[1]}"
    if command == MAV.MAV_CMD_MISSION_START:
        return CommandAnswer(MAV.MAV_RESULT_ACCEPTED, f"{who}: accepted (operator resume)", resume=True)
    if component == 0:
        return CommandAnswer(None, f"{who} to component 0: left to the autopilot")
    if command == MAV.MAV_CMD_REQUEST_MESSAGE:
        name = REQUESTABLE.get(int(param1))
        if name is None:
            return CommandAnswer(MAV.MAV_RESULT_FAILED, f"{who}: message {int(param1)} cannot be given: failed")
        return CommandAnswer(MAV.MAV_RESULT_ACCEPTED, f"{who}: accepted, {name} sent", send=name)
    return CommandAnswer(MAV.MAV_RESULT_UNSUPPORTED, f"{who}: unsupported by the executive")


class Router:
    """The counts of what went where, and the rate limit of refusal announcements."""

    def __init__(self, *, autopilot_system: int) -> None:
        self.autopilot_system = autopilot_system
        self.executive = (bridge.EXECUTIVE_SYSTEM, bridge.EXECUTIVE_COMPONENT)
        self.to_ground = 0  # frames of the autopilot's system forwarded to the ground station
        self.to_autopilot = 0  # frames of the ground station forwarded to the autopilot
        self.refused = 0  # commands for the autopilot refused while its link was silent
        self.unroutable = 0  # addressed to a system behind neither link
        self.failed = 0  # forwarding sends that raised (dropped, as UDP may)
        self._refusals = RefusalLog()

    def frame_for_ground(self, msg: Any) -> bytes | None:
        """The exact frame to forward to the ground station, for a message of the autopilot's system."""
        if msg.get_msgId() < 0 or msg.get_srcSystem() != self.autopilot_system:
            return None
        if (msg.get_srcSystem(), msg.get_srcComponent()) == self.executive:
            return None
        return bytes(msg.get_msgbuf()) or None

    def from_ground(self, msg: Any) -> Route:
        r = route(target_of(msg), autopilot_system=self.autopilot_system, executive=self.executive)
        if not (r.autopilot or r.executive):
            self.unroutable += 1
        return r

    def refuse(self, msg: Any, wall_s: float, *, link: str) -> str | None:
        """Count a command refused while the autopilot is silent; the announcement when one is due."""
        self.refused += 1
        self._refusals, covers = note_refusal(self._refusals, wall_s)
        if covers is None:
            return None
        more = f" ({covers} since the last report)" if covers > 1 else ""
        return (f"autopilot silent: {command_name(msg.command)} from {msg.get_srcSystem()}/{msg.get_srcComponent()}"
                f" refused (TEMPORARILY_REJECTED), {link}{more}")

    def summary(self) -> str:
        return (f"ground station: {self.to_ground:,} autopilot messages forwarded to it, {self.to_autopilot:,} of its"
                f" forwarded to the autopilot, {self.refused:,} commands refused (autopilot silent),"
                f" {self.unroutable:,} for no system here, {self.failed:,} sends failed")
