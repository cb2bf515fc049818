"""What ``lrauv X --help`` says above and below the flags: one user-facing sentence and an example.

Kept in one table so that every subcommand has both, whichever module registers it (the simulator's
module docstring is for developers, not for ``lrauv sim --help``). Coordinates are LON,LAT everywhere.
"""

from __future__ import annotations

import argparse
from typing import Any

# name: (description, example command lines)
HELP: dict[str, tuple[str, tuple[str, ...]]] = {
    "plan": ("Plan a feedback policy over a forecast and write the policy table (.lrpt) the vehicle executes. "
             "A mission file gives everything; flags override it.",
             ("lrauv plan missions/demo.yaml --out demo.lrpt --plot pics",
              "lrauv plan --forecast f.nc --bbox=-118.26,33.30,-117.70,33.70 --nx 29 --ny 21 --depths 0,5,10,15 "
              "--goal=-117.80,33.40,0")),
    "forecast": ("Inspect a forecast as the planner reads it, or write a built-in one (synthetic, gyre, tidal, ensemble).",
                 ("lrauv forecast info f.nc", "lrauv forecast synth out/f.nc --hours 72")),
    "evaluate": ("Fly each planning method many times in a truth field and compare arrival, energy and time.",
                 ("lrauv evaluate missions/demo.yaml --truth truth.nc --starts 20 --out out/eval",)),
    "batch": ("Plan every goal of many missions (or a fleet file) as parallel tasks, one table per goal.",
              ("lrauv batch missions/demo.yaml missions/two-goals.yaml --out out/batch",)),
    "holdout": ("Compare an ensemble plan with single-member plans, each flown in a member it did not see.",
                ("lrauv holdout missions/demo.yaml --ensemble ens.nc --starts 50",)),
    "exec": ("Run the onboard executive: read the vehicle over MAVLink, look up the policy table, command the autopilot.",
             ("lrauv exec --table demo.lrpt --mission missions/demo.yaml --link udpout:127.0.0.1:14560 --log run.mcap",)),
    "log": ("Tools for the executive's MCAP logs.", ("lrauv log recover run.mcap fixed.mcap",)),
    "sim": ("Run the simulated ArduSub-like vehicle in a truth forecast; it speaks MAVLink 2 over UDP to the executive.",
            ("lrauv sim --forecast truth.nc --start=-118.2,33.6 --listen 127.0.0.1:14560",)),
    "demo": ("Fly a planned mission end to end: the simulated vehicle and the executive over UDP, until the goal.",
             ("lrauv demo --table demo.lrpt --mission missions/demo.yaml --truth truth.nc --start=-118.2,33.6",)),
    "upload": ("Send a mission's goals (and planned tables) to a running executive over MAVLink.",
               ("lrauv upload missions/demo.yaml --to udpout:127.0.0.1:14551",)),
    "waypoints": ("Exchange goals with ground stations as QGC WPL 110 waypoint files.",
                  ("lrauv waypoints export missions/demo.yaml demo.waypoints",
                   "lrauv waypoints import demo.waypoints --mission missions/demo.yaml --out missions/edited.yaml")),
    "replay": ("Summarise, audit, report, export or re-stream a dive from the executive's MCAP log.",
               ("lrauv replay run.mcap --report out/report", "lrauv replay run.mcap --csv d.csv --geojson d.geojson")),
}


def epilog(examples: tuple[str, ...]) -> str:
    return "example" + ("s" if len(examples) > 1 else "") + ":\n" + "\n".join(f"  {e}" for e in examples)


def describe(subparsers: Any) -> None:
    """Give every subcommand parser its description and an example (argparse keeps them verbatim)."""
    for name, parser in subparsers.choices.items():
        if name in HELP:
            text, examples = HELP[name]
            parser.description, parser.epilog = text, epilog(examples)
            parser.formatter_class = argparse.RawDescriptionHelpFormatter
