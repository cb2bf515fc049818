"""The decision audit: run the helm's pure ``step`` again on a dive's logged inputs and compare.

The log holds everything a decision depended on (``executive.loop``): the
helm's settings (metadata ``helm``), every table's exact bytes (attachments
``policy-CRC.lrpt``), each message from the autopilot (``/mavlink/rx``, with its
fields), every plan swap (``/executive/policy``) and the executive's own events
(``/log``). Read in file order, which is the order the loop did things in, they
drive the same ``helm.step`` again; each decision it makes is compared with the
logged one. There should be no difference: one means the log does not say what
the vehicle did, or the helm is not a pure function of its inputs.

What the audit mirrors of ``Executive._on_message``: the autopilot's messages
(system 1, component 1) update the ``VehicleState`` through the same
``mavlink_bridge.apply``; a message older than the last of its kind is dropped;
position and attitude run a decision at their ``time_boot_ms``; a HEARTBEAT
runs the helm in the set-up phases (``helm.HEARTBEAT_PHASES``). Ticks that have no message
of their own are found from the events they log: link loss ("link lost: ...")
and an autopilot reboot ("autopilot time went back ...").

A time-varying table: the vehicle's UTC comes from the logged SYSTEM_TIME as the loop
learnt it (forgotten at a reboot), and each decision runs with the slice ``PolicyTable.slice_at``
gives for it, as in the loop (``executive.timeline.follow``). A decision that records another slice is a difference; it is then run again with the
slice it records, so that its action is checked against the plan the vehicle used and the
audit goes on from the helm state the vehicle had.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from executive import mavlink_bridge as bridge
from executive import plausibility, tide_watch, timeline
from planner.shore.replay.divelog import DiveLog, LogMessage
from planner.shore.replay.summary import slices_text
from executive.helm import (
    HEARTBEAT_PHASES,
    OPERATOR_RESUME,
    Decision,
    HelmConfig,
    HelmState,
    rebooted,
    resumed,
    step,
    swapped,
)
from executive.recorder import LogError, Topic
from executive.state import Situation, VehicleState
from planner.contract.errors import LrauvError
from planner.contract.progress import SILENT, Progress
from planner.contract.table import PolicyTable, TimeSlice

__all__ = ["AuditResult", "Mismatch", "audit"]

_COMPARED = ("cell", "situation", "action", "mode", "changed")  # what a decision is; time and position are inputs
_SLICE = ("slice", "slice_status")  # time-varying tables only: the plan it was made with
_LINK_LOST = "link lost:"  # helm._link_lost's event
_REBOOT = "autopilot time went back"  # Executive._on_message's event
_DECIDERS = bridge.DECISION_MESSAGES


@dataclass(frozen=True, slots=True)
class Mismatch:
    """A decision the audit made differently from the log (or made where the log has none, or not at all)."""

    time_s: float
    logged: Mapping[str, Any] | None
    audited: Mapping[str, Any] | None

    def describe(self) -> str:
        timed = any(d is not None and "slice" in d for d in (self.logged, self.audited))
        keys = _COMPARED + _SLICE if timed else _COMPARED

        def brief(d: Mapping[str, Any] | None) -> str:
            return "none" if d is None else ", ".join(f"{k}={d.get(k)}" for k in keys)

        return f"t={self.time_s:.3f} s: logged [{brief(self.logged)}] audited [{brief(self.audited)}]"


@dataclass(frozen=True, kw_only=True)
class AuditResult:
    decisions: int  # logged decisions compared
    mismatches: tuple[Mismatch, ...]
    tables: int  # tables used
    swaps: int  # plan swaps applied
    timed: int = 0  # decisions under a time-varying table, their slice checked too
    time_varying: tuple[str, ...] = ()  # each time-varying table: "CRC: time-varying, T slices from .. to .."

    @property
    def clean(self) -> bool:
        return not self.mismatches


@dataclass(frozen=True, slots=True)
class _Made:
    """A decision the audit made, and what it was made from (to make it again with another slice)."""

    decision: Decision
    current: TimeSlice | None
    helm: HelmState  # before the step
    now_s: float

    def record(self) -> dict[str, Any]:
        return timeline.decision_record(self.decision, self.current)


@dataclass
class _Audit:
    """The helm's inputs as the loop held them, advanced one log message at a time."""

    config: HelmConfig
    tables: Mapping[str, PolicyTable]
    table: PolicyTable | None
    autopilot_system: int = bridge.AUTOPILOT_SYSTEM
    helm: HelmState = field(default_factory=HelmState)
    vehicle: VehicleState = field(default_factory=VehicleState)
    last_time: dict[str, float] = field(default_factory=dict)
    pending: list[_Made] = field(default_factory=list)  # decisions made, not yet matched with the log's
    due: tuple[float, bool] | None = None  # a tick the loop ran here: (now_s, link_ok)
    swaps: int = 0
    unix_offset_s: float | None = None  # SYSTEM_TIME, as the loop holds it: UTC = vehicle time + offset
    gate: plausibility.Gate = field(default_factory=plausibility.Gate)  # the telemetry checks' state
    shift: tuple[int, float] | None = None  # the tide's timing the loop logged: (table CRC, s) (executive.tide_watch)

    def run_due(self) -> None:
        """Run the tick the last message called for.

        It waits until the next message that is not a swap, because the loop writes a
        swap it makes at the start of a tick after the message that caused the tick.
        """
        if self.due is None:
            return
        now_s, link_ok = self.due
        self.due = None
        table = self.table
        shift = self.shift[1] if table is not None and self.shift is not None and self.shift[0] == table.crc32 else 0.0
        current = None if table is None else timeline.slice_for(table, timeline.utc_s(now_s, self.unix_offset_s), shift)
        t = step(self.helm, self.vehicle, None if current is None else current.table, self.config, now_s=now_s,
                 link_ok=link_ok)
        if t.decision is not None:
            self.pending.append(_Made(t.decision, current, self.helm, now_s))
        self.helm = t.helm

    def again(self, made: _Made, logged: Any) -> _Made | None:
        """``made`` run again with the slice the log records, when that is a slice of the table; else None.

        Only the latest decision can be: the helm has not gone on from it (the log's next decision
        needs the next message).
        """
        table = self.table
        if (self.pending or table is None or not table.time_varying or made.current is None
                or isinstance(logged, bool) or not isinstance(logged, int) or not 0 <= logged < table.n_slices):
            return None
        current = TimeSlice(table.slice_table(logged), logged, made.current.status)
        # link_ok: a tick without the link makes no decision
        t = step(made.helm, self.vehicle, current.table, self.config, now_s=made.now_s, link_ok=True)
        if t.decision is None:
            return None
        self.helm = t.helm
        return _Made(t.decision, current, made.helm, made.now_s)

    def receive(self, m: LogMessage) -> None:
        p = m.payload
        if p.get("src_system") != self.autopilot_system or p.get("src_component") != bridge.AUTOPILOT_COMPONENT:
            return
        if p.get("rejected") is not None:  # the loop's clock check dropped it (plausibility.stamp)
            return
        msg = _Logged(p)
        kind = msg.get_type()
        t_boot = bridge.time_boot_s(msg)
        if t_boot is not None:
            t_boot += float(p.get("epoch_s") or 0.0)  # time_boot_ms wraps (plausibility.WRAP_S)
            if t_boot < self.last_time.get(kind, -1.0):
                return
            self.last_time[kind] = t_boot
        screened = plausibility.screen(self.gate, self.vehicle, bridge.apply(self.vehicle, msg, m.log_time_s), kind,
                                       self.config.limits, t_boot)
        self.gate, self.vehicle = screened.gate, screened.vehicle
        if kind == "SYSTEM_TIME":
            self.unix_offset_s = bridge.unix_offset_s(msg) or self.unix_offset_s
        if kind in _DECIDERS or (kind == "HEARTBEAT" and self.helm.phase in HEARTBEAT_PHASES):
            self.due = (m.log_time_s if t_boot is None else t_boot, True)

    def swap(self, p: Mapping[str, Any]) -> None:
        crc = p.get("table_crc32")
        self.table = None if crc is None else self.tables.get(crc)
        if crc is not None and self.table is None:
            raise LogError(f"swap at {p.get('time_s')} s: table {crc} is not attached to the log")
        if p.get("on_arrival") is not None:
            self.config = replace(self.config, on_arrival=p["on_arrival"])
        if p.get("helm_reset", True):
            self.helm = swapped(self.helm)
        self.swaps += 1


