"""``lrauv forecast``: describe a forecast file, or write a synthetic one (SCB, double gyre, tidal channel, ensemble).

The options of ``planner.forecast.synthetic.double_gyre.DoubleGyreSettings``,
``planner.forecast.synthetic.tidal.TidalSettings`` and of ``planner.forecast.synthetic.ensemble``
are declared here, so that building the parser imports no xarray; values are checked by the
settings, and a bad one names its option.
"""

from __future__ import annotations

import argparse
import sys
import dataclasses
import math
import pathlib
from pathlib import Path
from typing import Any

from planner.contract.arguments import Subcommands, floats
from planner.contract.columns import say
from planner.contract.errors import LrauvError, PlannerError

# An analytic source's settings field (or check name) -> the option that sets it (the settings' errors
# name the field): those of _grid_and_time_options, then each source's own.
_GRID_OPTIONS = {
    "bbox": "--bbox",
    "spacing_deg": "--spacing-deg",
    "depths_m": "--depths",
    "hours": "--hours",
    "step_h": "--step-h",
    "hours, step_h": "--hours/--step-h",
    "issue_time": "--issue-time",
}
GYRE_OPTIONS = {
    **_GRID_OPTIONS,
    "peak_speed_m_s": "--peak-speed-m-s",
    "eps": "--eps",
    "period_h": "--period-h",
    "phase_rad": "--phase-rad",
}
# TidalSettings field (or check name, or with_forecast_error argument) -> the option that sets it.
TIDAL_OPTIONS = {
    **_GRID_OPTIONS,
    "amplitude_m_s": "--amplitude-m-s",
    "period_h": "--period-h",
    "phase_rad": "--phase-rad",
    "residual_m_s": "--residual-m-s",
    "mouth_width_m": "--mouth-width-m",
    "neck_width_m": "--neck-width-m",
    "neck_length_m": "--neck-length-m",
    "bbox, mouth_width_m": "--bbox/--mouth-width-m",
    "phase_error_h": "--phase-error-h",
    "amplitude_error": "--amplitude-error",
}
GYRE_ONLY = ("peak_speed_m_s", "eps", "spread", "period_h", "step_h", "spacing_deg", "bbox", "depths", "issue_time")
SCB_ONLY = ("issue",)


