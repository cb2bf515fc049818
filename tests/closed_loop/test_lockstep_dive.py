"""The same seeded dive on a quiet and on a busy machine: ``lrauv sim`` in lockstep with the executive.

``lrauv sim`` runs as a process at 1000x (lockstep, slack 0, as at any speedup above 1) and the
executive in a thread. One run has two other processes burning a CPU each for its whole
length (this machine may have only two cores); the other has not. Lockstep makes the executive's
commands for a message take effect from the same simulated step however the processes are
scheduled, and the executive's clock does not run on while the simulator waits, so the two
runs make the same decisions at the same vehicle times and arrive at the same time.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from executive.recorder import read_messages
from tests.support.helpers import start_west_of_goal
from tests.support.loop_rig import ExecThread, Sim

pytestmark = pytest.mark.slow

BURNERS = 2


def _dive(table, forecast: Path, log: Path, *, busy: bool):  # type: ignore[no-untyped-def]
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(BURNERS if busy else 0)]
    sim = ex = None
    try:
        lon, lat = start_west_of_goal(table, cells=2)
        sim = Sim(forecast, (lon, lat), "--heading-deg", "90", "--position-delay-s", "5", "--speedup", "1000")
        ex = ExecThread(table, sim.port, log)
        summary = ex.join()
    finally:
        if ex is not None:
            ex.stop()
        if sim is not None:
            sim.stop()
        for proc in burners:
            proc.kill()
            proc.wait()
    assert summary is not None and summary.reached, summary
    decisions = [(p["time_s"], p["action"], tuple(p["cell"]) if p.get("cell") else None)
                 for _, _, p in read_messages(log, ["/executive/decision"])]
    commands = [(p["time_s"], p["kind"]) for _, _, p in read_messages(log, ["/executive/command"])]
    return summary.arrival_s, decisions, commands


def test_the_same_seed_gives_the_same_dive_on_a_busy_and_a_quiet_machine(demo_plan, synthetic_forecast, tmp_path):
    table = demo_plan.table
    busy = _dive(table, synthetic_forecast, tmp_path / "busy.mcap", busy=True)
    quiet = _dive(table, synthetic_forecast, tmp_path / "quiet.mcap", busy=False)
    arrival_busy, decisions_busy, commands_busy = busy
    arrival_quiet, decisions_quiet, commands_quiet = quiet
    print(f"\narrival {arrival_busy} s busy, {arrival_quiet} s quiet; {len(decisions_quiet)} decisions,"
          f" {len(commands_quiet)} commands")
    assert arrival_busy == arrival_quiet
    assert decisions_busy == decisions_quiet
    assert commands_busy == commands_quiet
