"""Synthetic forecast ensembles: one CF-1.8 netCDF file whose velocities have a ``member`` dimension.

Two kinds, both built from the single-file generators, so that member ``m`` of
an ensemble file holds exactly (bit for bit) the arrays that the single-file
writer writes for member ``m``'s settings:

- **Double gyre** (``planner.forecast.synthetic.double_gyre``). Member ``m`` is the gyre of
  ``gyre_ensemble(settings, members, seed, spread)[m]``: the base settings with
  three parameters drawn from ``numpy.random.default_rng(seed)``, member after
  member, in this order::

      eps            ~ U[0, min(2 eps, 0.5)]          (mean: the base eps; 0.5 is the gyre's limit)
      phase_rad      ~ U[0, 2 pi)                     (the base phase is not used)
      peak_speed_m_s = base peak x U[1 - spread, 1 + spread]

  Everything else (box, grid, period, times) is the base's. The dividing
  line's mean position is not perturbed. Members are drawn one after the
  other from one generator, so the first ``k`` members of a larger ensemble
  with the same seed are the ``k``-member ensemble. Any member can be
  written alone, e.g. as a truth, with ``write_gyre(path, members[m])``.
- **Southern California Bight** (``planner.forecast.synthetic.scb``). Member ``m`` is
  forecast issue ``issue`` of the base scenario with ``error_draw = m``
  (``scb_ensemble``): the same truth, an independent scene perturbation drawn
  from ``default_rng([seed, 2, issue, m])``, scaled like every issue so that
  over water ``RMS|member - truth| / RMS|truth| = error_scale *
  error_decay**issue`` before the speed clip: every member has the same error
  size, and all share the issue's time axis (issue time ``issue_time + issue
  * issue_interval_h``). The truth is ``write_synthetic(path, settings)``; a
  member alone is ``write_synthetic(path, members[m], issue_number=issue)``.

Layout: ``u`` and ``v`` (float32, m/s) have dims ``(member, time, depth, lat,
lon)``. CF (section 2.4) asks for time, depth, latitude and longitude in the
order T, Z, Y, X and for any other dimension to the left of them; the
Copernicus (C3S) and ECMWF ensemble files put their member dimension
(``number``, standard name ``realization``) first in the same way. Member
first also keeps each member's fields contiguous, so reading one member reads
one slab (chunks are one member and one time step). ``member`` is a
coordinate variable, int32 ``0..N-1``, ``standard_name = "realization"``.
Per-member parameters are 1-D variables along ``member`` (gyre:
``member_peak_speed_m_s``, ``member_eps``, ``member_phase_rad``; SCB:
``member_error_draw``). Global attributes are those of the single files for
the base settings (minus the per-member gyre parameters), plus
``ensemble_members``, ``ensemble_seed`` and ``ensemble_method`` saying how the
members were drawn. Writes are atomic (``planner.contract.atomic``).
"""

from __future__ import annotations

import math
import os
import pathlib
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any, TypeGuard

import numpy as np
import xarray as xr

from planner.contract.errors import PlannerError
from planner.forecast.synthetic import double_gyre, scb
from planner.forecast.synthetic.cf_writer import (
    netcdf_encoding,
    parse_time,
    with_numeric_time,
    write_netcdf,
)
from planner.forecast.synthetic.double_gyre import DoubleGyreSettings, synthesize_gyre
from planner.forecast.synthetic.scb import SyntheticSettings, synthesize

__all__ = [
    "ENSEMBLE_VERSION",
    "MAX_MEMBERS",
    "MEMBER_DIM",
    "gyre_ensemble",
    "scb_ensemble",
    "synthesize_gyre_ensemble",
    "synthesize_scb_ensemble",
    "write_gyre_ensemble",
    "write_scb_ensemble",
]

ENSEMBLE_VERSION = "1.0"
MEMBER_DIM = "member"
MAX_MEMBERS = 1000  # a guard against typos: an ensemble is built in memory


class _ArgumentError(PlannerError):
    """A bad argument; ``argument`` lets ``planner.cli.forecast`` name the command-line option."""

    def __init__(self, argument: str, message: str) -> None:
        super().__init__(message)
        self.argument = argument


def _is_int(value: object) -> TypeGuard[int | np.integer[Any]]:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _check_members(members: object) -> int:
    if not (_is_int(members) and 1 <= members <= MAX_MEMBERS):
        raise _ArgumentError("members", f"ensemble: `members` must be an integer in 1..{MAX_MEMBERS}; got {members!r}")
    return int(members)


def _check_non_negative_int(value: object, name: str) -> int:
    if not (_is_int(value) and value >= 0):
        raise _ArgumentError(name, f"ensemble: `{name}` must be an integer >= 0; got {value!r}")
    return int(value)


# --------------------------------------------------------------------------- double gyre


