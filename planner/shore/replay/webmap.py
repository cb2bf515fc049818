"""The report's interactive map: inline SVG and a few lines of plain JavaScript, nothing fetched.

The page must open on a ship's laptop with no network, so there are no map tiles,
no CDN and no library: the SVG draws, in local metres east and north of the
dive (equirectangular about its middle latitude), the land of the policy table
(layer 0), the planning forecast's surface currents as arrows, the geofence of the
helm's settings, the goal and its goal cells, and the track filtered of position
noise (``track_filter``) coloured by the action decided, with the start and the
end. The script pans (drag), zooms (wheel, or the buttons, about the pointer or
the middle) by moving the SVG's ``viewBox``, and keeps the markers the same size
on the screen. Each track piece, arrow and marker has a ``<title>`` tooltip.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from executive.helm import HelmConfig
from planner.contract.geodesy import EARTH_RADIUS_M
from planner.shore.plots.dive_track import TrackSegment, action_color, action_name, action_order, track_segments
from planner.shore.plots.style import FLOW_ARROW_COLOR, GOAL_COLOR, LAND_COLOR, START_COLOR

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.contract.table import PolicyTable
    from planner.pipeline import PlanResult
    from planner.shore.replay.dive import Dive, Track

__all__ = ["MAP_ID", "geofence_of", "map_section"]

MAP_ID = "dive-map"
GEOFENCE_COLOR = "#d62728"
WIDTH_PX = 960  # the drawing's size on a wide screen; it scales to the page
MAX_ARROWS_PER_AXIS = 40


# --------------------------------------------------------------------------- geofence


def geofence_of(dive: Dive) -> tuple[tuple[float, float], ...] | None:
    """The helm's geofence, (lon_deg, lat_deg) vertices, from the log's ``helm`` metadata; None without one."""
    config = dive.log.metadata.get("helm", {}).get("config")
    return None if config is None else HelmConfig.from_json(config).geofence


# --------------------------------------------------------------------------- the map


@dataclass(frozen=True, slots=True)
class _Plane:
    """Local metres: x east, y south (SVG's y grows downwards), about (lon0, lat0)."""

    lon0_deg: float
    lat0_deg: float

    def x(self, lon_deg: NDArray[np.float64] | float) -> NDArray[np.float64]:
        k = math.radians(1.0) * EARTH_RADIUS_M * math.cos(math.radians(self.lat0_deg))
        return np.asarray((np.asarray(lon_deg, np.float64) - self.lon0_deg) * k)

    def y(self, lat_deg: NDArray[np.float64] | float) -> NDArray[np.float64]:
        return np.asarray(-(np.asarray(lat_deg, np.float64) - self.lat0_deg) * math.radians(1.0) * EARTH_RADIUS_M)


def _f(v: float) -> str:
    return f"{v:.1f}"


def _points(x: NDArray[np.float64], y: NDArray[np.float64]) -> str:
    return " ".join(f"{_f(a)},{_f(b)}" for a, b in zip(x, y))


def map_section(dive: Dive, *, table: PolicyTable | None, goals: Sequence[PolicyTable],
                plan: PlanResult | None) -> tuple[str, list[str]]:
    """The map's HTML (a ``<figure>`` with the SVG, its buttons, legend and script) and notes on what it lacks.

    Empty HTML when no decision has a position.
    """

    track = dive.track
    segments = [s for s in track_segments(track) if s.rows.size > 0]
    if not segments:
        return "", ["the map is not drawn: no decision in the log has a position"]
    lat, lon = _filtered_positions(track)
    rows = np.concatenate([s.rows for s in segments])
    goal_lon = [t.goal_lon_deg for t in goals]
    goal_lat = [t.goal_lat_deg for t in goals]
    west, east = float(np.min(np.r_[lon[rows], goal_lon])), float(np.max(np.r_[lon[rows], goal_lon]))
    south, north = float(np.min(np.r_[lat[rows], goal_lat])), float(np.max(np.r_[lat[rows], goal_lat]))
    plane = _Plane(0.5 * (west + east), 0.5 * (south + north))
    x0, x1 = float(plane.x(west)), float(plane.x(east))
    y0, y1 = float(plane.y(north)), float(plane.y(south))
    least = 8 * _cell_m(table, plane) if table is not None else 500.0
    pad_x = max(0.08 * (x1 - x0), 0.5 * max(0.0, least - (x1 - x0)), 50.0)
    pad_y = max(0.08 * (y1 - y0), 0.5 * max(0.0, least - (y1 - y0)), 50.0)
    view = (x0 - pad_x, y0 - pad_y, x1 - x0 + 2 * pad_x, y1 - y0 + 2 * pad_y)
    px = view[2] / WIDTH_PX  # metres per screen pixel at the start
    notes: list[str] = []
    legend: list[tuple[str, str]] = []  # (swatch style, label)

    layers = []
    if table is not None:
        layers.append(_land(table, plane))
        legend.append((f"background:{LAND_COLOR}", "land (policy table, layer 0)"))
    else:
        notes.append("the map has no land: the log has no policy table attached")
    if plan is not None:
        arrows, key = _currents(plan, plane, px)
        layers.append(arrows)
        when = plan.table.forecast_time or f"step {plan.time_index}"
        legend.append((f"background:{FLOW_ARROW_COLOR}", f"current at {plan.grid.depth_m[0]:g} m, forecast of {when}"
                                                         f" (an arrow of one spacing: {key})"))
    else:
        notes.append("the map has no currents: they need the planning forecast (pass --forecast)")
    fence = geofence_of(dive)
    if fence:
        vx, vy = plane.x(np.array([v[0] for v in fence])), plane.y(np.array([v[1] for v in fence]))
        layers.append(f'<polygon id="map-geofence" points="{_points(vx, vy)}" fill="none" stroke="{GEOFENCE_COLOR}"'
                      ' stroke-width="2" stroke-dasharray="8 5" vector-effect="non-scaling-stroke">'
                      "<title>geofence (helm settings)</title></polygon>")
        legend.append((f"border:2px dashed {GEOFENCE_COLOR}", "geofence"))
    else:
        notes.append("the map has no geofence: the helm's settings in the log have none")
    layers.append(_goals(goals, plane, px))
    legend.append((f"background:{GOAL_COLOR};opacity:0.5", "goal cells and goal"))
    layers.append(_track(track, segments, lat, lon, plane))
    for a in action_order([s.action for s in segments]):
        legend.append((f"background:{action_color(a)}", action_name(a)))
    layers.append(_pins(track, rows, lat, lon, plane, px))
    legend.append((f"background:{START_COLOR};border-radius:50%", "start (first decision)"))
    legend.append(("background:white;border:2px solid black;border-radius:50%", "end of the log"))

    e = html.escape
    height = WIDTH_PX * view[3] / view[2]
    parts = [
        '<figure class="map">',
        '<div class="map-tools"><button type="button" data-zoom="0.5">+</button>'
        '<button type="button" data-zoom="2">&minus;</button><button type="button" data-zoom="0">reset</button>'
        " drag to pan, wheel to zoom</div>",
        f'<svg id="{MAP_ID}" viewBox="{" ".join(_f(v) for v in view)}" width="{WIDTH_PX}" height="{height:.0f}"'
        ' preserveAspectRatio="none" role="img" aria-label="map of the dive">',
        '<rect id="map-sea" x="-1e7" y="-1e7" width="2e7" height="2e7" fill="#eef4f9"/>',
        *layers,
        "</svg>",
        '<ul class="legend">',
        *(f'<li><span class="swatch" style="{e(style)}"></span>{e(label)}</li>' for style, label in legend),
        "</ul>",
        f"<figcaption>The track, filtered of position noise (the median fix of every {track.filtered().window_s:g} s),"
        " coloured by the action the executive decided; hover for times. Metres east and north of the middle of the"
        " dive.</figcaption>",
        f"<script>{_SCRIPT}</script>",
        "</figure>",
    ]
    return "\n".join(parts), notes


def _filtered_positions(track: Track) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each row's position on the filtered track, at the row's (running latest) vehicle time."""
    f = track.filtered()
    t = np.maximum.accumulate(np.where(np.isfinite(track.time_s), track.time_s, -np.inf))
    if len(f) == 0:
        return np.full(len(track), np.nan), np.full(len(track), np.nan)
    return np.interp(t, f.time_s, f.lat_deg), np.interp(t, f.time_s, f.lon_deg)


def _cell_m(table: PolicyTable, plane: _Plane) -> float:
    return float(min(plane.x(plane.lon0_deg + table.dlon_deg), -plane.y(plane.lat0_deg + table.dlat_deg)))


def _land(table: PolicyTable, plane: _Plane) -> str:
    """Land cells of layer 0, one rectangle per run of land along a row."""
    hx, hy = 0.5 * table.dlon_deg, 0.5 * table.dlat_deg
    out = ['<g id="map-land" fill="' + LAND_COLOR + '" stroke="none"><title>land (policy table)</title>']
    land = ~table.water[0]
    for j in range(table.ny):
        row = np.concatenate([[False], land[j], [False]])
        starts = np.flatnonzero(~row[:-1] & row[1:])
        stops = np.flatnonzero(row[:-1] & ~row[1:])
        top = float(plane.y(table.lat_deg[j] + hy))
        bottom = float(plane.y(table.lat_deg[j] - hy))
        for a, b in zip(starts, stops):
            left, right = float(plane.x(table.lon_deg[a] - hx)), float(plane.x(table.lon_deg[b - 1] + hx))
            out.append(f'<rect x="{_f(left)}" y="{_f(top)}" width="{_f(right - left)}" height="{_f(bottom - top)}"/>')
    out.append("</g>")
    return "\n".join(out)


def _currents(plan: PlanResult, plane: _Plane, px: float) -> tuple[str, str]:
    """Arrows of the planning forecast's top layer, thinned to ``MAX_ARROWS_PER_AXIS``; and the scale's words."""
    grid = plan.grid
    u, v = np.asarray(plan.u_m_s[0], np.float64), np.asarray(plan.v_m_s[0], np.float64)
    speed = np.hypot(u, v)
    stride = max(1, math.ceil(max(grid.lon_deg.size, grid.lat_deg.size) / MAX_ARROWS_PER_AXIS))
    spacing_m = stride * min(float(plane.x(plane.lon0_deg + grid.dlon_deg)),
                             float(-plane.y(plane.lat0_deg + grid.dlat_deg)))
    v98 = float(np.nanpercentile(speed, 98)) if np.isfinite(speed).any() else 0.0
    m_per_m_s = 0.9 * spacing_m / v98 if v98 > 0 else 0.0  # the 98th percentile speed spans 0.9 of a spacing
    out = [f'<g id="map-currents" stroke="{FLOW_ARROW_COLOR}" stroke-width="1.2" fill="none"'
           ' vector-effect="non-scaling-stroke">']
    for j in range(0, grid.lat_deg.size, stride):
        for i in range(0, grid.lon_deg.size, stride):
            s = speed[j, i]
            if not math.isfinite(s) or s <= 0:
                continue
            cx, cy = float(plane.x(grid.lon_deg[i])), float(plane.y(grid.lat_deg[j]))
            dx, dy = u[j, i] * m_per_m_s, -v[j, i] * m_per_m_s
            ax, ay, bx, by = cx - dx / 2, cy - dy / 2, cx + dx / 2, cy + dy / 2
            head = 0.3 * math.hypot(dx, dy)
            angle = math.atan2(dy, dx)
            h1 = (bx - head * math.cos(angle - 0.45), by - head * math.sin(angle - 0.45))
            h2 = (bx - head * math.cos(angle + 0.45), by - head * math.sin(angle + 0.45))
            out.append(f'<path d="M{_f(ax)} {_f(ay)}L{_f(bx)} {_f(by)}M{_f(h1[0])} {_f(h1[1])}L{_f(bx)} {_f(by)}'
                       f'L{_f(h2[0])} {_f(h2[1])}" vector-effect="non-scaling-stroke"><title>{s:.2f} m/s</title></path>')
    out.append("</g>")
    return "\n".join(out), f"{v98 / 0.9:.2f} m/s" if v98 > 0 else "no current"


def _goals(goals: Sequence[PolicyTable], plane: _Plane, px: float) -> str:
    out = [f'<g id="map-goal" fill="{GOAL_COLOR}">']
    for t in goals:
        cell = t.locate(t.goal_lat_deg, t.goal_lon_deg, t.goal_depth_m)
        if cell is not None:  # the goal cells: within goal_radius cells (Chebyshev) of the goal's (spec section 6)
            _, j, i = cell
            hx, hy = (t.goal_radius_cells + 0.5) * t.dlon_deg, (t.goal_radius_cells + 0.5) * t.dlat_deg
            left, top = float(plane.x(t.lon_deg[i] - hx)), float(plane.y(t.lat_deg[j] + hy))
            right, bottom = float(plane.x(t.lon_deg[i] + hx)), float(plane.y(t.lat_deg[j] - hy))
            out.append(f'<rect class="goal-cells" x="{_f(left)}" y="{_f(top)}" width="{_f(right - left)}"'
                       f' height="{_f(bottom - top)}" fill-opacity="0.22"><title>goal cells: within'
                       f" {t.goal_radius_cells} cell(s) of the goal's</title></rect>")
        out.append(f'<circle class="pin" data-px="7" cx="{_f(float(plane.x(t.goal_lon_deg)))}"'
                   f' cy="{_f(float(plane.y(t.goal_lat_deg)))}" r="{_f(7 * px)}" stroke="black" stroke-width="1.5"'
                   f' vector-effect="non-scaling-stroke"><title>goal ({t.goal_lon_deg:.5f}, {t.goal_lat_deg:.5f}),'
                   f" {t.goal_depth_m:g} m</title></circle>")
    out.append("</g>")
    return "\n".join(out)


def _track(track: Track, segments: Sequence[TrackSegment], lat: NDArray[np.float64], lon: NDArray[np.float64],
           plane: _Plane) -> str:
    out = ['<g id="map-track" fill="none" stroke-linejoin="round" stroke-linecap="round">']
    for s in segments:
        rows, action = s.rows, s.action
        x, y = plane.x(lon[rows]), plane.y(lat[rows])
        t0, t1 = float(track.time_s[rows[0]]), float(track.time_s[rows[-1]])
        out.append(f'<polyline class="track" data-action="{html.escape(action or "")}" points="{_points(x, y)}"'
                   f' stroke="{action_color(action)}" stroke-width="3" vector-effect="non-scaling-stroke">'
                   f"<title>{html.escape(action_name(action))}, {t0:.1f} s to {t1:.1f} s vehicle time</title>"
                   "</polyline>")
    out.append("</g>")
    return "\n".join(out)


def _pins(track: Track, rows: NDArray[np.int64], lat: NDArray[np.float64], lon: NDArray[np.float64],
          plane: _Plane, px: float) -> str:
    first, last = int(rows.min()), int(rows.max())
    out = ['<g id="map-ends" stroke="black" stroke-width="1.5">']
    for row, fill, what in ((first, START_COLOR, "start (first decision)"), (last, "white", "end of the log")):
        out.append(f'<circle class="pin" data-px="6" cx="{_f(float(plane.x(lon[row])))}"'
                   f' cy="{_f(float(plane.y(lat[row])))}" r="{_f(6 * px)}" fill="{fill}"'
                   f' vector-effect="non-scaling-stroke"><title>{what}, {track.time_s[row]:.1f} s</title></circle>')
    out.append("</g>")
    return "\n".join(out)


# Pan and zoom by moving the viewBox; markers keep their size on the screen (their data-px).
_SCRIPT = """
(function () {
  var svg = document.getElementById("%s"), vb = svg.viewBox.baseVal;
  var home = [vb.x, vb.y, vb.width, vb.height], drag = null;
  function scale() { return vb.width / svg.getBoundingClientRect().width; }
  function pins() {
    var u = scale();
    svg.querySelectorAll(".pin").forEach(function (c) { c.setAttribute("r", c.dataset.px * u); });
  }
  function set(x, y, w, h) { vb.x = x; vb.y = y; vb.width = w; vb.height = h; pins(); }
  function zoom(f, cx, cy) { set(cx - (cx - vb.x) * f, cy - (cy - vb.y) * f, vb.width * f, vb.height * f); }
  function at(e) {
    var r = svg.getBoundingClientRect();
    return [vb.x + (e.clientX - r.left) / r.width * vb.width, vb.y + (e.clientY - r.top) / r.height * vb.height];
  }
  svg.addEventListener("wheel", function (e) {
    e.preventDefault(); var p = at(e); zoom(e.deltaY < 0 ? 0.8 : 1.25, p[0], p[1]);
  }, {passive: false});
  svg.addEventListener("pointerdown", function (e) { drag = [e.clientX, e.clientY]; svg.setPointerCapture(e.pointerId); });
  svg.addEventListener("pointermove", function (e) {
    if (!drag) return;
    var u = scale();
    set(vb.x - (e.clientX - drag[0]) * u, vb.y - (e.clientY - drag[1]) * u, vb.width, vb.height);
    drag = [e.clientX, e.clientY];
  });
  svg.addEventListener("pointerup", function () { drag = null; });
  svg.parentNode.querySelectorAll("button[data-zoom]").forEach(function (b) {
    b.addEventListener("click", function () {
      var f = parseFloat(b.dataset.zoom);
      if (f === 0) set(home[0], home[1], home[2], home[3]);
      else zoom(f, vb.x + vb.width / 2, vb.y + vb.height / 2);
    });
  });
  window.addEventListener("resize", pins);
  pins();
})();
""" % MAP_ID
