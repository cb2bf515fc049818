"""MAVLink fuzzing at scale: a million frames into the executive and a million into the simulator.

Not a test (tests/closed_loop/test_fuzz_mavlink.py runs the same checks on tens of thousands).
Every frame is a real datagram over UDP on 127.0.0.1 into the real input path
(``Executive._drain``, ``Simulator._poll``), through the harness in
tests/support/mavfuzz.py. Four runs, about ``--frames`` each (default 520,000: over a million for each side):

1. executive, idle (no autopilot heard yet), invalid frames only: it must send
   nothing, count no message in and keep its state;
2. executive, a valid autopilot stream with invalid copies mixed in, some frames
   duplicated or one place late: its commands must equal those of a run on the
   valid frames alone (that run is made too, and not counted);
3. simulator, invalid frames only: its autopilot state must not change;
4. simulator, valid executive commands with invalid copies mixed in: the same
   autopilot state as the valid frames alone.

Resident memory (VmRSS) is sampled every 50,000 frames. Nothing may raise.

    .venv/bin/python bench/bench_fuzz.py [--frames 520000] [--seed 1]
"""

from __future__ import annotations

import argparse
import itertools
import os
import platform
import random
import socket
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from executive.helm import HelmState  # noqa: E402
from executive.state import VehicleState  # noqa: E402
from planner.contract.table import PolicyTable  # noqa: E402
from tests.support.mavfuzz import (  # noqa: E402
    ExecutiveHarness,
    autopilot_frames,
    autopilot_state,
    executive_frames,
    invalid_frames,
    noisy_stream,
    rss_mb,
)

SAMPLE_EVERY = 50_000


class Memory:
    def __init__(self) -> None:
        self.samples: list[float] = []

    def __call__(self, n: int) -> None:
        if n % SAMPLE_EVERY == 0:
            self.samples.append(rss_mb())

    def line(self) -> str:
        s = self.samples
        return (f"RSS {s[0]:.1f} MB at the start, {s[len(s) // 2]:.1f} at the middle, {s[-1]:.1f} at the end"
                f" (max {max(s):.1f}, {len(s)} samples)")


def table_and_truth(work: Path) -> tuple[PolicyTable, Path]:
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic
    from tests.support.helpers import plan_for

    truth = write_synthetic(work / "truth.nc", SyntheticSettings(seed=0, hours=24))
    return plan_for(truth).table, truth


def executive_idle(table: PolicyTable, work: Path, n: int, rng: random.Random) -> None:
    mem = Memory()
    harness = ExecutiveHarness.start(table, work / "idle.mcap")
    t0 = time.perf_counter()
    try:
        frames = invalid_frames(autopilot_frames(table, 500), rng)
        sent = harness.run(itertools.islice(frames, n), every=1000, on_progress=mem)
        ex = harness.executive
        ok = (not sent and ex.vehicle == VehicleState() and ex.helm == HelmState() and ex._counts["in"] == 0)
        print(f"1 executive idle, {n:,} invalid frames in {time.perf_counter() - t0:.1f} s: {len(sent)} messages out,"
              f" {ex._counts['in']} in, {ex._counts['bad']:,} counted bad; state unchanged: {ok}")
        print(f"  {mem.line()}")
    finally:
        harness.close()


def executive_noisy(table: PolicyTable, work: Path, n: int, rng: random.Random) -> None:
    valid = autopilot_frames(table, n // 3)  # 1.3 frames a step, 1.5 invalid ones per frame: about n in all
    noisy, clean = noisy_stream(valid, rng)
    runs = []
    for name, frames in (("clean", clean), ("noisy", noisy)):
        mem = Memory()
        harness = ExecutiveHarness.start(table, work / f"{name}.mcap")
        t0 = time.perf_counter()
        try:
            sent = harness.run(frames, on_progress=mem)
            runs.append((sent, harness.executive._counts["decisions"], time.perf_counter() - t0, mem))
        finally:
            harness.close()
    (sent_c, dec_c, _, _), (sent_n, dec_n, wall, mem) = runs
    print(f"2 executive running, {len(noisy):,} frames ({len(noisy) - len(clean):,} invalid among {len(clean):,}"
          f" valid, some of those twice or late) in {wall:.1f} s: {dec_n:,} decisions and {len(sent_n):,} messages out;"
          f" the same as the valid frames alone: {dec_n == dec_c and sent_n == sent_c}")
    print(f"  {mem.line()}")


def simulator(truth: Path, n: int, rng: random.Random, *, noisy: bool) -> None:
    from dataclasses import replace

    from vehicle_sim.endpoint import SimConfig, Simulator
    from vehicle_sim.world import World

    world = World.load(truth)
    config = SimConfig(start_lon_deg=-118.0, start_lat_deg=33.5, port=0)
    config = replace(config, autopilot=replace(config.autopilot, prearm_delay_s=0.0))
    if noisy:
        streams = dict(zip(("noisy", "clean"), noisy_stream(executive_frames(n // 2), rng, max_noise=3,
                                                            reorder=0.0, duplicate=0.0)))
    else:
        streams = {"noisy": list(itertools.islice(invalid_frames(executive_frames(50), rng), n))}
    results = {}
    for name, frames in streams.items():
        mem = Memory()
        with Simulator(world, config) as sim, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.bind(("127.0.0.1", 0))
            before = autopilot_state(sim)
            t0 = time.perf_counter()
            for k, data in enumerate(frames):
                sender.sendto(data, (sim.host, sim.port))
                if k % 50 == 0:
                    sim._poll()
                mem(k)
            sim._poll()
            results[name] = (before, autopilot_state(sim), sim.stats.messages_in, len(frames),
                             time.perf_counter() - t0, mem)
    before, after, messages_in, count, wall, mem = results["noisy"]
    if noisy:
        same = (after, messages_in) == results["clean"][1:3]
        print(f"4 simulator, {count:,} frames ({count - results['clean'][3]:,} invalid among"
              f" {results['clean'][3]:,} valid) in {wall:.1f} s: {messages_in:,} messages taken;"
              f" the same state as the valid frames alone: {same}")
    else:
        print(f"3 simulator, {count:,} invalid frames in {wall:.1f} s: {messages_in} messages taken;"
              f" state unchanged: {after == before}")
    print(f"  {mem.line()}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=520_000, help="frames in each of the four runs")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    print(f"machine    {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        table, truth = table_and_truth(work)
        rng = random.Random(args.seed)
        executive_idle(table, work, args.frames, rng)
        executive_noisy(table, work, args.frames, rng)
        simulator(truth, args.frames, rng, noisy=False)
        simulator(truth, args.frames, rng, noisy=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
