"""A dive with the simulator and the executive in lockstep, in this thread: the same dive on any machine.

The simulator steps its physics (``Simulator.step_once``) and sends what is due over UDP on
127.0.0.1; the executive then handles every datagram waiting (``Executive._drain``) before the
next step, and sends its heartbeat every vehicle second. Decisions run at the messages'
``time_boot_ms``, so when in vehicle time the vehicle does what does not depend on how fast the
machine is. This is the single-threaded form of the simulator's own lockstep
(``SimConfig.lockstep_slack_s``, docs/executive.md), which the closed-loop rigs use with the
two sides in their own threads or processes; here one loop drives both, for tests that only
need a dive and its log.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

from executive.helm import HelmConfig  # noqa: E402
from executive.loop import ExecConfig, Executive  # noqa: E402
from executive.state import Phase  # noqa: E402
from planner.contract.table import PolicyTable  # noqa: E402
from vehicle_sim.endpoint import SimConfig, Simulator  # noqa: E402
from vehicle_sim.world import World  # noqa: E402


def fly(table: PolicyTable, forecast: Path, log: Path, *, start: tuple[float, float], max_vehicle_s: float,
        linger_s: float = 10.0, heading_deg: float = 90.0) -> float | None:
    """Dive from ``start`` (lon, lat) until ``linger_s`` after arrival or ``max_vehicle_s``; the arrival time or None.

    The vehicle boots at the forecast's first time (SYSTEM_TIME's UTC follows from it).
    """
    sim = Simulator(World.load(forecast), SimConfig(start_lon_deg=start[0], start_lat_deg=start[1], port=0, seed=1,
                                                    start_heading_deg=heading_deg))
    try:
        ex = Executive(ExecConfig(link=f"udpout:127.0.0.1:{sim.port}", log_path=log, helm=HelmConfig()), table)
    except BaseException:
        sim.close()
        raise
    arrived: float | None = None
    next_heartbeat_s = 0.0
    try:
        while sim.time_s < max_vehicle_s and (arrived is None or sim.time_s < arrived + linger_s):
            if sim.time_s >= next_heartbeat_s:
                ex._heartbeat(time.monotonic())
                next_heartbeat_s += 1.0
            sim.step_once()
            while ex._input_waiting():
                ex._drain(time.monotonic())
            if arrived is None and ex.helm.phase is Phase.ARRIVED:
                arrived = sim.time_s
    finally:
        ex.close()
        sim.close()
    return arrived
