"""The executive's I/O shell: MAVLink link, vehicle clock and MCAP log around the pure helm.

One thread, one ``select`` loop. Each position or attitude message from the
autopilot updates the ``VehicleState`` and runs ``helm.step``; the commands it
returns are encoded by the bridge and sent, and everything (telemetry, state,
decisions, commands, events, raw MAVLink both ways) goes to the MCAP log.
Timing is vehicle time (``executive.clock``), so the loop is the same at any
simulator speedup.

Uploads arrive on the ground-station link (``gcs_link``) or through the
autopilot: goals by the mission protocol (``executive.mission_protocol``), tables and
forecasts by MAVLink FTP (``executive.ftp``). What becomes of them, and of the onboard
planner's tables, is ``executive.plan_changes``: checked, then swapped in whole just before a
decision, or refused with a reason and never replacing the running plan.
"""

from __future__ import annotations

import select
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from executive import mavlink_bridge as bridge
from executive import envelope, goal_tables, ground_station, parameters, plausibility, timeline
from executive import signing, tide_watch
from executive.clock import VehicleClock
from executive.helm import HEARTBEAT_PHASES, HelmConfig, HelmState, rebooted, resume_text, resumed, step
from executive.latency import LatencyHistogram
from executive.links import LinkGuard
from executive.mission_protocol import addressed_to
from executive.plan_changes import PlanChanges
from executive.station_link import StationLink
from executive.raw_log import RawFilter
from executive.goal_tables import MissionPlan
from executive.recorder import Recorder, Topic
from executive.state_writer import StateWriter
from executive.replanner import ForecastWatcher, Replanner
from executive.state import Command, Event, LogLevelName, Phase, Situation, VehicleState
from executive.uploads import UploadQuota, Uploads
from planner.contract.errors import ExecutiveError
from planner.contract.geodesy import BBox
from planner.contract.table import PolicyTable

_POLL_S = 0.05  # longest wait in select (wall); heartbeats and link checks run at least this often
_DRAIN_BUDGET_S = 0.01  # longest burst of input handling (wall) before time-driven work gets its turn
_HEARTBEAT_PERIOD_S = 1.0  # vehicle time (section 2.1: 1 Hz)
_STATE_FIELDS = tuple(f.name for f in fields(VehicleState))
_WATCH_PERIOD_S = 1.0  # wall seconds between looks at the watched forecast directory


@dataclass(frozen=True, kw_only=True)
class ExecConfig:
    link: str  # pymavlink address: udpout:127.0.0.1:14560, tcp:127.0.0.1:5760, ...
    log_path: Path
    helm: HelmConfig = field(default_factory=HelmConfig)
    exit_on_arrival: bool = False
    linger_s: float = 10.0  # vehicle seconds to keep the arrival behaviour before exiting
    max_wall_s: float | None = None
    max_vehicle_s: float | None = None
    autopilot_system: int = bridge.AUTOPILOT_SYSTEM
    gcs_link: str | None = None  # pymavlink address for the ground station (uploads), e.g. udpin:0.0.0.0:14551
    gcs_client_timeout_s: float | None = 30.0  # wall s: a ground station silent this long gets no more replies
    mission_path: Path | None = None  # the mission YAML: needed to plan onboard
    watch_dir: Path | None = None  # new forecast files here trigger a replan
    work_dir: Path | None = None  # uploaded forecasts and onboard plans (default: beside the log)
    replan_on_new_forecast: bool = True
    replan_period_s: float | None = None  # vehicle seconds between replans on the latest forecast
    signing: signing.SigningKey | None = None  # MAVLink 2 signing: required of uploads and commands, used on all we send
    state_dir: Path | None = None  # durable state for a restart (executive.durable): at start, every swap and tide fit
    upload_quota: UploadQuota = field(default_factory=UploadQuota)  # files and bytes uploads may hold (executive.uploads)
    coverage: BBox | None = None  # the mission's planning box: uploaded goals must lie in it (executive.envelope)


@dataclass(frozen=True, slots=True)
class RunSummary:
    """How a run ended: printed by ``lrauv exec`` and the demo."""

    reached: bool
    arrival_s: float | None  # vehicle time at the goal
    mission_time_s: float | None  # from the start of the mission (armed in GUIDED) to the goal
    energy_used_wh: float | None
    vehicle_time_s: float
    wall_s: float
    decisions: int
    messages_in: int
    messages_bad: int
    commands_out: int
    messages_not_logged: int  # the autopilot's unused messages, counted but not in the raw log (executive.raw_log)
    final_phase: str
    reason: str  # why the loop stopped
    log_path: str
    decision_median_us: float | None = None  # datagram read -> commands sent
    decision_p99_us: float | None = None
    message_p99_us: float | None = None  # including the MCAP writes


