"""Benchmarks of the closed loop (decision latency and throughput); figures go to docs/benchmarks.md.

1. Decision latency per telemetry message: parse one GLOBAL_POSITION_INT or
   ATTITUDE datagram, update the vehicle state, run the helm, encode and send the
   command and write everything to the MCAP log, in the real ``Executive``.
2. Executive CPU at 10 Hz telemetry: ``lrauv sim --speedup 1`` and ``lrauv exec
   --telemetry-hz 10`` as processes over UDP; the executive's user + system CPU
   time from ``os.wait4`` over its wall time.
3. The simulator's achieved speedup on a 24-hour mission with the executive
   logging to MCAP: both as processes, the simulator asked for 1000x, 2000x and
   flat out (1e6x), from the demo's start, so the run shows whether the loop
   still reaches the goal at that speed.

Usage: ``python bench/bench_exec.py [--quick] [--skip-cpu] [--skip-speedup]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from executive import mavlink_bridge as bridge  # noqa: E402
from executive.helm import HelmConfig  # noqa: E402
from executive.loop import ExecConfig, Executive  # noqa: E402
from planner.contract.modes import SubMode  # noqa: E402
from planner.contract.table import PolicyTable  # noqa: E402
from vehicle_sim.cli import wait_ready  # noqa: E402
from planner.shore.demo import stop_process  # noqa: E402

LRAUV = [sys.executable, "-m", "planner.cli"]
DEMO_START = "-117.96,33.34"  # as in the Makefile


def _prepare(work: Path) -> tuple[Path, Path, Path]:
    """Planning forecast (issue 0), truth forecast and the demo mission's table."""
    fc, truth, table = work / "forecast.nc", work / "truth.nc", work / "demo.lrpt"
    subprocess.run([*LRAUV, "forecast", "synth", str(fc), "--issue", "0"], check=True, capture_output=True)
    subprocess.run([*LRAUV, "forecast", "synth", str(truth)], check=True, capture_output=True)
    subprocess.run([*LRAUV, "plan", str(REPO / "missions" / "demo.yaml"), "--forecast", str(fc), "--out", str(table),
                    "--quiet"], check=True, capture_output=True)
    return fc, truth, table


def bench_latency(table_path: Path, work: Path, n: int) -> dict[str, float]:
    """Per-message cost of the executive's full path, MCAP on, over a real UDP socket."""
    table = PolicyTable.load(table_path)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    port = sink.getsockname()[1]
    ex = Executive(ExecConfig(link=f"udpout:127.0.0.1:{port}", log_path=work / "latency.mcap", helm=HelmConfig()), table)
    ap = bridge.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)

    def frame(msg) -> bytes:  # type: ignore[no-untyped-def]
        return msg.pack(ap)

    hb = frame(ap.heartbeat_encode(12, 3, 1 | 128, int(SubMode.GUIDED), 4))
    # The EKF vouches for an absolute position: the executive arms and follows the policy only then
    # (ArduSub's EKF_STATUS_REPORT, flag EKF_POS_HORIZ_ABS).
    ekf_flags = (bridge.mavlink.EKF_ATTITUDE | bridge.mavlink.EKF_VELOCITY_HORIZ | bridge.mavlink.EKF_POS_HORIZ_REL
                 | bridge.mavlink.EKF_POS_HORIZ_ABS | bridge.mavlink.EKF_POS_VERT_ABS)
    ekf = frame(ap.ekf_status_report_encode(ekf_flags, 0.1, 0.1, 0.1, 0.1, 0.1))
    # A straight run across the grid at 1 m/s, heading east, 10 Hz, alternating position and attitude.
    lat = table.lat0_deg + 0.5 * table.ny * table.dlat_deg
    frames = []
    t_ms = 100_000
    for step in range(n):
        t_ms += 100
        lon = table.lon0_deg + (step * 0.1) / (111_320.0 * 0.83)
        lon = table.lon0_deg + (lon - table.lon0_deg) % (table.nx * table.dlon_deg)
        if step % 2 == 0:
            frames.append(frame(ap.global_position_int_encode(t_ms, round(lat * 1e7), round(lon * 1e7), -2000, -2000,
                                                              0, 0, 0, 9000)))
        else:
            frames.append(frame(ap.attitude_encode(t_ms, 0.0, 0.0, 1.5708, 0.0, 0.0, 0.0)))
    ex._heartbeat(time.monotonic())  # binds the executive's socket
    ex_addr = ("127.0.0.1", ex.conn.port.getsockname()[1])
    for data in [hb] * 3 + [ekf] + frames:
        sink.sendto(data, ex_addr)  # a real datagram through the loopback, as the autopilot sends it
        ex._drain(time.monotonic())
        if ex._counts["in"] % 2000 == 0:
            sink.setblocking(False)
            while True:  # keep the sink's buffer from filling
                try:
                    sink.recv(65536)
                except BlockingIOError:
                    break
    d, m = ex.decision_latency, ex.message_cost
    result = {"messages": d.n, "decisions": ex._counts["decisions"], "median_us": d.percentile_us(50),
              "p99_us": d.percentile_us(99), "max_us": d.max_us, "with_log_median_us": m.percentile_us(50),
              "with_log_p99_us": m.percentile_us(99)}
    ex.close()
    sink.close()
    return result


