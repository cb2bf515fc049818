"""Benchmark the executive's replan latency: a new forecast file in the watched directory -> new table in use.

Not a test. The real ``Executive`` runs in a thread against the simulated vehicle
(``vehicle_sim.endpoint.Simulator``, another thread, real UDP on loopback, 200x); a forecast
issue is moved (``os.replace``) into its watched directory and the script times, from that
moment:

- detection: until the executive's ``ForecastWatcher`` reports the file (it polls once per
  wall second and takes a file once its size and mtime held still for one poll: 1 to 2 s by
  design);
- ``plan_s``: the child process ``lrauv plan ...`` alone (the executive's figure);
- ``latency_s``: from the watcher's report to the new table ready (the executive's figure);
- table check: the executive reading and checking the new table (CRC, shape, goal, grid) and
  queueing it, on the loop thread;
- swap wait: from the table ready to the swap at the next decision (the table check included);
- end to end: until the executive's table in use changes (polled every 5 ms from here).

And, to show the loop kept running: the decisions between the replace and the swap, their
rate, and the longest wall time between two helm steps (``Executive._tick``), against the same
loop for 2 s with no replan under way. The times inside the executive come from wrapping its
own methods on the instance (watcher poll, planner result, swap, tick); nothing else changes.

Two sizes: the demo mission (29 x 21 x 4 layers x 8 headings = 19,488 states) and the same
bbox at 100 x 100 (320,000 states, a temporary copy of the mission with nx/ny changed). Each
size gets its own executive and vehicle; the initial table is planned in-process on the
truth forecast. The vehicle boots 19 h into the forecast; forecast issues 0..3 (24 h each,
issued at 0, 6, 12, 18 h) all cover that time; each replan takes the next issue in turn (a new
file name every time), so each new table differs from the one it replaces.

"cold": one extra replan, before the others, whose planner child gets an empty numba cache
(``NUMBA_CACHE_DIR`` pointed at a new folder), so it compiles the solver; the other runs load
the compiled code from the project's cache (``planner/__pycache__``), whose state is printed.

    .venv/bin/python bench/bench_replan.py [--repeat 5] [--no-cold] [--sizes 19488,320000]
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shutil
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from executive import goal_tables
from executive.loop import ExecConfig, Executive  # noqa: E402
from executive.state import Phase  # noqa: E402
from planner.contract.mission import load_mission  # noqa: E402
from planner.pipeline import PlanRequest, make_plan  # noqa: E402
from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic  # noqa: E402
from vehicle_sim.endpoint import SimConfig, Simulator  # noqa: E402
from vehicle_sim.world import World  # noqa: E402

DEMO = REPO / "missions" / "demo.yaml"
SIZES = {19_488: (29, 21), 320_000: (100, 100)}  # states -> (nx, ny), 4 layers x 8 headings
SPEEDUP = 200.0
START_OFFSET_S = 19.0 * 3600  # vehicle boots 19 h into the truth forecast
TRUTH_HOURS = 30
ISSUES = (0, 1, 2, 3)  # issued at 0, 6, 12, 18 h; 24 h each: all cover 19 h (+ the run)
CELLS_WEST = 3  # start this many (paper-grid) cells west of the goal
POLL_S = 0.005
SWAP_TIMEOUT_S = 90.0
BASELINE_S = 2.0  # wall seconds of the loop with no replan, for the decision rate and gaps


def mission_for(nx: int, ny: int, folder: Path) -> Path:
    """The demo mission, or a copy of it with the region's nx/ny changed."""
    mission = load_mission(DEMO)
    if (mission.region.nx, mission.region.ny) == (nx, ny):
        return DEMO
    text = DEMO.read_text(encoding="utf-8")
    text = re.sub(r"(?m)^(\s*)nx:\s*\d+", rf"\g<1>nx: {nx}", text, count=1)
    text = re.sub(r"(?m)^(\s*)ny:\s*\d+", rf"\g<1>ny: {ny}", text, count=1)
    path = folder / f"demo-{nx}x{ny}.yaml"
    path.write_text(text, encoding="utf-8")
    copy = load_mission(path)
    assert (copy.region.nx, copy.region.ny) == (nx, ny), "the mission copy did not take the new grid"
    return path


def initial_table(mission_path: Path, truth: Path):  # type: ignore[no-untyped-def]
    mission = load_mission(mission_path)
    request = PlanRequest(forecast_path=truth, goal=mission.goals[0].goal, depths_m=mission.region.depths_m,
                          settings=mission.settings, bbox=mission.region.bbox, nx=mission.region.nx,
                          ny=mission.region.ny, time_index=0)
    return mission, make_plan(request).table