def gyre_ensemble(
    settings: DoubleGyreSettings, members: int, seed: int, spread: float = 0.2
) -> list[DoubleGyreSettings]:
    """The members' settings: ``settings`` with eps, phase and peak speed drawn per member (module docstring)."""
    if not isinstance(settings, DoubleGyreSettings):
        raise _ArgumentError("settings", f"gyre ensemble: `settings` must be DoubleGyreSettings; got {settings!r}")
    n = _check_members(members)
    seed = _check_non_negative_int(seed, "seed")
    if not (isinstance(spread, (int, float, np.integer, np.floating)) and not isinstance(spread, (bool, np.bool_))
            and math.isfinite(spread) and 0.0 <= spread < 1.0):
        raise _ArgumentError("spread", f"gyre ensemble: `spread` must be a number in [0, 1); got {spread!r}")
    rng = np.random.default_rng(seed)
    eps_high = min(2.0 * settings.eps, 0.5)
    out = []
    for _m in range(n):
        eps = float(rng.uniform(0.0, eps_high))
        phase = float(rng.uniform(0.0, 2.0 * np.pi))
        factor = float(rng.uniform(1.0 - spread, 1.0 + spread))
        out.append(replace(settings, eps=eps, phase_rad=phase, peak_speed_m_s=settings.peak_speed_m_s * factor))
    return out


def synthesize_gyre_ensemble(
    settings: DoubleGyreSettings, members: int, seed: int, spread: float = 0.2
) -> xr.Dataset:
    """The gyre ensemble as a CF-1.8 dataset (time as float hours, ready to write); dims in the module docstring."""
    member_settings = gyre_ensemble(settings, members, seed, spread)
    datasets = [synthesize_gyre(s) for s in member_settings]
    _lon, _lat, hours = double_gyre.gyre_axes(settings)
    attrs = double_gyre.global_attrs(settings, parse_time(settings.issue_time), float(hours[-1]))
    for key in ("gyre_peak_speed_m_s", "gyre_eps", "gyre_phase_rad"):
        del attrs[key]  # per member: variables member_*
    attrs["settings"] = repr(settings)
    eps_high = min(2.0 * settings.eps, 0.5)
    attrs.update({
        "title": f"Analytic double gyre currents (Shadden, Lekien and Marsden 2005), ensemble of {len(datasets)}",
        "history": (f"created by planner.forecast.synthetic.ensemble v{ENSEMBLE_VERSION} from planner.forecast.synthetic.double_gyre "
                    f"v{double_gyre.GENERATOR_VERSION}: {len(datasets)} members, seed={seed}, spread={float(spread):g}"
                    "; deterministic, no wall-clock time"),
        "ensemble_kind": "double gyre, perturbed parameters",
        "ensemble_members": np.int64(len(datasets)),
        "ensemble_seed": np.int64(seed),
        "ensemble_spread": float(spread),
        "ensemble_method": (
            "planner.forecast.synthetic.ensemble.gyre_ensemble(settings, members, seed, spread): for member m = 0, 1, ... in turn, "
            f"from numpy.random.default_rng({seed}): eps ~ U[0, {eps_high:g}] (min(2 eps, 0.5)), "
            f"phase_rad ~ U[0, 2 pi), peak_speed_m_s = {settings.peak_speed_m_s:g} x "
            f"U[{1.0 - spread:g}, {1.0 + spread:g}]; everything else as `settings` (the base). "
            "Member m alone: planner.forecast.synthetic.double_gyre.write_gyre(path, gyre_ensemble(...)[m])."),
    })
    extra = {
        "member_peak_speed_m_s": ([s.peak_speed_m_s for s in member_settings], np.float64,
                                  {"long_name": "peak speed of the steady gyre of each member", "units": "m s-1"}),
        "member_eps": ([s.eps for s in member_settings], np.float64,
                       {"long_name": "oscillation amplitude of the dividing line of each member", "units": "1"}),
        "member_phase_rad": ([s.phase_rad for s in member_settings], np.float64,
                             {"long_name": "oscillation phase at the issue time of each member", "units": "rad"}),
    }
    return _stack(datasets, attrs, extra)


def write_gyre_ensemble(
    path: str | os.PathLike[str],
    settings: DoubleGyreSettings,
    members: int,
    seed: int,
    spread: float = 0.2,
) -> pathlib.Path:
    """Write ``synthesize_gyre_ensemble(...)`` to ``path`` as netCDF-4, atomically. Returns the path."""
    return _write(path, synthesize_gyre_ensemble(settings, members, seed, spread))


# --------------------------------------------------------------------------- Southern California Bight


def scb_ensemble(settings: SyntheticSettings, members: int) -> list[SyntheticSettings]:
    """The members' settings: ``settings`` with ``error_draw = 0, 1, ..., members - 1``."""
    if not isinstance(settings, SyntheticSettings):
        raise _ArgumentError("settings", f"scb ensemble: `settings` must be SyntheticSettings; got {settings!r}")
    if settings.error_draw is not None:
        raise _ArgumentError("settings", "scb ensemble: `settings.error_draw` must be None (the members take draws "
                                         f"0..members-1); got {settings.error_draw!r}")
    return [replace(settings, error_draw=m) for m in range(_check_members(members))]