class _Logged:
    """A logged MAVLink message's fields as attributes, as ``mavlink_bridge.apply`` reads them."""

    def __init__(self, payload: Mapping[str, Any]) -> None:
        self.__dict__.update(payload["fields"])
        self._name = payload["name"]
        self._src = (payload["src_system"], payload["src_component"])

    def get_type(self) -> str:
        return self._name

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's spelling
        return self._src[0]

    def get_srcComponent(self) -> int:  # noqa: N802
        return self._src[1]


def logged_tables(dive: DiveLog) -> dict[str, PolicyTable]:
    """The attached tables by the CRC in their name (``policy-CRC.lrpt``)."""
    tables = {}
    for name, data in dive.attachments.items():
        if name.startswith("policy-") and name.endswith(".lrpt"):
            try:
                tables[name[len("policy-"):-len(".lrpt")]] = PolicyTable.from_bytes(data, name=f"{dive.path}: {name}")
            except LrauvError as exc:
                raise LogError(f"{dive.path}: attachment {name}: {exc}") from None
    return tables


def audit(dive: DiveLog, *, meter: Progress = SILENT) -> AuditResult:
    """Run the decisions of ``dive`` again and compare them with the logged ones; ``meter`` hears
    the decisions compared, of those the log holds."""
    helm_meta = dive.metadata.get("helm")
    if helm_meta is None or "config" not in helm_meta:
        raise LogError(f"{dive.path}: no 'helm' metadata: this log predates the decision audit"
                       " (written by an executive without it); nothing to run again")
    config = HelmConfig.from_json(helm_meta["config"])
    start = _start_helm(helm_meta, dive)
    tables = logged_tables(dive)
    state: _Audit | None = None
    start_index = int(helm_meta.get("goal_index", "0"))
    compared = timed = 0
    mismatches: list[Mismatch] = []
    total = dive.counts.get(Topic.DECISION, 0)
    meter.update("auditing decisions", 0, total, unit="decisions")
    for m in dive.messages((Topic.POLICY, Topic.MAVLINK_RX, Topic.DECISION, Topic.LOG)):
        p = m.payload
        if m.topic is Topic.POLICY:
            if p["reason"] == "loaded" and state is None and p.get("goal_index", 0) == start_index:
                state = _Audit(config=config, tables=tables, table=_table(tables, p, dive), helm=start)
            elif p["reason"] == "swapped":
                state = state or _Audit(config=config, tables=tables, table=None, helm=start)
                state.swap(p)
            continue
        if state is None:
            state = _Audit(config=config, tables=tables, table=None, helm=start)  # the executive started without a table
        state.run_due()
        if m.topic is Topic.MAVLINK_RX:
            state.receive(m)
        elif m.topic is Topic.LOG:
            text = p.get("message", "")
            if text.startswith(_LINK_LOST):
                state.due = (m.log_time_s, False)
            elif text.startswith(_REBOOT):
                state.vehicle, state.helm, state.last_time = VehicleState(), rebooted(state.helm), {}
                state.unix_offset_s, state.gate = None, plausibility.Gate()
            elif tide_watch.logged_shift(text) is not None:
                state.shift = tide_watch.logged_shift(text)
            elif text.startswith(OPERATOR_RESUME):
                state.helm = resumed(state.helm, clear_stop="safety stop" in text)
        elif m.topic is Topic.DECISION:
            compared += 1
            meter.update("auditing decisions", compared, total, unit="decisions")
            made = state.pending.pop(0) if state.pending else None
            audited = None if made is None else made.record()
            if audited is not None and "slice" in audited:
                timed += 1
                if audited["slice"] != p.get("slice"):
                    # A difference of its own; the action is checked against the slice the vehicle used.
                    redone = state.again(made, p.get("slice")) if made is not None else None
                    if redone is not None:
                        audited = {**redone.record(), **{k: audited[k] for k in _SLICE}}
            if audited is None or any(audited.get(k) != p.get(k) for k in _COMPARED + _SLICE):
                mismatches.append(Mismatch(p.get("time_s", m.log_time_s), p, audited))
    if state is not None and dive.complete:  # in a cut log the last decisions may be cut off: not a difference
        state.run_due()
        mismatches.extend(Mismatch(d.decision.time_s, None, d.record()) for d in state.pending)
    meter.update("auditing decisions", total, total, unit="decisions")
    varying = tuple(f"{crc}: {slices_text(timeline.slices_record(t))}" for crc, t in tables.items() if t.time_varying)
    return AuditResult(decisions=compared, mismatches=tuple(mismatches), tables=len(tables),
                       swaps=0 if state is None else state.swaps, timed=timed, time_varying=varying)