class Executive(PlanChanges, StationLink):
    """Runs the helm against a live MAVLink link until told to stop or the mission ends."""

    def __init__(self, config: ExecConfig, table: PolicyTable | MissionPlan | None, *,
                 table_bytes: Mapping[int, bytes] | None = None,
                 metadata: dict[str, dict[str, str]] | None = None, safety_stop: Situation | None = None,
                 tide: tide_watch.TideWatch | None = None) -> None:
        from pymavlink import mavutil  # transport classes only; encoding and parsing are the bridge's

        self.config = config
        if isinstance(table, PolicyTable):
            table = goal_tables.single(table, on_arrival=config.helm.on_arrival)
        self.plan: MissionPlan | None = table
        self.helm_config = self._config_for(self.plan)
        self.envelope = envelope.Envelope(max_depth_m=config.helm.max_depth_m, geofence=config.helm.geofence,
                                          coverage=config.coverage)
        for n, given in enumerate(() if self.plan is None else self.plan.tables):
            reason = None if given is None else envelope.check_table(given, self.envelope)
            if reason is not None:
                raise ExecutiveError(f"the table of goal {n} is outside the mission's safety section: {reason}")
        # Signing (executive.signing): one stream table for both links, as ArduPilot's; refusals by verdict.
        self.streams = None if config.signing is None else signing.Streams(config.signing)
        self.signature_refusals: dict[signing.Verdict, int] = {}
        self._refusal_logs: dict[tuple[signing.Verdict, signing.Link], signing.RefusalLog] = {}
        self.conn = bridge.open_link(config.link, source_system=bridge.EXECUTIVE_SYSTEM,
                                     source_component=bridge.EXECUTIVE_COMPONENT)
        self.link = LinkGuard(self.conn, config.autopilot_system)  # locked to the autopilot once heard
        self.raw = RawFilter(name for name, _ in config.helm.rates)  # what the raw MAVLink log keeps
        self.lockstep = False  # the autopilot asked for progress reports (a TIMESYNC request: a lockstep simulator)
        self.progress_reports = 0  # lockstep reports sent (bridge.progress_report)
        self._reported_s = 0.0  # the vehicle time of the last report
        self._closed_said = False  # the autopilot link's close was announced
        self._jumped_s = 0.0  # vehicle time of the last timestamp that jumped past the link-loss timeout
        self.mav = bridge.new_mav(self.conn, streams=self.streams, link_id=signing.LINK_ID_AUTOPILOT)
        self.gcs = None
        if config.gcs_link is not None:
            self.gcs = bridge.open_link(config.gcs_link, source_system=bridge.EXECUTIVE_SYSTEM,
                                        source_component=bridge.EXECUTIVE_COMPONENT,
                                        client_timeout_s=config.gcs_client_timeout_s, flag="--gcs")
            self.gcs_mav = bridge.new_mav(self.gcs, streams=self.streams, link_id=signing.LINK_ID_GROUND_STATION)
        self.router = ground_station.Router(autopilot_system=config.autopilot_system)  # the ground station's traffic
        # UDP carries whole frames in each datagram: the parser starts afresh with each, so the tail of
        # a cut frame can never join the next datagram's bytes into a frame nobody sent (TCP is a stream).
        self._datagrams = isinstance(self.conn, mavutil.mavudp)
        self._gcs_datagrams = self.gcs is not None and isinstance(self.gcs, mavutil.mavudp)
        self.clock = VehicleClock()
        self.vehicle = VehicleState()
        self.helm = HelmState(stop=safety_stop)  # a stop saved by the run before a restart holds (durable)
        self.gate = plausibility.Gate()  # telemetry checks (executive.plausibility)
        self.boot = plausibility.BootTime()
        # In the background (executive.log_writer): a full, slow or failing disk degrades the log, never control.
        self.recorder = Recorder(config.log_path, metadata=metadata or {}, background=True)
        self._last_time: dict[str, float] = {}
        self._next_heartbeat_s = 0.0
        self._next_heartbeat_wall = 0.0
        self._arrival_s: float | None = None
        self._counts = {"decisions": 0, "in": 0, "bad": 0, "out": 0, "stale": 0}
        self._stop_reason: str | None = None
        # Log writes wait until the message's commands are out: logging never delays control.
        self._later: list[tuple[Any, tuple[Any, ...], dict[str, Any]]] = []
        self.decision_latency = LatencyHistogram()  # datagram read -> commands sent
        self.message_cost = LatencyHistogram()  # datagram read -> everything logged
        # Plan changes: the next plan waits here for a decision boundary.
        self._pending: tuple[MissionPlan, dict[str, Any]] | None = None
        self.staged: MissionPlan | None = None  # uploaded goals still waiting for their first table
        self.swaps: list[dict[str, Any]] = []  # every swap's log record, for the summary and tests
        self._unix_offset_s: float | None = None  # SYSTEM_TIME: unix time = vehicle time + offset
        self.timeline = timeline.Timeline()  # the slice of a time-varying plan the last decision used
        # The current met and the tide's timing fitted to it; a restart keeps them (durable), as a pause in the record.
        self.tide = tide or tide_watch.TideWatch()
        self._work_dir = config.work_dir or config.log_path.with_name(config.log_path.stem + "-work")
        self.uploads = Uploads(accept_goals=self._accept_goals, accept_file=self._accept_file,
                               flying=self._flying, set_current=self._set_current,
                               refused=lambda what, why: self._refuse(self.clock.now_s(time.monotonic()), what, why,
                                                                      notify=False),
                               quota=config.upload_quota, forecast_dir=self._work_dir / "forecasts",
                               announce=lambda text: self._event(self.clock.now_s(time.monotonic()),
                                                                 Event("warning", text)))
        self.replanner = Replanner(config.mission_path, self._work_dir) if config.mission_path is not None else None
        self.watcher = ForecastWatcher(config.watch_dir) if config.watch_dir is not None else None
        self._next_watch_wall = 0.0
        self._latest_forecast: Path | None = None
        self._last_plan_s: float | None = None
        self._asked_next: int | None = None
        # What the decision audit (planner.shore.replay.audit) needs to run the helm again: its settings,
        # the active goal and every table's exact bytes.
        self.recorder.metadata("helm", {"config": self.helm_config.to_json(),
                                        "goal_index": str(self.plan.index if self.plan is not None else 0),
                                        "safety_stop": "" if safety_stop is None else safety_stop.value})
        self._record_map(0.0, geofence=True)  # goals, geofence and running plan on Foxglove's map
        self._blobs: dict[int, bytes] = {}  # every table's exact bytes, for the durable state
        # Off the decision path (executive.state_writer): a slow or full disk never holds up a decision.
        self.state_writer = None if config.state_dir is None else StateWriter(config.state_dir)
        if self.plan is not None and self.plan.table is not None:
            blobs = table_bytes or {}
            for index, table_n in enumerate(self.plan.tables):
                if table_n is not None:
                    self._blobs[table_n.crc32] = blobs.get(table_n.crc32) or table_n.to_bytes()
                    self._record_policy(table_n, self._blobs[table_n.crc32], "loaded", goal_index=index)
            kept = tide_watch.kept_text(self.tide)  # before any decision: the audit applies its shift
            if kept is not None:
                self._event(0.0, kept)
            self._save_state(0.0)
        else:
            self._event(0.0, Event("error", "no policy table: the vehicle will be surfaced"))

    def _config_for(self, plan: MissionPlan | None) -> HelmConfig:
        goal = None if plan is None else plan.goal
        if goal is None:
            return self.config.helm
        return replace(self.config.helm, on_arrival=goal.on_arrival)

    # -- public ------------------------------------------------------------------------

    def run(self, stop: Any = None) -> RunSummary:
        """Loop until ``stop.is_set()``, arrival (when configured) or a time limit."""
        wall0 = time.monotonic()
        try:
            self._heartbeat(wall0)
            while self._stop_reason is None:
                if stop is not None and stop.is_set():
                    self._stop_reason = "stopped"
                    break
                wall = time.monotonic()
                wait = min(_POLL_S, self._wall_to_heartbeat(wall))
                fd = self.link.fd  # a listening TCP link's changes with its client; None once closed
                fds = [f for f in (fd, None if self.gcs is None else self.gcs.fd) if f is not None]
                ready = select.select(fds, [], [], wait)[0] if fds else []
                if not fds:
                    time.sleep(wait)
                if fd is not None and fd in ready:
                    self._drain(time.monotonic())
                if self.gcs is not None and self.gcs.fd in ready:
                    self._drain_gcs()
                self._housekeeping(time.monotonic(), wall0)
        finally:
            summary = self._summary(time.monotonic() - wall0)
            self.close()
        return summary

    def close(self) -> None:
        if self.replanner is not None:
            self.replanner.close()
        if self.state_writer is not None:
            for event in self.state_writer.close():
                self._log(self.recorder.log, self.clock.now_s(time.monotonic()), event.level, event.text)
        if self.gcs is not None:
            self._log(self.recorder.log, self.clock.now_s(time.monotonic()), "info", self.router.summary())
        self._write_later()
        self.recorder.close()
        self.conn.close()
        if self.gcs is not None:
            self.gcs.close()

    # -- input -------------------------------------------------------------------------

    def _drain(self, wall: float) -> None:
        # Bounded, so that at high speedup a full socket cannot starve the heartbeat
        # (due every vehicle second) or the wall-time limit; at least one datagram per call.
        # Then one lockstep report: everything from the autopilot up to this vehicle time is handled.
        deadline = wall + min(_DRAIN_BUDGET_S, self._wall_to_heartbeat(wall))
        while True:
            data = self.link.read()  # a datagram, or all that waits of a stream (TCP, serial)
            if not data:
                break
            if not self.link.admit(data):  # from elsewhere, or a repeat
                self._warn_link()
                if time.monotonic() >= deadline:
                    break
                continue
            t0 = time.perf_counter()
            try:
                msgs = self.mav.parse_buffer(bytes(data) if not isinstance(data, bytes) else data) or []
            except Exception:  # pymavlink raises on some malformed frames even when robust
                self._counts["bad"] += 1
                msgs = []
            if any(bridge.asks_for_progress(m, self.config.autopilot_system) for m in msgs):
                self.lockstep = True  # answered by the report at the end of this burst
            if self._datagrams:
                bridge.end_datagram(self.mav)
                if (locked := self.link.lock_on(msgs)) is not None:
                    self._log(self.recorder.log, self.clock.now_s(time.monotonic()), "info",
                              f"autopilot link locked to {locked[0]}:{locked[1]}")
            wall = time.monotonic()
            for msg in msgs:
                decided = self._on_message(msg, wall)
                if decided:
                    self.decision_latency.add(time.perf_counter() - t0)
                self._to_ground(msg)  # once the decision's commands are out
                self._write_later()
                if decided:
                    self.message_cost.add(time.perf_counter() - t0)
            if wall >= deadline:
                break
        wall = time.monotonic()
        if self._wall_to_heartbeat(wall) <= 0.0:
            self._heartbeat(wall)  # due (vehicle time jumped on): sent before the report, which it carries, so
        else:                      # that a simulator in lockstep never steps past the executive's heartbeat
            self._report_progress(wall)

    def _drain_gcs(self) -> None:
        """Ground-station traffic: uploads only, never a decision; bounded like ``_drain``."""
        assert self.gcs is not None
        deadline = time.monotonic() + _DRAIN_BUDGET_S
        while time.monotonic() < deadline:
            data = self.gcs.recv()
            if not data:
                break
            try:
                msgs = self.gcs_mav.parse_buffer(bytes(data)) or []
            except Exception:  # as in _drain: a malformed frame is counted, never raised
                self._counts["bad"] += 1
                msgs = []
            if self._gcs_datagrams:
                bridge.end_datagram(self.gcs_mav)
            now_s = self.clock.now_s(time.monotonic())
            for msg in msgs:
                if msg.get_msgId() < 0:  # as in _on_message
                    self._counts["bad"] += 1
                    continue
                self._counts["in"] += 1
                if not self._admitted(msg, signing.Link.GROUND_STATION, now_s, from_autopilot=False):
                    continue
                self._log(self._record_rx, now_s, msg)
                self._from_ground(msg, now_s)
        self._write_later()

    def _admitted(self, msg: Any, link: signing.Link, now_s: float, *, from_autopilot: bool) -> bool:
        """With a signing key: whether ``msg`` goes on (``signing.must_be_signed``).

        A refusal is counted by verdict and never reaches ``Uploads`` or the raw MAVLink log;
        the warning (log and STATUSTEXT) is rate-limited per verdict and link (``signing.RefusalLog``).
        """
        if self.streams is None:
            return True
        verdict = bridge.signature(msg)
        kind = msg.get_type()
        if verdict is signing.Verdict.SIGNED or not signing.must_be_signed(
                kind, link=link, from_autopilot=from_autopilot,
                for_us=addressed_to(msg, bridge.EXECUTIVE_SYSTEM, bridge.EXECUTIVE_COMPONENT)):
            return True
        self.signature_refusals[verdict] = self.signature_refusals.get(verdict, 0) + 1
        log, covers = signing.note_refusal(self._refusal_logs.get((verdict, link), signing.RefusalLog()), time.monotonic())
        self._refusal_logs[(verdict, link)] = log
        if covers is not None:
            source = (msg.get_srcSystem(), msg.get_srcComponent())
            self._event(now_s, Event("warning", signing.refusal_text(verdict, kind, source, link, covers)))
        return False

    def _upload_message(self, msg: Any, mav: Any, now_s: float) -> None:
        if msg.get_type() in ground_station.COMMANDS | parameters.MESSAGES:
            self._component_message(msg, mav, now_s)  # executive.station_link
            return
        try:
            replies = self.uploads.handle(msg, mav, time.monotonic())
        except Exception as exc:  # an upload must never stop the loop: count it, say it, go on
            self._counts["bad"] += 1
            self._event(now_s, Event("error", f"{msg.get_type()} from {msg.get_srcSystem()}/{msg.get_srcComponent()}"
                                              f" dropped: {type(exc).__name__}: {exc}"))
            return
        for reply in replies:
            self._send_on(mav, now_s, reply)

    def _resume(self, now_s: float, *, clear_stop: bool, source: str) -> None:
        """An operator's explicit go: logged in the words the decision audit looks for."""
        text = resume_text(self.helm, clear_stop=clear_stop, source=source)
        if text is None:
            return
        self.helm = resumed(self.helm, clear_stop=clear_stop)
        self._event(now_s, Event("warning", text))
        self._log(self._save_state, now_s)

    def _log(self, fn: Any, *args: Any, **kwargs: Any) -> None:
        self._later.append((fn, args, kwargs))

    def _write_later(self) -> None:
        for fn, args, kwargs in self._later:
            fn(*args, **kwargs)
        self._later.clear()

    def _on_message(self, msg: Any, wall: float) -> bool:
        """Handle one message; True when it ran a decision."""
        kind = msg.get_type()
        if msg.get_msgId() < 0:  # BAD_DATA, or UNKNOWN_n: an id this dialect lacks, so its CRC is unchecked
            self._counts["bad"] += 1
            return False
        self._counts["in"] += 1
        t_boot = bridge.time_boot_s(msg)
        mine = bridge.from_autopilot(msg, self.config.autopilot_system)
        note: dict[str, Any] = {}  # what the checks made of the message, for its log record (the audit reads it)
        if mine and t_boot is not None:
            t_boot = self._stamp(t_boot, wall, note)
            if t_boot is None:
                if self.raw.keep(kind):
                    self._log(self._record_rx, self.clock.now_s(wall), msg, note)
                return False
        if mine and t_boot is not None and not self.clock.synced and self.vehicle.heartbeat_s is not None:
            # HEARTBEAT carries no time_boot_ms: one heard before the first timestamp was stamped
            # 0 s. Move it to the vehicle's time base, or an autopilot that booted more than the
            # link-loss timeout ago would look silent at once.
            self.vehicle = replace(self.vehicle, heartbeat_s=t_boot)
        if (mine and t_boot is not None and self.clock.synced
                and t_boot - self.clock.now_s(wall) > self.config.helm.link_loss_timeout_s):
            # Vehicle time jumped past the timeout: a simulator that ran on at its speedup through a silence the
            # clock timed at real time. The link is back; the heartbeat gets the timeout from here to follow.
            self._jumped_s = t_boot
        if mine and t_boot is not None and self.clock.observe(t_boot, wall):
            self._event(t_boot, Event("warning", "autopilot time went back: it rebooted; setting up again"))
            self.vehicle = VehicleState()
            self.helm = rebooted(self.helm)  # a safety stop or an override outlives the reboot
            self.gate = plausibility.Gate()
            self._last_time.clear()
            self._jumped_s = 0.0
            self._unix_offset_s = None  # relative to the old boot: UTC is unknown until the next SYSTEM_TIME
            self.tide = replace(self.tide, water_ne_m_s=None, since_s=0.0)  # no command yet
        now_s = self.clock.now_s(wall)
        if not mine and not self._admitted(msg, signing.Link.AUTOPILOT, now_s, from_autopilot=False):
            return False
        if not mine or self.raw.keep(kind):  # ArduSub's unused default streams are only counted
            self._log(self._record_rx, now_s, msg, note)
        if not mine:
            if kind in Uploads.MESSAGES | ground_station.COMMANDS | parameters.MESSAGES:  # a GCS behind the autopilot
                self._upload_message(msg, self.mav, now_s)
            return False
        if not ground_station.for_executive(msg, self.router.executive):
            return False  # the autopilot's answer to a ground station: forwarded, not ours
        if t_boot is not None:
            if t_boot < self._last_time.get(kind, -1.0):
                self._counts["stale"] += 1  # reordered or duplicated datagram: never step back in time
                return False
            self._last_time[kind] = t_boot
        screened = plausibility.screen(self.gate, self.vehicle, bridge.apply(self.vehicle, msg, now_s), kind,
                                       self.helm_config.limits, t_boot)
        self.gate, self.vehicle = screened.gate, screened.vehicle
        for event in screened.events:
            self._event(now_s, event)
        if kind == "SYSTEM_TIME":
            self._unix_offset_s = bridge.unix_offset_s(msg) or self._unix_offset_s
            self.recorder.system_time(msg.time_unix_usec, t_boot)  # the log's UTC (executive.log_clock)
        if kind in ("COMMAND_ACK", "STATUSTEXT"):
            level: LogLevelName = "info" if kind == "STATUSTEXT" and msg.severity > 4 else "warning"
            if kind == "COMMAND_ACK" and msg.result == 0:
                level = "info"
            if kind == "STATUSTEXT" and self.gcs is not None:  # the ground station has it as sent: not repeated
                self._log(self.recorder.log, now_s, level, bridge.command_text(msg))
            else:
                self._event(now_s, Event(level, bridge.command_text(msg)))
        if kind == "GLOBAL_POSITION_INT":
            self._log(self._record_state, now_s, self.vehicle, msg)
        if kind in bridge.DECISION_MESSAGES or (kind == "HEARTBEAT" and self.helm.phase in HEARTBEAT_PHASES):
            self._tick(now_s if t_boot is None else t_boot, link_ok=True)
            if kind == "GLOBAL_POSITION_INT":  # after the decision: a new shift holds from the next one on, as logged
                self._measure_current(now_s if t_boot is None else t_boot, msg, fresh=self.vehicle.position_s == t_boot)
            return kind in bridge.DECISION_MESSAGES
        return False

    def _measure_current(self, now_s: float, msg: Any, *, fresh: bool) -> None:
        # GLOBAL_POSITION_INT's ground velocity: vx north, vy east, cm/s.
        before = self.tide.clock.next_fit_unix_s
        self.tide, event = tide_watch.measured(self.tide, self.table, self.vehicle, now_s,
                                               timeline.utc_s(now_s, self._unix_offset_s), msg.vx / 100.0,
                                               msg.vy / 100.0, fresh=fresh,
                                               running=self.helm.phase is Phase.RUNNING)
        if event is not None:
            self._event(now_s, event)
        if self.tide.clock.next_fit_unix_s != before:  # fitted again (every 10 minutes): kept for a restart
            self._log(self._save_state, now_s)

    def _record_rx(self, now_s: float, msg: Any, note: Mapping[str, Any] | None = None) -> None:
        self.recorder.write(Topic.MAVLINK_RX, now_s, {**bridge.describe(msg), **(note or {})})

    def _stamp(self, raw_s: float, wall: float, note: dict[str, Any]) -> float | None:
        """The message's continuous vehicle time, or None when the checks drop it (``plausibility.stamp``)."""
        last = max(self._last_time.values(), default=None)
        stamped = plausibility.stamp(self.boot, raw_s, last_s=last,
                                     expected_s=self.clock.latest_s(wall) if self.clock.synced else None,
                                     rate=self.clock.rate, wall_s=wall, limits=self.helm_config.limits)
        first_doubt = stamped.verdict == "drop" and self.boot.doubts == 0
        self.boot = stamped.boot
        if stamped.boot.epoch_s:
            note["epoch_s"] = stamped.boot.epoch_s
        if stamped.text is not None and (stamped.verdict != "drop" or first_doubt):
            self._event(self.clock.now_s(wall), Event("info" if stamped.verdict == "wrapped" else "warning",
                                                      stamped.text if stamped.verdict != "drop"
                                                      else f"message dropped: {stamped.text}"))
        if stamped.verdict == "drop":
            self._counts["bad"] += 1
            note["rejected"] = stamped.text
            return None
        return stamped.time_s

    # -- decisions and output ---------------------------------------------------------------

    def _tick(self, now_s: float, *, link_ok: bool) -> None:
        if self._pending is not None:
            self._swap(now_s)  # the decision boundary: a new plan is used whole, from this decision on
        # A time-varying plan: the slice that holds at the vehicle's UTC time (a stationary one is its own slice).
        table = self.table
        followed = None if table is None else timeline.follow(
            self.timeline, table, timeline.utc_s(now_s, self._unix_offset_s), self.tide.shift_for(table))
        current = None if followed is None else followed.current
        tick = step(self.helm, self.vehicle, None if current is None else current.table, self.helm_config,
                    now_s=now_s, link_ok=link_ok)
        stopped = tick.helm.stop is not None and tick.helm.stop is not self.helm.stop
        self.helm = tick.helm
        if stopped:  # the stop must outlive a restart (durable): saved once this decision's commands are out
            self._log(self._save_state, now_s)
        if followed is not None and tick.decision is not None:  # the log announces the slice decisions use
            self.timeline = followed.timeline
            for event in followed.events:
                self._event(now_s, event)
        for event in tick.events:
            self._event(now_s, event)
        for cmd in tick.commands:
            self._send_command(now_s, cmd)
        if tick.decision is not None:
            self._counts["decisions"] += 1
            self._log(self.recorder.write, Topic.DECISION, now_s, timeline.decision_record(tick.decision, current))
        if self.helm.phase is Phase.ARRIVED:
            self._arrived(now_s)

    def _arrived(self, now_s: float) -> None:
        """At the active goal: go on to the next one (``on_arrival: next``) or end the mission."""
        plan = self.plan
        assert plan is not None
        if plan.goal is not None and plan.goal.on_arrival == "next" and plan.has_next:
            nxt = plan.index + 1
            if plan.tables[nxt] is not None:
                self._event(now_s, Event("info", f"goal {plan.index} reached: on to goal {nxt}"))
                self._propose(replace(plan, index=nxt), {"source": "next goal"})
                self._swap(now_s)
            elif self._asked_next != nxt:
                self._asked_next = nxt
                if self.replanner is not None:
                    self._event(now_s, Event("info", f"goal {plan.index} reached: planning goal {nxt} onboard, holding"))
                    self._request_plan(now_s, nxt, plan.goals[nxt], reason="next goal")
                else:
                    self._event(now_s, Event("error", f"goal {plan.index} reached but goal {nxt} has no table"
                                                      " and no onboard planner: holding"))
            return
        if self._arrival_s is None:
            self._arrival_s = now_s

    def _send_command(self, now_s: float, cmd: Command) -> None:
        msg = bridge.encode(self.mav, cmd, time_boot_ms=int(now_s * 1000) & 0xFFFFFFFF,
                            target_system=self.config.autopilot_system)
        self._send(now_s, msg)
        self.tide = tide_watch.commanded(self.tide, cmd, now_s)
        self._log(self._record_command, now_s, cmd)

    def _record_command(self, now_s: float, cmd: Command) -> None:
        fields = {name: getattr(cmd, name) for name in cmd.__slots__}
        self.recorder.write(Topic.COMMAND, now_s, {"time_s": now_s, "kind": type(cmd).__name__, **fields})

    def _send(self, now_s: float, msg: Any) -> None:
        self.mav.send(msg)
        self._counts["out"] += 1
        self._log(self._record_tx, now_s, msg)

    def _send_on(self, mav: Any, now_s: float, msg: Any) -> None:
        mav.send(msg)
        self._counts["out"] += 1
        self._log(self._record_tx, now_s, msg)

    def _record_tx(self, now_s: float, msg: Any) -> None:
        self.recorder.write(Topic.MAVLINK_TX, now_s, bridge.describe(msg))

    def _event(self, now_s: float, event: Event) -> None:
        self._log(self.recorder.log, now_s, event.level, event.text)
        if event.level in ("warning", "error"):
            for msg in bridge.statustexts(self.mav, event):
                self._send(now_s, msg)
            if self.gcs is not None:
                for msg in bridge.statustexts(self.gcs_mav, event):
                    self._send_on(self.gcs_mav, now_s, msg)

    def _record_state(self, now_s: float, v: VehicleState, msg: Any = None) -> None:
        lat, lon, depth = v.lat_deg, v.lon_deg, v.depth_m
        if lat is not None and lon is not None and depth is not None:  # VehicleState.has_position, narrowed
            # GLOBAL_POSITION_INT's ground velocity is NED in cm/s; LocationFix's is ENU in m/s.
            velocity = None if msg is None else (msg.vy / 100.0, msg.vx / 100.0, -msg.vz / 100.0)
            self.recorder.location_fix(now_s, lat_deg=lat, lon_deg=lon, depth_m=depth, heading_deg=v.heading_deg,
                                       velocity_enu_m_s=velocity)
        self.recorder.write(Topic.STATE, now_s, {name: getattr(v, name) for name in _STATE_FIELDS})

    def _record_policy(self, table: PolicyTable, table_bytes: bytes | None, reason: str, *, now_s: float = 0.0,
                       goal_index: int | None = None) -> None:
        header = table.header()
        record = {
            "time_s": now_s, "reason": reason, "table_crc32": f"{table.crc32:08x}",
            "forecast": header.get("forecast", {}), "grid": header.get("grid", {}), "goal": header.get("goal", {}),
            "model": header.get("model"), "criterion": header.get("criterion"),
        }
        if goal_index is not None:
            record["goal_index"] = goal_index
        if table.time_varying:
            record["slices"] = timeline.slices_record(table)
        self.recorder.write(Topic.POLICY, now_s, record)
        if table_bytes is not None:
            self._blobs[table.crc32] = table_bytes
            self.recorder.attach(f"policy-{table.crc32:08x}.lrpt", table_bytes)

    def _save_state(self, now_s: float) -> None:
        """The durable state (executive.durable): goals, tables, the active goal, the safety stop and the tide's
        record and shift, for a restart."""
        if self.state_writer is None or self.plan is None:
            return
        self.state_writer.save(self.plan, self._blobs, log_path=self.config.log_path,
                               mission_path=self.config.mission_path,
                               safety_stop=None if self.helm.stop is None else self.helm.stop.value,
                               tide=tide_watch.saved(self.tide))

    # -- time-driven work --------------------------------------------------------------------

    def _wall_to_heartbeat(self, wall: float) -> float:
        if self.clock.synced:
            return self.clock.wall_until(self._next_heartbeat_s, wall)
        return max(0.0, self._next_heartbeat_wall - wall)

    def _heartbeat(self, wall: float) -> None:
        now_s = self.clock.now_s(wall)
        healthy = self.helm.phase not in (Phase.SAFE, Phase.LINK_LOST)
        self._send(now_s, bridge.heartbeat(self.mav, healthy=healthy))
        self._report_progress(wall)
        if self.gcs is not None:
            self._send_on(self.gcs_mav, now_s, bridge.heartbeat(self.gcs_mav, healthy=healthy))
        self._next_heartbeat_s = now_s + _HEARTBEAT_PERIOD_S
        self._next_heartbeat_wall = wall + _HEARTBEAT_PERIOD_S

    def _housekeeping(self, wall: float, wall0: float) -> None:
        if self._wall_to_heartbeat(wall) <= 0.0:
            self._heartbeat(wall)
        now_s = self.clock.now_s(wall)
        unlogged = self.raw.report(now_s)
        if unlogged is not None:
            self._log(self.recorder.log, now_s, "debug", unlogged)
        hb = self.vehicle.heartbeat_s
        closed = self.link.closed  # the autopilot's side closed the stream: a lost link, no silence to wait out
        if closed and not self._closed_said:
            self._event(now_s, Event("error", f"autopilot link closed by the other end ({self.config.link})"))
        self._closed_said = closed
        if closed or (hb is not None and now_s - max(hb, self._jumped_s) > self.config.helm.link_loss_timeout_s
                      and not self._input_waiting()):
            self._tick(now_s, link_ok=False)
        if self.lockstep and now_s > self._reported_s:
            self._report_progress(wall)  # through a silence: the simulator follows the clock (docs/executive.md)
        for mav, msg in self.uploads.tick(wall):  # mission protocol retries
            self._send_on(mav, now_s, msg)
        self._replanning(now_s, wall)
        self._write_later()
        for event in self.recorder.maybe_flush():  # the log's own health: degraded, writing again
            self._event(now_s, event)
        for event in [] if self.state_writer is None else self.state_writer.poll():
            self._event(now_s, event)
        cfg = self.config
        if cfg.exit_on_arrival and self._arrival_s is not None and now_s - self._arrival_s >= cfg.linger_s:
            self._stop_reason = "arrived"
        elif cfg.max_vehicle_s is not None and now_s >= cfg.max_vehicle_s:
            self._stop_reason = "vehicle time limit"
        elif cfg.max_wall_s is not None and wall - wall0 >= cfg.max_wall_s:
            self._stop_reason = "wall time limit"

    def _input_waiting(self) -> bool:
        """Datagrams from the autopilot wait unread: the loop is behind, the link is not silent.

        At a simulator speedup a short stall of this process (a busy machine) spans many
        vehicle seconds; the heartbeat that would have ended the silence may be in the socket.
        """
        waiting = self.link.input_waiting()  # datagrams from elsewhere are never a sign of the autopilot
        self._warn_link()
        return waiting

    def _report_progress(self, wall: float) -> None:
        """A lockstep report (``bridge.progress_report``) after each burst of autopilot input and each heartbeat,
        once the autopilot has asked for one. Not logged: it paces a simulator and says nothing about the vehicle.
        """
        if self.lockstep:
            self._reported_s = self.clock.now_s(wall)
            self.mav.send(bridge.progress_report(self.mav, self._reported_s))
            self.progress_reports += 1

    def _warn_link(self) -> None:
        wall = time.monotonic()
        text = self.link.warning(wall)
        if text is not None:
            self._event(self.clock.now_s(wall), Event("warning", text))

    def _replanning(self, now_s: float, wall: float) -> None:
        if self.watcher is not None and wall >= self._next_watch_wall:
            self._next_watch_wall = wall + _WATCH_PERIOD_S
            for path in self.watcher.poll():
                self._new_forecast(now_s, path, wall)
        if self.replanner is None:
            return
        result = self.replanner.poll()
        if result is not None:
            self._replan_done(now_s, result)
        period = self.config.replan_period_s
        plan = self._base()
        if (period is not None and plan is not None and plan.goal is not None and self.helm.phase is Phase.RUNNING
                and not self.replanner.busy and (self._last_plan_s is None or now_s - self._last_plan_s >= period)):
            if self._last_plan_s is None:
                self._last_plan_s = now_s  # the period counts from the start
            else:
                self._request_plan(now_s, plan.index, plan.goal, reason="period")

    def _summary(self, wall_s: float) -> RunSummary:
        start = self.helm.mission_start_s
        mission = None if self._arrival_s is None or start is None else self._arrival_s - start
        return RunSummary(
            reached=self._arrival_s is not None, arrival_s=self._arrival_s, mission_time_s=mission,
            energy_used_wh=self.vehicle.energy_used_wh, vehicle_time_s=self.vehicle.time_s, wall_s=wall_s,
            decisions=self._counts["decisions"], messages_in=self._counts["in"], messages_bad=self._counts["bad"],
            commands_out=self._counts["out"], messages_not_logged=self.raw.skipped_total, final_phase=self.helm.phase.value,
            reason=self._stop_reason or "stopped", log_path=str(self.config.log_path),
            decision_median_us=self.decision_latency.percentile_us(50),
            decision_p99_us=self.decision_latency.percentile_us(99),
            message_p99_us=self.message_cost.percentile_us(99),
        )
