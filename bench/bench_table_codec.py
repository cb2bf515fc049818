"""Benchmark writing and reading policy tables: bytes, and seconds to write and to read each (docs/benchmarks.md).

Not a test. Each TABLE file is read once, then written (``PolicyTable.to_bytes``, compressed as the
planner writes it) and read back (``PolicyTable.from_bytes``, as the executive reads an upload)
``--repeat`` times; the best of each is reported. ``--repo`` runs another checkout's table code on
the same files, so old and new code are measured the same day on the same plans.

    .venv/bin/python bench/bench_table_codec.py TABLE.lrpt [TABLE.lrpt ...] [--repeat 5] [--repo PATH]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

_MEASURE = """
import json, sys, time
from planner.contract.table import PolicyTable
out = []
for path in sys.argv[2:]:
    table = PolicyTable.load(path)
    write, read = [], []
    for _ in range(int(sys.argv[1])):
        t = time.perf_counter(); data = table.to_bytes(); write.append(time.perf_counter() - t)
        t = time.perf_counter(); PolicyTable.from_bytes(data); read.append(time.perf_counter() - t)
    out.append({"table": path, "slices": table.n_slices, "bytes": len(data), "write_s": min(write), "read_s": min(read)})
print(json.dumps(out))
"""


def measure(repo: Path, tables: list[Path], repeat: int) -> list[dict[str, float | int | str]]:
    env = dict(os.environ, PYTHONPATH=str(repo))
    done = subprocess.run([sys.executable, "-c", _MEASURE, str(repeat), *map(str, tables)], cwd=repo, env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tables", type=Path, nargs="+")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--repo", type=Path, default=REPO, help="the checkout to run (default: this one)")
    args = parser.parse_args()
    print(f"{'table':40s} {'slices':>6s} {'bytes':>9s} {'write s':>8s} {'read s':>8s}")
    for row in measure(args.repo, [t.resolve() for t in args.tables], args.repeat):
        print(f"{Path(str(row['table'])).name:40s} {row['slices']:6d} {row['bytes']:9,d} {row['write_s']:8.3f} {row['read_s']:8.4f}")


if __name__ == "__main__":
    main()
