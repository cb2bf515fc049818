"""What ``lrauv X --help`` and ``lrauv X Y --help`` say above and below the flags: what it does and an example.

Kept in one table so that every subcommand, nested ones too, has both, whichever module registers it
(the simulator's module docstring is for developers, not for ``lrauv sim --help``). Coordinates are
LON,LAT everywhere. Help fits in 100 columns (``planner.contract.columns``) on any terminal.
"""

from __future__ import annotations

import argparse
import shutil
import textwrap
from typing import Any

from planner.contract.columns import WIDTH

# name: (description, example command lines)
HELP: dict[str, tuple[str, tuple[str, ...]]] = {
    "plan": ("Plan a feedback policy over a forecast and write the policy table (.lrpt) the vehicle executes. "
             "A mission file gives everything; flags override it.",
             ("lrauv plan missions/demo.yaml --out demo.lrpt --plot pics",
              "lrauv plan --forecast f.nc --bbox=-118.26,33.30,-117.70,33.70 --nx 29 --ny 21 --depths 0,5,10,15 "
              "--goal=-117.80,33.40,0")),
    "forecast": ("Inspect a forecast as the planner reads it, write a built-in one (synthetic, gyre, tidal, ensemble), "
                 "or a copy of one made wrong on purpose (perturb).",
                 ("lrauv forecast info f.nc", "lrauv forecast synth out/f.nc --hours 72")),
    "forecast perturb": ("Write a copy of a forecast file whose currents run early (or late, with a negative "
                         "phase error) and are stronger or weaker: a forecast with a known error, to fly a plan "
                         "made on it through the original as the truth (lrauv evaluate).",
                         ("lrauv forecast perturb hycom.nc out/hycom-early.nc --phase-error-h 1 --amplitude-error -0.2",
                          "lrauv evaluate missions/eval-hycom.yaml --forecast out/hycom-early.nc --truth hycom.nc")),
    "forecast info": ("Describe a forecast as the planner reads it: its grid, times, depths, variables, land and "
                      "current speeds. A URL is downloaded to the cache first.",
                      ("lrauv forecast info out/f.nc", "lrauv forecast info f.nc --variables uo,vo")),
    "forecast synth": ("Write the built-in synthetic Southern California Bight forecast (netCDF): the truth, or "
                       "with --issue a forecast of it whose error shrinks with each issue.",
                       ("lrauv forecast synth out/truth.nc", "lrauv forecast synth out/forecast.nc --issue 0 --hours 48")),
    "forecast gyre": ("Write the analytic double gyre (Shadden et al. 2005) as a forecast (netCDF): a steady or "
                      "oscillating pair of eddies for testing plans against known currents.",
                      ("lrauv forecast gyre out/gyre.nc --peak-speed-m-s 1.5",
                       "lrauv forecast gyre out/steady.nc --eps 0")),
    "forecast tidal": ("Write an M2 tidal current through a channel with a constriction as a forecast (netCDF); "
                       "its error options make a forecast of it.",
                       ("lrauv forecast tidal out/tidal.nc", "lrauv forecast tidal out/fc.nc --phase-error-h 0.5")),
    "forecast ensemble": ("Write a synthetic forecast ensemble: one netCDF file whose currents have a leading "
                          "member dimension, for planning against every member at once.",
                          ("lrauv forecast ensemble out/ens.nc --kind gyre --members 10",
                           "lrauv forecast ensemble out/ens.nc --kind scb --members 5 --issue 1")),
    "evaluate": ("Fly each planning method many times in a truth field and compare arrival, energy and time.",
                 ("lrauv evaluate missions/demo.yaml --truth truth.nc --starts 20 --out out/eval",)),
    "batch": ("Plan every goal of many missions (or a fleet file) as parallel tasks, one table per goal.",
              ("lrauv batch missions/demo.yaml missions/two-goals.yaml --out out/batch",)),
    "holdout": ("Compare an ensemble plan with single-member plans, each flown in a member it did not see.",
                ("lrauv holdout missions/demo.yaml --ensemble ens.nc --starts 50",)),
    "exec": ("Run the onboard executive: read the vehicle over MAVLink, look up the policy table, command the autopilot.",
             ("lrauv exec --table demo.lrpt --mission missions/demo.yaml --link udpout:127.0.0.1:14560 --log run.mcap",)),
    "log": ("Tools for the executive's MCAP logs.", ("lrauv log recover run.mcap fixed.mcap",)),
    "log recover": ("Rebuild a readable log from one left by a killed executive (no footer or index): every whole "
                    "message is kept, the torn end dropped.",
                    ("lrauv log recover run.mcap", "lrauv log recover run.mcap fixed.mcap")),
    "sim": ("Run the simulated ArduSub-like vehicle in a truth forecast; it speaks MAVLink 2 over UDP to the executive.",
            ("lrauv sim --forecast truth.nc --start=-118.2,33.6 --listen 127.0.0.1:14560",)),
    "demo": ("Fly a planned mission end to end: the simulated vehicle and the executive over UDP, until the goal.",
             ("lrauv demo --table demo.lrpt --mission missions/demo.yaml --truth truth.nc --start=-118.2,33.6",)),
    "upload": ("Send a mission's goals (and planned tables) to a running executive over MAVLink.",
               ("lrauv upload missions/demo.yaml --to udpout:127.0.0.1:14551",)),
    "waypoints": ("Exchange goals with ground stations as QGC WPL 110 waypoint files.",
                  ("lrauv waypoints export missions/demo.yaml demo.waypoints",
                   "lrauv waypoints import demo.waypoints --mission missions/demo.yaml --out missions/edited.yaml")),
    "waypoints export": ("Write a mission's goals as a QGC WPL 110 waypoint file (item 0 is home) that QGroundControl, "
                         "Mission Planner and MAVProxy open.",
                         ("lrauv waypoints export missions/demo.yaml demo.waypoints",
                          "lrauv waypoints export missions/demo.yaml demo.waypoints --home=-118.0,33.5")),
    "waypoints import": ("Write a mission whose goals are a QGC WPL 110 waypoint file's, everything else taken from "
                         "a base mission.",
                         ("lrauv waypoints import demo.waypoints --mission missions/demo.yaml --out missions/edited.yaml",)),
    "replay": ("Summarise, audit, report, export or re-stream a dive from the executive's MCAP log.",
               ("lrauv replay run.mcap --report out/report", "lrauv replay run.mcap --csv d.csv --geojson d.geojson")),
}


