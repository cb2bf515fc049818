"""Link faults on UDP: the closed loop through ``tests.support.linkfault.LinkFaultProxy``.

``lrauv sim`` runs as a process, the executive in a thread, and the proxy between
them drops, duplicates, reorders and delays datagrams, or cuts the link. All fault
times are vehicle seconds (see ``tests/support/linkfault.py``). With 30 % loss, 5 %
duplication, reordering and 2 s latency spikes both ways the vehicle still reaches
its goal; a silence beyond ``link_loss_timeout_s`` makes the executive ask for its
``on_breach`` mode, and a short outage or spike does not. Every process and thread a
test starts is stopped by it.
"""

from __future__ import annotations

import os
import signal
import socket
import time
from itertools import pairwise

import pytest

from executive.helm import DEFAULT_RATES
from executive.recorder import Topic, read_messages
from executive.state import Phase
from planner.contract.modes import SubMode
from tests.support.helpers import assert_audit_clean, start_west_of_goal, wait_until
from tests.support.linkfault import Faults, LinkFaultProxy
from tests.support.loop_rig import FAILSAFE_SLACK_S, ExecThread, Sim
from planner.shore.demo import read_track
from planner.shore.replay.divelog import open_dive

pytestmark = pytest.mark.slow

MISSION_SPEEDUP = 300.0  # the whole mission (about 1.2 h of vehicle time) in some 15 s
FAILSAFE_SPEEDUP = 50.0  # 1 s of vehicle time is 20 ms: short outages keep their length on a busy machine
LINK_LOSS_TIMEOUT_S = 30.0  # HelmConfig's default, vehicle seconds
# A silence counts at real time (executive.clock): at a simulator's speedup the timeout is wall seconds,
# so the tests that wait for a link loss use a short one (more than a busy machine's stalls: 1 s of grace + 3 s).
CUT_LINK_LOSS_TIMEOUT_S = 3.0
# The whole-mission runs: at 300x the default 30 s is 0.1 s of wall time, and a stall that long of
# the proxy's threads on a busy 2-core machine (a fault of the host, not of the link under test)
# once made the executive declare the link lost on a fresh clone. 120 s is 0.4 s of wall time and
# still far beyond the longest silence these faults make (2 s spikes, 30 % loss of 1 Hz heartbeats).
MISSION_LINK_LOSS_TIMEOUT_S = 120.0
SIM_HEARTBEAT_TIMEOUT_S = 5.0  # the simulator's GCS heartbeat failsafe (ArduSub's FS_GCS_TIMEOUT default)
MAV_STATE_CRITICAL = 5
# SURFACE, or ALT_HOLD once at the surface: ArduSub completes SURFACE by itself (SURFACE_COMPLETE).
SURFACED = (SubMode.SURFACE, SubMode.ALT_HOLD)
MAV_CMD_SET_MESSAGE_INTERVAL = 511

# Spikes: 150-450 s apart, 20 s long, every datagram held 2 s more (vehicle time).
SPIKES = {"spike_s": 2.0, "spike_every_s": 300.0, "spike_duration_s": 20.0}
LOSSY = Faults(loss=0.30, duplicate=0.05, reorder=0.05, **SPIKES)
_TELEMETRY_AGE_S = 5.0  # vehicle seconds: a position the executive decides on is at most this old (spikes of 2 s)


def _logs(path) -> list[str]:  # type: ignore[no-untyped-def]
    return [p["message"] for _, _, p in read_messages(path, ["/log"])]


def _decision_times(path) -> list[float]:  # type: ignore[no-untyped-def]
    return [p["time_s"] for _, _, p in read_messages(path, ["/executive/decision"])]


