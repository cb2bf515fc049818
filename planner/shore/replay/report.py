"""A post-dive report: pictures of a logged dive and one HTML page that shows them (``lrauv replay --report``).

``write_report`` draws, from an ``planner.shore.replay.dive.Dive``, the tables attached to
its log and, when the planning forecast was found, the plan made again from it
(``planner.shore.replay.nominal.plan_again``):

- ``track.png``: the track coloured by the action decided, over land (the
  table's water mask, layer 0) and, with a plan, the surface-layer currents of
  the planning forecast and the nominal path from the first decision's state;
- ``timeseries.png``: depth, heading, action and energy used against vehicle time;
- ``cost.png`` (with a plan only): the predicted cost-to-go of the state at each
  decision (spec section 8; for a physical plan the energy still to spend, Wh, on
  the same scale as the energy spent) against the energy actually spent;
- ``index.html``: a header (mission, table, UTC start and end, the decision
  audit's verdict, links to the exports written with it), the autopilot's
  failsafes and status texts, an interactive map (``planner.shore.replay.webmap``:
  inline SVG, nothing fetched, so it works offline), the summary text, the
  pictures, and a note for each picture that could not be drawn (or was drawn
  without something).

The pictures are drawn by ``planner.shore.plots.dive_track`` (the map, and the
track's runs and segments, re-exported here) and ``planner.shore.plots.dive_series``.
Every file is written atomically (``planner.contract.atomic``).
"""

from __future__ import annotations

import html
import math
import os
import urllib.parse
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from planner.contract.atomic import write_atomic
from planner.shore.plots.dive_series import plot_cost as _plot_cost
from planner.shore.plots.dive_series import plot_timeseries as _plot_timeseries
from planner.shore.plots.dive_track import NEED_FORECAST as _NEED_FORECAST
from planner.shore.plots.dive_track import ActionRun, TrackSegment, action_runs, track_segments
from planner.shore.plots.dive_track import plot_dive_track as _plot_track
from planner.shore.replay.autopilot import severity_name
from planner.shore.replay.summary import executive_failsafes, failsafe_lines
from planner.shore.replay.webmap import map_section

if TYPE_CHECKING:  # pragma: no cover - typing only
    from planner.shore.replay.dive import Dive, Track
    from planner.pipeline import PlanResult
    from planner.contract.table import PolicyTable

__all__ = ["ActionRun", "TrackSegment", "action_runs", "track_segments", "write_report"]

TRACK_PNG = "track.png"
TIMESERIES_PNG = "timeseries.png"
COST_PNG = "cost.png"
INDEX_HTML = "index.html"



# --------------------------------------------------------------------------- the report