def add_parser(sub: Subcommands) -> None:
    fc = sub.add_parser("forecast", help="inspect or generate forecasts")
    fsub = fc.add_subparsers(dest="forecast_command", required=True)
    info = fsub.add_parser("info", help="describe a forecast file as the loader understands it")
    info.add_argument("file", metavar="FILE|URL", help="a netCDF file, or the http(s) URL of one (downloaded to the cache)")
    _variables_option(info)
    info.add_argument("--grid-file", type=Path, help="grid file (lon/lat/mask/angle) for a forecast without them")
    info.add_argument("--cache-dir", type=Path, metavar="DIR",
                      help="cache for downloaded forecasts (default: $LRAUV_CACHE_DIR, $XDG_CACHE_HOME/lrauv or "
                           "~/.cache/lrauv)")
    synth = fsub.add_parser("synth", help="write the built-in synthetic Southern California Bight forecast")
    synth.add_argument("out", type=Path, help="netCDF file to write")
    synth.add_argument("--seed", type=int, default=0, help="seed of the scenario's eddies and errors (default 0)")
    synth.add_argument("--hours", type=int, default=72, help="forecast length in whole hours (default 72)")
    synth.add_argument("--issue", type=int, help="forecast issue number (error shrinks with each issue); default: the truth")

    gyre = fsub.add_parser("gyre", help="write the analytic double gyre (Shadden et al. 2005) as a forecast")
    gyre.add_argument("out", type=Path, help="netCDF file to write")
    gyre.add_argument("--peak-speed-m-s", type=float, help="peak speed of the steady gyre, m/s (default 0.5)")
    gyre.add_argument("--eps", type=float, help="oscillation amplitude of the dividing line, 0..0.5 (default 0.1; 0 = steady)")
    gyre.add_argument("--period-h", type=float, help="oscillation period in hours (default 12)")
    gyre.add_argument("--phase-rad", type=float, help="oscillation phase at the issue time, radians (default 0)")
    _grid_and_time_options(gyre, hours=48, bbox="-118.2,33.3,-117.8,33.467")

    tidal = fsub.add_parser("tidal", help="write an M2 tidal current through a channel with a constriction as a forecast")
    tidal.add_argument("out", type=Path, help="netCDF file to write")
    tidal.add_argument("--amplitude-m-s", type=float, help="tidal current amplitude at the neck, m/s (default 0.8)")
    tidal.add_argument("--period-h", type=float, help="tidal period in hours (default M2, 12.4206)")
    tidal.add_argument("--phase-rad", type=float, help="tidal phase at the issue time, radians (default 0: flood east at full strength)")
    tidal.add_argument("--residual-m-s", type=float, help="steady residual current at the neck, m/s, positive east (default 0.05)")
    tidal.add_argument("--mouth-width-m", type=float, help="channel width at the box's east and west edges, m (default 9000)")
    tidal.add_argument("--neck-width-m", type=float, help="channel width at the constriction, m (default 6000)")
    tidal.add_argument("--neck-length-m", type=float, help="e-folding half-length of the constriction, m (default 8000)")
    tidal.add_argument("--phase-error-h", type=float,
                       help="forecast error: the tide runs H hours early (phase + 2 pi H / period; default 0)")
    tidal.add_argument("--amplitude-error", type=float,
                       help="forecast error: amplitude times 1 + F, F >= -1 (default 0)")
    _grid_and_time_options(tidal, hours=72, bbox="-118.2,33.3,-117.8,33.5")

    perturb = fsub.add_parser("perturb", help="write a copy of a forecast file with its currents early or late, and stronger or weaker")
    perturb.add_argument("file", help="forecast file to copy (netCDF)")
    perturb.add_argument("out", type=Path, help="netCDF file to write")
    perturb.add_argument("--phase-error-h", type=float, default=0.0,
                         help="the copy's currents run H hours early: at time t it holds the file's t + H (default 0)")
    perturb.add_argument("--amplitude-error", type=float, default=0.0,
                         help="the copy's currents are times 1 + F, F >= -1 (default 0)")
    _variables_option(perturb)

    ens = fsub.add_parser("ensemble", help="write a synthetic forecast ensemble: one file, u/v with a leading member dimension")
    ens.add_argument("out", type=Path, help="netCDF file to write")
    ens.add_argument("--kind", choices=["gyre", "scb"], required=True,
                     help="gyre: double gyres with drawn eps, phase and peak speed; scb: one SCB forecast issue, independent error draws")
    ens.add_argument("--members", type=int, required=True, help="number of members, 1..1000")
    ens.add_argument("--seed", type=int, default=0,
                     help="gyre: seed of the members' draws; scb: the scenario's seed, as `lrauv forecast synth --seed` (default 0)")
    ens.add_argument("--hours", type=float, help="forecast length in hours (gyre: default 48; scb: whole hours, default 72)")
    ens.add_argument("--peak-speed-m-s", type=float, help="gyre: base peak speed, m/s; members x U[1 - spread, 1 + spread] (default 0.5)")
    ens.add_argument("--eps", type=float, help="gyre: base eps; members draw eps from U[0, min(2 eps, 0.5)] (default 0.1)")
    ens.add_argument("--spread", type=float, help="gyre: relative spread of the members' peak speed, 0 <= spread < 1 (default 0.2)")
    ens.add_argument("--period-h", type=float, help="gyre: oscillation period in hours (default 12)")
    ens.add_argument("--step-h", type=float, help="gyre: time step in hours (default 1)")
    ens.add_argument("--spacing-deg", type=float, help="gyre: grid spacing in degrees (default 0.005)")
    ens.add_argument("--bbox", help="gyre: WEST,SOUTH,EAST,NORTH in degrees (default -118.2,33.3,-117.8,33.467)")
    ens.add_argument("--depths", help="gyre: layer depths in metres (default 0,5,10,15)")
    ens.add_argument("--issue-time", help="gyre: ISO 8601 issue time, t = 0 (default 2026-01-15T00:00:00Z)")
    ens.add_argument("--issue", type=int, help="scb: forecast issue of every member, its issue time and error size (default 0)")