def test_the_proxy_drops_duplicates_reorders_delays_and_cuts_as_asked():
    """The proxy on its own, between two plain sockets (no simulator: vehicle time is wall x speedup)."""
    speedup = 10.0  # 1 s of vehicle time is 0.1 s
    far = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # stands for the simulator
    near = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # stands for the executive
    proxy = None
    try:
        far.bind(("127.0.0.1", 0))
        near.bind(("127.0.0.1", 0))
        far.settimeout(1.0)
        near.settimeout(1.0)
        proxy = LinkFaultProxy(far.getsockname()[1], speedup=speedup, seed=3,
                               up=Faults(loss=0.3, duplicate=0.05, reorder=0.05))

        def send(n: int) -> None:
            near.sendto(b"%d" % n, ("127.0.0.1", proxy.port))

        def receive(got: list[int], wait_s: float) -> None:
            """Append what arrives until nothing has for ``wait_s``."""
            far.settimeout(wait_s)
            try:
                while True:
                    got.append(int(far.recv(100)))
            except TimeoutError:
                pass
            finally:
                far.settimeout(1.0)

        got: list[int] = []
        for n in range(2000):
            send(n)
            if n % 50 == 49:  # a few at a time: a socket buffer holds only a few hundred datagrams
                assert wait_until(lambda sent=n + 1: proxy.counters("up").received == sent, 10)
                receive(got, 0.002)
        proxy.set_faults(up=Faults())
        send(2000)  # a datagram still held for reordering goes out after this one
        receive(got, 0.3)
        c = proxy.counters("up")
        assert c.received == 2001 and len(got) == c.forwarded, c
        assert 500 < c.dropped < 700 and c.duplicated > 50 and c.reordered > 50, c
        assert len(got) - len(set(got)) == c.duplicated
        unique = list(dict.fromkeys(got))
        assert len(unique) == 2001 - c.dropped
        # Each reordered datagram comes right after the next one: one step back in the sequence.
        assert sum(1 for a, b in pairwise(unique) if a > b) == c.reordered

        # One 2 s latency spike (0.2 s of wall time): held, in order.
        proxy.spike(duration_s=1.0, delay_s=2.0, up=True, down=False)
        t0 = time.monotonic()
        for n in range(5):
            send(n)
        assert [int(far.recv(100)) for _ in range(5)] == [0, 1, 2, 3, 4]
        assert time.monotonic() - t0 >= 0.95 * 2.0 / speedup
        assert c.spikes == 1 and c.delayed == 5

        # A 3 s outage of the uplink only: dropped, then through again; the downlink stays open.
        proxy.outage(3.0, up=True, down=False)
        send(7)
        far.sendto(b"8", proxy.back.getsockname())
        assert near.recv(100) == b"8"
        assert wait_until(lambda: c.cut == 1, 5)
        start, end, up, down = proxy.outages[-1]
        assert end - start == pytest.approx(3.0) and up and not down
        assert wait_until(lambda: proxy.vehicle_s() >= end, 5)
        send(9)
        assert far.recv(100) == b"9"
    finally:
        if proxy is not None:
            proxy.close()
        far.close()
        near.close()


