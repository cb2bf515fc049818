"""Lockstep: the simulator never steps its physics past what the executive has reported handled.

A plain UDP socket plays the executive (system 1, component 191): it sends lockstep reports
(TIMESYNC requests, ts1 = vehicle time in ns) and reads the telemetry. The simulator runs in a
thread at a speedup of 10^9, so anything that let it run free would put it hours ahead at once;
each check waits until the simulator is waiting for a report, then reads where it stopped.
"""

from __future__ import annotations

import os
import socket
import threading

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from tests.support.helpers import sim_cli, wait_until  # noqa: E402
from vehicle_sim.endpoint import SimConfig, Simulator  # noqa: E402
from vehicle_sim.world import World  # noqa: E402

COMPANION = (1, 191)  # the executive: MAV_COMP_ID_ONBOARD_COMPUTER of the vehicle's system
GCS = (255, 190)


class Companion:
    """A socket speaking MAVLink 2 as ``source`` to the simulator; counts what it receives."""

    def __init__(self, port: int, source: tuple[int, int] = COMPANION) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.0)
        self.to = ("127.0.0.1", port)
        self.mav = mavlink.MAVLink(None, srcSystem=source[0], srcComponent=source[1])
        self.parser = mavlink.MAVLink(None)
        self.got: list[object] = []

    def send(self, msg: object) -> None:
        self.sock.sendto(msg.pack(self.mav), self.to)  # type: ignore[attr-defined]

    def heartbeat(self) -> None:
        self.send(self.mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 4))

    def report(self, vehicle_s: float) -> None:
        self.send(self.mav.timesync_encode(0, round(vehicle_s * 1000) * 1_000_000))

    def close(self) -> None:
        self.sock.close()


@pytest.fixture()
def running():
    """Start a simulator in a thread with the given config changes; stops it and closes its sockets after."""
    made: list[tuple[Simulator, threading.Event, threading.Thread]] = []

    def start(**config) -> Simulator:  # type: ignore[no-untyped-def]
        sim = Simulator(World.calm(), SimConfig(start_lat_deg=33.0, start_lon_deg=-118.0, port=0, speedup=1e9,
                                                **config))
        stop = threading.Event()
        thread = threading.Thread(target=sim.run, kwargs={"stop_event": stop}, daemon=True)
        made.append((sim, stop, thread))
        thread.start()
        return sim

    yield start
    for sim, stop, thread in made:
        stop.set()
        thread.join(10)
        sim.close()
        assert not thread.is_alive()


@pytest.fixture()
def companion():
    """Make ``Companion`` peers of a simulator; closes them after the test."""
    made: list[Companion] = []

    def make(sim: Simulator, source: tuple[int, int] = COMPANION, *, report_s: float | None = 0.0) -> Companion:
        """A peer that has sent its heartbeat and (unless None) a first report."""
        made.append(Companion(sim.port, source))
        made[-1].heartbeat()
        if report_s is not None:
            made[-1].report(report_s)
        return made[-1]

    yield make
    for peer in made:
        peer.close()


def _waiting(sim: Simulator, waits: int) -> bool:
    return wait_until(lambda: sim.stats.lockstep_waits >= waits, 10)


def test_the_physics_waits_for_each_report(running, companion):
    sim = running(lockstep_slack_s=0.0)
    peer = companion(sim)
    # At boot ATTITUDE streams at 10 Hz: the first step sends one stamped 0.1 s, then the
    # simulator waits until that has been handled.
    assert _waiting(sim, 2) and sim.time_s == pytest.approx(0.1), sim.time_s
    peer.report(0.1)
    assert _waiting(sim, 3) and sim.time_s == pytest.approx(0.2), sim.time_s
    assert sim.reported_s == pytest.approx(0.1)
    peer.report(0.05)  # an older report changes nothing
    peer.heartbeat()  # neither does other traffic
    assert wait_until(lambda: sim.stats.messages_in >= 5, 10)
    assert sim.time_s == pytest.approx(0.2) and sim.reported_s == pytest.approx(0.1)
    assert sim.stats.lockstep_expired == 0


def test_the_slack_lets_the_physics_run_that_far_ahead(running, companion):
    sim = running(lockstep_slack_s=1.0)
    peer = companion(sim)
    assert _waiting(sim, 2) and sim.time_s == pytest.approx(1.0), sim.time_s
    peer.report(5.0)
    assert _waiting(sim, 3) and sim.time_s == pytest.approx(6.0), sim.time_s


def test_a_ground_stations_timesync_is_no_report(running, companion):
    sim = running(lockstep_slack_s=0.0)
    companion(sim, GCS, report_s=100.0)  # QGroundControl and MAVProxy send TIMESYNC requests of their own
    assert wait_until(lambda: sim.stats.messages_in >= 2, 10)
    assert sim.reported_s is None and sim.time_s == 0.0


def test_without_an_executive_the_vehicle_runs_free_after_the_wait_and_a_report_brings_it_back(running, companion):
    sim = running(lockstep_slack_s=0.0, lockstep_first_wait_wall_s=0.05, lockstep_wait_wall_s=60.0)
    assert wait_until(lambda: sim.time_s > 100.0, 10), sim.time_s
    assert sim.stats.lockstep_expired == 1 and sim.reported_s is None
    waits = sim.stats.lockstep_waits  # the wait at the start
    peer = companion(sim)  # an executive starts, far behind: the vehicle waits for it
    assert _waiting(sim, waits + 1)
    stopped = sim.time_s
    peer.report(stopped)
    assert _waiting(sim, waits + 2) and sim.time_s == pytest.approx(stopped + 0.1), (stopped, sim.time_s)
    assert sim.stats.lockstep_expired == 1


def test_a_report_that_stops_advancing_lets_the_vehicle_run_free(running, companion):
    sim = running(lockstep_slack_s=0.0, lockstep_wait_wall_s=0.05)
    companion(sim)  # then silence: the executive stopped, or the uplink is cut
    assert wait_until(lambda: sim.time_s > 100.0, 10), sim.time_s
    assert sim.stats.lockstep_expired == 1 and sim.reported_s == 0.0


def test_cli_turns_lockstep_on_above_1x_and_checks_the_slack(synthetic_forecast):
    from vehicle_sim.cli import _add_arguments, _configure
    import argparse

    p = argparse.ArgumentParser()
    _add_arguments(p)
    base = ["--forecast", str(synthetic_forecast), "--start=-118.10,33.45"]
    assert _configure(p.parse_args(base))[1].lockstep_slack_s is None
    assert _configure(p.parse_args([*base, "--speedup", "1000"]))[1].lockstep_slack_s == 0.0
    assert _configure(p.parse_args([*base, "--speedup", "1000", "--lockstep-slack-s", "0.5"]))[1].lockstep_slack_s == 0.5
    assert _configure(p.parse_args([*base, "--speedup", "1000", "--no-lockstep"]))[1].lockstep_slack_s is None
    done = sim_cli(*base, "--speedup", "100", "--lockstep-slack-s", "-1")
    assert done.returncode == 2 and done.stderr.startswith("lrauv sim: error: --lockstep-slack-s '-1': expected")