def _start_helm(helm_meta: Mapping[str, str], dive: DiveLog) -> HelmState:
    """The helm the executive started with: fresh, or holding the safety stop a restart carried over."""
    stop = helm_meta.get("safety_stop") or None
    if stop is None:
        return HelmState()
    try:
        return HelmState(stop=Situation(stop))
    except ValueError:
        raise LogError(f"{dive.path}: metadata helm.safety_stop {stop!r} is not a known limit") from None


def _table(tables: Mapping[str, PolicyTable], p: Mapping[str, Any], dive: DiveLog) -> PolicyTable:
    crc = p.get("table_crc32")
    if not isinstance(crc, str) or crc not in tables:  # the tables are keyed by their CRC's text
        raise LogError(f"{dive.path}: the loaded table {crc} is not attached to the log; cannot run the helm again")
    return tables[crc]


def summary_line(result: AuditResult) -> str:
    verdict = "no difference" if result.clean else f"{len(result.mismatches)} DIFFERENT"
    line = (f"audit      {result.decisions:,} decisions run again with {result.tables} logged table(s),"
            f" {result.swaps} swap(s): {verdict}")
    if result.time_varying:  # stationary logs keep the line they always had
        line += (f"\n           {result.timed:,} decisions under a time-varying table, each slice checked against"
                 " the vehicle's UTC time: " + "; ".join(result.time_varying))
    return line