@pytest.mark.parametrize("faults", ["lossy both ways", "uplink spikes only"])
def test_the_mission_reaches_its_goal_through_a_faulty_link(demo_plan, synthetic_forecast, tmp_path, faults):
    """30 % loss, 5 % duplication, reordering and 2 s spikes both ways; or commands delayed 2 s only.

    Velocity targets expire 3 s after the last one on ArduSub and the executive sends one
    every second, so a 2 s delay on the uplink alone must not stall the vehicle either.
    The simulator runs in lockstep with slack (2.5 s; 1.5 s with its heartbeat failsafe
    on: ``loop_rig.FAILSAFE_SLACK_S``), so that a lost step or report does not stall
    it. With 30 % of the executive's 1 Hz heartbeats lost, four in a row
    go missing about once in 120 (0.3 ** 4), and an autopilot failsafe is an override
    the executive yields to (docs/executive.md, "Authority"): on the lossy link the
    simulator's heartbeat failsafe is off (ArduSub's FS_GCS_ENABLE 0); with the spikes
    alone it keeps ArduSub's 5 s failsafe, which must never fire.
    """
    table = demo_plan.table
    lon, lat = start_west_of_goal(table, cells=2)  # two cells: thousands of faulty messages, a shorter suite
    track, log = tmp_path / "track.csv", tmp_path / "faulty.mcap"
    up, down = (LOSSY, LOSSY) if faults == "lossy both ways" else (Faults(**SPIKES), Faults())
    lossy = faults == "lossy both ways"
    failsafe_s, slack_s = (0.0, 2.5) if lossy else (SIM_HEARTBEAT_TIMEOUT_S, FAILSAFE_SLACK_S)
    sim = Sim(synthetic_forecast, (lon, lat), "--heading-deg", "90", "--position-delay-s", "10",
              "--speedup", f"{MISSION_SPEEDUP:g}", "--lockstep-slack-s", f"{slack_s:g}",
              "--heartbeat-timeout-s", f"{failsafe_s:g}", "--gcs-sysid", "1", track=track)
    proxy = ex = None
    try:
        proxy = LinkFaultProxy(sim.port, speedup=MISSION_SPEEDUP, seed=5, up=up, down=down)
        ex = ExecThread(table, proxy.port, log, link_loss_timeout_s=MISSION_LINK_LOSS_TIMEOUT_S)
        summary = ex.join()
    finally:
        if ex is not None:
            ex.stop()
        if proxy is not None:
            proxy.close()
        sim.stop()
    assert summary is not None and summary.reached, summary
    # The vehicle itself, not only the executive's picture of it, was in a goal cell when the executive
    # arrived: the true track near that vehicle time, allowing for the age of the telemetry it decided on
    # (2 s spikes). Not the track's last row: after the executive stops, the simulator runs on for as long
    # as the machine's load keeps it, and the current moves the vehicle.
    truth = read_track(track)
    near = [k for k, t in enumerate(truth["time_s"]) if abs(t - summary.arrival_s) <= _TELEMETRY_AGE_S]
    assert near and any(table.lookup(truth["lat_deg"][k], truth["lon_deg"][k], truth["depth_m"][k],
                                     truth["heading_deg"][k]).reason == "at_goal" for k in near), (
        summary.arrival_s, [(truth["time_s"][k], truth["lat_deg"][k], truth["lon_deg"][k]) for k in near])
    # The faults really happened, in the directions asked for.
    u, d = proxy.counters("up"), proxy.counters("down")
    failsafes = sum("heartbeat lost" in text for _, text in proxy.texts)
    print(f"\n{faults}: {summary.vehicle_time_s:.0f} s vehicle, {summary.wall_s:.1f} s wall, "
          f"{failsafes} simulator heartbeat failsafes\n  up   {u.as_dict()}\n  down {d.as_dict()}")
    assert u.spikes >= 3 and u.delayed > 20
    if faults == "lossy both ways":
        for c in (u, d):
            assert c.dropped > 300 and c.duplicated > 30 and c.reordered > 30, c
            assert c.spikes >= 3 and c.delayed > 40, c  # a two-cell mission: about half the messages of a longer one
    else:
        assert u.dropped == d.dropped == 0 and d.spikes == 0 and d.delayed == 0
        assert failsafes == 0
    # Duplicated, reordered and late telemetry never made a decision go back in time.
    times = _decision_times(log)
    assert times == sorted(times)
    assert not any(m.startswith("link lost") for m in _logs(log))
    assert_audit_clean(log)


def _running(ex: ExecThread) -> bool:
    return ex.executive.helm.phase is Phase.RUNNING and ex.executive._counts["decisions"] > 5


