"""MAVLink input fuzzing of the executive and the simulator (the million-frame run is bench/bench_fuzz.py).

Real datagrams over UDP on 127.0.0.1 into the real input paths. Checked: nothing
raises; an invalid frame changes nothing and makes no command; a valid stream
with corrupted, duplicated and reordered frames mixed in gives exactly the
decisions and commands of the same valid stream alone.
"""

from __future__ import annotations

import random
import socket
from dataclasses import replace

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from executive.helm import HelmState
from executive.state import Phase, VehicleState
from vehicle_sim.endpoint import SimConfig, Simulator
from vehicle_sim.world import World

from tests.support.helpers import assert_audit_clean
from tests.support.mavfuzz import (
    ExecutiveHarness,
    autopilot_frames,
    autopilot_state,
    executive_frames,
    invalid_frames,
    noisy_stream,
    parses,
)

N_INVALID = 20_000


def test_invalid_frames_change_nothing_in_an_idle_executive(demo_plan, tmp_path):
    """An executive that has heard no autopilot yet, fed only invalid frames: it stays as it was, silent."""
    rng = random.Random(1)
    harness = ExecutiveHarness.start(demo_plan.table, tmp_path / "idle.mcap")
    try:
        frames = invalid_frames(autopilot_frames(demo_plan.table, 200), rng)
        for n in range(N_INVALID):
            harness.feed(next(frames))
            if n % 1000 == 0:
                assert _beyond_heartbeats(harness.sent()) == []
        ex = harness.executive
        assert _beyond_heartbeats(harness.sent()) == []  # not one command, nothing but its 1 Hz heartbeat
        assert ex.vehicle == VehicleState() and ex.helm == HelmState() and ex.helm.phase is Phase.WAIT_LINK
        assert ex._counts["in"] == 0 and ex._counts["decisions"] == 0 and ex._counts["bad"] > 0
    finally:
        harness.close()


def _beyond_heartbeats(sent: list) -> list[str]:  # type: ignore[type-arg]
    """What the executive sent other than its heartbeat (due every second, of wall time before an autopilot is heard)."""
    return [m.get_type() for m in sent if m.get_type() != "HEARTBEAT"]


def _run(table, log, frames):  # type: ignore[no-untyped-def]
    harness = ExecutiveHarness.start(table, log)
    try:
        sent = harness.run(frames)
        return harness.executive._counts["decisions"], sent
    finally:
        harness.close()


def test_corrupted_duplicated_and_reordered_frames_give_the_clean_streams_decisions(demo_plan, tmp_path):
    noisy, clean = noisy_stream(autopilot_frames(demo_plan.table, 3000), random.Random(2))
    assert len(noisy) - len(clean) > 3000
    d_clean, sent_clean = _run(demo_plan.table, tmp_path / "clean.mcap", clean)
    d_noisy, sent_noisy = _run(demo_plan.table, tmp_path / "noisy.mcap", noisy)
    assert d_clean > 1000
    assert d_noisy == d_clean
    assert sent_noisy == sent_clean  # no command came from an invalid frame, none was lost to one
    assert_audit_clean(tmp_path / "noisy.mcap")


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=400))
def test_any_bytes_are_taken_without_an_exception_or_a_command(demo_plan, tmp_path_factory, data):
    harness = _shared_harness(demo_plan, tmp_path_factory)
    before = harness.executive._counts["in"]
    harness.feed(data)
    if not parses(data):
        assert harness.executive._counts["in"] == before
        assert _beyond_heartbeats(harness.sent()) == []


_HARNESS: dict[str, ExecutiveHarness] = {}


def _shared_harness(demo_plan, tmp_path_factory) -> ExecutiveHarness:  # type: ignore[no-untyped-def]
    if "h" not in _HARNESS:
        _HARNESS["h"] = ExecutiveHarness.start(demo_plan.table, tmp_path_factory.mktemp("fuzz") / "any.mcap")
    return _HARNESS["h"]


def teardown_module() -> None:
    for harness in _HARNESS.values():
        harness.close()
    _HARNESS.clear()


# -- the simulator --------------------------------------------------------------------------------


def _sim_feed(sim: Simulator, sender: socket.socket, frames) -> None:  # type: ignore[no-untyped-def]
    for n, data in enumerate(frames):
        sender.sendto(data, (sim.host, sim.port))
        if n % 50 == 0:
            sim._poll()
    sim._poll()


def test_the_simulator_takes_invalid_frames_without_a_change(synthetic_forecast):
    rng = random.Random(3)
    with Simulator(World.load(synthetic_forecast), SimConfig(start_lon_deg=-118.0, start_lat_deg=33.5, port=0)) as sim, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        sender.bind(("127.0.0.1", 0))
        before = autopilot_state(sim)
        frames = invalid_frames(executive_frames(50), rng)
        _sim_feed(sim, sender, (next(frames) for _ in range(N_INVALID)))
        assert autopilot_state(sim) == before
        assert sim.stats.messages_in == 0 and sim.stats.datagrams_in == N_INVALID


def test_the_simulator_obeys_the_valid_frames_among_corrupted_ones_as_if_alone(synthetic_forecast):
    rng = random.Random(4)
    noisy, clean = noisy_stream(executive_frames(500), rng, max_noise=4, reorder=0.0, duplicate=0.0)
    states = []
    for frames in (clean, noisy):
        config = SimConfig(start_lon_deg=-118.0, start_lat_deg=33.5, port=0)
        config = replace(config, autopilot=replace(config.autopilot, prearm_delay_s=0.0))
        with Simulator(World.load(synthetic_forecast), config) as sim, \
                socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.bind(("127.0.0.1", 0))
            _sim_feed(sim, sender, frames)
            states.append((autopilot_state(sim), sim.stats.messages_in))
    assert states[0] == states[1]
    assert states[0][0]["armed"]  # the valid frames did something: the comparison is not empty