def _start_sim(truth: Path, work: Path, *extra: str) -> tuple[subprocess.Popen[str], int]:
    sim = subprocess.Popen([*LRAUV, "sim", "--forecast", str(truth), "--start", DEMO_START, "--listen", "127.0.0.1:0",
                            "--quiet", *extra], stdout=subprocess.PIPE, text=True)
    return sim, wait_ready(sim)


def _wait4(proc: subprocess.Popen[str]) -> tuple[int, float]:
    """Wait for a child and return (status, user + system CPU seconds)."""
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, usage.ru_utime + usage.ru_stime


def bench_cpu(table: Path, truth: Path, work: Path, seconds: float) -> dict[str, float]:
    sim, port = _start_sim(truth, work, "--speedup", "1", "--position-delay-s", "5")
    try:
        t0 = time.monotonic()
        ex = subprocess.Popen([*LRAUV, "exec", "--table", str(table), "--link", f"udpout:127.0.0.1:{port}",
                               "--log", str(work / "cpu.mcap"), "--telemetry-hz", "10", "--max-wall-s", str(seconds),
                               "--quiet"], text=True)
        _, cpu_s = _wait4(ex)
        wall = time.monotonic() - t0
    finally:
        stop_process(sim)
    return {"wall_s": wall, "cpu_s": cpu_s, "cpu_pct": 100.0 * cpu_s / wall}


def bench_speedup(table: Path, truth: Path, work: Path, hours: float, speedup: float) -> dict[str, float]:
    duration = hours * 3600.0
    sim, port = _start_sim(truth, work, "--speedup", str(speedup), "--duration-s", str(duration))
    t0 = time.monotonic()  # simulated time starts with the ready line: process start-up is not counted
    ex = subprocess.Popen([*LRAUV, "exec", "--table", str(table), "--link", f"udpout:127.0.0.1:{port}",
                           "--mission", str(REPO / "missions" / "demo.yaml"), "--log", str(work / "speedup.mcap"),
                           "--max-vehicle-h", str(hours)], stdout=subprocess.PIPE, text=True)
    try:
        sim.wait(timeout=3600)
        sim_wall = time.monotonic() - t0
        out, _ = ex.communicate(timeout=120)
    finally:
        for p in (ex, sim):
            stop_process(p)
    size = (work / "speedup.mcap").stat().st_size
    return {"sim_hours": hours, "asked": speedup, "wall_s": sim_wall, "achieved": duration / sim_wall,
            "log_mib": size / 2**20, "exec_output": out.strip()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller runs (a smoke test of the script)")
    ap.add_argument("--skip-cpu", action="store_true")
    ap.add_argument("--skip-speedup", action="store_true")
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        _, truth, table = _prepare(work)
        lat = bench_latency(table, work, 2_000 if args.quick else 50_000)
        print(f"decision latency: {lat['messages']:,} messages ({lat['decisions']:,} decisions), median"
              f" {lat['median_us']:.0f} us, p99 {lat['p99_us']:.0f} us, max {lat['max_us']:.0f} us;"
              f" including the MCAP writes median {lat['with_log_median_us']:.0f} us, p99 {lat['with_log_p99_us']:.0f} us")
        if not args.skip_cpu:
            cpu = bench_cpu(table, truth, work, 5.0 if args.quick else 60.0)
            print(f"executive CPU at 10 Hz telemetry: {cpu['cpu_s']:.2f} s CPU in {cpu['wall_s']:.1f} s wall"
                  f" = {cpu['cpu_pct']:.1f} % of one core")
        if not args.skip_speedup:
            for asked in ((1000.0,) if args.quick else (1000.0, 2000.0, 1e6)):
                sp = bench_speedup(table, truth, work, 1.0 if args.quick else 24.0, asked)
                print(f"simulator speedup: {sp['sim_hours']:g} h mission, asked {sp['asked']:g}x: {sp['wall_s']:.1f} s wall"
                      f" = {sp['achieved']:.0f}x real time; MCAP log {sp['log_mib']:.1f} MiB")
                print("  " + sp["exec_output"].replace("\n", "\n  "))
    return 0


if __name__ == "__main__":
    sys.exit(main())
