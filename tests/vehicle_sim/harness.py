"""The UDP test harness of the simulator: a pymavlink peer, and a simulator stepped from the test thread.

A ``Bench`` drives the ``Simulator`` step by step (``step_once``) while its ``Peer``, a
pymavlink ``udpout`` connection over 127.0.0.1, talks to it: simulated time is then exact and
the tests deterministic. Used by the tests of this directory (fixture ``bench`` in conftest.py).
"""

from __future__ import annotations

import math
import os
import select

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from planner.contract.geodesy import M_PER_DEG_LAT  # noqa: E402
from planner.contract.modes import SubMode  # noqa: E402
from planner.contract.vehicle import VehicleParams  # noqa: E402
from vehicle_sim.autopilot import AutopilotSettings  # noqa: E402
from vehicle_sim.dynamics import Body  # noqa: E402
from vehicle_sim.endpoint import SimConfig, Simulator  # noqa: E402
from vehicle_sim.world import World  # noqa: E402

QUIET = VehicleParams(position_noise_m=0.0, heading_noise_deg=0.0, depth_noise_m=0.0)
DT = 0.1


class Peer:
    """A pymavlink peer of the simulator: a GCS (255/190) or the companion computer (1/191)."""

    def __init__(self, port: int, system: int = 255, component: int = 190) -> None:
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=system,
                                               source_component=component, dialect="ardupilotmega")
        self.mav = self.conn.mav
        self.got: list = []  # type: ignore[type-arg]

    def heartbeat(self) -> None:
        self.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)

    def command(self, command: int, *params: float, target=(1, 1)) -> None:  # type: ignore[no-untyped-def]
        p = list(params) + [0.0] * (7 - len(params))
        self.mav.command_long_send(target[0], target[1], command, 0, *p)

    def drain(self, wait_s: float = 0.0) -> list:  # type: ignore[type-arg]
        """Everything that has arrived (waiting up to ``wait_s`` for the first datagram)."""
        if wait_s:
            select.select([self.conn.port], [], [], wait_s)
        new = []
        while (msg := self.conn.recv_msg()) is not None:
            if msg.get_type() != "BAD_DATA":
                new.append(msg)
        self.got.extend(new)
        return new

    def of(self, kind: str) -> list:  # type: ignore[type-arg]
        return [m for m in self.got if m.get_type() == kind]

    def texts(self) -> list[str]:
        return [m.text for m in self.of("STATUSTEXT")]

    def acks(self, command: int) -> list[int]:
        return [m.result for m in self.of("COMMAND_ACK") if m.command == command]

    def close(self) -> None:
        self.conn.close()


class Bench:
    """A simulator stepped from the test thread, and one peer that keeps its heartbeat going."""

    def __init__(self, world: World | None = None, *, lat_lon=(33.0, -118.0), depth_m: float = 0.0,  # type: ignore[no-untyped-def]
                 heading_deg: float = 0.0, system: int = 255, component: int = 190, params=QUIET,
                 sim: dict | None = None, **autopilot) -> None:  # type: ignore[no-untyped-def,type-arg]
        """``sim``: more SimConfig fields; ``autopilot``: AutopilotSettings fields (EKF position after 2 s here)."""
        settings = AutopilotSettings(**{"position_delay_s": 2.0, **autopilot})
        config = SimConfig(start_lat_deg=lat_lon[0], start_lon_deg=lat_lon[1], start_depth_m=depth_m,
                           start_heading_deg=heading_deg, port=0, speedup=1e9, params=params, autopilot=settings,
                           **(sim or {}))
        self.sim = Simulator(world or World.calm(), config)
        self.peer = Peer(self.sim.port, system, component)
        self.beating = True
        self.peer.heartbeat()
        self.step(1)

    def step(self, n: int) -> None:
        for _ in range(n):
            before = self.sim._t_ms
            self.sim.step_once()
            if self.beating and before // 1000 != self.sim._t_ms // 1000:  # 1 Hz heartbeat, in simulated time
                self.peer.heartbeat()
            self.peer.drain()

    def advance(self, seconds: float) -> None:
        self.step(round(seconds / DT))

    def command(self, command: int, *params: float, target=(1, 1)) -> None:  # type: ignore[no-untyped-def]
        self.peer.command(command, *params, target=target)
        self.step(1)
        self.peer.drain(0.05)

    def guided_and_armed(self) -> None:
        self.advance(self.sim.config.autopilot.position_delay_s)
        self.command(mavlink.MAV_CMD_DO_SET_MODE, 1, SubMode.GUIDED)
        self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        assert self.sim.mode is SubMode.GUIDED and self.sim.armed

    def close(self) -> None:
        self.peer.close()
        self.sim.close()



def vel_yaw(peer: Peer, north: float, east: float, yaw_deg: float, mask: int = 2503) -> None:
    peer.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, mask, 0, 0, 0,
                                                north, east, 0.0, 0, 0, 0, math.radians(yaw_deg), 0)


def north_m(b: Body, lat0: float) -> float:
    return (b.lat_deg - lat0) * M_PER_DEG_LAT