def _start_rig(demo_plan, synthetic_forecast, log, link_loss_timeout_s=LINK_LOSS_TIMEOUT_S, **helm):  # type: ignore[no-untyped-def]
    """Simulator, proxy and executive at ``FAILSAFE_SPEEDUP``, following the plan; stopped by ``_stop_rig``."""
    lon, lat = start_west_of_goal(demo_plan.table, cells=6)
    # A later --speedup overrides Sim's own (argparse keeps the last).
    # The simulator's GCS failsafe counts the executive's heartbeats (MAV_GCS_SYSID 1: system 1).
    sim = Sim(synthetic_forecast, (lon, lat), "--position-delay-s", "5", "--speedup", f"{FAILSAFE_SPEEDUP:g}",
              "--heartbeat-timeout-s", f"{SIM_HEARTBEAT_TIMEOUT_S:g}", "--gcs-sysid", "1")
    proxy = ex = None
    try:
        proxy = LinkFaultProxy(sim.port, speedup=FAILSAFE_SPEEDUP, seed=11)
        ex = ExecThread(demo_plan.table, proxy.port, log, link_loss_timeout_s=link_loss_timeout_s, **helm)
        assert wait_until(lambda: proxy.mode() == SubMode.GUIDED and _running(ex), 30), proxy.modes[-3:]
        _watch(proxy, ex, proxy.vehicle_s() + 30.0, set())
    except BaseException:
        _stop_rig(sim, proxy, ex)
        raise
    return sim, proxy, ex


def _stop_rig(sim, proxy, ex):  # type: ignore[no-untyped-def]
    summary = None
    try:
        if ex is not None:
            summary = ex.stop()
    finally:
        if proxy is not None:
            proxy.close()
        sim.stop()
    return summary


def _watch(proxy: LinkFaultProxy, ex: ExecThread, until_vehicle_s: float, phases: set[Phase]) -> None:
    """Wait until the vehicle's clock passes ``until_vehicle_s``, noting the executive's phases meanwhile."""
    def done() -> bool:
        phases.add(ex.executive.helm.phase)
        return proxy.vehicle_s() >= until_vehicle_s

    assert wait_until(done, 30), f"vehicle time {proxy.vehicle_s():.1f} s did not reach {until_vehicle_s:.1f} s"


def test_a_short_outage_or_latency_spike_fires_no_failsafe(demo_plan, synthetic_forecast, tmp_path):
    """2 s of silence both ways, then 2 s of latency both ways: shorter than every timeout."""
    log = tmp_path / "short.mcap"
    sim, proxy, ex = _start_rig(demo_plan, synthetic_forecast, log)
    phases: set[Phase] = set()
    try:
        t0 = proxy.vehicle_s()
        proxy.outage(2.0, up=True, down=True)
        _watch(proxy, ex, t0 + 10.0, phases)
        proxy.spike(10.0, 2.0, up=True, down=True)
        # Past the end of both, by more than the link-loss timeout.
        _watch(proxy, ex, t0 + 20.0 + LINK_LOSS_TIMEOUT_S + 10.0, phases)
        assert _running(ex)
    finally:
        _stop_rig(sim, proxy, ex)
    # In lockstep the vehicle waits out the outage (its 2 s may pass with nothing sent either way):
    # what counts is that nothing fired.
    for direction in ("up", "down"):
        c = proxy.counters(direction)
        assert c.spikes == 1 and c.delayed > 0, (direction, c)
    assert Phase.LINK_LOST not in phases, phases
    assert [m for t, m in proxy.modes if t >= t0] and all(m == SubMode.GUIDED for t, m in proxy.modes if t >= t0)
    assert not any("heartbeat lost" in text for _, text in proxy.texts), proxy.texts
    assert all(status != MAV_STATE_CRITICAL for _, status in proxy.exec_status)
    assert not any(m.startswith("link lost") for m in _logs(log))
    times = _decision_times(log)
    assert times == sorted(times)
    assert_audit_clean(log)