def write_report(
    dive: Dive,
    out_dir: str | os.PathLike[str],
    *,
    tables: Mapping[str, PolicyTable],
    plan: PlanResult | None,
    summary_text: str,
    audit_text: str | None = None,
    exports: Sequence[str | os.PathLike[str]] = (),
) -> Path:
    """Write the dive's pictures and ``index.html`` into ``out_dir`` (created if needed); returns the page's path.

    ``tables``: the log's tables by CRC (``planner.shore.replay.audit.logged_tables``); land
    comes from the first table the track used, each goal's marker from the
    table of its goal's first segment. ``plan``: one of those tables planned
    again on its forecast (``planner.shore.replay.nominal.plan_again``), or None when the
    forecast is not at hand; without it the track has no currents or nominal
    path and ``cost.png`` is not drawn, and the page says so. The prediction
    covers the decisions made under that table (one with the plan's actions).
    ``summary_text`` is shown as it is, escaped, in a ``<pre>`` block; ``audit_text``
    (``planner.shore.replay.audit.summary_line``, None when the audit did not run) heads
    the page with the mission and the UTC times, and ``exports`` (CSV, GeoJSON, GPX
    written beside it) are linked by their paths relative to ``out_dir``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    track = dive.track
    drawn: list[tuple[str, str]] = []  # (file name, caption)
    notes: list[tuple[str, str]] = []  # (file name, why it is missing or incomplete)
    has_position = bool(np.any(np.isfinite(track.lat_deg) & np.isfinite(track.lon_deg)))

    first = _first_table(dive, tables, plan)
    plan_rows = np.zeros(len(track), dtype=bool) if plan is None else _plan_rows(dive, tables, plan)
    if first is None:
        notes.append((TRACK_PNG, "not drawn: the log has no policy table attached, so there is no map to draw on"))
    elif not has_position:
        notes.append((TRACK_PNG, "not drawn: no decision in the log has a position"))
    else:
        caption, missing = _plot_track(dive, first, _goal_tables(dive, tables, first), plan, plan_rows,
                                       out / TRACK_PNG)
        drawn.append((TRACK_PNG, caption))
        if missing:
            notes.append((TRACK_PNG, missing))

    if len(track):
        drawn.append((TIMESERIES_PNG, _plot_timeseries(dive, out / TIMESERIES_PNG)))
    else:
        notes.append((TIMESERIES_PNG, "not drawn: the log has no decision"))

    if plan is None:
        notes.append((COST_PNG, f"not drawn: the predicted cost-to-go needs {_NEED_FORECAST}"))
    else:
        cost = _cost_along_track(track, plan, plan_rows)
        if not np.isfinite(cost).any():
            notes.append((COST_PNG, f"not drawn: no decision under the planned table ({plan.table.crc32:08x}) had a"
                                    " reachable table state"))
        else:
            drawn.append((COST_PNG, _plot_cost(dive, cost, plan, bool(plan_rows.all()), out / COST_PNG)))

    figure, map_notes = map_section(dive, table=first, goals=[] if first is None else _goal_tables(dive, tables, first),
                                    plan=plan)
    notes += [("map", text) for text in map_notes]
    index = out / INDEX_HTML
    head = _header(dive, audit_text, [Path(p) for p in exports], out)
    write_atomic(index, _page(dive, summary_text, drawn, notes, head=head, figure=figure).encode("utf-8"))
    return index


def _utc(dive: Dive, time_s: float) -> str:
    unix = dive.utc_s(time_s)
    if not isinstance(unix, float) or not math.isfinite(unix):  # utc_s of a float: a float, or None without UTC
        return "unknown (the autopilot sent no SYSTEM_TIME)"
    return datetime.fromtimestamp(round(unix), UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def _header(dive: Dive, audit_text: str | None, exports: list[Path], out: Path) -> str:
    """The table heading the page: mission, table, UTC start and end, audit verdict, exports, failsafes."""
    e = html.escape
    meta = dive.log.metadata.get("executive", {})
    rows = [("Mission", e(meta.get("mission") or "none named (the executive ran a table alone)"))]
    if meta.get("table"):
        rows.append(("Table", f"{e(meta['table'])} ({e(meta.get('table_crc32', '?'))})"))
    track = dive.track
    if len(track):
        start, end = float(track.time_s[0]), float(np.nanmax(track.time_s))
        rows.append(("Start", f"{_utc(dive, start)} ({start:.1f} s vehicle time)"))
        rows.append(("End", f"{_utc(dive, end)} ({end:.1f} s vehicle time, {(end - start) / 3600:.2f} h later)"))
    if audit_text is None:
        rows.append(("Audit", "not run (--no-audit)"))
    else:
        verdict = audit_text.removeprefix("audit").strip()
        ok = verdict.endswith("no difference")
        rows.append(("Audit", f'<span class="{"ok" if ok else "bad"}">{e(verdict)}</span>'))
    links = [f'<a href="{e(urllib.parse.quote(Path(os.path.relpath(p, out)).as_posix()))}">{e(p.name)}</a>'
             for p in exports]
    rows.append(("Exports", ", ".join(links) if links else "none written (--csv, --geojson, --gpx)"))
    rows.append(("Log", f"<code>{e(str(dive.log.path))}</code>: {e(dive.log.where_it_ends())}"))
    body = "\n".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    return f'<table class="head">\n{body}\n</table>\n' + _autopilot(dive)


def _autopilot(dive: Dive) -> str:
    """The failsafes (the autopilot's and the executive's) and the autopilot's status texts by severity."""
    e = html.escape
    a = dive.autopilot
    lines = failsafe_lines(a, executive_failsafes(dive.track.situation, dive.track.time_s))
    parts = ["<h2>Failsafes and autopilot messages</h2>", f"<pre>{e(chr(10).join(lines))}</pre>"]
    if a.texts:
        counts = ", ".join(f"{name} {n:,}" for name, n in a.by_severity().items())
        parts.append(f"<p>{len(a.texts):,} status texts from the autopilot (STATUSTEXT): {e(counts)}</p>")
        distinct: dict[tuple[int, str], list[float]] = {}
        for t in a.texts:
            distinct.setdefault((t.severity, t.text), []).append(t.time_s)
        parts.append('<table class="texts"><tr><th>severity</th><th>count</th><th>first (s)</th><th>last (s)</th>'
                     "<th>text</th></tr>")
        for (severity, text), times in sorted(distinct.items(), key=lambda kv: (kv[0][0], -len(kv[1]))):
            parts.append(f'<tr class="sev{severity}"><td>{severity_name(severity)}</td><td>{len(times):,}</td>'
                         f"<td>{times[0]:.1f}</td><td>{times[-1]:.1f}</td><td>{e(text)}</td></tr>")
        parts.append("</table>")
    else:
        parts.append("<p>No status text from the autopilot in the log.</p>")
    return "\n".join(parts)


