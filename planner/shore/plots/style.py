"""The look shared by the shore-side pictures: colours, DPI, matplotlib imported lazily, figures and PNGs.

Used by the plan pictures (``flow``, ``policy``, ``nominal_path``), the track
picture (``track``) and the dive report (``planner.shore.replay.report``).

Matplotlib is imported only by ``load_matplotlib``, called when a picture is
drawn, so importing the plots package stays cheap. Figures are built with
``matplotlib.figure.Figure`` on an explicit Agg canvas: nothing here touches
pyplot's global state or the process backend. Every PNG is written atomically
(a temporary file in the same folder, then ``os.replace``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from planner.contract.actions import Action
from planner.contract.atomic import atomic_target

__all__ = [
    "ACTION_COLORS",
    "DPI",
    "FLOW_ARROW_COLOR",
    "GOAL_COLOR",
    "LAND_COLOR",
    "ROTATE_MARKERS",
    "START_COLOR",
    "WATER_COLOR",
    "action_label",
    "load_matplotlib",
    "new_figure",
    "nice_speed",
    "save_png",
    "truncated_cmap",
]

DPI = 150
LAND_COLOR = "#d9c39a"  # tan
WATER_COLOR = "#eef4f9"  # very light sea blue, for the path picture
GOAL_COLOR = "#1a9850"  # green (paper Fig. 6: green goal)
START_COLOR = "#e41a1c"  # red (paper Fig. 6: red start)
FLOW_ARROW_COLOR = "#8c96a3"
# One colour per action code (spec section 5), Okabe-Ito based; none is pure red or green.
ACTION_COLORS: dict[Action, str] = {
    Action.DRIFT: "#0072b2",
    Action.FORWARD: "#d55e00",
    Action.FORWARD_LEFT: "#a6430a",  # physical plans' course offsets: darker and lighter FORWARD
    Action.FORWARD_RIGHT: "#f08a4b",
    Action.ROTATE_LEFT: "#cc79a7",
    Action.ROTATE_RIGHT: "#e69f00",
    Action.UP: "#009e73",
    Action.DOWN: "#6a3d9a",
    Action.AT_GOAL: GOAL_COLOR,
    Action.UNREACHABLE: "#7f7f7f",
}
# Circular arrows for the rotations, in the policy and nominal path pictures.
ROTATE_MARKERS = {Action.ROTATE_LEFT: r"$\circlearrowleft$", Action.ROTATE_RIGHT: r"$\circlearrowright$"}


def load_matplotlib() -> Any:
    """Import the matplotlib pieces used here, lazily; returns the package."""
    import matplotlib
    import matplotlib.backends.backend_agg
    import matplotlib.collections
    import matplotlib.colors
    import matplotlib.dates
    import matplotlib.figure
    import matplotlib.lines
    import matplotlib.patches
    import matplotlib.patheffects
    import matplotlib.ticker

    return matplotlib


def new_figure(mpl: Any, width_in: float, height_in: float) -> Any:
    """A Figure on its own Agg canvas: no pyplot, no global backend switch."""
    fig = mpl.figure.Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    mpl.backends.backend_agg.FigureCanvasAgg(fig)
    return fig


def save_png(fig: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically; returns the path."""
    with atomic_target(path) as tmp:
        fig.savefig(tmp, format="png", dpi=DPI, facecolor="white")
    return Path(path)


def truncated_cmap(mpl: Any, name: str, lo: float, hi: float) -> Any:
    """The part ``lo``..``hi`` (fractions) of the named colormap, as a colormap of its own."""
    base = mpl.colormaps[name]
    return mpl.colors.ListedColormap(base(np.linspace(lo, hi, 256)), name=f"{name}_{lo:g}_{hi:g}")


def nice_speed(x: float) -> float:
    """A round speed near ``x`` for the arrow key (1, 2 or 5 times a power of ten)."""
    if x <= 0:
        return 0.1
    p = 10.0 ** math.floor(math.log10(x))
    return float(min((m * p for m in (1, 2, 5, 10)), key=lambda c: abs(c - x)))


def action_label(a: Action) -> str:
    """The action's name for legends, e.g. ``forward left``."""
    return a.name.replace("_", " ").lower()