def _grid_and_time_options(parser: argparse.ArgumentParser, *, hours: float, bbox: str) -> None:
    """The options an analytic source shares: its length, step, grid and issue time (their defaults in the help)."""
    parser.add_argument("--hours", type=float, help=f"forecast length in hours (default {hours:g})")
    parser.add_argument("--step-h", type=float, help="time step in hours (default 1)")
    parser.add_argument("--spacing-deg", type=float, help="grid spacing in degrees (default 0.005)")
    parser.add_argument("--bbox", help=f"WEST,SOUTH,EAST,NORTH in degrees, points on the edges (default {bbox})")
    parser.add_argument("--depths", help="layer depths in metres (default 0,5,10,15)")
    parser.add_argument("--issue-time", help="ISO 8601 issue time, t = 0 (default 2026-01-15T00:00:00Z)")


def run(args: argparse.Namespace) -> int:
    if args.forecast_command == "info":
        from planner.forecast import describe, open_forecast

        from planner.cli.plan import local_forecast

        path = local_forecast(args.file, args.cache_dir)
        say(describe(open_forecast(path, variables=_variables(args), grid_file=args.grid_file)))
        return 0
    if args.forecast_command == "ensemble":
        say(f"wrote {write_ensemble_from_args(args)}")
        return 0
    if args.forecast_command == "perturb":
        from planner.forecast.perturb import write_perturbed

        path = write_perturbed(args.file, args.out, phase_error_h=args.phase_error_h,
                               amplitude_error=args.amplitude_error, variables=_variables(args))
        say(f"wrote {path}")
        return 0
    if args.forecast_command == "gyre":
        from planner.forecast.synthetic.double_gyre import write_gyre

        say(f"wrote {write_gyre(args.out, settings_from_args(args))}")
        return 0
    if args.forecast_command == "tidal":
        from planner.forecast.synthetic.tidal import write_tidal

        say(f"wrote {write_tidal(args.out, tidal_settings_from_args(args))}")
        return 0
    from planner.forecast.synthetic.scb import SyntheticSettings, write_synthetic

    which = "the truth" if args.issue is None else f"issue {args.issue}"
    print(f"  synthesising {args.hours} h of the Southern California Bight forecast ({which})", file=sys.stderr,
          flush=True)
    path = write_synthetic(args.out, SyntheticSettings(seed=args.seed, hours=args.hours), issue_number=args.issue)
    say(f"wrote {path}")
    return 0


def _variables_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--variables", type=lambda t: t.split(","), metavar="U,V",
                        help="the velocity variables' names, when they cannot be found by standard or common name")


def _variables(args: argparse.Namespace) -> tuple[str, str] | None:
    """``--variables`` as (u, v); a list of other than two names is refused naming the option."""
    if not args.variables:
        return None
    if len(args.variables) != 2:
        raise LrauvError(f"--variables: expected two names U,V; got {','.join(args.variables)}")
    return args.variables[0], args.variables[1]


def settings_from_args(args: argparse.Namespace) -> Any:
    """``DoubleGyreSettings`` from ``lrauv forecast gyre``'s options; bad values raise ``PlannerError`` naming the option."""
    from planner.forecast.synthetic.double_gyre import DoubleGyreSettings

    return _settings_from(args, DoubleGyreSettings, GYRE_OPTIONS)


def tidal_settings_from_args(args: argparse.Namespace) -> Any:
    """``TidalSettings`` from ``lrauv forecast tidal``'s options, forecast error applied; bad values name the option."""
    from planner.forecast.synthetic.tidal import TidalSettings, with_forecast_error

    phase_error_h = getattr(args, "phase_error_h", None)
    amplitude_error = getattr(args, "amplitude_error", None)
    return _settings_from(args, TidalSettings, TIDAL_OPTIONS, then=lambda settings: with_forecast_error(
        settings, phase_error_h=0.0 if phase_error_h is None else phase_error_h,
        amplitude_error=0.0 if amplitude_error is None else amplitude_error))


