"""``lrauv batch``: a plan for every goal of many missions, as parallel tasks (docs/scale-out.md).

Arguments are mission files or fleet files. A fleet file lists vehicles and their missions::

    fleet:
      - {vehicle: tethys, mission: demo.yaml}
      - {vehicle: daphne, mission: demo-physical.yaml}

(paths relative to the fleet file). Every goal of every mission is one task: the task gets
the plan request (forecast path, grid, goal, settings), plans it with ``make_plan`` and returns
the table's bytes; this process writes ``OUT/<vehicle>/goal-<n>.lrpt`` atomically. Forecast files
must be readable where the workers run (a shared filesystem for a remote cluster).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from planner.contract.atomic import write_atomic
from planner.contract.errors import LrauvError, MissionError, ShoreError

if TYPE_CHECKING:  # for the annotation only: this module loads no numpy
    from planner.pipeline import PlanRequest, SampleCache

MAX_FLEET_BYTES = 1 << 20


@dataclass(frozen=True, kw_only=True)
class BatchItem:
    """One goal to plan: for which vehicle, which goal of its mission, and where the table goes."""

    vehicle: str
    goal_index: int
    request: PlanRequest
    out: Path
    where: str = ""  # the goal's mission line, "missions/x.yaml:31 goals[1]", for its errors


@dataclass(frozen=True, kw_only=True)
class BatchResult:
    vehicle: str
    goal_index: int
    table: bytes | None
    reachable: int
    water_states: int
    plan_s: float
    error: str | None = None


def load_fleet(path: Path) -> list[tuple[str, Path]]:
    """(vehicle name, mission path) of each entry of a fleet file; errors name file, line and key."""
    from planner.contract.mission import YamlDocument, YamlSection

    try:
        size = path.stat().st_size
        if size > MAX_FLEET_BYTES:
            raise MissionError(f"{path}: {size:,} bytes; a fleet file is at most {MAX_FLEET_BYTES:,} bytes")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MissionError(f"{path}: no such fleet file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MissionError(f"{path}: cannot read: {exc}") from None
    doc = YamlDocument(path, text)
    top = YamlSection(doc, doc.root, "", {"fleet"})
    entries = top.raw("fleet")
    if not isinstance(entries, list) or not entries:
        raise doc.error("fleet", f"expected a list of {{vehicle: NAME, mission: FILE}}; got {entries!r}")
    out: list[tuple[str, Path]] = []
    seen: set[str] = set()
    for n, raw in enumerate(entries):
        e = YamlSection(doc, raw, f"fleet[{n}]", {"vehicle", "mission"})
        name = e.text("vehicle")
        if not name or "/" in name or name in (".", ".."):
            raise doc.error(e.path("vehicle"), f"expected a vehicle name usable as a folder name; got {name!r}")
        if name in seen:
            raise doc.error(e.path("vehicle"), f"vehicle {name!r} is listed twice")
        seen.add(name)
        out.append((name, path.parent / e.text("mission")))
    return out


def is_fleet(path: Path) -> bool:
    """A fleet file has a top-level ``fleet`` key (a mission never does)."""
    import yaml

    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(MAX_FLEET_BYTES + 1)
        doc = yaml.safe_load(head)
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False  # the mission loader gives the precise error
    return isinstance(doc, dict) and "fleet" in doc


def collect(files: list[Path], out_dir: Path, forecast: Path | None) -> list[BatchItem]:
    """Every goal of every mission named directly or through a fleet file."""
    from planner.contract.mission import load_mission
    from planner.pipeline import PlanRequest, mission_forecast

    vehicles: list[tuple[str, Path]] = []
    for f in files:
        vehicles.extend(load_fleet(f) if is_fleet(f) else [(f.stem, f)])
    names = [v for v, _ in vehicles]
    dupes = sorted({v for v in names if names.count(v) > 1})
    if dupes:
        raise ShoreError(f"batch: vehicle names must be unique (they name the output folders); repeated: {', '.join(dupes)}")
    items = []
    for vehicle, path in vehicles:
        mission = load_mission(path)
        fc = forecast or mission_forecast(mission)
        for g, goal in enumerate(mission.goals):
            request = PlanRequest.for_mission(mission, fc, goal_index=g)
            items.append(BatchItem(vehicle=vehicle, goal_index=g, request=request,
                                   out=out_dir / vehicle / f"goal-{g}.lrpt", where=goal.where))
    return items


def plan_item(item: BatchItem) -> BatchResult:
    """One task: plan one goal. Bad input comes back as an error, so one bad goal stops nothing else."""
    from planner.pipeline import make_plan

    t = time.perf_counter()
    try:
        result = make_plan(item.request, samples=_worker_samples())
    except LrauvError as exc:
        return BatchResult(vehicle=item.vehicle, goal_index=item.goal_index, table=None, reachable=0,
                           water_states=0, plan_s=time.perf_counter() - t,
                           error=f"{item.where}: {exc}" if item.where else str(exc))
    return BatchResult(
        vehicle=item.vehicle, goal_index=item.goal_index, table=result.table.to_bytes(),
        reachable=int(result.solution.reachable.sum()), water_states=int(result.model.water.sum()) * 8,
        plan_s=time.perf_counter() - t,
    )


def _worker_samples() -> SampleCache:
    """This process's goal-free samples: a worker that plans several goals on one forecast samples it once."""
    from planner.pipeline import SampleCache

    global _SAMPLES
    if _SAMPLES is None:
        _SAMPLES = SampleCache()
    return _SAMPLES


_SAMPLES: SampleCache | None = None


@dataclass(frozen=True, kw_only=True)
class BatchRun:
    """Every goal's result, in the order collected; ``written[n]`` is item n's table file (None: it failed)."""

    items: tuple[BatchItem, ...]
    results: tuple[BatchResult, ...]
    written: tuple[Path | None, ...]
    elapsed_s: float

    @property
    def failed(self) -> int:
        return sum(1 for r in self.results if r.error is not None)


def run_batch(files: Sequence[Path], *, out_dir: Path, forecast: Path | None = None, scheduler: str | None = None,
              workers: int | None = None, note: Callable[[str], None] | None = None) -> BatchRun:
    """Plan every goal of ``files`` (missions, fleets) as tasks of the runner; write each table under ``out_dir``."""
    from planner.cluster import open_runner

    items = collect(list(files), out_dir, forecast)
    t0 = time.perf_counter()
    with open_runner(scheduler, workers=workers) as runner:
        if note is not None:
            note(f"{len(items)} goals, {runner.describe()}")
        results = runner.map(plan_item, items)
    written = tuple(None if r.table is None else write_atomic(item.out, r.table) for item, r in zip(items, results))
    return BatchRun(items=tuple(items), results=tuple(results), written=written, elapsed_s=time.perf_counter() - t0)
