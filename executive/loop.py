"""The executive's I/O shell: MAVLink link, vehicle clock and MCAP log around the pure helm.

One thread, one ``select`` loop. Each position or attitude message from the
autopilot updates the ``VehicleState`` and runs ``helm.step``; the commands it
returns are encoded by the bridge and sent, and everything (telemetry, state,
decisions, commands, events, raw MAVLink both ways) goes to the MCAP log.
Timing is vehicle time (``executive.clock``), so the loop is the same at any
simulator speedup.
"""

from __future__ import annotations

import select
import time
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from executive import mavlink_bridge as bridge
from executive.clock import VehicleClock
from executive.helm import Decision, HelmConfig, HelmState, step
from executive.latency import LatencyHistogram
from executive.recorder import Recorder, Topic
from executive.state import Command, Event, Phase, VehicleState
from planner.table import PolicyTable

_POLL_S = 0.05  # longest wait in select (wall); heartbeats and link checks run at least this often
_DRAIN_BUDGET_S = 0.01  # longest burst of input handling (wall) before time-driven work gets its turn
_HEARTBEAT_PERIOD_S = 1.0  # vehicle time (section 2.1: 1 Hz)
_STATE_FIELDS = tuple(f.name for f in fields(VehicleState))


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
    final_phase: str
    reason: str  # why the loop stopped
    log_path: str
    decision_median_us: float | None = None  # datagram read -> commands sent
    decision_p99_us: float | None = None
    message_p99_us: float | None = None  # including the MCAP writes


