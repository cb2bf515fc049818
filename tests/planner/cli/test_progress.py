"""Progress on long work: the library reports growing counts to a meter, the command line draws bars only on a terminal."""

from __future__ import annotations

import fcntl
import os
import pty
import select
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from tests.support import REPO

LRAUV = str(Path(sys.executable).parent / "lrauv")
TINY = ["--bbox=-118.26,33.30,-117.70,33.70", "--nx=8", "--ny=6", "--depths=0,10", "--goal=-117.90,33.50,0",
        "--goal-radius=1"]


class Recorder:
    """A ``Progress`` that keeps every call."""

    def __init__(self) -> None:
        self.updates: list[tuple[str, float, float, str]] = []
        self.notes: list[str] = []

    def update(self, task: str, done: float, total: float, *, unit: str = "", detail: str = "") -> None:
        self.updates.append((task, done, total, detail))

    def note(self, text: str) -> None:
        self.notes.append(text)

    def counts(self, task: str) -> list[tuple[float, float]]:
        return [(d, t) for name, d, t, _ in self.updates if name == task]


def assert_climbs_to_total(counts: list[tuple[float, float]]) -> None:
    assert len(counts) >= 2, counts
    done = [d for d, _ in counts]
    assert done == sorted(done), counts
    assert {t for _, t in counts} == {counts[-1][1]} and done[-1] == counts[-1][1] > 0, counts


@pytest.mark.parametrize("model", ["paper", "physical"])
def test_a_small_plan_reports_sampling_and_solving_up_to_their_totals(synthetic_forecast, model):
    from tests.support.helpers import DEMO_MISSION
    from planner.contract.mission import load_mission
    from planner.pipeline import PlanRequest, make_plan
    from dataclasses import replace

    m = load_mission(DEMO_MISSION)
    settings = replace(m.settings, model=model, criterion="robust")
    request = PlanRequest(forecast_path=synthetic_forecast, goal=m.goals[0].goal, depths_m=(0.0, 10.0),
                          settings=settings, bbox=m.region.bbox, nx=10, ny=8, time_index=0)
    meter = Recorder()
    make_plan(request, meter=meter)
    assert_climbs_to_total(meter.counts("solving"))
    if model == "physical":
        assert_climbs_to_total(meter.counts("sampling"))


def test_a_plan_off_a_terminal_draws_no_bar(synthetic_forecast, tmp_path):
    proc = subprocess.run([LRAUV, "plan", f"--forecast={synthetic_forecast}", *TINY, f"--out={tmp_path / 't.lrpt'}"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "planning on" in proc.stderr  # the notes still come
    assert "%|" not in proc.stderr and "\r" not in proc.stderr and "\u2588" not in proc.stderr, proc.stderr


def _under_a_terminal(args: list[str]) -> tuple[int, str]:
    """Run ``args`` with stdin, stdout and stderr on a pseudo-terminal; its exit status and all it wrote."""
    main, child = pty.openpty()
    # A terminal has a size (a bare pseudo-terminal's is 0 x 0, on which tqdm draws nothing): 24 rows of 100.
    fcntl.ioctl(child, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    proc = subprocess.Popen(args, stdin=child, stdout=child, stderr=child, close_fds=True, cwd=REPO)
    os.close(child)
    chunks = []
    while True:
        ready, _, _ = select.select([main], [], [], 120.0)
        if not ready:
            proc.kill()
            break
        try:
            data = os.read(main, 4096)
        except OSError:  # the child closed the terminal (Linux: EIO)
            break
        if not data:
            break
        chunks.append(data)
    os.close(main)
    return proc.wait(timeout=30), b"".join(chunks).decode(errors="replace")


@pytest.mark.parametrize("quiet", [False, True])
def test_a_plan_on_a_terminal_shows_its_bars_unless_quiet(synthetic_forecast, tmp_path, quiet):
    status, text = _under_a_terminal([LRAUV, "plan", f"--forecast={synthetic_forecast}", *TINY, "--model=physical",
                                      f"--out={tmp_path / 't.lrpt'}", *(["--quiet"] if quiet else [])])
    assert status == 0, text
    if quiet:
        assert "%|" not in text and "sampling:" not in text, text
    else:
        assert "sampling: 100%|" in text and "solving: 100%|" in text, text