def nbi_count(folder: Path) -> int:
    return sum(1 for _ in folder.glob("**/*.nbi")) if folder.exists() else 0


class Probe:
    """Times taken inside the running executive by wrapping its own methods (instance attributes only)."""

    def __init__(self, ex: Executive) -> None:
        self.seen: dict[str, float] = {}  # file name -> monotonic time the watcher reported it
        self.ready: list[tuple[float, str | None]] = []  # (monotonic, error) when a planner result came in
        self.swapped: list[tuple[float, int]] = []  # (monotonic, decisions) at each swap
        self.refused: list[str] = []
        self.handling_s: list[float] = []  # time in _replan_done (check the table, queue it): on the loop thread
        self.last_tick = 0.0
        self.max_gap_s = 0.0  # longest wall time between two decisions (helm ticks) since reset_gap()
        self.max_gap_at = 0.0  # when that gap ended
        assert ex.watcher is not None
        watcher_poll, replan_done, swap, refuse = ex.watcher.poll, ex._replan_done, ex._swap, ex._refuse
        tick = ex._tick

        def poll():  # type: ignore[no-untyped-def]
            found = watcher_poll()
            t = time.monotonic()
            for p in found:
                self.seen[p.name] = t
            return found

        def done(now_s, result):  # type: ignore[no-untyped-def]
            t = time.monotonic()
            self.ready.append((t, result.error))
            try:
                return replan_done(now_s, result)
            finally:
                self.handling_s.append(time.monotonic() - t)

        def tick_(now_s, *args, **kwargs):  # type: ignore[no-untyped-def]
            t = time.monotonic()
            if self.last_tick and t - self.last_tick > self.max_gap_s:
                self.max_gap_s, self.max_gap_at = t - self.last_tick, t
            self.last_tick = t
            return tick(now_s, *args, **kwargs)

        def swap_(now_s):  # type: ignore[no-untyped-def]
            self.swapped.append((time.monotonic(), ex._counts["decisions"]))
            return swap(now_s)

        def refuse_(now_s, what, reason, *args, **kwargs):  # type: ignore[no-untyped-def]
            self.refused.append(f"{what}: {reason}")
            return refuse(now_s, what, reason, *args, **kwargs)

        ex.watcher.poll = poll  # type: ignore[method-assign]
        ex._replan_done = done  # type: ignore[method-assign]
        ex._swap = swap_  # type: ignore[method-assign]
        ex._refuse = refuse_  # type: ignore[method-assign]
        ex._tick = tick_  # type: ignore[method-assign]

    def reset_gap(self) -> None:
        self.max_gap_s = 0.0
        self.last_tick = time.monotonic()


def wait(predicate, timeout_s: float, step_s: float = 0.02) -> bool:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step_s)
    return False