def _page(dive: Dive, summary_text: str, drawn: list[tuple[str, str]], notes: list[tuple[str, str]], *,
          head: str = "", figure: str = "") -> str:
    e = html.escape
    name = dive.log.path.name
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        f"<title>Dive report: {e(name)}</title>",
        "<style>",
        "body { font-family: sans-serif; margin: 1.5em auto; max-width: 1400px; padding: 0 1em; color: #222; }",
        "pre { background: #f5f5f5; border: 1px solid #ddd; padding: 0.8em; overflow-x: auto; }",
        "figure { margin: 1.5em 0; }",
        "img { max-width: 100%; height: auto; border: 1px solid #ddd; }",
        "figcaption { color: #555; margin-top: 0.3em; }",
        ".notes li { color: #8a4b00; }",
        "table { border-collapse: collapse; } th, td { text-align: left; padding: 0.15em 0.8em 0.15em 0; }",
        "table.texts td, table.texts th { border-bottom: 1px solid #eee; }",
        ".ok { color: #1a7f37; font-weight: bold; } .bad, .sev0, .sev1, .sev2 { color: #b00020; font-weight: bold; }",
        ".sev3, .sev4 { color: #8a4b00; }",
        "figure.map svg { width: 100%; height: auto; border: 1px solid #bbb; touch-action: none; cursor: grab; }",
        ".map-tools { margin-bottom: 0.3em; color: #555; } .map-tools button { min-width: 2.2em; }",
        "ul.legend { list-style: none; padding: 0; display: flex; flex-wrap: wrap; gap: 0.3em 1.2em; }",
        ".swatch { display: inline-block; width: 1.6em; height: 0.8em; margin-right: 0.4em; vertical-align: middle; }",
        "</style>",
        "</head>",
        "<body>",
        f"<h1>Dive report: {e(name)}</h1>",
        head,
    ]
    if figure:
        parts += ["<h2>Map</h2>", figure]
    parts += [
        "<h2>Summary</h2>",
        f"<pre>{e(summary_text)}</pre>",
    ]
    if notes:
        parts.append("<h2>Notes</h2>")
        parts.append('<ul class="notes">')
        parts.extend(f"<li><code>{e(file)}</code>: {e(text)}</li>" for file, text in notes)
        parts.append("</ul>")
    parts.append("<h2>Pictures</h2>")
    for file, caption in drawn:
        parts.append("<figure>")
        parts.append(f'<a href="{e(file)}"><img src="{e(file)}" alt="{e(caption)}"></a>')
        parts.append(f"<figcaption>{e(caption)}</figcaption>")
        parts.append("</figure>")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


# --------------------------------------------------------------------------- which table


def _first_table(dive: Dive, tables: Mapping[str, PolicyTable], plan: PlanResult | None) -> PolicyTable | None:
    """The first table the track used, else the first one loaded (POLICY records), else any logged, else the plan's."""
    for crc in dict.fromkeys(dive.track.table_crc32):
        if crc is not None and crc in tables:
            return tables[crc]
    for p in dive.policy:
        logged = p.get("table_crc32")
        if p.get("reason") in ("loaded", "swapped") and logged is not None and logged in tables:
            return tables[logged]
    if tables:
        return next(iter(tables.values()))
    return None if plan is None else plan.table


def _goal_tables(dive: Dive, tables: Mapping[str, PolicyTable], first: PolicyTable) -> list[PolicyTable]:
    """A table for each goal the track went for (the table of its first segment), each goal position once."""
    out: list[PolicyTable] = []
    seen: set[tuple[float, float]] = set()
    for seg in dive.track.segments():
        t = tables.get(seg.table_crc32) if seg.table_crc32 is not None else None
        if t is not None and (t.goal_lon_deg, t.goal_lat_deg) not in seen:
            seen.add((t.goal_lon_deg, t.goal_lat_deg))
            out.append(t)
    return out or [first]


def _plan_rows(dive: Dive, tables: Mapping[str, PolicyTable], plan: PlanResult) -> NDArray[np.bool_]:
    """Rows driven by the table ``plan`` was made again from: one whose actions are the plan's, state for state.

    (``plan_again`` guarantees equal actions; the CRC may differ, as the header
    names the forecast file by its path.)
    """
    mine = {crc for crc, t in tables.items()
            if crc == f"{plan.table.crc32:08x}"
            or (t.actions.shape == plan.table.actions.shape and np.array_equal(t.actions, plan.table.actions))}
    return np.fromiter((c in mine for c in dive.track.table_crc32), dtype=bool, count=len(dive.track))


def _cost_along_track(track: Track, plan: PlanResult, rows: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The plan's cost-to-go of each row's table state (spec section 8), NaN where unreachable, where the row
    has no state, or where the row is not in ``rows`` (a mask: the rows driven by the planned table)."""
    cost_table = plan.solution.cost  # a property that builds the array: read it once
    inside = rows & np.all((track.cell >= 0) & (track.cell < np.asarray(cost_table.shape)), axis=1)
    cost = np.full(len(track), np.nan)
    l, j, i, k = track.cell[inside].T
    cost[inside] = cost_table[l, j, i, k]
    cost[~np.isfinite(cost)] = np.nan
    return cost

