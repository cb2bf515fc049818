"""Benchmark the time-varying physical plan against the stationary one on the demo (docs/benchmarks.md).

Not a test. ``lrauv plan missions/demo-physical.yaml --forecast <SCB issue 0, hourly>`` runs
stationary and with ``--time-varying --horizon-h H`` (a slice per forecast hour), ``--repeat``
times each after one warm-up run (numba's compile cache). It reports the best "plan" (sampling
plus solve, as the command reports it) and "process" (the whole command) of each, their ratio,
the peak RSS, and the two tables' sizes with their upload time over a satellite link of
``--link-bit-s`` (2,400 bit/s by default): as bytes on the wire, and framed as MAVLink FTP writes
(the executive's upload path: 239 data bytes in each 266-byte MAVLink 2 FILE_TRANSFER_PROTOCOL frame).

    .venv/bin/python bench/bench_time_varying.py [--repeat 3] [--horizon-h 72] [--slice-h H] [--forecast F.nc] [--json OUT] [--repo PATH]
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_physical_scale import DEMO, REPO, compile_bytecode, run_plan

FTP_DATA = 239  # bytes of file per FILE_TRANSFER_PROTOCOL message (MAVLink FTP "Payload Format")
FTP_FRAME = 10 + 3 + 251 + 2  # MAVLink 2 header, target network/system/component, payload, checksum


def upload_s(size: int, bit_s: float) -> tuple[float, float]:
    """Seconds to send ``size`` bytes: bare, and as MAVLink FTP writes."""
    return size * 8 / bit_s, math.ceil(size / FTP_DATA) * FTP_FRAME * 8 / bit_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--horizon-h", type=float, default=72.0)
    parser.add_argument("--slice-h", type=float, help="hours between slices (default: every forecast step, hourly)")
    parser.add_argument("--forecast", type=Path, help="default: the SCB synthetic forecast, issue 0, 72 h")
    parser.add_argument("--link-bit-s", type=float, default=2400.0)
    parser.add_argument("--json", type=Path)
    parser.add_argument("--repo", type=Path, default=REPO, help="the checkout to run (default: this one)")
    args = parser.parse_args()
    compile_bytecode(args.repo)
    tmp = Path(tempfile.mkdtemp(prefix="bench-tv-"))
    forecast = args.forecast
    if forecast is None:
        forecast = tmp / "forecast.nc"
        subprocess.run([sys.executable, "-m", "planner.cli", "forecast", "synth", str(forecast), "--issue", "0"],
                       cwd=REPO, check=True, capture_output=True)
    nx, ny = DEMO
    rows = {}
    slices = ("--slice-h", f"{args.slice_h:g}") if args.slice_h else ()
    for name, extra in (("stationary", ()), ("time-varying", ("--time-varying", "--horizon-h", f"{args.horizon_h:g}", *slices))):
        out = tmp / f"{name}.lrpt"
        runs = [run_plan(args.repo, forecast, nx, ny, 1, out, model="physical", extra=extra) for _ in range(args.repeat + 1)]
        best = runs[1:] or runs
        size = out.stat().st_size
        rows[name] = {"plan_s": min(r[0] for r in best), "process_s": min(r[1] for r in best),
                      "peak_rss_mb": max(r[2] for r in best) / 1e6, "table_bytes": size,
                      "upload_s": upload_s(size, args.link_bit_s)}
        print(f"{name:<13} plan {rows[name]['plan_s']:8.2f} s  process {rows[name]['process_s']:8.2f} s  "
              f"peak {rows[name]['peak_rss_mb']:6.0f} MB  table {size:,} bytes, upload {rows[name]['upload_s'][0]:.1f} s "
              f"bare, {rows[name]['upload_s'][1]:.1f} s as MAVLink FTP at {args.link_bit_s:g} bit/s", flush=True)
    st, tv = rows["stationary"], rows["time-varying"]
    print(f"ratio         plan {tv['plan_s'] / st['plan_s']:.1f}x, process {tv['process_s'] / st['process_s']:.1f}x, "
          f"table {tv['table_bytes'] / st['table_bytes']:.1f}x")
    print(f"machine: {platform.machine()}, {platform.python_version()}, best of {args.repeat} after a warm-up")
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, "horizon_h": args.horizon_h, "slice_h": args.slice_h,
                                         "repeat": args.repeat}, indent=1))


if __name__ == "__main__":
    main()
