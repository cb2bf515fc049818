"""Missions in YAML: parsed once, at the edge, into frozen dataclasses (docs/missions.md).

Every error names the file, the line and the key path, says what was expected
and what was found: ``missions/x.yaml:14 goals[0].depth_m: 40 m is deeper than
the deepest layer 15 m``. Unknown keys are errors.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from planner.contract.errors import LrauvError, MissionError
from planner.contract.geodesy import BBox, swap_hint
from planner.contract.settings import (
    BREACH_ACTION_OPTIONS,
    CRITERIA,
    DEFAULT_TIMING_BLOCK_CELLS,
    MODEL_OPTIONS,
    ON_ARRIVAL_OPTIONS,
    UNCERTAINTY_OPTIONS,
    BreachAction,
    ChoiceT,
    Costs,
    Goal,
    OnArrival,
    PhysicalSettings,
    PlanSettings,
    check_choice,
)
from planner.contract.waypoints import (
    GOAL_FRAMES,
    MAV_CMD_NAV_WAYPOINT,
    MAX_GOALS,
    ArrivalCode,
    MavFrame,
    MissionItem,
    MissionResult,
    WaypointError,
    check_position,
    command_name,
    frame_name,
    from_float32,
    home_item,
    to_e7,
)
from planner.contract.vehicle import VehicleParams

# The defaults of the vehicle figures are the simulator's (one set of numbers for the project).
_VP = VehicleParams()


@dataclass(frozen=True, kw_only=True)
class ForecastSource:
    """Exactly one of ``file`` (``url`` when it is given as an http(s) URL), ``directory`` (watched for new files)
    or ``synthetic_seed``."""

    file: Path | None = None
    url: str | None = None  # kept as written: joined to the mission's folder it would lose a slash of "http://"
    directory: Path | None = None
    synthetic_seed: int | None = None
    synthetic_hours: int = 72
    time_index: int | None = None
    time_iso: str | None = None
    variables: tuple[str, str] | None = None
    grid_file: Path | str | None = None  # an http(s) URL kept as written, as ``url``
    # "missions/x.yaml:7 forecast.file", for errors found when the source is opened; not part of equality
    where: str = field(default="", compare=False, repr=False)


@dataclass(frozen=True, kw_only=True)
class Region:
    """Planning grid: ``bbox`` None means the forecast's own grid."""

    bbox: BBox | None
    nx: int | None
    ny: int | None
    depths_m: tuple[float, ...]
    # "missions/x.yaml:12 region.bbox" where the mission gives one, for a bbox the forecast does not cover
    where: str = field(default="", compare=False, repr=False)


@dataclass(frozen=True, kw_only=True)
class EnergyModel:
    """Electrical power by use, watts (defaults: ``vehicle_sim.dynamics.VehicleParams``, a Tethys-class LRAUV)."""

    hotel_w: float = _VP.hotel_w
    propulsion_w: float = _VP.propulsion_w  # at cruise speed, scaling with (speed / cruise)^3
    buoyancy_w: float = _VP.buoyancy_w
    battery_wh: float = _VP.battery_wh


# A mission sets the cruise speed only; the through-water speed limit (the simulator's cap, and the physical
# model's for station keeping while rotating) keeps VehicleParams' default ratio to it (1.5 m/s / 1.0 m/s),
# and never falls below VehicleParams' default: max(1.5 m/s, 1.5 x cruise), so it is always >= cruise.
MAX_SPEED_RATIO = _VP.max_speed_m_s / _VP.cruise_speed_m_s


