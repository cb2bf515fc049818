"""Energy of one method against another over the same starts, with how sure the figure is.

``lrauv evaluate`` judges methods by the ratio of their mean energies over the starts both
arrived from (docs/evaluation.md), and several targets turn on a few per cent of it. With a
couple of hundred starts whose energies spread by tens of per cent, a few per cent is within
the noise of which starts were drawn, so each ratio comes with a 95 % interval from a paired
bootstrap over those starts (Efron and Tibshirani, "An Introduction to the Bootstrap", 1993,
ch. 13, the percentile interval): the starts are resampled with replacement, each keeping its
pair of energies, and the excess recomputed. The resampling is seeded, so the same runs always
give the same interval.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.shore.evaluation.runs import RunResult

RESAMPLES = 4000
CONFIDENCE = 0.95
_PICKS = 1 << 20  # start indices drawn at once: 8 MB, and twice that for the energies they pick


@dataclass(frozen=True, kw_only=True)
class EnergyComparison:
    """``excess``: ``method``'s mean energy over ``against``'s, less one (-0.1: a tenth less), on the
    ``starts`` both arrived from, and its ``CONFIDENCE`` interval (``low``, ``high``; NaN with fewer
    than two starts)."""

    method: str
    against: str
    starts: int
    excess: float
    low: float
    high: float


def compare_energy(results: Sequence[RunResult], method: str, against: str, *, resamples: int = RESAMPLES,
                   seed: int = 0) -> EnergyComparison:
    """The comparison of ``method`` with ``against`` over the starts both arrived from."""
    a = {r.start: r.energy_wh for r in results if r.method == method and r.outcome == "arrived"}
    b = {r.start: r.energy_wh for r in results if r.method == against and r.outcome == "arrived"}
    common = sorted(a.keys() & b.keys())
    ea = np.array([a[s] for s in common])
    eb = np.array([b[s] for s in common])
    if not common:
        return EnergyComparison(method=method, against=against, starts=0, excess=math.nan, low=math.nan,
                                high=math.nan)
    excess = float(ea.mean() / eb.mean() - 1.0)
    if len(common) < 2:
        return EnergyComparison(method=method, against=against, starts=1, excess=excess, low=math.nan, high=math.nan)
    rng = np.random.default_rng(seed)
    spread = np.empty(resamples)
    rows = max(1, _PICKS // len(common))  # resamples drawn at a time: memory stays flat in the starts
    for lo in range(0, resamples, rows):
        pick = rng.integers(0, len(common), size=(min(rows, resamples - lo), len(common)))
        spread[lo:lo + pick.shape[0]] = ea[pick].mean(axis=1) / eb[pick].mean(axis=1) - 1.0
    tail = 100.0 * (1.0 - CONFIDENCE) / 2.0
    low, high = np.percentile(spread, [tail, 100.0 - tail])
    return EnergyComparison(method=method, against=against, starts=len(common), excess=excess, low=float(low),
                            high=float(high))


def every_pair(results: Sequence[RunResult], methods: Sequence[str]) -> list[EnergyComparison]:
    """Each method against each one after it in ``methods``, in that order."""
    return [compare_energy(results, m, other) for i, m in enumerate(methods) for other in methods[i + 1:]]
