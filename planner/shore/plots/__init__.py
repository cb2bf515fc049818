"""Pictures of a plan (paper Figs. 3, 5, 6) and of a vehicle track: the public boundary of the plots package.

Each public function draws one figure and writes it as one PNG, atomically, and
returns its path. The modules, named after what they draw:

- ``flow``: the currents of every layer (``plot_flow_fields``);
- ``policy``: the policy for one heading in one layer (``plot_policy``);
- ``nominal_path``: the nominal path to the goal (``plot_nominal_path``, ``default_start``);
- ``plan_pictures``: all three in one folder (``plot_all``);
- ``track``: an executed track coloured by autopilot mode (``plot_track``);
- ``style`` and ``map_axes``: colours, figures, PNG saving and map drawing, shared
  with ``planner.shore.replay.report``; ``solutions``: what the plan pictures read
  from a paper or physical solution.

Matplotlib is imported only when a picture is drawn, so importing this package
is cheap (numpy only).
"""

from planner.shore.plots.currents import ForecastMoment, moment_of_plan
from planner.shore.plots.flow import plot_flow_fields
from planner.shore.plots.nominal_path import default_start, plot_nominal_path
from planner.shore.plots.plan_pictures import plot_all
from planner.shore.plots.policy import plot_policy
from planner.shore.plots.style import ACTION_COLORS
from planner.shore.plots.track import plot_track, track_times_and_currents

__all__ = [
    "ACTION_COLORS",
    "ForecastMoment",
    "default_start",
    "moment_of_plan",
    "plot_all",
    "plot_flow_fields",
    "plot_nominal_path",
    "plot_policy",
    "plot_track",
    "track_times_and_currents",
]