def run_size(states: int, nx: int, ny: int, work: Path, truth: Path, issue_files: dict[int, Path], repeat: int,
             cold: bool) -> list[dict]:
    folder = work / f"s{states}"
    folder.mkdir()
    mission_path = mission_for(nx, ny, folder)
    t0 = time.perf_counter()
    mission, table = initial_table(mission_path, truth)
    init_s = time.perf_counter() - t0
    n_states = table.nx * table.ny * len(mission.region.depths_m) * 8
    assert n_states == states, (n_states, states)
    # Start CELLS_WEST cells of the paper grid west of the goal: the same place at both sizes.
    paper = load_mission(DEMO).region
    dlon_paper = (paper.bbox.east_deg - paper.bbox.west_deg) / (paper.nx - 1)  # centres on the edges
    start = (table.goal_lon_deg - CELLS_WEST * dlon_paper, table.goal_lat_deg)
    assert table.lookup(start[1], start[0], 0.0, 0.0).reason == "ok", "the start is not in the table"
    inbox, staging = folder / "inbox", folder / "staging"
    inbox.mkdir()
    staging.mkdir()

    sim = Simulator(World.load(truth), SimConfig(start_lon_deg=start[0], start_lat_deg=start[1], port=0,
                                                 speedup=SPEEDUP, seed=3, start_offset_s=START_OFFSET_S))
    sim_stop, ex_stop = threading.Event(), threading.Event()
    sim_thread = threading.Thread(target=sim.run, kwargs={"stop_event": sim_stop}, daemon=True)
    config = ExecConfig(link=f"udpout:127.0.0.1:{sim.port}", log_path=folder / "exec.mcap", gcs_link=None,
                        mission_path=mission_path, watch_dir=inbox, work_dir=folder / "work", max_wall_s=170.0)
    ex = Executive(config, goal_tables.MissionPlan(goals=mission.goals, tables=(table,)))
    probe = Probe(ex)
    ex_thread = threading.Thread(target=ex.run, args=(ex_stop,), daemon=True)
    rows: list[dict] = []
    sim_thread.start()
    ex_thread.start()
    try:
        ok = wait(lambda: ex.helm.phase is Phase.RUNNING and ex._counts["decisions"] > 5
                  and ex._unix_offset_s is not None, 30.0)
        assert ok, "the executive did not start following the plan"
        # Baseline: the loop with no replan under way.
        dec0, probe_t0 = ex._counts["decisions"], time.monotonic()
        probe.reset_gap()
        time.sleep(BASELINE_S)
        baseline = {"rate": (ex._counts["decisions"] - dec0) / (time.monotonic() - probe_t0), "gap": probe.max_gap_s}
        plan_runs = [("cold", ISSUES[k % len(ISSUES)]) for k in range(1 if cold else 0)]
        plan_runs += [("warm", ISSUES[(k + len(plan_runs)) % len(ISSUES)]) for k in range(repeat)]
        for k, (kind, issue) in enumerate(plan_runs):
            if kind == "cold":
                os.environ["NUMBA_CACHE_DIR"] = str(folder / "numba-empty")  # read by the planner child only
            else:
                os.environ.pop("NUMBA_CACHE_DIR", None)
            name = f"run{k}-issue{issue}.nc"
            staged = staging / name
            shutil.copyfile(issue_files[issue], staged)
            old = ex.table
            n_swaps, n_ready = len(probe.swapped), len(probe.ready)
            dec0 = ex._counts["decisions"]
            vt0 = ex.vehicle.time_s
            probe.reset_gap()
            t_replace = time.monotonic()
            os.replace(staged, inbox / name)
            changed = wait(lambda old=old, n=n_ready: (ex.table is not old
                                                       or (len(probe.ready) > n and probe.ready[-1][1])),
                           SWAP_TIMEOUT_S, POLL_S)
            t_use = time.monotonic()
            max_gap, max_gap_at = probe.max_gap_s, probe.max_gap_at
            os.environ.pop("NUMBA_CACHE_DIR", None)
            if not changed or ex.table is old:
                err = probe.ready[-1][1] if len(probe.ready) > n_ready else "timed out"
                raise RuntimeError(f"{name}: no new table in use ({err}; refusals: {probe.refused})")
            if not wait(lambda n=n_swaps: len(ex.swaps) > n, 2.0, 0.001):
                raise RuntimeError(f"{name}: the new table is in use but its swap record is missing")
            swap = ex.swaps[-1]
            t_seen = probe.seen[name]
            t_ready = probe.ready[n_ready][0]
            t_swap, dec_swap = probe.swapped[n_swaps]
            rows.append({
                "states": states, "run": k, "kind": kind, "issue": issue, "source": swap["source"],
                "detect_s": t_seen - t_replace, "plan_s": swap["plan_s"], "latency_s": swap["latency_s"],
                "swap_wait_s": t_swap - t_ready, "e2e_s": t_use - t_replace, "decisions": dec_swap - dec0,
                "vehicle_s": (ex.vehicle.time_s or 0.0) - (vt0 or 0.0), "phase": ex.helm.phase.value,
                "crc_changed": swap["table_crc32"] != swap["previous"]["table_crc32"],
                "handling_ms": 1000 * probe.handling_s[n_ready], "max_gap_ms": 1000 * max_gap,
                "gap_at_s": max_gap_at - t_seen,
                "rate": (dec_swap - dec0) / (t_swap - t_replace),
            })
            if kind == "cold":
                rows[-1]["cold_cache_files"] = nbi_count(folder / "numba-empty")
            time.sleep(0.3)
    finally:
        os.environ.pop("NUMBA_CACHE_DIR", None)
        ex_stop.set()
        ex_thread.join(timeout=15)
        sim_stop.set()
        sim_thread.join(timeout=15)
        sim.close()
        assert not ex_thread.is_alive() and not sim_thread.is_alive(), "a thread did not stop"
    print(f"  {states:,} states ({nx} x {ny} x 4 x 8): initial plan in-process {init_s:.2f} s; table"
          f" {len(table.to_bytes()):,} bytes; {ex._counts['decisions']} decisions in the run; refusals:"
          f" {len(probe.refused)}; no replan ({BASELINE_S:g} s): {baseline['rate']:.0f} decisions/s,"
          f" longest gap {1000 * baseline['gap']:.1f} ms", flush=True)
    for r in rows:
        if "cold_cache_files" in r:
            print(f"  cold run: the empty numba cache held {r['cold_cache_files']} index files after it"
                  " (the child compiled and cached the solver)")
    return rows


