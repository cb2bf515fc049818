"""Plan changes on a running executive: uploads, onboard plans and swaps, always between two decisions.

Goals arrive by the mission protocol, tables and forecasts by MAVLink FTP, and tables from the
onboard planner (``executive.replanner``). Each is checked (``executive.envelope`` against the
mission's safety section, ``executive.goal_tables`` against the mission) and either queued to
replace the running plan whole at the next decision, or refused with a reason that is logged
and told to the ground station; a refused one never replaces the running plan.

``PlanChanges`` is the half of ``executive.loop.Executive`` that does this; it shares the
executive's state (declared below) and its log and event methods.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from executive import envelope, goal_tables, map_layers, timeline
from executive.clock import VehicleClock
from executive.goal_tables import MissionPlan
from executive.helm import HelmConfig, HelmState, swapped
from executive.recorder import Recorder, Topic
from executive.replanner import PlanJob, PlanResult, Replanner
from executive.state import Event
from executive.uploads import Uploads
from planner.contract.errors import LrauvError
from planner.contract.table import PolicyTable


class PlanChanges:
    """Uploads, onboard plans and swaps; mixed into ``executive.loop.Executive``, whose state it shares."""

    config: Any  # executive.loop.ExecConfig (that module imports this one)
    plan: MissionPlan | None
    staged: MissionPlan | None  # uploaded goals still waiting for their first table
    swaps: list[dict[str, Any]]
    helm: HelmState
    helm_config: HelmConfig
    envelope: envelope.Envelope
    clock: VehicleClock
    recorder: Recorder
    uploads: Uploads
    replanner: Replanner | None
    _pending: tuple[MissionPlan, dict[str, Any]] | None
    _arrival_s: float | None
    _asked_next: int | None
    _unix_offset_s: float | None
    _latest_forecast: Path | None
    _last_plan_s: float | None
    _work_dir: Path

    @property
    def table(self) -> PolicyTable | None:
        """The table in use: the active goal's."""
        return None if self.plan is None else self.plan.table

    # The executive's own (executive.loop).
    def _event(self, now_s: float, event: Event) -> None:
        raise NotImplementedError

    def _log(self, fn: Any, *args: Any, **kwargs: Any) -> None:
        raise NotImplementedError

    def _save_state(self, now_s: float) -> None:
        raise NotImplementedError

    def _config_for(self, plan: MissionPlan | None) -> HelmConfig:
        raise NotImplementedError

    def _resume(self, now_s: float, *, clear_stop: bool, source: str) -> None:
        raise NotImplementedError

    def _record_policy(self, table: PolicyTable, table_bytes: bytes | None, reason: str, *, now_s: float = 0.0,
                       goal_index: int | None = None) -> None:
        raise NotImplementedError

    def _propose(self, plan: MissionPlan, note: dict[str, Any]) -> None:
        """Queue ``plan`` to replace the running one at the next decision."""
        self._pending = (plan, note)

    def _base(self) -> MissionPlan | None:
        return self._pending[0] if self._pending is not None else self.plan

    def _swap(self, now_s: float) -> None:
        assert self._pending is not None
        new, note = self._pending
        self._pending = None
        old, old_table = self.plan, self.table
        self.plan = new
        self.helm_config = self._config_for(new)
        reset = new.table is not old_table
        if reset:
            self.helm = swapped(self.helm)
        if old is None or new.goals != old.goals:
            self._arrival_s, self._asked_next = None, None  # a new mission
        record = {"time_s": now_s, "reason": "swapped", **note, "goal_index": new.index,
                  "on_arrival": self.helm_config.on_arrival, "helm_reset": reset,
                  "previous": goal_tables.identity(old_table), **goal_tables.identity(new.table)}
        if new.table is not None:
            record["forecast"] = {"identity": new.table.forecast_identity, "time": new.table.forecast_time}
            if new.table.time_varying:
                record["slices"] = timeline.slices_record(new.table)
        self.swaps.append(record)
        self._log(self.recorder.write, Topic.POLICY, now_s, record)
        self._log(self._record_map, now_s)
        self._log(self._save_state, now_s)  # after this decision's commands are out
        prev = record["previous"]["table_crc32"]
        self._event(now_s, Event("info", f"plan swapped ({note.get('source', '?')}): goal {new.index},"
                                         f" table {prev} -> {record['table_crc32']}"))

    def _record_map(self, now_s: float, *, geofence: bool = False) -> None:
        """The mission on Foxglove's map (``executive.map_layers``): the goals and the running plan, each
        replacing its last; the geofence once (``geofence``), as the mission's safety section never changes."""
        if geofence:
            self.recorder.geojson(Topic.MAP_GEOFENCE, now_s, map_layers.geofence_layer(self.config.helm.geofence))
        self.recorder.geojson(Topic.MAP_GOALS, now_s, map_layers.goals_layer(self.plan))
        self.recorder.geojson(Topic.MAP_PLAN, now_s, map_layers.plan_layer(self.plan))

    def _refuse(self, now_s: float, what: str, reason: str, table: PolicyTable | None = None, *,
                notify: bool = True) -> str:
        record: dict[str, Any] = {"time_s": now_s, "reason": "refused", "refusal": f"{what}: {reason}"}
        if table is not None:  # a file that is no table has no identity to log
            record.update(goal_tables.identity(table))
        self._log(self.recorder.write, Topic.POLICY, now_s, record)
        event = Event("warning", f"refused {what}: {reason}; the running plan goes on")
        if notify:
            self._event(now_s, event)
        else:  # the protocol has told the ground station itself
            self._log(self.recorder.log, now_s, event.level, event.text)
        return reason

    def _accept_goals(self, goals: tuple[Any, ...]) -> str | None:
        """Goals uploaded by the mission protocol: staged until the first goal has a table."""
        now_s = self.clock.now_s(time.monotonic())  # goals is never empty: items_to_goals refuses that
        base = self._base() or MissionPlan(goals=(), tables=())
        reason = envelope.check_goals(goals, self.envelope, self.table)
        if reason is not None:
            return self._refuse(now_s, "mission", reason, notify=False)
        self._resume(now_s, clear_stop=False, source="a mission upload")  # an upload ends an override, not a stop
        if tuple(goals) == base.goals:  # the running goals again (lrauv upload sends them before tables)
            self.staged = None
            self._event(now_s, Event("info", f"mission of {len(goals)} goals accepted: the running goals, kept"))
            return None
        staged = goal_tables.adopt(tuple(goals), base)
        kept = f"; goal {staged.index} stays the active goal" if staged.index else ""
        self._event(now_s, Event("info", f"mission of {len(goals)} goals accepted{kept}"))
        if staged.table is not None:
            self.staged = None
            self._propose(staged, {"source": "uploaded mission"})
        else:
            self.staged = staged
            if self.replanner is not None:
                self._request_plan(now_s, 0, staged.goals[0], reason="uploaded mission")
            else:
                self._event(now_s, Event("info", "waiting for the table of goal 0 (MAVLink FTP /tables/)"))
        return None

    def _flying(self) -> tuple[Any, ...]:
        """The mission items of the goals the vehicle is flying now, for a download (``wp list``)."""
        return goal_tables.flown_items(self._base(), self.uploads.missions.items)

    def _set_current(self, seq: int) -> str | None:
        """MISSION_SET_CURRENT: make goal ``seq - 1`` (item 0 is home) the active goal; None, or why not."""
        now_s = self.clock.now_s(time.monotonic())
        plan = self._base()
        if plan is None or not 1 <= seq <= len(plan.goals):
            count = 0 if plan is None else len(plan.goals)
            return self._refuse(now_s, f"MISSION_SET_CURRENT {seq}", f"expected an item 1..{count}", notify=False)
        index = seq - 1
        if index == plan.index:
            return None
        if plan.tables[index] is None:
            return self._refuse(now_s, f"MISSION_SET_CURRENT {seq}", f"goal {index} has no table yet", notify=False)
        self._event(now_s, Event("info", f"MISSION_SET_CURRENT: goal {index} is now the active goal"))
        self._propose(replace(plan, index=index), {"source": "MISSION_SET_CURRENT"})
        return None

    def _accept_file(self, path: str, data: bytes) -> str | None:
        """A file uploaded by MAVLink FTP: a table (``*.lrpt``) or a forecast (``*.nc``)."""
        now_s = self.clock.now_s(time.monotonic())
        name = path.rsplit("/", 1)[-1]
        if name.endswith(".nc"):
            return self._accept_forecast(now_s, name, data)
        if not name.endswith(".lrpt"):
            return self._refuse(now_s, path, "expected a policy table (*.lrpt) or a forecast (*.nc)")
        try:
            table = PolicyTable.from_bytes(data, name=path)  # CRC, version and shape
        except LrauvError as exc:
            return self._refuse(now_s, path, str(exc))
        return self._offer(now_s, table, data, {"source": f"upload {path}"})

    def _offer(self, now_s: float, table: PolicyTable, data: bytes | None, note: dict[str, Any]) -> str | None:
        """Check a new table against the staged mission, then the running one; queue it if it fits."""
        what = f"table {table.crc32:08x}"
        outside = envelope.check_table(table, self.envelope)
        if outside is not None:
            return self._refuse(now_s, what, outside, table)
        candidates = []
        if self.staged is not None:
            candidates.append(("staged", self.staged))
        base = self._base()
        if base is not None:
            candidates.append(("running", base))
        reasons = []
        for which, plan in candidates:
            verdict = goal_tables.check_table(table, plan)
            if not verdict.accepted:
                reasons.append(verdict.reason)
                continue
            assert verdict.goal_index is not None
            new = goal_tables.with_table(plan, verdict.goal_index, table)
            self._record_policy(table, data, "received", now_s=now_s)
            if which == "staged":
                if new.table is None:
                    self.staged = new
                    return None
                self.staged = None
                self._propose(new, {**note, "mission": "uploaded"})
            else:
                self._propose(new, note)
            return None
        if not candidates:
            reasons.append("there is no mission to match it against")
        return self._refuse(now_s, what, "; ".join(r for r in reasons if r), table)

    def _accept_forecast(self, now_s: float, name: str, data: bytes) -> str | None:
        if self.replanner is None:
            return self._refuse(now_s, name, "this executive has no mission to plan onboard (lrauv exec --mission)")
        try:
            path = self.uploads.forecasts.add(name, data)
        except OSError as exc:  # a full disk refuses the upload (FTP NAK), never the loop
            return self._refuse(now_s, name, f"cannot store it in {self._work_dir}: {exc.strerror or exc}")
        self._new_forecast(now_s, path, time.monotonic())
        for old in self.uploads.prune_forecasts(keep={path, *self.replanner.forecasts},  # superseded ones go
                                                plans=(self.plan, self._base(), self.staged)):
            self._log(self.recorder.log, now_s, "info", f"superseded forecast {old.name} removed")
        return None

    def _new_forecast(self, now_s: float, path: Path, seen_wall: float) -> None:
        self._latest_forecast = path
        plan = self._base()
        self._event(now_s, Event("info", f"new forecast {path.name}"))
        if self.replanner is None or not self.config.replan_on_new_forecast or plan is None or plan.goal is None:
            return
        self._request_plan(now_s, plan.index, plan.goal, reason=f"new forecast {path.name}",
                           seen_wall=seen_wall)

    def _request_plan(self, now_s: float, index: int, goal: Any, *, reason: str,
                      seen_wall: float | None = None) -> None:
        assert self.replanner is not None
        when = None
        if self._unix_offset_s is not None:
            when = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(now_s + self._unix_offset_s))
        job = PlanJob(goal_index=index, goal=goal, forecast=self._latest_forecast, time_iso=when, reason=reason,
                      requested_wall_s=seen_wall if seen_wall is not None else time.monotonic())
        self.replanner.request(job)
        self._last_plan_s = now_s
        self._log(self.recorder.log, now_s, "info", f"planning goal {index} onboard ({reason})")

    def _replan_done(self, now_s: float, result: PlanResult) -> None:
        job = result.job
        if result.error is not None or result.table_bytes is None:
            self._refuse(now_s, f"onboard plan ({job.reason})", result.error or "no table")
            return
        try:
            table = PolicyTable.from_bytes(result.table_bytes, name="onboard plan")
        except LrauvError as exc:
            self._refuse(now_s, f"onboard plan ({job.reason})", str(exc))
            return
        note = {"source": f"onboard plan ({job.reason})", "latency_s": round(result.latency_s, 3),
                "plan_s": round(result.finished_wall_s - result.started_wall_s, 3)}
        self._offer(now_s, table, result.table_bytes, note)
