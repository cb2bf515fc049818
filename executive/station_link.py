"""The executive's ground-station side: forwarding both ways, and its own component's answers.

``StationLink`` is mixed into ``executive.loop.Executive`` (as ``executive.plan_changes`` is) and
shares its state; the decisions are ``executive.ground_station``'s (routing, refusals, commands)
and ``executive.parameters``' (the parameter protocol), the encoding ``executive.mavlink_bridge``'s.
Forwarding writes another node's frame as it came, after the decision's commands are out, and a
send that fails is counted, never raised into the loop.
"""

from __future__ import annotations

import time
from typing import Any

from executive import ground_station, parameters
from executive import mavlink_bridge as bridge
from executive.goal_tables import MissionPlan
from executive.helm import HelmConfig, HelmState
from executive.links import LinkGuard
from executive.mission_protocol import addressed_to
from executive.recorder import Recorder
from executive.state import Event, Phase, VehicleState


class StationLink:
    """Forwarding and the component's answers; mixed into ``executive.loop.Executive``, whose state it shares."""

    config: Any  # executive.loop.ExecConfig (that module imports this one)
    conn: Any  # the autopilot link
    link: LinkGuard
    gcs: Any  # the ground-station link, or None
    gcs_mav: Any
    router: ground_station.Router
    vehicle: VehicleState
    plan: MissionPlan | None
    helm: HelmState
    helm_config: HelmConfig
    recorder: Recorder

    # The executive's own (executive.loop).
    def _event(self, now_s: float, event: Event) -> None:
        raise NotImplementedError

    def _log(self, fn: Any, *args: Any, **kwargs: Any) -> None:
        raise NotImplementedError

    def _send_on(self, mav: Any, now_s: float, msg: Any) -> None:
        raise NotImplementedError

    def _resume(self, now_s: float, *, clear_stop: bool, source: str) -> None:
        raise NotImplementedError

    def _upload_message(self, msg: Any, mav: Any, now_s: float) -> None:
        raise NotImplementedError

    # -- forwarding -----------------------------------------------------------------------

    def _to_ground(self, msg: Any) -> None:
        """The autopilot's message to the ground station's clients (those heard recently), as its exact frame."""
        frame = None if self.gcs is None else self.router.frame_for_ground(msg)
        if frame is not None and bridge.listening(self.gcs):
            self._count(bridge.forward(self.gcs, frame), to_ground=True)

    def _from_ground(self, msg: Any, now_s: float) -> None:
        """A ground station's message: to the autopilot (a command refused while it is silent), and/or to us."""
        where = self.router.from_ground(msg)
        if where.autopilot and msg.get_type() in ground_station.COMMANDS and not ground_station.reachable(
                heartbeat_s=self.vehicle.heartbeat_s, now_s=now_s, timeout_s=self.config.helm.link_loss_timeout_s,
                closed=self.link.closed):
            peer = (msg.get_srcSystem(), msg.get_srcComponent())
            self._send_on(self.gcs_mav, now_s, bridge.command_ack(
                self.gcs_mav, msg.command, bridge.mavlink.MAV_RESULT_TEMPORARILY_REJECTED, peer))
            text = self.router.refuse(msg, time.monotonic(), link=self.config.link)
            self._log(self.recorder.log, now_s, "info", f"{ground_station.command_name(msg.command)} from"
                                                        f" {peer[0]}/{peer[1]} refused: the autopilot link is silent")
            if text is not None:
                self._event(now_s, Event("warning", text))
        elif where.autopilot:
            self._count(bridge.forward(self.conn, bytes(msg.get_msgbuf())), to_ground=False)
        if where.executive:
            self._upload_message(msg, self.gcs_mav, now_s)

    def _count(self, ok: bool, *, to_ground: bool) -> None:
        if not ok:
            self.router.failed += 1
        elif to_ground:
            self.router.to_ground += 1
        else:
            self.router.to_autopilot += 1

    # -- the executive's own component (system 1, component 191) -------------------------------

    def _component_message(self, msg: Any, mav: Any, now_s: float) -> None:
        """A command or parameter message addressed to the executive (or to component 0 of its system)."""
        if not addressed_to(msg, bridge.EXECUTIVE_SYSTEM, bridge.EXECUTIVE_COMPONENT) or msg.target_system == 0:
            return
        if msg.get_type() in parameters.MESSAGES:
            self._parameter_message(msg, mav, now_s)
        else:
            self._operator_command(msg, mav, now_s)

    def _operator_command(self, msg: Any, mav: Any, now_s: float) -> None:
        """COMMAND_LONG / COMMAND_INT (``ground_station.answer_command``); MAV_CMD_MISSION_START resumes
        (docs/executive.md, "Authority"). Every answer is logged."""
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        answer = ground_station.answer_command(msg.command, msg.param1, component=msg.target_component, peer=peer)
        self._log(self.recorder.log, now_s, "info", answer.text)
        if answer.resume:
            self._resume(now_s, clear_stop=True, source=f"MAV_CMD_MISSION_START from {peer[0]}/{peer[1]}")
        if answer.result is not None:
            self._send_on(mav, now_s, bridge.command_ack(mav, msg.command, answer.result, peer))
        if answer.send == "HEARTBEAT":
            healthy = self.helm.phase not in (Phase.SAFE, Phase.LINK_LOST)
            self._send_on(mav, now_s, bridge.heartbeat(mav, healthy=healthy))
        elif answer.send == "AUTOPILOT_VERSION":
            self._send_on(mav, now_s, bridge.autopilot_version(mav))

    def _parameter_message(self, msg: Any, mav: Any, now_s: float) -> None:
        """The parameter protocol (``executive.parameters``): read-only parameters, every answer logged."""
        plan, helm = self.plan, self.helm_config
        params = parameters.table(parameters.Facts(
            goal_index=-1 if plan is None else plan.index, goal_count=0 if plan is None else len(plan.goals),
            safety_stop=self.helm.stop is not None, max_depth_m=helm.max_depth_m, min_battery_pct=helm.min_battery_pct))
        answer = parameters.answer(params, msg.get_type(), name=parameters.param_name(getattr(msg, "param_id", "")),
                                   index=getattr(msg, "param_index", -1), value=getattr(msg, "param_value", 0.0),
                                   peer=(msg.get_srcSystem(), msg.get_srcComponent()))
        for v in answer.values:  # the protocol's answer first, then what is said of it
            self._send_on(mav, now_s, bridge.param_value(mav, v.name, v.value, v.index, v.count))
        if answer.refused:
            self._event(now_s, Event("warning", answer.text))
        else:
            self._log(self.recorder.log, now_s, "info", answer.text)