def synthesize_scb_ensemble(settings: SyntheticSettings, members: int, issue: int = 0) -> xr.Dataset:
    """Forecast issue ``issue`` of ``settings`` with ``members`` independent error draws, as a CF-1.8 dataset."""
    member_settings = scb_ensemble(settings, members)
    issue = _check_non_negative_int(issue, "issue")
    datasets = [synthesize(s, issue_number=issue) for s in member_settings]
    issued = scb.issue_datetime(settings, issue_number=issue)
    n = len(datasets)
    attrs = scb.global_attrs(settings, issue, issued, f"forecast issue {issue}, ensemble of {n}")
    relative = settings.error_scale * settings.error_decay**issue
    attrs.update({
        "history": (f"created by planner.forecast.synthetic.ensemble v{ENSEMBLE_VERSION} from planner.forecast.synthetic.scb "
                    f"v{scb.GENERATOR_VERSION}: {n} members of issue {issue}, seed={settings.seed}"
                    "; deterministic, no wall-clock time"),
        "ensemble_kind": "Southern California Bight, independent forecast errors of one size",
        "ensemble_members": np.int64(n),
        "ensemble_seed": np.int64(settings.seed),
        "ensemble_method": (
            f"planner.forecast.synthetic.ensemble.scb_ensemble: member m is forecast issue {issue} of `settings` with error_draw = m, "
            f"its scene perturbation drawn from numpy.random.default_rng([{settings.seed}, 2, {issue}, m]) and "
            f"scaled so that over water RMS|member - truth| / RMS|truth| = error_scale * error_decay**issue = "
            f"{relative:g} before the speed clip; the truth is planner.forecast.synthetic.scb.write_synthetic(path, settings). "
            f"Member m alone: write_synthetic(path, replace(settings, error_draw=m), issue_number={issue})."),
    })
    extra = {
        "member_error_draw": ([s.error_draw for s in member_settings], np.int32,
                              {"long_name": "error draw of each member (SyntheticSettings.error_draw)"}),
    }
    return _stack(datasets, attrs, extra)


def write_scb_ensemble(
    path: str | os.PathLike[str], settings: SyntheticSettings, members: int, issue: int = 0
) -> pathlib.Path:
    """Write ``synthesize_scb_ensemble(...)`` to ``path`` as netCDF-4, atomically. Returns the path."""
    return _write(path, synthesize_scb_ensemble(settings, members, issue))


# --------------------------------------------------------------------------- file


def _stack(
    datasets: Sequence[xr.Dataset],
    attrs: dict[str, object],
    extra: Mapping[str, tuple[Sequence[object], Any, Mapping[str, str]]],
) -> xr.Dataset:
    """Members' datasets (same grid and times) as one dataset with ``u``, ``v`` along a leading ``member``."""
    first = with_numeric_time(datasets[0])
    n = len(datasets)
    data_vars: dict[str, object] = {}
    for name in ("u", "v"):
        values = np.stack([ds[name].values for ds in datasets])
        data_vars[name] = ((MEMBER_DIM, *first[name].dims), values, dict(first[name].attrs))
    for key, var in first.data_vars.items():
        if key not in ("u", "v"):  # the same for every member (the SCB bathymetry h)
            data_vars[str(key)] = var
    for extra_name, (member_values, dtype, var_attrs) in extra.items():
        data_vars[extra_name] = ((MEMBER_DIM,), np.asarray(member_values, dtype=dtype), dict(var_attrs))
    member = (MEMBER_DIM, np.arange(n, dtype=np.int32), {"standard_name": "realization", "long_name": "ensemble member"})
    coords = {MEMBER_DIM: member, **{str(k): v for k, v in first.coords.items()}}
    return xr.Dataset(data_vars=data_vars, coords=coords, attrs=attrs)


def _encoding(ds: xr.Dataset) -> dict[str, dict[str, object]]:
    """The single files' encoding, chunked one member and one time step at a time."""
    encoding = {name: dict(enc) for name, enc in netcdf_encoding(ds).items()}
    for name in ("u", "v"):
        chunks = encoding[name]["chunksizes"]
        if not isinstance(chunks, tuple):  # netcdf_encoding chunks the velocities by a tuple
            raise TypeError(f"{name}: chunksizes {chunks!r} is not a tuple")
        encoding[name]["chunksizes"] = (1, *chunks)
    encoding[MEMBER_DIM] = {"dtype": "int32", "_FillValue": None}
    for key in ds.data_vars:
        if str(key).startswith("member_"):
            encoding[str(key)] = {"_FillValue": None}
    return encoding


def _write(path: str | os.PathLike[str], ds: xr.Dataset) -> pathlib.Path:
    return write_netcdf(path, ds, _encoding(ds))