def _settings_from(args: argparse.Namespace, cls: Any, options: dict[str, str], then: Any = lambda s: s) -> Any:
    """An analytic source's settings from the options of the same names (a default for each option not
    given), ``then`` applied; a refused value raises ``PlannerError`` naming its option."""
    default = cls()
    west, south, east, north, depths = _box_and_depths(args, default)
    box = {"west_deg": west, "south_deg": south, "east_deg": east, "north_deg": north, "depths_m": depths}
    values = {f.name: getattr(default, f.name) if getattr(args, f.name, None) is None else getattr(args, f.name)
              for f in dataclasses.fields(cls) if f.name not in box}  # argparse values are untyped: the settings check them
    try:
        return then(cls(**box, **values))
    except PlannerError as exc:
        field = getattr(exc, "field", None)  # the settings' errors carry the field they refuse
        if field is None:
            raise
        raise PlannerError(f"{options.get(field, field)}: {exc}") from None


def write_ensemble_from_args(args: argparse.Namespace) -> pathlib.Path:
    """``lrauv forecast ensemble``: write the ensemble that the options describe; bad values name the option."""
    from planner.forecast.synthetic.ensemble import (
        write_gyre_ensemble,
        write_scb_ensemble,
    )
    from planner.forecast.synthetic.scb import SyntheticSettings

    kind = getattr(args, "kind", None)
    given = {name for name in (*GYRE_ONLY, *SCB_ONLY) if getattr(args, name, None) is not None}
    try:
        if kind == "gyre":
            if wrong := sorted(given & set(SCB_ONLY)):
                raise PlannerError(f"{_option(wrong[0])}: only for --kind scb")
            spread = 0.2 if getattr(args, "spread", None) is None else args.spread
            settings = settings_from_args(args)  # names the option itself
            return write_gyre_ensemble(args.out, settings, args.members, args.seed, spread)
        if kind == "scb":
            if wrong := sorted(given & set(GYRE_ONLY)):
                raise PlannerError(f"{_option(wrong[0])}: only for --kind gyre")
            hours = 72.0 if getattr(args, "hours", None) is None else float(args.hours)
            if not (math.isfinite(hours) and hours == int(hours) and hours >= 1):
                raise PlannerError(f"--hours: --kind scb takes whole hours >= 1; got {args.hours!r}")
            if not (_is_int(args.seed) and args.seed >= 0):
                raise PlannerError(f"--seed: must be an integer >= 0; got {args.seed!r}")
            synthetic = SyntheticSettings(seed=int(args.seed), hours=int(hours))
            issue = 0 if getattr(args, "issue", None) is None else args.issue
            return write_scb_ensemble(args.out, synthetic, args.members, issue)
    except PlannerError as exc:
        argument = getattr(exc, "argument", None)  # the ensemble's errors carry the argument they refuse
        if argument is None:
            raise
        raise PlannerError(f"{_option(argument)}: {exc}") from None
    raise PlannerError(f"--kind: expected gyre or scb; got {kind!r}")


def _box_and_depths(args: argparse.Namespace, default: Any) -> tuple[float, float, float, float, tuple[float, ...]]:
    """``--bbox`` and ``--depths`` as given, else the default settings' box and depths."""
    west, south, east, north = default.west_deg, default.south_deg, default.east_deg, default.north_deg
    if getattr(args, "bbox", None) is not None:
        west, south, east, north = _floats(args.bbox, 4, "--bbox")
    depths = default.depths_m
    if getattr(args, "depths", None) is not None:
        depths = tuple(_floats(args.depths, None, "--depths"))
    return west, south, east, north, depths


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def _is_int(value: object) -> bool:
    import numpy as np

    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _floats(text: str, n: int | None, option: str) -> list[float]:
    try:
        return floats(str(text), n, option)
    except argparse.ArgumentTypeError as exc:
        raise PlannerError(str(exc)) from None