def epilog(examples: tuple[str, ...]) -> str:
    """The examples, one command each; a long one goes on over lines that end in a backslash, as a shell reads it."""
    lines = []
    for example in examples:
        parts = textwrap.wrap(example, _TEXT_WIDTH - 6, break_long_words=False, break_on_hyphens=False)
        lines += [("  " if n == 0 else "      ") + part + (" \\" if n < len(parts) - 1 else "")
                  for n, part in enumerate(parts)]
    return "example" + ("s" if len(examples) > 1 else "") + ":\n" + "\n".join(lines)


# Descriptions and examples are wrapped here, for an 80-column terminal; argparse keeps them verbatim.
_TEXT_WIDTH = 78


class UserHelp(argparse.RawDescriptionHelpFormatter):
    """argparse's help, the description and examples as written, no wider than 100 columns on a wide terminal."""

    def __init__(self, prog: str, indent_increment: int = 2, max_help_position: int = 24, width: int | None = None):
        width = min(width or shutil.get_terminal_size().columns - 2, WIDTH)
        super().__init__(prog, indent_increment, max_help_position, width)


def describe(subparsers: Any, prefix: str = "") -> None:
    """Give every subcommand parser, nested ones too, its description and examples (``HELP``)."""
    for name, parser in subparsers.choices.items():
        key = f"{prefix}{name}"
        if key in HELP:
            text, examples = HELP[key]
            parser.description, parser.epilog = textwrap.fill(text, _TEXT_WIDTH), epilog(examples)
        parser.formatter_class = UserHelp
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                describe(action, f"{key} ")