@pytest.mark.parametrize("cut", ["downlink", "both ways"])
def test_the_failsafe_fires_beyond_the_link_loss_timeout(demo_plan, synthetic_forecast, tmp_path, cut):
    """A silence longer than ``link_loss_timeout_s``: the executive asks for SURFACE (on_breach).

    Downlink only: the vehicle still hears the executive, which surfaces it once the
    timeout has passed; the simulator, in lockstep, follows the executive's clock through
    the silence (its reports go on at real time: executive.clock). Both ways: the
    simulator, hearing no heartbeat from the executive, runs its own GCS failsafe after
    5 s as ArduSub does (this simulator surfaces; ArduSub's default disarms); the
    executive's SURFACE requests are lost.
    When the link comes back (both ways: the uplink first, so the simulator's failsafe has cleared
    when the executive hears it again), the executive sets up again and the vehicle returns to GUIDED.
    """
    log = tmp_path / "cut.mcap"
    both = cut == "both ways"
    timeout_s = CUT_LINK_LOSS_TIMEOUT_S
    # Cut both ways, the simulator runs free at its speedup through the timeout's wall seconds: hundreds of its
    # seconds without a position. A position timeout longer than that keeps the return to GUIDED what is tested.
    sim, proxy, ex = _start_rig(demo_plan, synthetic_forecast, log, timeout_s, position_timeout_s=3600.0)
    try:
        t0 = proxy.vehicle_s()
        proxy.cut(up=both, down=True)
        assert wait_until(lambda: ex.executive.helm.phase is Phase.LINK_LOST, 20), ex.executive.helm.phase
        assert wait_until(lambda: proxy.mode() in SURFACED, 20), proxy.modes[-3:]
        # A SURFACE request again (every retry_s of the executive's clock: real time through the silence).
        assert wait_until(lambda: sum(m == SubMode.SURFACE for t, m in proxy.mode_requests if t >= t0) >= 2, 20)
        if both:
            # The uplink first, until the simulator has heard the executive and cleared its own failsafe: the first
            # heartbeat the executive then hears is not a failsafe's. Restored together, which comes first is the
            # machine's load: hearing the failsafe still active (MAV_STATE_CRITICAL), the executive lets it win and
            # waits for an operator (tests/executive/test_authority.py), which is not this test's path.
            proxy.cut(up=False, down=True)
            assert wait_until(lambda: any("Failsafe cleared" in text for t, text in proxy.texts if t >= t0), 20), \
                proxy.texts[-3:]
        proxy.cut(up=False, down=False)
        t1 = proxy.vehicle_s()
        assert wait_until(lambda: proxy.mode() == SubMode.GUIDED and _running(ex), 20), proxy.modes[-3:]
    finally:
        _stop_rig(sim, proxy, ex)
    # Vehicle times from the last heartbeat that got through before the cut, each way.
    last_vehicle_hb = max(t for t, _ in proxy.modes if t < t0)
    last_exec_hb = max(t for t, _ in proxy.exec_status if t < t0)
    surface_requests = [t - last_vehicle_hb for t, m in proxy.mode_requests if t0 <= t <= t1 and m == SubMode.SURFACE]
    surfaced = next(t for t, m in proxy.modes if t >= t0 and m in SURFACED)
    lost_texts = [t - last_exec_hb for t, text in proxy.texts if t >= t0 and "heartbeat lost" in text]
    # The executive waited for the timeout on its own clock, extrapolated through the silence
    # (after its grace, at real time: executive.clock), one step after the last heartbeat it heard.
    lost_at = next(t for _, t, p in read_messages(log, ["/log"]) if p["message"].startswith("link lost"))
    heard = max(t for _, t, p in read_messages(log, ["/mavlink/rx"])
                if p["name"] == "HEARTBEAT" and p["src_component"] == 1 and t < lost_at)
    # The bound past the timeout is the loop's own delay at real time (a busy machine's scheduling).
    assert timeout_s < lost_at - heard <= timeout_s + 2.0, (heard, lost_at)
    assert surface_requests, proxy.mode_requests[-5:]
    assert len(surface_requests) >= 2  # repeated every retry_s (2 s) while the link is down
    assert any(status == MAV_STATE_CRITICAL for t, status in proxy.exec_status if t0 <= t < t1)
    if both:
        # The simulator's own failsafe came first (after its 5 s heartbeat timeout: tests/vehicle_sim times it on
        # the simulator's clock; the proxy's reading of vehicle time here is extrapolated from wall time), and the
        # vehicle surfaced on it: in the simulator's stream the text comes before the mode.
        assert len(lost_texts) == 1, proxy.texts
        assert 0.0 < lost_texts[0] and surfaced - last_exec_hb >= lost_texts[0], (lost_texts, surfaced - last_exec_hb)
        assert proxy.counters("up").cut > 0
        # Cleared once the executive's heartbeat came back (its stamp may precede the proxy's reading of t1).
        assert any("Failsafe cleared" in text for t, text in proxy.texts if t >= t0), proxy.texts[-3:]
    else:
        # The vehicle heard the executive all along: it surfaced on the executive's request.
        assert lost_texts == [], proxy.texts
        assert surfaced - last_vehicle_hb >= surface_requests[0]
        assert proxy.counters("up").cut == 0
    logs = _logs(log)
    assert any(m.startswith("link lost") and "asking for SURFACE" in m for m in logs), logs
    assert any(m.startswith("link regained") for m in logs), logs
    assert_audit_clean(log)


