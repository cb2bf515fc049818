"""A Foxglove layout for the executive's logs: import it in Foxglove (Layouts, Import from file) beside the log.

Panels: the Map with the track (``/vehicle/fix``, followed) and the mission's GeoJSON layers
(goals, geofence, running plan); the Log panel on ``/log``; a Plot of depth and battery from
``/vehicle/state``; a State Transitions panel of the helm's action and situation; Raw Messages
on ``/vehicle/state``. The JSON is Foxglove's layout format (``configById`` keyed by panel type
and id, ``layout`` the split tree); panel types as Foxglove names them: ``map``, ``RosOut``
(the Log panel), ``Plot``, ``StateTransitions``, ``RawMessages``. Plots are against the
message's log time, which is UTC (``executive.log_clock``), so the time axis is the dive's.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from executive.recorder import Topic
from planner.contract.atomic import write_atomic

__all__ = ["foxglove_layout", "layout_topics", "write_layout"]

_MAP, _LOG, _PLOT, _STATES, _RAW = "map!lrauv-map", "RosOut!lrauv-log", "Plot!lrauv-plot", \
    "StateTransitions!lrauv-states", "RawMessages!lrauv-raw"
_MAP_LAYERS = (Topic.MAP_GEOFENCE, Topic.MAP_PLAN, Topic.MAP_GOALS)
_COLOURS = {Topic.FIX: "#1f77b4", Topic.MAP_GEOFENCE: "#d62728", Topic.MAP_PLAN: "#7f7f7f", Topic.MAP_GOALS: "#2ca02c"}


def _path(topic: Topic, field: str) -> str:
    return f"{topic.value}.{field}"


def foxglove_layout() -> dict[str, Any]:
    """The layout as a JSON object."""
    series = [{"value": _path(Topic.STATE, "depth_m"), "enabled": True, "timestampMethod": "receiveTime",
               "label": "depth (m)"},
              {"value": _path(Topic.STATE, "battery_pct"), "enabled": True, "timestampMethod": "receiveTime",
               "label": "battery (%)"}]
    return {
        "configById": {
            _MAP: {"layer": "map", "customTileUrl": "", "disabledTopics": [], "followTopic": Topic.FIX.value,
                   "topicColors": {t.value: c for t, c in _COLOURS.items()}, "zoomLevel": 11},
            _LOG: {"topicToRender": Topic.LOG.value, "searchTerms": [], "minLogLevel": 2},
            _PLOT: {"paths": series, "showLegend": True, "legendDisplay": "floating", "showXAxisLabels": True,
                    "showYAxisLabels": True, "isSynced": True, "xAxisVal": "timestamp"},
            _STATES: {"paths": [{"value": _path(Topic.DECISION, "action"), "timestampMethod": "receiveTime"},
                                {"value": _path(Topic.DECISION, "situation"), "timestampMethod": "receiveTime"}],
                      "isSynced": True},
            _RAW: {"topicPath": Topic.STATE.value, "diffEnabled": False, "diffMethod": "custom", "diffTopicPath": "",
                   "showFullMessageForDiff": False},
        },
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": {
            "direction": "row",
            "first": {"direction": "column", "first": _MAP, "second": _LOG, "splitPercentage": 65},
            "second": {"direction": "column", "first": _PLOT,
                       "second": {"direction": "column", "first": _STATES, "second": _RAW, "splitPercentage": 40},
                       "splitPercentage": 45},
            "splitPercentage": 55,
        },
    }


def layout_topics(layout: dict[str, Any]) -> set[str]:
    """Every topic a layout names (message paths cut at the field), for checking it against a log."""
    names: set[str] = set()
    for config in layout["configById"].values():
        for key in ("followTopic", "topicToRender", "topicPath"):
            if config.get(key):
                names.add(config[key])
        names.update(config.get("topicColors", {}))
        names.update(p["value"].split(".", 1)[0] for p in config.get("paths", ()))
    return names


def write_layout(path: str | os.PathLike[str]) -> Path:
    """Write the layout to ``path`` atomically; returns the path."""
    data = json.dumps(foxglove_layout(), indent=2) + "\n"
    write_atomic(Path(path), data.encode())
    return Path(path)
