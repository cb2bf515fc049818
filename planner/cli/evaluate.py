"""``lrauv evaluate``: the Monte Carlo comparison of docs/evaluation.md, as a table, files and plots."""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

from planner.cli.cluster_options import add_cluster_arguments
from planner.cli.progress_bar import announcer, bars
from planner.contract.arguments import Subcommands
from planner.contract.atomic import write_atomic
from planner.contract.columns import say
from planner.contract.errors import LrauvError
from planner.shore.evaluation.comparison import CONFIDENCE, EnergyComparison, every_pair
from planner.shore.evaluation.runs import (
    DEFAULT_METHODS,
    METHODS,
    OUTCOMES,
    MethodSummary,
    RunResult,
    summarise,
)


def add_parser(sub: Subcommands) -> None:
    p = sub.add_parser("evaluate", help="Monte Carlo closed-loop comparison of plans over a truth field")
    p.add_argument("mission", type=Path, help="mission YAML: region, vehicle, planning settings, the first goal")
    p.add_argument("--forecast", type=Path, help="planning forecast (default: the mission's)")
    p.add_argument("--truth", type=Path, nargs="+", required=True,
                   help="truth forecast file(s) the runs fly through (several: each from its first time on)")
    p.add_argument("--starts", type=int, default=100, help="start states (default 100)")
    p.add_argument("--seed", type=int, default=0, help="seed of the start states (default 0)")
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS),
                   help=f"comma-separated, of {','.join(METHODS)} (default {','.join(DEFAULT_METHODS)})")
    p.add_argument("--dt-s", type=float, default=2.0, help="physics step in seconds (default 2)")
    p.add_argument("--max-hours", type=float, default=24.0, help="a run times out after this (default 24)")
    p.add_argument("--replan-h", type=float, help="plan again every H hours at the nearest forecast step (default: once)")
    p.add_argument("--time-index", type=int, default=0, help="forecast step the runs start at (default 0)")
    p.add_argument("--cruise-speed", type=float, help="override the mission's vehicle cruise speed, m/s")
    p.add_argument("--resolution", action="store_true",
                   help="also plan the physical model on a grid of half the spacing and compare the starts' predictions")
    p.add_argument("--out", type=Path, help="write runs.csv, summary.json and PNG plots here")
    add_cluster_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from planner.cluster import open_runner
    from planner.contract.atomic import check_folder_target
    from planner.contract.mission import load_mission
    from planner.pipeline import mission_forecast
    from planner.shore.evaluation.campaign import (
        CampaignSpec,
        prepare,
        resolution_change,
        run_all,
    )
    from vehicle_sim.world import WorldError, load_truth

    mission = load_mission(args.mission)
    if args.out is not None:
        check_folder_target(args.out)  # before the runs' minutes, not after them
    if args.cruise_speed is not None:
        vehicle = mission.settings.vehicle
        if not (math.isfinite(args.cruise_speed) and args.cruise_speed > 0):
            raise LrauvError(f"--cruise-speed: expected a speed in m/s > 0; got {args.cruise_speed}")
        vehicle = replace(vehicle, cruise_speed_m_s=args.cruise_speed,
                          max_speed_m_s=max(vehicle.max_speed_m_s, args.cruise_speed))
        mission = replace(mission, settings=replace(mission.settings, vehicle=vehicle))
    forecast = args.forecast or mission_forecast(mission)
    try:
        truth = load_truth(args.truth)
    except WorldError as exc:
        raise LrauvError(str(exc)) from None
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    spec = CampaignSpec(mission=mission, forecast_path=forecast, truth=truth, methods=methods, n_starts=args.starts,
                        seed=args.seed, dt_s=args.dt_s, max_time_s=args.max_hours * 3600.0,
                        replan_s=None if args.replan_h is None else args.replan_h * 3600.0, time_index=args.time_index)
    with bars(quiet=args.quiet) as meter:
        note = announcer(meter, quiet=args.quiet)
        campaign = prepare(spec, note=note, meter=meter)
        with open_runner(args.scheduler, workers=args.workers) as runner:
            note(f"{len(campaign.starts)} starts x {len(methods)} methods, {runner.describe()}")
            campaign = run_all(campaign, runner=runner, meter=meter)
    summaries = summarise(campaign.results, methods)
    comparisons = every_pair(campaign.results, methods)
    resolution = resolution_change(campaign) if args.resolution else None
    say(format_table(summaries))
    if comparisons:
        say("\n" + format_comparisons(comparisons))
    # A run cut before the mission's own limit may be a vehicle waiting for a tide (docs/evaluation.md).
    timed_out = sum(s.outcomes["timed_out"] for s in summaries)
    mission_h = mission.safety.max_mission_time_s / 3600.0
    if timed_out and args.max_hours < mission_h:
        say(f"note       {timed_out} run(s) timed out at {args.max_hours:g} h (--max-hours); the mission allows "
            f"{mission_h:g} h")
    if resolution is not None:
        for m, r in resolution.items():
            say(f"resolution {m}: predicted start cost changes by median {r['median']:.1%}, p90 {r['p90']:.1%},"
                f" max {r['max']:.1%} over {int(r['starts'])} starts when the spacing halves")
    t = campaign.timings_s
    say(f"time       plans {t['plan_s']:.1f} s, {len(campaign.results)} runs {t['runs_s']:.1f} s")
    if args.out is not None:
        meta = {"mission": str(args.mission), "forecast": str(forecast), "truth": [str(p) for p in args.truth],
                "starts": args.starts, "seed": args.seed, "dt_s": args.dt_s, "max_hours": args.max_hours,
                "replan_h": args.replan_h, "cruise_speed_m_s": mission.settings.vehicle.cruise_speed_m_s}
        for path in write_outputs(args.out, campaign.results, summaries, resolution, meta, comparisons):
            say(f"wrote      {path}")
    return 0


