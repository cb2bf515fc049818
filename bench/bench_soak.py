"""Soak benchmark: a 7-day simulated mission at speedup, replanning every 24 h. Not a test.

``lrauv sim`` and ``lrauv exec`` run as processes over UDP on loopback, as in
``make demo``, on an 8-day synthetic forecast. The mission is the demo's with a
goal on the far side of the region, ``on_arrival: hold`` (the executive keeps
deciding, station keeping, once it is there), no mission-time limit within the
week, and ``replanning.period_h: 24``: every vehicle day the executive plans again
in a child process on the forecast step of the vehicle's UTC time and swaps the
new table in. Every ``--sample-s`` wall seconds the script records each process's
resident memory (``/proc/PID/status`` VmRSS) and the log's size on disk.

Afterwards it reads the log (``planner.shore.replay.divelog``/``planner.shore.replay.dive``) and prints,
per vehicle day: decisions per vehicle hour, log bytes, and the executive's RSS at
the end of that day, plus the replans. The figures go into docs/benchmarks.md.

    .venv/bin/python bench/bench_soak.py [--days 7] [--speedup 1000] [--out out/soak]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from planner.shore.replay.dive import load_dive  # noqa: E402
from planner.shore.replay.divelog import open_dive  # noqa: E402
from planner.shore.demo import stop_process, wait_ready  # noqa: E402

LRAUV = [sys.executable, "-m", "planner.cli"]
START = "-118.20,33.62"  # north-west of the region, far from the goal
GOAL = "{lat_deg: 33.38, lon_deg: -117.78, depth_m: 0, radius_cells: 1, on_arrival: hold}"


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def mission_text(forecast: Path, days: int) -> str:
    text = (REPO / "missions" / "demo.yaml").read_text()
    text = text.replace("  synthetic: {seed: 0, hours: 72}\n", f"  file: {forecast}\n")
    text = text.replace("  - {lat_deg: 33.40, lon_deg: -117.80, depth_m: 0, radius_cells: 1, on_arrival: hold}",
                        f"  - {GOAL}")
    text = text.replace("  on_new_forecast: true\n", "  on_new_forecast: true\n  period_h: 24\n")
    text = text.replace("  max_mission_time_h: 72\n", f"  max_mission_time_h: {24 * days + 24}\n")
    assert f"file: {forecast}" in text and "period_h: 24" in text and GOAL in text
    return text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=7)
    ap.add_argument("--speedup", type=float, default=1000.0)
    ap.add_argument("--sample-s", type=float, default=5.0)
    ap.add_argument("--out", type=Path, default=REPO / "out" / "soak")
    args = ap.parse_args()
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    forecast = out / "forecast.nc"
    hours = 24 * (args.days + 1)
    subprocess.run([*LRAUV, "forecast", "synth", str(forecast), "--hours", str(hours)], check=True,
                   stdout=subprocess.DEVNULL)
    mission = out / "soak.yaml"
    mission.write_text(mission_text(forecast.resolve(), args.days))
    table = out / "soak.lrpt"
    subprocess.run([*LRAUV, "plan", str(mission), "--out", str(table)], check=True, stdout=subprocess.DEVNULL)
    log = out / "soak.mcap"
    print(f"machine    {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    print(f"mission    {args.days} days at {args.speedup:g}x, replan every 24 h, forecast {hours} h; log {log}", flush=True)
    sim = subprocess.Popen([*LRAUV, "sim", "--forecast", str(forecast), "--start", START, "--speedup",
                            str(args.speedup), "--listen", "127.0.0.1:0", "--quiet", "--heartbeat-timeout-s", "0"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ex = None
    samples: list[tuple[float, float | None, float | None, int]] = []
    stop = threading.Event()
    try:
        port = wait_ready(sim)
        ex = subprocess.Popen([*LRAUV, "exec", "--table", str(table), "--mission", str(mission), "--link",
                               f"udpout:127.0.0.1:{port}", "--log", str(log), "--max-vehicle-h", str(24 * args.days),
                               "--work-dir", str(out / "work")],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

        def sample() -> None:
            t0 = time.monotonic()
            while not stop.wait(args.sample_s):
                size = log.stat().st_size if log.exists() else 0
                samples.append((time.monotonic() - t0, rss_mb(ex.pid), rss_mb(sim.pid), size))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        t0 = time.monotonic()
        output, _ = ex.communicate()
        wall = time.monotonic() - t0
    finally:
        stop.set()
        stop_process(ex)
        stop_process(sim)
    print(output.strip())
    print(f"wall       {wall:.0f} s for {args.days} vehicle days ({args.days * 86400 / wall:.0f}x)")
    report(log, samples, args.days)
    return 0 if ex is not None and ex.returncode in (0, 1) else 1


def report(log: Path, samples: list[tuple[float, float | None, float | None, int]], days: int) -> None:
    dive = load_dive(open_dive(log))
    tr = dive.track
    t0 = float(tr.time_s[0])
    day = ((tr.time_s - t0) // 86400).astype(int)
    print(f"log        {log.stat().st_size / 1e6:.1f} MB, {open_dive(log).n_messages:,} messages,"
          f" {len(tr):,} decisions")
    print("day  decisions/vehicle-h   log MB at end   exec RSS MB at end   sim RSS MB at end")
    n = len(samples)
    for d in range(days):
        rows = day == d
        hours = max(float(tr.time_s[rows].max() - tr.time_s[rows].min()) / 3600.0, 1e-9) if rows.any() else 0.0
        rate = rows.sum() / hours if hours else float("nan")
        # Samples are in wall time; the run is close to uniform in vehicle time: take the sample
        # at the end of this day's share of the run.
        s = samples[min(n - 1, round((d + 1) * n / days) - 1)] if n else (0.0, None, None, 0)
        print(f"{d + 1:>3}  {rate:19.0f}   {s[3] / 1e6:13.1f}   {s[1] or float('nan'):18.1f}   {s[2] or float('nan'):17.1f}")
    swaps = [p for p in dive.policy if p.get("reason") == "swapped"]
    refused = [p for p in dive.policy if p.get("reason") == "refused"]
    print(f"replans    {len(swaps)} swapped in, {len(refused)} refused: "
          + ", ".join(f"{p['time_s'] / 3600:.1f} h ({p.get('plan_s', '?')} s)" for p in swaps))
    rss = [s[1] for s in samples if s[1] is not None]
    if rss:
        print(f"exec RSS   first {rss[0]:.1f} MB, max {max(rss):.1f} MB, last {rss[-1]:.1f} MB over {len(rss)} samples")


if __name__ == "__main__":
    raise SystemExit(main())
