"""How late the current the vehicle meets runs against its forecast: a time shift fitted onboard.

A time-varying plan commits to the forecast's timing of the tide. Where the real tide runs an
hour late, the plan crosses a channel's neck against the flood it expected to ride
(docs/evaluation.md measured that an hour's timing error costs more than a fifth less tidal
amplitude). The vehicle measures the current it meets: over ground minus through the water.
Fitting that record to the forecast's own current, shifted in time, says how far to shift the
UTC time at which the plan's slices are looked up.

The reference is a time-varying table's per-slice current (``PolicyTable.slice_current_m_s``: the
mean over each region's water cells, a region being a layer or a block of one; each observation is
compared with its own region's). Observations are at most one a minute, each the median of
that minute's measurements (at least ``MIN_BIN_SAMPLES``), so one bad measurement never decides; a
fit over the last ``WINDOW_S`` chooses the shift ``tau`` (and a scale ``a``, the vehicle's place against the
region's mean) minimising ``sum |obs(t) - a ref(t + tau)|^2``. Each shift is judged by the share of
the observations' variance it explains (R^2) over the observations whose shifted time lies within
the slices; the best is accepted when its observations span at least ``MIN_SPAN_S`` and it
explains ``MIN_R2`` of them, with a scale within ``SCALE_RANGE`` and its shift inside the search
range, not on its edge. Until then the plan is looked up at the vehicle's own UTC time (``advance`` says when an accepted shift is withdrawn).

Pure: ``observe``, ``fit`` and ``advance`` take and return frozen values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import median

import numpy as np
from numpy.typing import NDArray

MAX_SHIFT_S = 3.0 * 3600.0  # a quarter of an M2 period each way: a larger error is another tide, not a late one
STEP_S = 300.0  # shifts tried 5 minutes apart
WINDOW_S = 6.0 * 3600.0  # half a semi-diurnal tide of record
MIN_SPAN_S = 2.0 * 3600.0  # a sixth of a semi-diurnal tide: its timing shows, with the plan still hours to run
MIN_R2 = 0.8
BIN_S = 60.0
MIN_BIN_SAMPLES = 3  # a minute of fewer measurements is dropped: its median would be one sample's, or two's mean
SCALE_RANGE = (0.25, 4.0)  # the current met against the region's mean: beyond, the fit explains noise, not the tide
MAX_CURRENT_M_S = 5.0  # a measurement above this is not an ocean current (the fastest tidal races are near 5 m/s)
REFIT_S = 600.0  # the shift is fitted again every 10 minutes of record


@dataclass(frozen=True, slots=True)
class Observation:
    """The current met over one minute (the median of its measurements), at UTC ``unix_s`` in reference region
    ``region`` (``PolicyTable.current_region``)."""

    unix_s: float
    region: int
    east_m_s: float
    north_m_s: float


@dataclass(frozen=True, slots=True)
class CurrentRecord:
    """The last ``WINDOW_S`` of observations, and the measurements of the minute being filled."""

    observations: tuple[Observation, ...] = ()
    bin_start_s: float | None = None
    bin_last_s: float | None = None
    bin_region: int = -1
    bin_east: tuple[float, ...] = ()
    bin_north: tuple[float, ...] = ()


@dataclass(frozen=True, slots=True)
class TimingFit:
    """The fitted shift (s: look the plan up at UTC + ``shift_s``), scale, share of variance explained,
    and the record it came from; ``accepted`` says whether it may be used."""

    shift_s: float
    scale: float
    r2: float
    span_s: float  # of the observations this shift was fitted over
    observations: int
    accepted: bool
    record_span_s: float = 0.0  # of the whole record

    def describe(self) -> str:
        late = "behind" if self.shift_s < 0 else "ahead of"
        best = "" if self.accepted else "at best "
        return (f"the current met runs {best}{abs(self.shift_s) / 60:.0f} min {late} the forecast (scale "
                f"{self.scale:.2f}, r2 {self.r2:.2f} over {self.span_s / 3600:.1f} h, {self.observations} minutes)")


def observe(record: CurrentRecord, unix_s: float, region: int, east_m_s: float, north_m_s: float) -> CurrentRecord:
    """``record`` with one measurement of the current added (a non-finite or impossible one is dropped)."""
    if not (math.isfinite(unix_s) and math.isfinite(east_m_s) and math.isfinite(north_m_s)):
        return record
    if math.hypot(east_m_s, north_m_s) > MAX_CURRENT_M_S:
        return record
    if record.bin_start_s is not None and region == record.bin_region and 0.0 <= unix_s - record.bin_start_s < BIN_S:
        return CurrentRecord(record.observations, record.bin_start_s, unix_s, region, record.bin_east + (east_m_s,),
                             record.bin_north + (north_m_s,))
    observations = record.observations
    if len(record.bin_east) >= MIN_BIN_SAMPLES and record.bin_start_s is not None and record.bin_last_s is not None:
        # Stamped at the middle of its own measurements: a minute cut short (a change of region) keeps its time.
        observations = (*observations, Observation(0.5 * (record.bin_start_s + record.bin_last_s), record.bin_region,
                                                   median(record.bin_east), median(record.bin_north)))
    observations = tuple(o for o in observations if unix_s - WINDOW_S <= o.unix_s <= unix_s)
    return CurrentRecord(observations, unix_s, unix_s, region, (east_m_s,), (north_m_s,))


def fit(record: CurrentRecord, slice_unix_s: tuple[float, ...] | NDArray[np.float64],
        current_m_s: NDArray[np.float64]) -> TimingFit | None:
    """The shift that best maps the record onto the reference ``current_m_s`` (slices, regions, east/north) at
    ``slice_unix_s``; None with fewer than two observations."""
    obs = record.observations
    times = np.asarray(slice_unix_s, dtype=np.float64)
    if len(obs) < 2 or times.size < 2 or not bool(np.all(np.diff(times) > 0)):
        return None
    t = np.array([o.unix_s for o in obs])
    region = np.clip(np.array([o.region for o in obs]), 0, current_m_s.shape[1] - 1)
    o = np.array([[o.east_m_s, o.north_m_s] for o in obs])  # (n, 2)
    shifts = np.arange(-MAX_SHIFT_S, MAX_SHIFT_S + STEP_S / 2.0, STEP_S)
    when = t[None, :] + shifts[:, None]  # (shifts, n)
    # An observation whose shifted time lies outside the slices has no reference: left out of that shift's fit.
    valid = ((when >= times[0]) & (when <= times[-1])).astype(np.float64)
    idx = np.clip(np.searchsorted(times, when, side="right") - 1, 0, times.size - 2)
    w = np.clip((when - times[idx]) / (times[idx + 1] - times[idx]), 0.0, 1.0)[..., None]
    ref = ((1.0 - w) * current_m_s[idx, region] + w * current_m_s[idx + 1, region]) * valid[..., None]  # (shifts, n, 2)
    rr = np.einsum("snc,snc->s", ref, ref)
    scale = np.where(rr > 0.0, np.einsum("snc,nc->s", ref, o) / np.where(rr > 0.0, rr, 1.0), 0.0)
    scale = np.maximum(scale, 0.0)  # a current that runs against the forecast is not a late one
    miss = (o[None] - scale[:, None, None] * ref) * valid[..., None]
    resid = np.einsum("snc,snc->s", miss, miss)
    count = valid.sum(axis=1)
    mean = np.einsum("sn,nc->sc", valid, o) / np.maximum(count, 1.0)[:, None]
    spread = np.einsum("sn,snc->s", valid, (o[None] - mean[:, None, :]) ** 2)
    r2_all = np.where(spread > 0.0, 1.0 - resid / np.where(spread > 0.0, spread, 1.0), -np.inf)
    first = np.where(valid > 0, t[None, :], np.inf).min(axis=1)
    last = np.where(valid > 0, t[None, :], -np.inf).max(axis=1)
    spans = np.where(count > 1, last - first, 0.0)
    r2_all = np.where(count > 1, r2_all, -np.inf)
    # The best over all shifts, even one that keeps few observations (the rest fall outside the slices,
    # as early in a plan for the shifts that look back): it is then not accepted, on its short span.
    # Restricting the choice to shifts with a long record instead biases it towards those that look
    # forward, which keep more of it (an hour late was fitted 40 minutes late).
    best = int(np.argmax(r2_all))
    r2 = float(r2_all[best]) if math.isfinite(r2_all[best]) else 0.0
    span = float(spans[best])
    accepted = (span >= MIN_SPAN_S and r2 >= MIN_R2 and 0 < best < shifts.size - 1
                and SCALE_RANGE[0] <= float(scale[best]) <= SCALE_RANGE[1])
    return TimingFit(shift_s=float(shifts[best]), scale=float(scale[best]), r2=r2, span_s=span,
                     observations=int(count[best]), accepted=accepted, record_span_s=float(t.max() - t.min()))


@dataclass(frozen=True, slots=True)
class TideClock:
    """The record, the shift in use (s; the plan's slices are looked up at UTC + ``shift_s``) and the last fit."""

    record: CurrentRecord = CurrentRecord()
    shift_s: float = 0.0
    last_fit: TimingFit | None = None
    next_fit_unix_s: float = -math.inf


def advance(clock: TideClock, unix_s: float, region: int, east_m_s: float, north_m_s: float,
            slice_unix_s: tuple[float, ...] | NDArray[np.float64], current_m_s: NDArray[np.float64]) -> TideClock:
    """``clock`` after one measurement of the current; every ``REFIT_S`` the shift is fitted again. An
    accepted fit replaces it. A fit over enough record that is not accepted sets it back to none: the
    forecast's current, shifted, no longer explains the current met (a vehicle gone where the region's
    mean says little of its own current). A fit over too little record (measurements paused, the record
    thinned out) leaves the last shift: it says nothing new."""
    record = observe(clock.record, unix_s, region, east_m_s, north_m_s)
    if unix_s < clock.next_fit_unix_s:
        return TideClock(record, clock.shift_s, clock.last_fit, clock.next_fit_unix_s)
    result = fit(record, slice_unix_s, current_m_s)
    if result is None or (not result.accepted and result.record_span_s < MIN_SPAN_S):
        shift = clock.shift_s
    else:
        shift = result.shift_s if result.accepted else 0.0
    return TideClock(record, shift, result if result is not None else clock.last_fit, unix_s + REFIT_S)
