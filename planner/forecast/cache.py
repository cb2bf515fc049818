"""The per-user cache of forecast files: synthetic forecasts planned from a mission, and downloads.

``--cache-dir DIR``, else ``$LRAUV_CACHE_DIR``, else ``$XDG_CACHE_HOME/lrauv`` (XDG Base
Directory Specification: a relative XDG_CACHE_HOME is invalid and ignored), else
``~/.cache/lrauv``. Everything in it can be deleted: it is made again when needed.
"""

from __future__ import annotations

import os
from pathlib import Path

CACHE_ENV = "LRAUV_CACHE_DIR"


def cache_dir(override: str | os.PathLike[str] | None = None) -> Path:
    """The cache folder (not created here): ``override``, ``$LRAUV_CACHE_DIR``, ``$XDG_CACHE_HOME/lrauv`` or ``~/.cache/lrauv``."""
    if override is not None and os.fspath(override):
        return Path(override).expanduser()
    env = os.environ.get(CACHE_ENV, "")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".cache"
    return base / "lrauv"


def forecasts_dir(override: str | os.PathLike[str] | None = None) -> Path:
    """Where cached forecast files go: ``forecasts/`` in the cache folder."""
    return cache_dir(override) / "forecasts"
