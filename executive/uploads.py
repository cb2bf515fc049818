"""Uploads addressed to the executive: goals by the mission protocol, files by MAVLink FTP.

This is the only place that knows which messages belong to which service. It routes
each message addressed to us (system 1, component 191, or broadcast) to the protocol's
state machine (``executive.mission_protocol``, ``executive.ftp``) and encodes the replies
for the link the request came on. What to do with a finished upload is the loop's
business: the two ``accept`` hooks return None to take it or a reason to refuse it.

Storage: uploads hold at most ``UploadQuota`` (files and bytes; a write beyond it is
refused, ``executive.ftp``), and the forecasts the loop keeps on disk for the onboard
planner are a ``ForecastStore``, from which superseded forecasts are removed.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from executive import mavlink_bridge as bridge
from executive import mission_protocol as mp
from executive.ftp import FtpServer
from planner.contract.atomic import write_atomic
from planner.contract.errors import ExecutiveError, LrauvError
from planner.contract.mission import items_to_goals

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class UploadQuota:
    """What uploads may hold at once: files (stored and being uploaded) and their bytes."""

    max_files: int = 16
    max_bytes: int = 64 * 1024 * 1024

    def __post_init__(self) -> None:
        for name in ("max_files", "max_bytes"):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and value > 0):
                raise ExecutiveError(f"upload quota {name}: expected a positive whole number; got {value!r}")


class ForecastStore:
    """Uploaded forecasts on disk, for the onboard planner; ``prune`` removes superseded ones.

    Only files written here in this run are ever removed (never a watched directory's, nor a
    file left by an earlier run). Each file's identity is the one tables carry
    (``sha256:`` + 16 hex digits of the file's SHA-256, ``planner.forecast.files.file_identity``),
    computed once from the uploaded bytes.
    """

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self._identities: dict[Path, str] = {}  # oldest first

    def add(self, name: str, data: bytes) -> Path:
        """Write ``data`` as ``name`` atomically; ``OSError`` when the disk refuses."""
        path = write_atomic(self.directory / name, data)
        self._identities.pop(path, None)
        self._identities[path] = "sha256:" + hashlib.sha256(data).hexdigest()[:16]
        return path

    def prune(self, *, keep: Iterable[Path], identities: Iterable[str | None]) -> list[Path]:
        """Remove the stored forecasts not in ``keep`` whose identity no plan names; the paths removed."""
        kept, wanted = set(keep), set(identities)
        removed = []
        for path, identity in list(self._identities.items()):
            if path in kept or identity in wanted:
                continue
            try:
                path.unlink(missing_ok=True)
            except OSError as exc:  # tried again at the next prune
                log.warning("cannot remove the superseded forecast %s: %s", path, exc.strerror or exc)
                continue
            del self._identities[path]
            removed.append(path)
        return removed

    @property
    def paths(self) -> list[Path]:
        return list(self._identities)

class Uploads:
    """Mission-protocol and FTP servers behind one ``handle``; replies go back on the caller's link."""

    MESSAGES = mp.RECEIVER_MESSAGES | {"FILE_TRANSFER_PROTOCOL"}

    def __init__(self, *, accept_goals: Callable[[tuple[Any, ...]], str | None],
                 accept_file: Callable[[str, bytes], str | None], refused: Callable[[str, str], object],
                 flying: Callable[[], tuple[Any, ...]] | None = None,
                 set_current: Callable[[int], str | None] | None = None,
                 quota: UploadQuota = UploadQuota(), announce: Callable[[str], object] = lambda text: None,
                 forecast_dir: Path | None = None) -> None:
        self._accept_goals = accept_goals
        self._refused = refused
        self.quota = quota
        self.ftp = FtpServer(accept=accept_file, max_files=quota.max_files, max_total_bytes=quota.max_bytes,
                             max_file_bytes=quota.max_bytes, announce=announce)
        self.forecasts = ForecastStore(forecast_dir or Path("forecasts"))
        # Downloads serve what the vehicle is flying (``flying``), not merely the last list accepted.
        self.missions = mp.MissionReceiver(accept=self._accept_items, serve=flying, set_current=set_current)
        self._mav: Any = None  # the link of the last mission-protocol peer, for retries

    def _accept_items(self, items: tuple[mp.MissionItem, ...]) -> str | None:
        try:
            goals = items_to_goals(items)
        except LrauvError as exc:  # the protocol answers with the error's own MAV_MISSION_RESULT
            self._refused("mission", str(exc))
            raise
        return self._accept_goals(goals)

    def handle(self, msg: Any, mav: Any, wall_s: float) -> list[Any]:
        """Replies (encoded with ``mav``) to one message; [] when it is not for us."""
        kind = msg.get_type()
        if kind == "FILE_TRANSFER_PROTOCOL":
            if not mp.addressed_to(msg, bridge.EXECUTIVE_SYSTEM, bridge.EXECUTIVE_COMPONENT):
                return []
            peer = (msg.get_srcSystem(), msg.get_srcComponent())
            reply = self.ftp.handle(bytes(msg.payload))
            if reply is None:
                return []
            return [mav.file_transfer_protocol_encode(0, peer[0], peer[1], reply)]
        outs = mp.dispatch(self.missions, msg, wall_s, system=bridge.EXECUTIVE_SYSTEM,
                           component=bridge.EXECUTIVE_COMPONENT)
        if outs:
            self._mav = mav
        return [mp.encode(mav, out) for out in outs]

    def prune_forecasts(self, *, keep: Iterable[Path], plans: Iterable[Any]) -> list[Path]:
        """Remove superseded forecasts from the disk and the FTP store; the paths removed.

        Kept: ``keep`` (the newest, those a planner job uses or waits with) and every forecast a
        table of ``plans`` (the running, pending and staged ``MissionPlan``; None skipped) came from.
        """
        identities = {t.forecast_identity for plan in plans if plan is not None for t in plan.tables if t is not None}
        removed = self.forecasts.prune(keep=keep, identities=identities)
        names = {p.name for p in removed}
        for path in [p for p in self.ftp.files if p.rsplit("/", 1)[-1] in names]:
            self.ftp.discard(path)
        return removed

    def tick(self, wall_s: float) -> list[tuple[Any, Any]]:
        """(link, message) pairs due by time: mission-protocol re-requests and give-ups."""
        if self._mav is None:
            return []
        return [(self._mav, mp.encode(self._mav, out)) for out in self.missions.tick(wall_s)]

