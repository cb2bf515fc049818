"""A simulated vehicle and an executive (with a ground-station link) in threads, over real UDP on ephemeral ports.

The simulator runs in lockstep with the executive (``SimConfig.lockstep_slack_s``, slack 0 by
default): it never steps past what the executive has handled, so a run does not depend on how
busy the machine is (docs/executive.md, "Lockstep").
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from executive import goal_tables  # noqa: E402
from executive.helm import HelmConfig  # noqa: E402
from executive.loop import ExecConfig, Executive  # noqa: E402
from executive.state import Phase  # noqa: E402
from tests.support.helpers import DEMO_MISSION, assert_audit_clean, wait_until  # noqa: E402
from vehicle_sim.autopilot import AutopilotSettings  # noqa: E402
from vehicle_sim.endpoint import SimConfig, Simulator  # noqa: E402
from vehicle_sim.world import World  # noqa: E402

DEMO = DEMO_MISSION
SPEEDUP = 200.0
# The executive's wall-time limit and the longest wait for its end: a safety net for a run gone wrong, far above
# what a busy 2-core machine needs (lockstep makes the run itself the same on any machine).
WALL_LIMIT_S = 600.0


class Live:
    """A simulated vehicle and an executive (with a ground-station link) in threads."""

    def __init__(self, forecast: Path, plan: goal_tables.MissionPlan, log: Path, *, start: tuple[float, float],
                 mission: Path | None = DEMO, watch: Path | None = None, exit_on_arrival: bool = False,
                 speedup: float = SPEEDUP, start_depth_m: float = 0.0, replan_period_s: float | None = None,
                 signing=None, autopilot: AutopilotSettings | None = None, lockstep_slack_s: float | None = 0.0,
                 **helm) -> None:  # type: ignore[no-untyped-def]
        # The vehicle boots 6.5 h into the forecast, after issue 1's issue time (6 h): a newer
        # issue that arrives during the run is then one that exists at that time.
        self.sim = Simulator(World.load(forecast), SimConfig(start_lon_deg=start[0], start_lat_deg=start[1], port=0,
                                                             speedup=speedup, seed=3, start_offset_s=6.5 * 3600,
                                                             start_depth_m=start_depth_m,
                                                             autopilot=autopilot or AutopilotSettings(),
                                                             lockstep_slack_s=lockstep_slack_s))
        config = ExecConfig(link=f"udpout:127.0.0.1:{self.sim.port}", log_path=log, gcs_link="udpin:127.0.0.1:0",
                            mission_path=mission, watch_dir=watch, work_dir=log.parent / "work", max_wall_s=WALL_LIMIT_S,
                            exit_on_arrival=exit_on_arrival, linger_s=5.0, replan_period_s=replan_period_s,
                            signing=signing, helm=HelmConfig(**helm))
        try:
            self.executive = Executive(config, plan)
        except BaseException:
            self.sim.close()
            raise
        self.gcs_port = self.executive.gcs.port.getsockname()[1]
        self._sim_stop = threading.Event()
        self._sim_thread = threading.Thread(target=self.sim.run, kwargs={"stop_event": self._sim_stop}, daemon=True)
        self._sim_thread.start()
        self._stop = threading.Event()
        self.summary = None
        self._audited = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        self.summary = self.executive.run(self._stop)

    def ground_station(self):  # type: ignore[no-untyped-def]
        return mavutil.mavlink_connection(f"udpout:127.0.0.1:{self.gcs_port}", source_system=255, source_component=190)

    def wait(self, predicate, timeout_s: float = 30.0) -> bool:  # type: ignore[no-untyped-def]
        return wait_until(predicate, timeout_s)

    def running(self) -> bool:
        return self.executive.helm.phase is Phase.RUNNING and self.executive._counts["decisions"] > 5

    def join(self, timeout_s: float = WALL_LIMIT_S):  # type: ignore[no-untyped-def]
        self._thread.join(timeout_s)
        return self.stop()

    def stop(self):  # type: ignore[no-untyped-def]
        self._stop.set()
        self._thread.join(timeout=10)
        self._sim_stop.set()
        self._sim_thread.join(timeout=10)
        self.sim.close()
        assert not self._thread.is_alive() and not self._sim_thread.is_alive()
        if self.summary is not None and not self._audited:  # every run here is also a decision-audit case
            self._audited = True
            assert_audit_clean(self.executive.config.log_path)
        return self.summary


@contextmanager
def following(rig: Live) -> Iterator[Live]:
    """``rig`` once its executive follows the plan; stopped (and its log audited) at the end."""
    try:
        assert rig.wait(rig.running), "the executive did not start following the plan"
        yield rig
    finally:
        rig.stop()