def fmt_range(values: list[float], digits: int = 2) -> str:
    if len(values) == 1:
        return f"{values[0]:.{digits}f}"
    return f"{statistics.median(values):.{digits}f} ({min(values):.{digits}f} to {max(values):.{digits}f})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="19488,320000", help="states, comma-separated: 19488 and/or 320000")
    ap.add_argument("--repeat", type=int, default=5, help="warm replans per size (default 5)")
    ap.add_argument("--no-cold", action="store_true", help="skip the replan with an empty numba cache")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    import numba
    import numpy

    cache = REPO / "planner" / "__pycache__"
    print(f"machine: {platform.machine()} {platform.system()}, {os.cpu_count()} CPUs,"
          f" Python {platform.python_version()}, numpy {numpy.__version__}, numba {numba.__version__}")
    print(f"numba cache {cache.relative_to(REPO)}: {nbi_count(cache)} index files before the run"
          f"{' (empty: the first warm run compiles into it)' if nbi_count(cache) == 0 else ''}")
    t_all = time.perf_counter()
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench-replan-") as tmp:
        work = Path(tmp)
        truth = write_synthetic(work / "truth.nc", SyntheticSettings(seed=0, hours=TRUTH_HOURS))
        issue_files = {n: write_synthetic(work / f"issue{n}.nc", SyntheticSettings(seed=0, hours=24), issue_number=n)
                       for n in ISSUES}
        for i, states in enumerate(sizes):
            nx, ny = SIZES[states]
            rows += run_size(states, nx, ny, work, truth, issue_files, args.repeat, cold=not args.no_cold and i == 0)
    print(f"numba cache after: {nbi_count(cache)} index files; total {time.perf_counter() - t_all:.0f} s wall")
    print()
    print("| states | run | cache | issue | detect (s) | plan_s (s) | latency_s (s) | table check (ms)"
          " | swap wait (ms) | end to end (s) | decisions during | decisions/s | longest gap (ms)"
          " | gap ended (s after seen) | vehicle s | phase |")
    print("|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for r in rows:
        print(f"| {r['states']:,} | {r['run']} | {r['kind']} | {r['issue']} | {r['detect_s']:.2f} | {r['plan_s']:.2f}"
              f" | {r['latency_s']:.2f} | {r['handling_ms']:.1f} | {1000 * r['swap_wait_s']:.0f} | {r['e2e_s']:.2f}"
              f" | {r['decisions']} | {r['rate']:.0f} | {r['max_gap_ms']:.1f}"
              f" | {r['gap_at_s']:+.3f} | {r['vehicle_s']:.0f} | {r['phase']} |")
    print()
    print("median (range) per size; cold = the replan whose planner child had an empty numba cache:")
    print("| states | cache | runs | detect (s) | plan_s (s) | latency_s (s) | table check (ms) | end to end (s)"
          " | decisions during | longest gap (ms) |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for states in sizes:
        for kind in ("cold", "warm"):
            sel = [r for r in rows if r["states"] == states and r["kind"] == kind]
            if not sel:
                continue
            print(f"| {states:,} | {kind} | {len(sel)} | {fmt_range([r['detect_s'] for r in sel])}"
                  f" | {fmt_range([r['plan_s'] for r in sel])} | {fmt_range([r['latency_s'] for r in sel])}"
                  f" | {fmt_range([r['handling_ms'] for r in sel], 1)} | {fmt_range([r['e2e_s'] for r in sel])}"
                  f" | {fmt_range([r['decisions'] for r in sel], 0)}"
                  f" | {fmt_range([r['max_gap_ms'] for r in sel], 1)} |")
    unchanged = [r for r in rows if not r["crc_changed"]]
    if unchanged:
        print(f"note: {len(unchanged)} swap(s) brought a table with the same CRC as the one it replaced")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
