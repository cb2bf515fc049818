"""The executive's log size per vehicle hour under ArduSub's default telemetry, with and without the raw filter.

A scripted autopilot (tests/support/scripted_autopilot.py) sends ArduSub SITL's default
streams (36 message types, about 91 messages a vehicle second: tests/support/ardusub_streams.py)
over real UDP to a deterministic executive with no table, for ``--minutes`` of vehicle time.
Run 1 keeps every message in the raw log (as before ``executive.raw_log``); run 2 keeps what the
executive reads. Sizes are scaled to an hour. The frames' unused fields are zero, so they compress
better than ArduSub's real ones (its raw log measured 26 MB a vehicle hour on SITL): read the ratio.

    PYTHONPATH=. .venv/bin/python bench/bench_raw_log.py [--minutes 10]
"""

from __future__ import annotations

import argparse
import platform
import sys
import tempfile
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from executive.raw_log import READ_KINDS  # noqa: E402
from tests.support.ardusub_streams import RATES_HZ, frames  # noqa: E402
from tests.support.scripted_autopilot import Stepped  # noqa: E402


def run(minutes: float, *, keep_all: bool, out: Path) -> tuple[int, int]:
    """(log bytes, messages sent) for ``minutes`` of vehicle time."""
    rig = Stepped(None, out)
    if keep_all:
        rig.executive.raw.kinds = READ_KINDS | frozenset(RATES_HZ)
    sent = 0
    try:
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        for n, (_, frame) in enumerate(frames(mav, 10_000, minutes * 60.0)):
            rig.ap.conn.write(frame)
            sent += 1
            if n % 20 == 0:
                rig.pump()
        rig.pump()
    finally:
        rig.close()
    return out.stat().st_size, sent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        for keep_all in (True, False):
            size, sent = run(args.minutes, keep_all=keep_all, out=Path(tmp) / f"log-{keep_all}.mcap")
            per_hour_mb = size * 60.0 / args.minutes / 1e6
            label = "every message logged raw" if keep_all else "messages the executive reads"
            print(f"{label:<28} {sent:,} messages in {args.minutes:g} vehicle min: {size:,} bytes,"
                  f" {per_hour_mb:.1f} MB per vehicle hour")


if __name__ == "__main__":
    main()