def format_table(summaries: list[MethodSummary]) -> str:
    """The two tables printed by ``lrauv evaluate``, each within 100 columns: what became of the runs
    (counts), then how well each method did (shares; medians over its arrived runs)."""
    counts = (f"{'method':<18} {'runs':>5} {'marked':>6} {'arrived':>7} {'stranded':>8} {'left':>5} {'timeout':>7}"
              f" {'gave up':>7} {'refused':>7}")
    lines = ["runs by outcome", counts, "-" * len(counts)]
    for s in summaries:
        o = s.outcomes
        lines.append(f"{s.method:<18} {s.runs:>5} {s.marked_reachable:>6} {o['arrived']:>7} {o['stranded']:>8}"
                     f" {o['left_region']:>5} {o['timed_out']:>7} {o['gave_up']:>7} {o['refused']:>7}")
    figures = (f"{'method':<18} {'success':>8} {'of marked':>9} {'coverage':>8} {'time h':>7} {'energy Wh':>9}"
               f" {'pred Wh':>8} {'pred err':>8} {'vs naive':>8}")
    lines += ["", "figures (success: arrived of all runs; of marked: arrived of the runs from starts the plan marks "
                  "reachable; coverage: of the starts some method arrived from, those it marks; time, energy, "
                  "predicted: medians of arrived runs; pred err: spent / predicted - 1)",
              figures, "-" * len(figures)]
    for s in summaries:
        lines.append(
            f"{s.method:<18} {_pct(s.success_rate):>8} {_pct(s.success_from_reachable):>9} {_pct(s.coverage):>8}"
            f" {_num(s.median_time_h, 2):>7} {_num(s.median_energy_wh, 1):>9} {_num(s.median_predicted_wh, 1):>8}"
            f" {_pct(s.energy_error, signed=True):>8} {_pct(s.energy_vs_naive, signed=True):>8}")
    common = summaries[0].all_arrived if summaries else 0
    if common and len(summaries) > 1:
        means = ", ".join(f"{s.method} {s.mean_energy_all_arrived_wh:.1f}" for s in summaries)
        lines.append(f"mean energy on the {common} starts every method arrived from, Wh: {means}")
    return "\n".join(lines)