def test_a_stalled_simulator_is_not_a_silent_link(demo_plan, synthetic_forecast, tmp_path):
    """The simulator's process stops for 2.5 s of wall time (SIGSTOP), as ArduSub SITL did writing its log.

    Its clock stops with it: 2.5 s of wall time is no vehicle time at all. The executive's clock
    runs on through the silence at real time after its grace (``executive.clock``), so it counts
    1.5 s, far from the 30 s timeout; extrapolated at the measured 50x it would count 75 s and
    declare the link lost. Nor does vehicle time step back when the simulator goes on.
    """
    log = tmp_path / "stall.mcap"
    sim, proxy, ex = _start_rig(demo_plan, synthetic_forecast, log)
    phases: set[Phase] = set()
    try:
        os.kill(sim.proc.pid, signal.SIGSTOP)
        try:
            time.sleep(2.5)
        finally:
            os.kill(sim.proc.pid, signal.SIGCONT)
        t0 = proxy.vehicle_s()
        _watch(proxy, ex, t0 + 20.0, phases)
        assert _running(ex)
    finally:
        _stop_rig(sim, proxy, ex)
    assert ex.executive.clock.rate > 10.0  # a simulator's speedup, measured (the stall counted at real time)
    assert Phase.LINK_LOST not in phases, phases
    assert not any(m.startswith("link lost") for m in _logs(log))
    rx_times = [m.log_time_s for m in open_dive(log).messages([Topic.MAVLINK_RX])]  # in the order received
    assert rx_times == sorted(rx_times)  # the clock never stepped back
    assert_audit_clean(log)


def test_the_telemetry_rates_asked_for_are_in_force_after_lost_requests(demo_plan, synthetic_forecast, tmp_path):
    """Every command of the first set-up is lost; GUIDED and arming are asked again, and so should the rates be."""
    speedup = 100.0
    lon, lat = start_west_of_goal(demo_plan.table, cells=6)
    sim = Sim(synthetic_forecast, (lon, lat), "--position-delay-s", "5", "--speedup", f"{speedup:g}")
    proxy = ex = None
    try:
        proxy = LinkFaultProxy(sim.port, speedup=speedup, seed=17, up=Faults(drop_types=frozenset({"COMMAND_LONG"})))
        ex = ExecThread(demo_plan.table, proxy.port, tmp_path / "rates.mcap")
        assert wait_until(lambda: sum(c == MAV_CMD_SET_MESSAGE_INTERVAL for _, c in proxy.commands)
                          >= len(DEFAULT_RATES), 30), proxy.commands
        proxy.set_faults(up=Faults())
        assert wait_until(lambda: proxy.mode() == SubMode.GUIDED and _running(ex), 30), proxy.modes[-3:]
        t0, before = proxy.vehicle_s(), proxy.heard("down")
        _watch(proxy, ex, t0 + 60.0, set())
        t1, after = proxy.vehicle_s(), proxy.heard("down")
    finally:
        _stop_rig(sim, proxy, ex)
    assert proxy.counters("up").filtered >= len(DEFAULT_RATES)
    too_fast = {}
    for name, interval_s in DEFAULT_RATES:
        count = after[name] - before[name]
        if count > 1.2 * (t1 - t0) / interval_s + 2:
            too_fast[name] = round(count / (t1 - t0), 2)
    print(f"\nstreams above the rate asked for (Hz): {too_fast}")
    assert too_fast == {}