class Executive:
    """Runs the helm against a live MAVLink link until told to stop or the mission ends."""

    def __init__(self, config: ExecConfig, table: PolicyTable | None, *, table_bytes: bytes | None = None,
                 metadata: dict[str, dict[str, str]] | None = None) -> None:
        from pymavlink import mavutil  # transport only; encoding and parsing are the bridge's

        self.config = config
        self.table = table
        self.conn = mavutil.mavlink_connection(config.link, source_system=bridge.EXECUTIVE_SYSTEM,
                                               source_component=bridge.EXECUTIVE_COMPONENT)
        self.mav = bridge.new_mav(self.conn)
        self.clock = VehicleClock()
        self.vehicle = VehicleState()
        self.helm = HelmState()
        self.recorder = Recorder(config.log_path, metadata=metadata or {})
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
        if table is not None:
            self._record_policy(table, table_bytes, "loaded")
        else:
            self._event(0.0, Event("error", "no policy table: the vehicle will be surfaced"))

    # -- public ------------------------------------------------------------------------

    def run(self, stop: Any = None) -> RunSummary:
        """Loop until ``stop.is_set()``, arrival (when configured) or a time limit."""
        wall0 = time.monotonic()
        fd = self.conn.fd
        try:
            self._heartbeat(wall0)
            while self._stop_reason is None:
                if stop is not None and stop.is_set():
                    self._stop_reason = "stopped"
                    break
                wall = time.monotonic()
                wait = min(_POLL_S, self._wall_to_heartbeat(wall))
                ready, _, _ = select.select([fd], [], [], wait)
                if ready:
                    self._drain(time.monotonic())
                self._housekeeping(time.monotonic(), wall0)
        finally:
            summary = self._summary(time.monotonic() - wall0)
            self.close()
        return summary

    def close(self) -> None:
        self._write_later()
        self.recorder.close()
        self.conn.close()

    # -- input -------------------------------------------------------------------------

    def _drain(self, wall: float) -> None:
        # Bounded, so that at high speedup a full socket cannot starve the heartbeat
        # (due every vehicle second) or the wall-time limit; at least one datagram per call.
        deadline = wall + min(_DRAIN_BUDGET_S, self._wall_to_heartbeat(wall))
        while True:
            data = self.conn.recv()
            if not data:
                return
            t0 = time.perf_counter()
            try:
                msgs = self.mav.parse_buffer(bytes(data) if not isinstance(data, bytes) else data) or []
            except Exception:  # pymavlink raises on some malformed frames even when robust
                self._counts["bad"] += 1
                msgs = []
            wall = time.monotonic()
            for msg in msgs:
                decided = self._on_message(msg, wall)
                if decided:
                    self.decision_latency.add(time.perf_counter() - t0)
                self._write_later()
                if decided:
                    self.message_cost.add(time.perf_counter() - t0)
            if wall >= deadline:
                return

    def _log(self, fn: Any, *args: Any, **kwargs: Any) -> None:
        self._later.append((fn, args, kwargs))

    def _write_later(self) -> None:
        for fn, args, kwargs in self._later:
            fn(*args, **kwargs)
        self._later.clear()

    def _on_message(self, msg: Any, wall: float) -> bool:
        """Handle one message; True when it ran a decision."""
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self._counts["bad"] += 1
            return False
        self._counts["in"] += 1
        t_boot = bridge.time_boot_s(msg)
        mine = bridge.from_autopilot(msg, self.config.autopilot_system)
        if mine and t_boot is not None and not self.clock.synced and self.vehicle.heartbeat_s is not None:
            # HEARTBEAT carries no time_boot_ms: one heard before the first timestamp was stamped
            # 0 s. Move it to the vehicle's time base, or an autopilot that booted more than the
            # link-loss timeout ago would look silent at once.
            self.vehicle = replace(self.vehicle, heartbeat_s=t_boot)
        if mine and t_boot is not None and self.clock.observe(t_boot, wall):
            self._event(t_boot, Event("warning", "autopilot time went back: it rebooted; setting up again"))
            self.vehicle = VehicleState()
            self.helm = HelmState()
            self._last_time.clear()
        now_s = self.clock.now_s(wall)
        self._log(self._record_rx, now_s, msg)
        if not mine:
            return False
        if t_boot is not None:
            if t_boot < self._last_time.get(kind, -1.0):
                self._counts["stale"] += 1  # reordered or duplicated datagram: never step back in time
                return False
            self._last_time[kind] = t_boot
        self.vehicle = bridge.apply(self.vehicle, msg, now_s)
        if kind in ("COMMAND_ACK", "STATUSTEXT"):
            level = "info" if kind == "STATUSTEXT" and msg.severity > 4 else "warning"
            if kind == "COMMAND_ACK" and msg.result == 0:
                level = "info"
            self._event(now_s, Event(level, bridge.command_text(msg)))  # type: ignore[arg-type]
        if kind == "GLOBAL_POSITION_INT":
            self._log(self._record_state, now_s, self.vehicle)
        if kind in bridge.DECISION_MESSAGES or (kind == "HEARTBEAT" and self.helm.phase is not Phase.RUNNING):
            self._tick(now_s if t_boot is None else t_boot, link_ok=True)
            return kind in bridge.DECISION_MESSAGES
        return False

    def _record_rx(self, now_s: float, msg: Any) -> None:
        self.recorder.write(Topic.MAVLINK_RX, now_s, bridge.describe(msg))

    # -- decisions and output ---------------------------------------------------------------

    def _tick(self, now_s: float, *, link_ok: bool) -> None:
        tick = step(self.helm, self.vehicle, self.table, self.config.helm, now_s=now_s, link_ok=link_ok)
        self.helm = tick.helm
        for event in tick.events:
            self._event(now_s, event)
        for cmd in tick.commands:
            self._send_command(now_s, cmd)
        if tick.decision is not None:
            self._counts["decisions"] += 1
            self._log(self.recorder.write, Topic.DECISION, now_s, _decision_payload(tick.decision))
        if self.helm.phase is Phase.ARRIVED and self._arrival_s is None:
            self._arrival_s = now_s

    def _send_command(self, now_s: float, cmd: Command) -> None:
        msg = bridge.encode(self.mav, cmd, time_boot_ms=int(now_s * 1000) & 0xFFFFFFFF,
                            target_system=self.config.autopilot_system)
        self._send(now_s, msg)
        self._log(self._record_command, now_s, cmd)

    def _record_command(self, now_s: float, cmd: Command) -> None:
        fields = {name: getattr(cmd, name) for name in cmd.__slots__}  # type: ignore[union-attr]
        self.recorder.write(Topic.COMMAND, now_s, {"time_s": now_s, "kind": type(cmd).__name__, **fields})

    def _send(self, now_s: float, msg: Any) -> None:
        self.mav.send(msg)
        self._counts["out"] += 1
        self._log(self._record_tx, now_s, msg)

    def _record_tx(self, now_s: float, msg: Any) -> None:
        self.recorder.write(Topic.MAVLINK_TX, now_s, bridge.describe(msg))

    def _event(self, now_s: float, event: Event) -> None:
        self._log(self.recorder.log, now_s, event.level, event.text)
        if event.level in ("warning", "error"):
            self._send(now_s, bridge.statustext(self.mav, event))

    def _record_state(self, now_s: float, v: VehicleState) -> None:
        if v.has_position:
            self.recorder.location_fix(now_s, lat_deg=v.lat_deg, lon_deg=v.lon_deg, depth_m=v.depth_m)  # type: ignore[arg-type]
        self.recorder.write(Topic.STATE, now_s, {name: getattr(v, name) for name in _STATE_FIELDS})

    def _record_policy(self, table: PolicyTable, table_bytes: bytes | None, reason: str) -> None:
        header = table.header()
        self.recorder.write(Topic.POLICY, 0.0, {
            "time_s": 0.0, "reason": reason, "table_crc32": f"{table.crc32:08x}",
            "forecast": header.get("forecast", {}), "grid": header.get("grid", {}), "goal": header.get("goal", {}),
            "model": header.get("model"), "criterion": header.get("criterion"),
        })
        if table_bytes is not None:
            self.recorder.attach(f"policy-{table.crc32:08x}.lrpt", table_bytes)

    # -- time-driven work --------------------------------------------------------------------

    def _wall_to_heartbeat(self, wall: float) -> float:
        if self.clock.synced:
            return self.clock.wall_until(self._next_heartbeat_s, wall)
        return max(0.0, self._next_heartbeat_wall - wall)

    def _heartbeat(self, wall: float) -> None:
        now_s = self.clock.now_s(wall)
        healthy = self.helm.phase not in (Phase.SAFE, Phase.LINK_LOST)
        self._send(now_s, bridge.heartbeat(self.mav, healthy=healthy))
        self._next_heartbeat_s = now_s + _HEARTBEAT_PERIOD_S
        self._next_heartbeat_wall = wall + _HEARTBEAT_PERIOD_S

    def _housekeeping(self, wall: float, wall0: float) -> None:
        if self._wall_to_heartbeat(wall) <= 0.0:
            self._heartbeat(wall)
        now_s = self.clock.now_s(wall)
        hb = self.vehicle.heartbeat_s
        if hb is not None and now_s - hb > self.config.helm.link_loss_timeout_s:
            self._tick(now_s, link_ok=False)
        self._write_later()
        self.recorder.maybe_flush()
        cfg = self.config
        if cfg.exit_on_arrival and self._arrival_s is not None and now_s - self._arrival_s >= cfg.linger_s:
            self._stop_reason = "arrived"
        elif cfg.max_vehicle_s is not None and now_s >= cfg.max_vehicle_s:
            self._stop_reason = "vehicle time limit"
        elif cfg.max_wall_s is not None and wall - wall0 >= cfg.max_wall_s:
            self._stop_reason = "wall time limit"

    def _summary(self, wall_s: float) -> RunSummary:
        start = self.helm.mission_start_s
        mission = None if self._arrival_s is None or start is None else self._arrival_s - start
        return RunSummary(
            reached=self._arrival_s is not None, arrival_s=self._arrival_s, mission_time_s=mission,
            energy_used_wh=self.vehicle.energy_used_wh, vehicle_time_s=self.vehicle.time_s, wall_s=wall_s,
            decisions=self._counts["decisions"], messages_in=self._counts["in"], messages_bad=self._counts["bad"],
            commands_out=self._counts["out"], final_phase=self.helm.phase.value,
            reason=self._stop_reason or "stopped", log_path=str(self.config.log_path),
            decision_median_us=self.decision_latency.percentile_us(50),
            decision_p99_us=self.decision_latency.percentile_us(99),
            message_p99_us=self.message_cost.percentile_us(99),
        )


def _decision_payload(d: Decision) -> dict[str, Any]:
    return {
        "time_s": d.time_s, "lat_deg": d.lat_deg, "lon_deg": d.lon_deg, "depth_m": d.depth_m,
        "heading_deg": d.heading_deg, "cell": list(d.cell) if d.cell is not None else None,
        "situation": d.situation.value, "action": d.action.name if d.action is not None else None,
        "mode": d.mode.name, "changed": d.changed,
    }
