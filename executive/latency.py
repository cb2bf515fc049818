"""Decision latency, measured in the running executive (docs/benchmarks.md).

A fixed histogram with 1 us bins (the last bin collects everything slower), so
a week-long mission costs a constant 80 kB and percentiles are exact to 1 us.
"""

from __future__ import annotations

from dataclasses import dataclass, field

_BINS = 10_000  # 0 .. 9.999 ms in 1 us steps; slower samples land in the last bin


@dataclass(slots=True)
class LatencyHistogram:
    counts: list[int] = field(default_factory=lambda: [0] * _BINS)
    n: int = 0
    max_us: float = 0.0

    def add(self, seconds: float) -> None:
        us = seconds * 1e6
        self.counts[min(int(us), _BINS - 1)] += 1
        self.n += 1
        if us > self.max_us:
            self.max_us = us

    def percentile_us(self, q: float) -> float | None:
        """Upper edge of the bin holding the ``q``-th percentile (0 < q <= 100); None when empty."""
        if self.n == 0:
            return None
        rank = max(1, round(q / 100.0 * self.n))
        seen = 0
        for us, count in enumerate(self.counts):
            seen += count
            if seen >= rank:
                return float(us + 1)
        return float(_BINS)
