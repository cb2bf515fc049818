"""Whether a plan's first run will compile its kernels (numba's on-disk cache has no entry for them yet).

Compiling the solver takes seconds on the first run after an install or a change of its source;
later runs load it from ``__pycache__`` at once. The command line announces the slow first run.
"""

from __future__ import annotations

from typing import Any

COMPILING = "compiling the solver (first run only) ..."


def needs_compile(kernel: Any) -> bool:
    """True when ``kernel`` (a ``numba.njit(cache=True)`` dispatcher) is neither compiled in this process
    nor cached on disk for this source. Reads numba's cache index (not public API): anything unexpected
    there counts as cached, so a numba that changes it costs an announcement, never a failure."""
    if getattr(kernel, "signatures", None):
        return False
    try:
        return not kernel._cache._cache_file._load_index()
    except Exception:  # numba's cache layout changed, or caching is off: say nothing rather than guess
        return False