@dataclass(frozen=True, kw_only=True)
class Vehicle:
    """The mission's vehicle figures (docs/missions.md); ``params()`` gives the simulator's and the physical
    model's ``VehicleParams`` from them, so one set of figures drives both."""

    cruise_speed_m_s: float = _VP.cruise_speed_m_s
    yaw_rate_deg_s: float = _VP.yaw_rate_deg_s
    glide_rate_m_s: float = _VP.glide_rate_m_s
    energy: EnergyModel = field(default_factory=EnergyModel)

    @property
    def max_speed_m_s(self) -> float:
        """The through-water speed limit: max(VehicleParams' default 1.5 m/s, 1.5 x cruise)."""
        return max(_VP.max_speed_m_s, MAX_SPEED_RATIO * self.cruise_speed_m_s)

    def params(self) -> VehicleParams:
        """These figures as ``VehicleParams``; the figures a mission does not set keep VehicleParams' defaults."""
        e = self.energy
        return VehicleParams(
            cruise_speed_m_s=self.cruise_speed_m_s, max_speed_m_s=self.max_speed_m_s,
            yaw_rate_deg_s=self.yaw_rate_deg_s, glide_rate_m_s=self.glide_rate_m_s,
            hotel_w=e.hotel_w, propulsion_w=e.propulsion_w, buoyancy_w=e.buoyancy_w, battery_wh=e.battery_wh,
        )


@dataclass(frozen=True, kw_only=True)
class MissionGoal:
    goal: Goal
    on_arrival: OnArrival = "hold"
    # "missions/x.yaml:31 goals[0]", for errors found later (a goal on land); "" when uploaded; not part of equality
    where: str = field(default="", compare=False)


@dataclass(frozen=True, kw_only=True)
class Replanning:
    on_new_forecast: bool = True
    period_s: float | None = None


@dataclass(frozen=True, kw_only=True)
class Safety:
    max_mission_time_s: float = 7 * 86400.0
    min_battery_pct: float = 10.0
    max_depth_m: float = 50.0
    geofence: tuple[tuple[float, float], ...] | None = None  # (lon_deg, lat_deg) vertices
    link_loss_timeout_s: float = 30.0
    on_breach: BreachAction = "surface"


@dataclass(frozen=True, kw_only=True)
class Signing:
    """Where the MAVLink 2 signing key comes from; never the key itself (docs/missions.md, "Signing").

    Exactly one of ``key_file`` and ``passphrase_env``. The key is read when it is used
    (``lrauv exec``, ``lrauv upload``: ``executive.signing.load_key``), not here, so that
    planning a mission never needs it; ``where`` names the mission line for those errors.
    """

    key_file: Path | None = None  # 32 raw bytes or 64 hex digits; relative to the mission's folder; ~ expanded
    passphrase_env: str | None = None  # a variable holding a passphrase: key = sha256(passphrase), as MAVProxy's
    link_id: int = 0  # the link id `lrauv upload` signs with (give each ground station its own)
    where: str = ""  # "missions/x.yaml:31 signing.key_file"


@dataclass(frozen=True, kw_only=True)
class Mission:
    name: str
    path: Path
    forecast: ForecastSource
    region: Region
    vehicle: Vehicle
    settings: PlanSettings
    goals: tuple[MissionGoal, ...]
    replanning: Replanning
    safety: Safety
    signing: Signing | None = None  # None: uploads and commands are not signed


def is_url(text: str) -> bool:
    """An ``http://`` or ``https://`` text, as ``planner.forecast.remote.is_url`` (the contract loads no forecast code)."""
    return re.match(r"^https?://", text.strip(), re.IGNORECASE) is not None


