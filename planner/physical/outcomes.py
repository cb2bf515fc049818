"""Outcome lists of the physical model's samples: per (cell, channel), the outcome cells any sample
ended in, with their sample counts and largest energies (``planner.physical.sampling.SampleStats``).

A sample ends within two cells of its own, so an outcome is a *slot*, its offset within +-2 cells:
``slot = (dj + 2) * 5 + (di + 2)``. The sampling kernel counts into dense (cells, channels, 25)
blocks; ``compact`` turns a block into lists, ``splice`` replaces some cells' lists (a goal's
patch), ``merge`` adds a second forecast member's lists to the first's.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

SLOTS = 25  # outcome cells within +-2 cells: slot = (dj + 2) * 5 + (di + 2)

_F64 = NDArray[np.float64]
_I64 = NDArray[np.int64]
_Mask = NDArray[np.bool_]


@numba.njit(cache=True)
def compact(  # pragma: no cover
    cells: _I64, n_ch: int, hazard: _Mask, count: NDArray[np.int32], emax: _F64, n_out: _I64,
) -> tuple[NDArray[np.int8], NDArray[np.int32], _F64]:
    """The dense samples of ``cells`` as outcome lists (slots ascending); ``n_out`` gets each channel's length."""
    total = 0
    for r in range(cells.size):
        for ch in range(n_ch):
            if not hazard[r, ch]:
                for s in range(SLOTS):
                    if count[r, ch, s] > 0:
                        total += 1
    slot = np.empty(total, dtype=np.int8)
    cnt = np.empty(total, dtype=np.int32)
    em = np.empty(total)
    e = 0
    for r in range(cells.size):
        for ch in range(n_ch):
            k = 0
            if not hazard[r, ch]:
                for s in range(SLOTS):
                    if count[r, ch, s] > 0:
                        slot[e] = s
                        cnt[e] = count[r, ch, s]
                        em[e] = emax[r, ch, s]
                        e += 1
                        k += 1
            n_out[cells[r] * n_ch + ch] = k
    return slot, cnt, em


@numba.njit(cache=True)
def splice(  # pragma: no cover
    ptr: _I64, slot: NDArray[np.int8], count: NDArray[np.int32], emax: _F64, new_ptr: _I64, cells: _I64, n_ch: int,
    slot_p: NDArray[np.int8], count_p: NDArray[np.int32], emax_p: _F64,
) -> tuple[NDArray[np.int8], NDArray[np.int32], _F64]:
    """The outcome lists with those of ``cells`` (in that order, from ``compact``) replaced."""
    n = new_ptr[-1]
    out_slot = np.empty(n, dtype=np.int8)
    out_count = np.empty(n, dtype=np.int32)
    out_emax = np.empty(n)
    patched = np.full(ptr.size - 1, -1, dtype=np.int64)
    e = 0
    for r in range(cells.size):
        for ch in range(n_ch):
            q = cells[r] * n_ch + ch
            patched[q] = e
            e += new_ptr[q + 1] - new_ptr[q]
    for q in range(ptr.size - 1):
        lo = new_ptr[q]
        k = new_ptr[q + 1] - lo
        if patched[q] >= 0:
            src = patched[q]
            for t in range(k):
                out_slot[lo + t] = slot_p[src + t]
                out_count[lo + t] = count_p[src + t]
                out_emax[lo + t] = emax_p[src + t]
        else:
            src = ptr[q]
            for t in range(k):
                out_slot[lo + t] = slot[src + t]
                out_count[lo + t] = count[src + t]
                out_emax[lo + t] = emax[src + t]
    return out_slot, out_count, out_emax


@numba.njit(cache=True)
def merge(  # pragma: no cover
    ptr_a: _I64, slot_a: NDArray[np.int8], count_a: NDArray[np.int32], emax_a: _F64,
    ptr_b: _I64, slot_b: NDArray[np.int8], count_b: NDArray[np.int32], emax_b: _F64,
) -> tuple[_I64, NDArray[np.int8], NDArray[np.int32], _F64]:
    """Two members' outcome lists merged per channel: counts summed, the larger energy kept."""
    nq = ptr_a.size - 1
    ptr = np.zeros(nq + 1, dtype=np.int64)
    cap = slot_a.size + slot_b.size
    slot = np.empty(cap, dtype=np.int8)
    count = np.empty(cap, dtype=np.int32)
    emax = np.empty(cap)
    e = 0
    for q in range(nq):
        a, a_end = ptr_a[q], ptr_a[q + 1]
        b, b_end = ptr_b[q], ptr_b[q + 1]
        while a < a_end or b < b_end:
            if b >= b_end or (a < a_end and slot_a[a] < slot_b[b]):
                slot[e], count[e], emax[e] = slot_a[a], count_a[a], emax_a[a]
                a += 1
            elif a >= a_end or slot_b[b] < slot_a[a]:
                slot[e], count[e], emax[e] = slot_b[b], count_b[b], emax_b[b]
                b += 1
            else:
                slot[e], count[e], emax[e] = slot_a[a], count_a[a] + count_b[b], max(emax_a[a], emax_b[b])
                a += 1
                b += 1
            e += 1
        ptr[q + 1] = e
    return ptr, slot[:e].copy(), count[:e].copy(), emax[:e].copy()