def format_comparisons(comparisons: list[EnergyComparison]) -> str:
    """Each pair of methods: the excess of the mean energy on the starts both arrived from, with its interval."""
    lines = [f"energy, method against method on the starts both arrived from (mean over mean - 1; "
             f"{CONFIDENCE:.0%} interval, paired bootstrap over those starts)"]
    width = max(len(f"{c.method} vs {c.against}") for c in comparisons)
    for c in comparisons:
        interval = (f"[{_pct(c.low, signed=True)}, {_pct(c.high, signed=True)}]" if math.isfinite(c.low)
                    else "[-]")
        lines.append(f"  {f'{c.method} vs {c.against}':<{width}} {_pct(c.excess, signed=True):>7} {interval:<18}"
                     f" {c.starts} start{'' if c.starts == 1 else 's'}")
    return "\n".join(lines)


def _pct(x: float, *, signed: bool = False) -> str:
    if not math.isfinite(x):
        return "-"
    return f"{x:+.1%}" if signed else f"{x:.1%}"


def _num(x: float, digits: int) -> str:
    return "-" if not math.isfinite(x) else f"{x:.{digits}f}"


def write_outputs(out: Path, results: tuple[RunResult, ...], summaries: list[MethodSummary],
                  resolution: dict[str, dict[str, float]] | None, meta: dict[str, Any],
                  comparisons: list[EnergyComparison]) -> list[Path]:
    """runs.csv, summary.json and the plots, each written atomically."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["method", "start", "outcome", "time_s", "energy_wh", "predicted_wh", "marked_reachable"])
    for r in results:
        w.writerow([r.method, r.start, r.outcome, f"{r.time_s:.1f}", f"{r.energy_wh:.4f}",
                    "" if not math.isfinite(r.predicted_wh) else f"{r.predicted_wh:.4f}", int(r.marked_reachable)])
    paths = [write_atomic(out / "runs.csv", buf.getvalue().encode())]
    summary = {"meta": meta, "methods": [_clean(asdict(s)) for s in summaries], "resolution": resolution,
               "comparisons": [_clean(asdict(c)) for c in comparisons], "confidence": CONFIDENCE}
    paths.append(write_atomic(out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode()))
    paths.extend(plot_evaluation(out, results, summaries))
    return paths


def _clean(d: dict[str, Any]) -> dict[str, Any]:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def plot_evaluation(out: Path, results: tuple[RunResult, ...], summaries: list[MethodSummary]) -> list[Path]:
    """outcomes.png (outcome counts per method), energy.png (predicted vs spent; energy per method)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = [s.method for s in summaries]
    colours = {"arrived": "#2a9d8f", "stranded": "#6d4c41", "left_region": "#e76f51", "timed_out": "#f4a261",
               "gave_up": "#8d99ae", "refused": "#d9d9d9"}
    fig, ax = plt.subplots(figsize=(8, 4), dpi=110)
    bottom = [0] * len(methods)
    for o in OUTCOMES:
        counts = [s.outcomes[o] for s in summaries]
        ax.bar(methods, counts, bottom=bottom, color=colours[o], label=o.replace("_", " "))
        bottom = [b + c for b, c in zip(bottom, counts)]
    ax.set_ylabel("runs")
    ax.set_title("Outcome of every run, by method")
    ax.legend(fontsize=8, ncol=3)
    fig.tight_layout()
    paths = [_save(fig, out / "outcomes.png")]

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.5), dpi=110)
    for m in methods:
        pts = [(r.predicted_wh, r.energy_wh) for r in results
               if r.method == m and r.outcome == "arrived" and math.isfinite(r.predicted_wh)]
        if pts:
            a1.scatter([p for p, _ in pts], [e for _, e in pts], s=10, label=m)
    lim = max([r.energy_wh for r in results if r.outcome == "arrived"] + [1.0])
    a1.plot([0, lim], [0, lim], color="k", lw=0.8)
    a1.set_xlabel("predicted energy at the start, Wh")
    a1.set_ylabel("energy spent, Wh")
    a1.set_title("Predicted against spent (arrived runs)")
    a1.legend(fontsize=8)
    data = [[r.energy_wh for r in results if r.method == m and r.outcome == "arrived"] for m in methods]
    a2.boxplot([d if d else [math.nan] for d in data], tick_labels=methods)
    a2.set_ylabel("energy spent, Wh (arrived runs)")
    a2.tick_params(axis="x", labelrotation=20)
    a2.set_title("Energy per method")
    fig.tight_layout()
    paths.append(_save(fig, out / "energy.png"))
    return paths


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return write_atomic(path, buf.getvalue())