MAX_MISSION_BYTES = 1 << 20  # a mission is a few kB; 1,000 goals are about 80 kB
MAX_VALUES = 100_000  # values in the document once YAML aliases are expanded (a "billion laughs" bomb)
# libyaml's composer where PyYAML was built with it: 7 times faster, the same nodes and marks.
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class YamlDocument:
    """A YAML document with the line of every key path, for error messages."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        self.lines: dict[str, int] = {}
        self.n_values = 0
        try:
            node = yaml.compose(text, Loader=_LOADER)
        except yaml.reader.ReaderError as exc:  # a character YAML does not allow (NUL, other controls)
            line = text.count("\n", 0, exc.position) + 1
            raise MissionError(f"{path}:{line}: not valid YAML: character #x{exc.character:04x} is not allowed"
                               f" in YAML ({exc.reason})") from None
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            at_line = f":{mark.line + 1}" if mark is not None else ""
            problem = " ".join((getattr(exc, "problem", None) or str(exc)).split())
            raise MissionError(f"{path}{at_line}: not valid YAML: {problem}") from None
        if node is None:
            raise MissionError(f"{path}: the file is empty; expected a mission mapping")
        self.root = self._build(node, "")

    def _build(self, node: yaml.Node, key: str) -> Any:
        self.n_values += 1
        if self.n_values > MAX_VALUES:
            raise MissionError(f"{self.path}:{node.start_mark.line + 1}: more than {MAX_VALUES:,} values once YAML"
                               " aliases are expanded; a mission needs far fewer (an alias bomb?)")
        self.lines.setdefault(key, node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            out: dict[str, Any] = {}
            for k_node, v_node in node.value:
                name = str(k_node.value)
                sub = f"{key}.{name}" if key else name
                if name in out:
                    raise MissionError(f"{self.path}:{k_node.start_mark.line + 1} {sub}: duplicate key")
                self.lines[sub] = k_node.start_mark.line + 1
                out[name] = self._build(v_node, sub)
            return out
        if isinstance(node, yaml.SequenceNode):
            return [self._build(v, f"{key}[{n}]") for n, v in enumerate(node.value)]
        return _scalar(node)

    def error(self, key: str, message: str) -> MissionError:
        parent = key
        line = self.lines.get(parent)
        while line is None and parent:  # a missing key: point at the nearest enclosing one
            parent = parent[: max(parent.rfind("."), parent.rfind("["), 0)]
            line = self.lines.get(parent)
        where = f"{self.path}:{line}" if line else str(self.path)
        return MissionError(f"{where} {key}: {message}" if key else f"{where}: {message}")


def _scalar(node: yaml.Node) -> Any:
    loader = yaml.SafeLoader("")
    return loader.construct_object(node, deep=True)


class YamlSection:
    """Typed access to one mapping of the document, refusing unknown keys."""

    def __init__(self, doc: YamlDocument, value: Any, key: str, allowed: set[str]) -> None:
        self.doc, self.key = doc, key
        if value is None:
            value = {}
        if not isinstance(value, dict):
            raise doc.error(key, f"expected a mapping; got {type(value).__name__} {value!r}")
        unknown = sorted(set(value) - allowed)
        if unknown:
            first = f"{key}.{unknown[0]}" if key else unknown[0]
            raise doc.error(first, f"unknown key; expected one of: {', '.join(sorted(allowed))}")
        self.value = value

    def path(self, name: str) -> str:
        return f"{self.key}.{name}" if self.key else name

    def has(self, name: str) -> bool:
        return name in self.value and self.value[name] is not None

    def raw(self, name: str, default: Any = None) -> Any:
        return self.value.get(name, default)

    def number(self, name: str, default: float | None = None, *, minimum: float | None = None,
               maximum: float | None = None, unit: str = "") -> float:
        if name not in self.value or self.value[name] is None:
            if default is None:
                raise self.doc.error(self.path(name), f"required; expected a number{(' in ' + unit) if unit else ''}")
            return default
        v = self.value[name]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise self.doc.error(self.path(name), f"expected a number{(' in ' + unit) if unit else ''}; got {v!r}")
        if minimum is not None and v < minimum:
            raise self.doc.error(self.path(name), f"expected at least {minimum:g}{(' ' + unit) if unit else ''}; got {v!r}")
        if maximum is not None and v > maximum:
            raise self.doc.error(self.path(name), f"expected at most {maximum:g}{(' ' + unit) if unit else ''}; got {v!r}")
        return float(v)

    def integer(self, name: str, default: int | None = None, *, minimum: int | None = None) -> int:
        if name not in self.value or self.value[name] is None:
            if default is None:
                raise self.doc.error(self.path(name), "required; expected a whole number")
            return default
        v = self.value[name]
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.doc.error(self.path(name), f"expected a whole number; got {v!r}")
        if minimum is not None and v < minimum:
            raise self.doc.error(self.path(name), f"expected at least {minimum}; got {v}")
        return v

    def text(self, name: str, default: str | None = None) -> str:
        if name not in self.value or self.value[name] is None:
            if default is None:
                raise self.doc.error(self.path(name), "required; expected text")
            return default
        v = self.value[name]
        if not isinstance(v, str) or not v.strip():
            raise self.doc.error(self.path(name), f"expected non-empty text; got {v!r}")
        return v

    def choice(self, name: str, options: tuple[ChoiceT, ...], default: ChoiceT) -> ChoiceT:
        v = self.text(name, default)
        for option in options:
            if option == v:
                return option
        raise self.doc.error(self.path(name), f"expected one of {', '.join(options)}; got {v!r}")

    def boolean(self, name: str, default: bool) -> bool:
        v = self.value.get(name, default)
        if not isinstance(v, bool):
            raise self.doc.error(self.path(name), f"expected true or false; got {v!r}")
        return v

    def section(self, name: str, allowed: set[str]) -> YamlSection:
        return YamlSection(self.doc, self.value.get(name), self.path(name), allowed)


def load_mission(path: str | os.PathLike[str]) -> Mission:
    """Read and validate a mission file; raise MissionError naming file, line and key."""
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > MAX_MISSION_BYTES:
            raise MissionError(f"{p}: {size:,} bytes; a mission file is at most {MAX_MISSION_BYTES:,} bytes"
                               f" ({MAX_GOALS} goals fit in a tenth of that)")
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MissionError(f"{p}: no such mission file") from None
    except UnicodeDecodeError as exc:
        raise MissionError(f"{p}: not a text file (byte {exc.start} is not UTF-8): expected a mission in YAML") from None
    except OSError as exc:
        raise MissionError(f"{p}: cannot read: {exc}") from None
    doc = YamlDocument(p, text)
    top = YamlSection(doc, doc.root, "", {"name", "forecast", "region", "vehicle", "planning", "goals", "replanning", "safety",
                                       "signing"})
    base = p.parent

    fc = top.section("forecast", {"file", "directory", "synthetic", "time", "time_index", "variables", "grid_file"})
    sources = [k for k in ("file", "directory", "synthetic") if fc.has(k)]
    if len(sources) != 1:
        raise doc.error("forecast", f"expected exactly one of file, directory or synthetic; got {sources or 'none'}")
    seed, hours = None, 72
    if fc.has("synthetic"):
        syn = fc.section("synthetic", {"seed", "hours"})
        seed, hours = syn.integer("seed", 0, minimum=0), syn.integer("hours", 72, minimum=1)
    variables = fc.raw("variables")
    if variables is not None and not (
        isinstance(variables, list) and len(variables) == 2 and all(isinstance(x, str) for x in variables)
    ):
        raise doc.error("forecast.variables", f"expected two variable names [U, V]; got {variables!r}")
    file_text = fc.text("file") if fc.has("file") else None
    forecast = ForecastSource(
        file=base / file_text if file_text is not None and not is_url(file_text) else None,
        url=file_text.strip() if file_text is not None and is_url(file_text) else None,
        directory=(base / fc.text("directory")) if fc.has("directory") else None,
        synthetic_seed=seed,
        synthetic_hours=hours,
        time_index=fc.integer("time_index", minimum=0) if fc.has("time_index") else None,
        time_iso=str(fc.raw("time")) if fc.has("time") else None,
        variables=tuple(variables) if variables else None,
        grid_file=None if not fc.has("grid_file") else fc.text("grid_file").strip() if is_url(fc.text("grid_file"))
        else base / fc.text("grid_file"),
        where=f"{doc.path}:{doc.lines[f'forecast.{sources[0]}']} forecast.{sources[0]}",
    )

    rg = top.section("region", {"bbox", "nx", "ny", "depths_m"})
    depths = rg.raw("depths_m")
    if not (isinstance(depths, list) and depths and all(isinstance(d, int | float) and not isinstance(d, bool) for d in depths)):
        raise doc.error("region.depths_m", f"expected a list of layer depths in metres; got {depths!r}")
    if any(d < 0 for d in depths) or any(b <= a for a, b in zip(depths, depths[1:])):
        raise doc.error("region.depths_m", f"expected non-negative depths, strictly increasing; got {depths}")
    bbox_raw = rg.raw("bbox", "forecast")
    if bbox_raw == "forecast":
        bbox, nx, ny = None, (rg.integer("nx", minimum=2) if rg.has("nx") else None), (rg.integer("ny", minimum=2) if rg.has("ny") else None)
    else:
        if not (isinstance(bbox_raw, list) and len(bbox_raw) == 4 and all(isinstance(x, int | float) and not isinstance(x, bool) for x in bbox_raw)):
            raise doc.error("region.bbox", f"expected [WEST, SOUTH, EAST, NORTH] in degrees or 'forecast'; got {bbox_raw!r}")
        try:
            bbox = BBox(west_deg=bbox_raw[0], south_deg=bbox_raw[1], east_deg=bbox_raw[2], north_deg=bbox_raw[3])
        except LrauvError as exc:
            raise doc.error("region.bbox", str(exc).split(": ", 1)[-1]) from None
        nx, ny = rg.integer("nx", minimum=2), rg.integer("ny", minimum=2)
    bbox_line = doc.lines.get("region.bbox") if bbox is not None else None
    region = Region(bbox=bbox, nx=nx, ny=ny, depths_m=tuple(float(d) for d in depths),
                    where=f"{doc.path}:{bbox_line} region.bbox" if bbox_line else "")

    vh = top.section("vehicle", {"cruise_speed_m_s", "yaw_rate_deg_s", "glide_rate_m_s", "energy"})
    en = vh.section("energy", {"hotel_w", "propulsion_w", "buoyancy_w", "battery_wh"})
    d_en, d_vh = EnergyModel(), Vehicle()
    vehicle = Vehicle(
        cruise_speed_m_s=vh.number("cruise_speed_m_s", d_vh.cruise_speed_m_s, minimum=0.01, unit="m/s"),
        yaw_rate_deg_s=vh.number("yaw_rate_deg_s", d_vh.yaw_rate_deg_s, minimum=0.1, unit="deg/s"),
        glide_rate_m_s=vh.number("glide_rate_m_s", d_vh.glide_rate_m_s, minimum=0.01, unit="m/s"),
        energy=EnergyModel(
            hotel_w=en.number("hotel_w", d_en.hotel_w, minimum=0, unit="W"),
            propulsion_w=en.number("propulsion_w", d_en.propulsion_w, minimum=0, unit="W"),
            buoyancy_w=en.number("buoyancy_w", d_en.buoyancy_w, minimum=0, unit="W"),
            battery_wh=en.number("battery_wh", d_en.battery_wh, minimum=1, unit="Wh"),
        ),
    )

    pl = top.section("planning", {"model", "criterion", "uncertainty", "costs", "calm_speed_m_s", "physical",
                                  "time_varying", "horizon_h", "slice_h", "timing_correction",
                                  "timing_block_cells"})
    model = pl.choice("model", MODEL_OPTIONS, "paper")
    criterion_text = pl.text("criterion", "robust")
    if criterion_text not in CRITERIA[model]:
        has = CRITERIA[model]
        known = criterion_text in {c for cs in CRITERIA.values() for c in cs}
        raise doc.error("planning.criterion", f"the {model} model has {' and '.join(has)}; got {criterion_text!r}"
                        if known else f"expected one of {', '.join(has)} (the {model} model's); got {criterion_text!r}")
    criterion = check_choice("planning.criterion", criterion_text, CRITERIA[model])
    cs = pl.section("costs", {"drift", "forward", "rotate", "glide"})
    d_costs = Costs()
    try:
        costs = Costs(**{name: cs.raw(name, getattr(d_costs, name)) for name in ("drift", "forward", "rotate", "glide")})
    except LrauvError as exc:
        key = str(exc).split(":", 1)[0]
        raise doc.error(f"planning.{key}", str(exc).split(": ", 1)[-1]) from None
    time_varying = pl.boolean("time_varying", False)
    if time_varying and model != "physical":
        raise doc.error("planning.time_varying", f"needs planning.model physical (its transitions carry durations); got {model!r}")
    timing_correction = pl.boolean("timing_correction", False)
    timing_block = pl.integer("timing_block_cells", minimum=1) if pl.has("timing_block_cells") else None
    if timing_block is not None and not timing_correction:  # a key that would do nothing: refused, not ignored
        raise doc.error("planning.timing_block_cells", "a reference current per block is for the tide's timing: it needs"
                                                       " planning.timing_correction: true")
    settings = PlanSettings(
        model=model,
        criterion=criterion,
        uncertainty=pl.choice("uncertainty", UNCERTAINTY_OPTIONS, "lateral"),
        costs=costs,
        calm_speed_m_s=pl.number("calm_speed_m_s", 0.01, minimum=0, unit="m/s"),
        physical=_physical(doc, pl),
        vehicle=vehicle.params(),
        time_varying=time_varying,
        horizon_h=pl.number("horizon_h", 72.0, minimum=1, unit="h"),
        slice_h=pl.number("slice_h", minimum=0.01, unit="h") if pl.has("slice_h") else None,
        timing_correction=timing_correction,
        timing_block_cells=DEFAULT_TIMING_BLOCK_CELLS if timing_block is None else timing_block,
        error_measured=_measured(pl),
    )

    goals_raw = top.raw("goals")
    if not isinstance(goals_raw, list) or not goals_raw:
        raise doc.error("goals", f"expected a list of one or more goals; got {goals_raw!r}")
    if len(goals_raw) > MAX_GOALS:
        raise doc.error("goals", f"expected at most {MAX_GOALS} goals; got {len(goals_raw)}")
    goals = []
    deepest = region.depths_m[-1]
    for n, g_raw in enumerate(goals_raw):
        g = YamlSection(doc, g_raw, f"goals[{n}]", {"lat_deg", "lon_deg", "depth_m", "radius_cells", "on_arrival"})
        lat = g.number("lat_deg", unit="degrees")
        lon = g.number("lon_deg", unit="degrees")
        depth = g.number("depth_m", unit="m", minimum=0)
        if not -90 <= lat <= 90:
            raise doc.error(g.path("lat_deg"), f"expected a latitude in [-90, 90]; got {lat:g}{swap_hint(lon, lat)}")
        if depth > deepest + 1e-9:
            raise doc.error(g.path("depth_m"), f"{depth:g} m is deeper than the deepest layer {deepest:g} m")
        goals.append(
            MissionGoal(
                goal=Goal(lon_deg=lon, lat_deg=lat, depth_m=depth, radius_cells=g.integer("radius_cells", 1, minimum=0)),
                on_arrival=g.choice("on_arrival", ON_ARRIVAL_OPTIONS, "hold"),
                where=f"{doc.path}:{doc.lines[g.key]} {g.key}",
            )
        )

    rp = top.section("replanning", {"on_new_forecast", "period_h"})
    replanning = Replanning(
        on_new_forecast=rp.boolean("on_new_forecast", True),
        period_s=rp.number("period_h", minimum=0.01, unit="h") * 3600.0 if rp.has("period_h") else None,
    )

    sf = top.section("safety", {"max_mission_time_h", "min_battery_pct", "max_depth_m", "geofence", "link_loss_timeout_s", "on_breach"})
    fence_raw = sf.raw("geofence")
    fence = None
    if fence_raw is not None:
        if not (isinstance(fence_raw, list) and len(fence_raw) >= 3 and all(
            isinstance(pt, list) and len(pt) == 2 and all(isinstance(x, int | float) and not isinstance(x, bool) for x in pt)
            for pt in fence_raw
        )):
            raise doc.error("safety.geofence", "expected a polygon of at least 3 [LON, LAT] vertices in degrees")
        fence = tuple((float(a), float(b)) for a, b in fence_raw)
    safety = Safety(
        max_mission_time_s=sf.number("max_mission_time_h", 7 * 24.0, minimum=0.01, unit="h") * 3600.0,
        min_battery_pct=sf.number("min_battery_pct", 10.0, minimum=0, maximum=100, unit="%"),
        max_depth_m=sf.number("max_depth_m", 50.0, minimum=0, unit="m"),
        geofence=fence,
        link_loss_timeout_s=sf.number("link_loss_timeout_s", 30.0, minimum=0.1, unit="s"),
        on_breach=sf.choice("on_breach", BREACH_ACTION_OPTIONS, "surface"),
    )
    if safety.max_depth_m < deepest:
        raise doc.error("safety.max_depth_m", f"{safety.max_depth_m:g} m is shallower than the deepest layer {deepest:g} m")
    return Mission(
        name=top.text("name"), path=p, forecast=forecast, region=region, vehicle=vehicle, settings=settings,
        goals=tuple(goals), replanning=replanning, safety=safety,
        signing=_signing(doc, top, base) if top.has("signing") else None,
    )


PHYSICAL_INTEGERS = ("start_points", "error_members", "rk4_steps", "max_iterations")
PHYSICAL_NUMBERS = {"current_error_m_s": "m/s", "max_transition_s": "s", "min_cost_wh": "Wh", "tolerance_wh": "Wh"}


def _measured(pl: YamlSection) -> bool:
    """``planning.physical.current_error_m_s: measured``: the size from the data (docs/time-varying.md)."""
    ph = pl.raw("physical")
    return isinstance(ph, dict) and ph.get("current_error_m_s") == "measured"


def _physical(doc: YamlDocument, pl: YamlSection) -> PhysicalSettings:
    """``planning.physical``: the physical model's sampling (docs/physical-model.md); the paper model ignores it.

    A key that is absent or null keeps ``PhysicalSettings``' default (for ``max_transition_s`` that is None:
    the model's own limit from the cell size and the cruise speed).
    """
    ph = pl.section("physical", set(PHYSICAL_INTEGERS) | set(PHYSICAL_NUMBERS) | {"course_offsets"})
    d = PhysicalSettings()
    values: dict[str, Any] = {name: ph.integer(name) if ph.has(name) else getattr(d, name) for name in PHYSICAL_INTEGERS}
    values.update({name: ph.number(name, unit=unit) if ph.has(name) and not (name == "current_error_m_s" and _measured(pl))
                   else getattr(d, name) for name, unit in PHYSICAL_NUMBERS.items()})
    values["course_offsets"] = ph.boolean("course_offsets", d.course_offsets) if ph.has("course_offsets") else d.course_offsets
    try:
        return PhysicalSettings(**values)
    except LrauvError as exc:  # "physical.NAME: message"
        key, _, message = str(exc).partition(": ")
        raise doc.error(f"planning.{key}", message) from None


def _signing(doc: YamlDocument, top: YamlSection, base: Path) -> Signing:
    sg = top.section("signing", {"key_file", "passphrase_env", "link_id"})
    sources = [k for k in ("key_file", "passphrase_env") if sg.has(k)]
    if len(sources) != 1:
        raise doc.error("signing", f"expected exactly one of key_file or passphrase_env (the key itself never goes"
                                   f" in a mission file); got {sources or 'none'}")
    name = sources[0]
    value = sg.text(name)
    if name == "passphrase_env" and not value.replace("_", "").isalnum():
        raise doc.error("signing.passphrase_env", f"expected the name of an environment variable; got {value!r}")
    link_id = sg.integer("link_id", 0, minimum=0)
    if link_id > 255:
        raise doc.error("signing.link_id", f"expected 0 to 255; got {link_id}")
    line = doc.lines.get(f"signing.{name}")
    return Signing(key_file=base / Path(value).expanduser() if name == "key_file" else None,
                   passphrase_env=value if name == "passphrase_env" else None,
                   link_id=link_id, where=f"{doc.path}:{line} signing.{name}")


# -- goals as MAVLink mission items (the encoding is planner.contract.waypoints')


def goals_to_items(goals: Sequence[MissionGoal], *, home_lat_deg: float, home_lon_deg: float) -> tuple[MissionItem, ...]:
    """Home, then one MAV_CMD_NAV_WAYPOINT per goal (the encoding in ``planner.contract.waypoints``)."""
    items = [home_item(home_lat_deg, home_lon_deg)]
    for n, mg in enumerate(goals):
        g = mg.goal
        check_position(f"goal {n}", g.lat_deg, g.lon_deg)
        if not (math.isfinite(g.depth_m) and g.depth_m >= 0):
            raise WaypointError(f"goal {n}: depth {g.depth_m!r} m: expected a depth >= 0 m")
        items.append(MissionItem(
            n + 1, int(MavFrame.GLOBAL_RELATIVE_ALT_INT), MAV_CMD_NAV_WAYPOINT, 0, 1,
            0.0, float(g.radius_cells), float(ArrivalCode[mg.on_arrival.upper()].value), 0.0,
            to_e7(g.lat_deg), to_e7(g.lon_deg), 0.0 - g.depth_m,
        ))
    return tuple(items)


def items_to_goals(items: Sequence[MissionItem]) -> tuple[MissionGoal, ...]:
    """The goals in a mission (item 0 is home and skipped); WaypointError names the item and what is wrong."""
    for n, item in enumerate(items):
        if item.seq != n:
            raise WaypointError(f"item {item.seq}: out of sequence; expected seq {n}", MissionResult.INVALID_SEQUENCE)
        if item.mission_type != 0:
            raise WaypointError(f"item {n}: mission_type {item.mission_type} is not a mission (0)", MissionResult.UNSUPPORTED)
    if not items:  # MISSION_CLEAR_ALL or a count of 0 (MAVProxy's `wp clear`): there is no goal-less plan to fly
        raise WaypointError("clearing the goals is not supported: the vehicle keeps its current goals; to change them "
                            "upload a new mission (`wp load FILE`, `lrauv upload`); to stop, change the autopilot's mode "
                            "(the executive then stands aside)", MissionResult.UNSUPPORTED)
    if len(items) < 2:
        raise WaypointError("no goals: expected home (item 0) and at least one goal item", MissionResult.INVALID)
    if len(items) - 1 > MAX_GOALS:
        raise WaypointError(f"{len(items) - 1} goals: expected at most {MAX_GOALS}", MissionResult.NO_SPACE)
    goals = []
    for item in items[1:]:
        lat, lon, depth, radius, code = _goal_fields(item)
        goals.append(MissionGoal(goal=Goal(lon_deg=lon, lat_deg=lat, depth_m=depth, radius_cells=radius),
                                 on_arrival=check_choice("on_arrival", code.on_arrival, ON_ARRIVAL_OPTIONS)))
    return tuple(goals)


def _goal_fields(item: MissionItem) -> tuple[float, float, float, int, ArrivalCode]:
    where = f"item {item.seq}"
    if item.command != MAV_CMD_NAV_WAYPOINT:
        raise WaypointError(f"{where}: command {command_name(item.command)} is not a goal; "
                            f"expected {command_name(MAV_CMD_NAV_WAYPOINT)}", MissionResult.UNSUPPORTED)
    if item.frame not in GOAL_FRAMES:
        raise WaypointError(f"{where}: frame {frame_name(item.frame)} is not supported; expected "
                            f"{frame_name(MavFrame.GLOBAL_RELATIVE_ALT_INT)} or {frame_name(MavFrame.GLOBAL_RELATIVE_ALT)}",
                            MissionResult.UNSUPPORTED_FRAME)
    if item.param1 != 0:
        raise WaypointError(f"{where}: param1 (hold time) {item.param1:g} s is not supported; expected 0",
                            MissionResult.INVALID_PARAM1)
    radius = item.param2
    if not (math.isfinite(radius) and radius >= 0 and radius == int(radius)):
        raise WaypointError(f"{where}: param2 (radius_cells) {radius:g} is not a whole number >= 0",
                            MissionResult.INVALID_PARAM2)
    code = item.param3
    if not (math.isfinite(code) and code == int(code) and int(code) in {c.value for c in ArrivalCode}):
        known = ", ".join(f"{c.value} {c.on_arrival}" for c in ArrivalCode)
        raise WaypointError(f"{where}: param3 (on_arrival) {code:g} is not a known code; expected {known}",
                            MissionResult.INVALID_PARAM3)
    lat, lon = item.lat_deg, item.lon_deg
    if not -90 <= lat <= 90:
        raise WaypointError(f"{where}: latitude {lat:.7f} deg is out of range [-90, 90]", MissionResult.INVALID_PARAM5_X)
    if not -180 <= lon <= 180:
        raise WaypointError(f"{where}: longitude {lon:.7f} deg is out of range [-180, 180]", MissionResult.INVALID_PARAM6_Y)
    if not math.isfinite(item.z) or item.z > 0:
        raise WaypointError(f"{where}: z {item.z:g} m is above the surface; expected z <= 0 (z = -depth_m)",
                            MissionResult.INVALID_PARAM7)
    depth = 0.0 - from_float32(item.z)
    return lat, lon, depth, int(radius), ArrivalCode(int(code))
