"""Where parallel work runs: in this process, or on a Dask cluster (docs/scale-out.md).

One switch for every command that has parallel work (ensemble members, batch plans, Monte
Carlo runs): by default a local Dask cluster sized to the machine (one single-threaded worker
process per core: the work is numba and plain Python, which hold the GIL); ``--scheduler
ADDRESS`` sends the same tasks to an existing cluster; ``--scheduler in-process`` runs them
here, one after another, without Dask. A ``Runner`` maps a picklable function over items and
returns the results in the items' order, so every runner gives the same results.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from planner.contract.errors import PlannerError

T = TypeVar("T")
R = TypeVar("R")
IN_PROCESS = "in-process"
_CONNECT_TIMEOUT_S = 5.0
# A scheduler's address as Dask writes it: [PROTOCOL://]HOST:PORT, an IPv6 host in brackets.
_SCHEDULER_ADDRESS = re.compile(r"(?:[a-z][a-z0-9+.-]*://)?(?:\[[0-9A-Fa-f:.]+\]|[^\s:/\[\]]+):[0-9]{1,5}")


class Runner(Protocol):
    """Runs ``fn(item, **shared)`` for every item; results in order."""

    @property
    def workers(self) -> int: ...

    def map(self, fn: Callable[..., R], items: Sequence[Any], **shared: Any) -> list[R]: ...


@dataclass(frozen=True)
class InProcess:
    """No Dask: one item after another in this process."""

    @property
    def workers(self) -> int:
        return 1

    def map(self, fn: Callable[..., R], items: Sequence[Any], **shared: Any) -> list[R]:
        return [fn(item, **shared) for item in items]

    def describe(self) -> str:
        return "in this process"


class DaskRunner:
    """Tasks on a ``distributed.Client``. Shared arguments are sent to every worker once."""

    def __init__(self, client: Any, *, what: str) -> None:
        self.client = client
        self._what = what

    @property
    def workers(self) -> int:
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def map(self, fn: Callable[..., R], items: Sequence[Any], **shared: Any) -> list[R]:
        if not items:
            return []
        sent = {k: self.client.scatter(v, broadcast=True, hash=False) for k, v in shared.items()}
        futures = self.client.map(_on_one_thread, list(items), pure=False, task_function=fn, **sent)
        return list(self.client.gather(futures))

    def describe(self) -> str:
        return f"{self._what}, {self.workers} workers"


@contextlib.contextmanager
def open_runner(scheduler: str | None = None, *, workers: int | None = None) -> Iterator[InProcess | DaskRunner]:
    """The runner for ``--scheduler`` (None: a local cluster with ``workers`` or one per core)."""
    if scheduler == IN_PROCESS:
        yield InProcess()
        return
    try:
        from distributed import Client
    except ImportError as exc:  # pragma: no cover - dask is a dependency
        raise PlannerError(f"--scheduler: Dask's distributed package is not installed ({exc}); use --scheduler {IN_PROCESS}") from None
    if scheduler is not None:
        if _SCHEDULER_ADDRESS.fullmatch(scheduler) is None:
            raise PlannerError(f"--scheduler {scheduler!r}: expected tcp://HOST:PORT of a running `dask scheduler`, "
                               f"or {IN_PROCESS}")
        try:
            client = Client(scheduler, timeout=_CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise PlannerError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there ({exc}); expected "
                               f"tcp://HOST:PORT of a running `dask scheduler`, or {IN_PROCESS}") from None
        with client:
            yield DaskRunner(client, what=f"Dask scheduler {scheduler}")
        return
    n = workers if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise PlannerError(f"--workers: expected at least 1; got {n}")
    with local_cluster(n) as cluster, Client(cluster, set_as_default=False) as client:
        yield DaskRunner(client, what="local Dask cluster")


def local_cluster(n_workers: int) -> Any:
    """A ``distributed.LocalCluster`` of single-threaded worker processes on 127.0.0.1."""
    from distributed import LocalCluster

    return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                        scheduler_port=0, silence_logs=40)


def _on_one_thread(item: Any, *, task_function: Callable[..., R], **shared: Any) -> R:
    """Run a task with numba's parallel loops on one thread: a worker is one core's worth of work,
    so n workers use n cores, not n x cores (numba's setting is per calling thread)."""
    import numba

    numba.set_num_threads(1)
    return task_function(item, **shared)


def chunks(n: int, workers: int, *, per_worker: int = 4) -> list[range]:
    """``range(n)`` cut into about ``per_worker`` pieces per worker: few enough that Dask's
    per-task overhead stays small against the work, enough to balance uneven runs."""
    if n <= 0:
        return []
    pieces = max(1, min(n, workers * per_worker))
    size = math.ceil(n / pieces)
    return [range(i, min(i + size, n)) for i in range(0, n, size)]

