"""The MCAP log's write cost: ``Recorder.write`` in the caller's thread, a chunk flushed every 100 messages.

Writes ``--messages`` state messages (a payload like the loop's vehicle state, ~300 bytes of
JSON) with ``background=False``, so the figure is the whole cost the writer thread pays per
message: encode, apply into the MCAP writer, compression at each flush, the bytes to the file;
``--repeat`` runs, best and median per message. Before them, a log of ``--chunks`` one-message
chunks (a dive flushing every second): the cost a chunk, its finish (summary and footer), and
the process's peak RSS growth over it.

    PYTHONPATH=. .venv/bin/python bench/bench_log_writer.py [--messages 100000] [--chunks 100000]
"""

from __future__ import annotations

import argparse
import platform
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from executive.recorder import Recorder, Topic  # noqa: E402

PAYLOAD = {"lat_deg": 36.8, "lon_deg": -121.9, "depth_m": 12.5, "heading_deg": 271.0, "speed_m_s": 1.0,
           "battery_pct": 87.5, "phase": "running", "goal_index": 2, "u_m_s": 0.1, "v_m_s": -0.2,
           "alt_m": 30.1, "pitch_deg": 1.0, "roll_deg": 0.5, "mode": "GUIDED", "armed": True}


def per_message_us(n: int, out: Path) -> float:
    with Recorder(out, utc_offset_ns=0, flush_interval_s=1e9) as rec:
        t0 = time.perf_counter()
        for i in range(n):
            rec.write(Topic.STATE, i * 0.01, {**PAYLOAD, "i": i}, publish_time_s=1.0)
            if i % 100 == 99:
                rec.flush()
        return (time.perf_counter() - t0) / n * 1e6


def many_chunks(n: int, out: Path) -> tuple[float, float, float]:
    """(us a chunk, finish s, peak RSS growth MB) for ``n`` one-message chunks."""
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rec = Recorder(out, utc_offset_ns=0, flush_interval_s=1e9)
    t0 = time.perf_counter()
    for i in range(n):
        rec.write(Topic.STATE, float(i), {"i": i}, publish_time_s=1.0)
        rec.flush()
    t1 = time.perf_counter()
    rec.close()
    t2 = time.perf_counter()
    return (t1 - t0) / n * 1e6, t2 - t1, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=100_000)
    ap.add_argument("--chunks", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(f"Python {platform.python_version()}, {platform.machine()}")
    with tempfile.TemporaryDirectory() as tmp:
        # The chunks first: the peak RSS they raise is then theirs.
        chunk_us, finish_s, rss_mb = many_chunks(args.chunks, Path(tmp) / "chunks.mcap")
        print(f"{args.chunks:,} one-message chunks: {chunk_us:.1f} us a chunk, finish {finish_s:.2f} s,"
              f" peak RSS +{rss_mb:.1f} MB")
        runs = [per_message_us(args.messages, Path(tmp) / f"w{k}.mcap") for k in range(args.repeat)]
        print(f"write, {args.messages:,} messages, flush every 100: best {min(runs):.1f} us,"
              f" median {statistics.median(runs):.1f} us a message")


if __name__ == "__main__":
    main()
