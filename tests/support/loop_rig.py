"""The closed loop's two sides for the tests: ``lrauv sim`` as a child process, the executive in a thread.

``lrauv sim`` runs in lockstep with the executive, as it does at any speedup above 1 (slack 0
unless a test passes ``--lockstep-slack-s``): the loop does not depend on how busy the machine is.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

from executive.helm import HelmConfig
from executive.loop import ExecConfig, Executive
from planner.shore.demo import stop_process
from vehicle_sim.cli import wait_ready

LRAUV = [sys.executable, "-m", "planner.cli"]
SPEEDUP = 400.0
# Lockstep slack for a lossy link while the simulator's 5 s heartbeat failsafe is on: the executive's
# heartbeats come every vehicle second of its clock, which may jump by up to the slack (telemetry lost)
# and lag the vehicle by the slack, so 1 + 2 x slack + 0.5 (a step of telemetry) must stay under 5 s.
FAILSAFE_SLACK_S = 1.5


class Sim:
    """``lrauv sim`` as a child process on an ephemeral port."""

    def __init__(self, forecast: Path, start: tuple[float, float], *extra: str, track: Path | None = None) -> None:
        cmd = [*LRAUV, "sim", "--forecast", str(forecast), "--start", f"{start[0]},{start[1]}", "--listen", "127.0.0.1:0",
               "--speedup", str(SPEEDUP), "--seed", "1", *extra]
        if track is not None:
            cmd += ["--track", str(track)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            self.port = wait_ready(self.proc)
        except Exception:
            self.stop()
            raise

    def stop(self) -> int:
        stop_process(self.proc)
        return self.proc.returncode


WALL_LIMIT_S = 600.0  # the executive's wall-time limit in these rigs, and the longest wait for its end


class ExecThread:
    # Safety nets, not measurements: a run ends at arrival (lockstep makes it the same dive on any machine); these
    # only stop a run that went wrong, so they are far above what a busy 2-core machine needs.
    def __init__(self, table, port: int, log: Path, *, max_wall_s: float = WALL_LIMIT_S, **helm) -> None:  # type: ignore[no-untyped-def]
        config = ExecConfig(link=f"udpout:127.0.0.1:{port}", log_path=log, exit_on_arrival=True, linger_s=20.0,
                            max_wall_s=max_wall_s, helm=HelmConfig(**helm))
        self.executive = Executive(config, table)
        self.stop_event = threading.Event()
        self.summary = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        self.summary = self.executive.run(self.stop_event)

    def join(self, timeout: float = WALL_LIMIT_S):  # type: ignore[no-untyped-def]
        self.thread.join(timeout)
        if self.thread.is_alive():
            self.stop_event.set()
            self.thread.join(10)
        return self.summary

    def stop(self):  # type: ignore[no-untyped-def]
        self.stop_event.set()
        return self.join(10)
