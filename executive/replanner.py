"""Onboard replanning, off the control loop: new forecasts are noticed here and planned in a child process.

``ForecastWatcher`` polls a directory for new forecast files (``*.nc``), taking a file only
once its size and modification time have held still for one poll, so a file still being
written is not planned on (writers should still write atomically, as ``lrauv forecast synth``
does). ``Replanner`` runs ``lrauv plan`` for one goal at a time in a child process
at a lower CPU priority, so the executive's loop never waits for the solver and never
imports it (the vehicle side stays light). The loop polls ``Replanner.poll`` and swaps the new
table in at a decision boundary (``executive.goal_tables``, ``executive.loop``).

One job runs at a time; a request made while one runs replaces any request still waiting,
so a burst of forecasts plans only the newest.
"""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from planner.contract.mission import MissionGoal

_STDERR_TAIL = 400  # characters of the planner's error kept for the log
# The child lowers its own priority, so that the solver never takes the CPU from the control
# loop; doing it here rather than in a preexec_fn lets Popen use vfork: 0.3 ms instead of 4 ms
# (and 12 ms measured in bench/bench_replan.py) of the loop's time per replan.
_CHILD = "import os, sys; os.nice(10); from planner.cli import main; sys.exit(main(sys.argv[1:]))"


@dataclass(frozen=True, slots=True)
class PlanJob:
    """One goal to plan: on which forecast, for which plan, and why."""

    goal_index: int
    goal: MissionGoal
    forecast: Path | None  # None: the mission's own forecast source
    time_iso: str | None  # forecast time to plan at (the vehicle's UTC time when known)
    reason: str  # "new forecast NAME", "period", "next goal", "uploaded mission"
    requested_wall_s: float  # time.monotonic() when the trigger was seen


@dataclass(frozen=True, slots=True)
class PlanResult:
    job: PlanJob
    table_bytes: bytes | None
    error: str | None
    started_wall_s: float
    finished_wall_s: float

    @property
    def latency_s(self) -> float:
        """From the trigger (a new forecast file seen, say) to the table ready to swap in."""
        return self.finished_wall_s - self.job.requested_wall_s


class ForecastWatcher:
    """New ``*.nc`` files in a directory, each reported once, when it has stopped changing.

    Files present at start are not new. A file is known by its name: a forecast written again
    under an old name is not reported (forecast feeds name each issue anew)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self._seen = {p.name for p in self._files()}  # already there: the running plan knows them
        self._sizes: dict[str, tuple[int, int]] = {}

    def _files(self) -> list[Path]:
        try:
            return sorted(p for p in self.directory.glob("*.nc") if p.is_file())
        except OSError:
            return []

    def poll(self) -> list[Path]:
        """Files that appeared since the last call and have held still for one poll, oldest name first."""
        ready = []
        for p in self._files():
            if p.name in self._seen:
                continue
            try:
                st = p.stat()
            except OSError:
                continue
            sig = (st.st_size, st.st_mtime_ns)
            if self._sizes.get(p.name) == sig and st.st_size > 0:
                self._seen.add(p.name)
                self._sizes.pop(p.name, None)
                ready.append(p)
            else:
                self._sizes[p.name] = sig
        return ready


class Replanner:
    """Plans one goal at a time in a child process; ``poll`` returns each finished job once."""

    def __init__(self, mission_path: Path, work_dir: Path) -> None:
        self.mission_path = mission_path
        self.work_dir = work_dir
        self._proc: subprocess.Popen[bytes] | None = None
        self._job: PlanJob | None = None
        self._started = 0.0
        self._waiting: PlanJob | None = None
        self._count = 0

    @property
    def busy(self) -> bool:
        return self._proc is not None or self._waiting is not None

    @property
    def forecasts(self) -> frozenset[Path]:
        """The forecast files of the job running and the one waiting: not to be removed under them."""
        return frozenset(j.forecast for j in (self._job, self._waiting) if j is not None and j.forecast is not None)

    def request(self, job: PlanJob) -> None:
        self._waiting = job
        if self._proc is None:
            self._start()

    def poll(self) -> PlanResult | None:
        if self._proc is None or self._proc.poll() is None:
            return None
        job, proc = self._job, self._proc
        assert job is not None
        self._proc, self._job = None, None
        out, err = self._paths(self._count)
        table_bytes, error = None, None
        if proc.returncode == 0:
            try:
                table_bytes = out.read_bytes()
            except OSError as exc:
                error = f"the planner wrote no table: {exc}"
        else:
            try:
                text = err.read_text(errors="replace").strip()
            except OSError:
                text = ""
            last = text.splitlines()[-1] if text else f"exit status {proc.returncode}"
            error = last[-_STDERR_TAIL:]
        for path in (out, err):
            path.unlink(missing_ok=True)
        result = PlanResult(job, table_bytes, error, self._started, time.monotonic())
        if self._waiting is not None:
            self._start()
        return result

    def close(self) -> None:
        self._waiting = None
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()
        self._proc = None

    def _paths(self, n: int) -> tuple[Path, Path]:
        return self.work_dir / f"replan-{n}.lrpt", self.work_dir / f"replan-{n}.stderr"

    def _start(self) -> None:
        job, self._waiting = self._waiting, None
        assert job is not None
        self._count += 1
        self.work_dir.mkdir(parents=True, exist_ok=True)
        out, err = self._paths(self._count)
        g = job.goal.goal
        cmd = [sys.executable, "-c", _CHILD, "plan", str(self.mission_path), "--quiet", "--out", str(out),
               f"--goal={g.lon_deg!r},{g.lat_deg!r},{g.depth_m!r}", f"--goal-radius={g.radius_cells}"]
        if job.forecast is not None:
            cmd += [f"--forecast={job.forecast}"]
        if job.time_iso is not None:
            cmd += [f"--time={job.time_iso}"]
        with open(err, "wb") as err_file:
            self._proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err_file)
        self._job, self._started = job, time.monotonic()

