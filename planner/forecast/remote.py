"""Forecasts given as http(s) URLs: downloaded once into the cache folder, then read as files.

A URL names a netCDF file on a web server: a THREDDS ``fileServer`` URL, an ERDDAP ``.nc``
request, a Hyrax or NCSS netCDF response, or any plain HTTP file. The body is streamed to a
temporary file in the cache (``planner.forecast.cache``) and moved into place only when it is
complete and starts like a netCDF-3 or HDF5 (netCDF-4) file; beside it a ``.json`` records the
URL, the content identity (``sha256:``, as ``file_identity``), the size and the server's
``ETag``/``Last-Modified``. Asking again sends those back (HTTP conditional GET, RFC 9110
section 13): ``304 Not Modified`` reuses the copy, anything else downloads it again.

An OPeNDAP dataset URL is not a file: ``planner.forecast.opendap`` tells it by its ``URL.dds``
and reads the part a plan needs over DAP instead (``fetch_source`` chooses).
"""

from __future__ import annotations

import hashlib
import http.client
import json
import os
import re
import urllib.error
import urllib.request
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from urllib.parse import urlsplit

from planner import __version__
from planner.contract.atomic import atomic_target, write_atomic
from planner.contract.errors import ForecastError
from planner.forecast.cache import forecasts_dir

TIMEOUT_S = 60.0  # per socket operation, not for the whole download
_BLOCK = 1 << 20
# netCDF classic, 64-bit offset and CDF-5; HDF5 (netCDF-4) superblock at offset 0.
_MAGIC = (b"CDF\x01", b"CDF\x02", b"CDF\x05", b"\x89HDF\r\n\x1a\n")


@dataclass(frozen=True, kw_only=True)
class Fetched:
    """A forecast URL and its copy in the cache."""

    url: str
    path: Path
    identity: str  # sha256: of the bytes, as planner.forecast.file_identity
    size_bytes: int
    downloaded: bool  # False: the server said the cached copy is current (304)

    def describe(self) -> str:
        how = "downloaded" if self.downloaded else "not modified, cached copy"
        return f"{self.url} -> {self.path} ({how}, {self.size_bytes:,} bytes, {self.identity})"


def file_sha256(path: Path) -> str:
    """``sha256:`` + the first 16 hex characters of the SHA-256 of the file's bytes (``OSError`` as it comes)."""
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(_BLOCK), b""):
            digest.update(block)
    return "sha256:" + digest.hexdigest()[:16]


def is_url(source: object) -> bool:
    """True for an ``http://`` or ``https://`` text (a path never is)."""
    return isinstance(source, str) and re.match(r"^https?://", source.strip(), re.IGNORECASE) is not None


def fetch(url: str, cache: str | os.PathLike[str] | None = None, *, timeout_s: float = TIMEOUT_S) -> Fetched:
    """The cached copy of the netCDF file at ``url``, downloaded when the server has a newer one or none is cached.

    Every failure is a ``ForecastError`` that names the URL: HTTP errors with their status, an
    unreachable server, a cut download, a body that is not netCDF.
    """
    url = url.strip()
    parts = urlsplit(url)
    if parts.scheme.lower() not in ("http", "https") or not parts.hostname:
        raise ForecastError(f"{url}: expected an http:// or https:// URL with a host name")
    folder = forecasts_dir(cache)
    name = re.sub(r"[^A-Za-z0-9._-]", "_", parts.path.rstrip("/").rsplit("/", 1)[-1])[-80:] or "forecast"
    path = folder / f"{hashlib.sha256(url.encode()).hexdigest()[:16]}-{name}"
    meta_path = path.with_name(path.name + ".json")
    meta = _cached_meta(meta_path, url) if path.is_file() else {}
    headers = {"User-Agent": f"lrauv-feedback/{__version__}"}
    if meta.get("etag"):
        headers["If-None-Match"] = str(meta["etag"])
    if meta.get("last_modified"):
        headers["If-Modified-Since"] = str(meta["last_modified"])
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers), timeout=timeout_s) as response:
            identity, size = _download(response, url, path)
            etag, modified = response.headers.get("ETag"), response.headers.get("Last-Modified")
    except urllib.error.HTTPError as exc:
        if exc.code == 304 and meta:
            size = path.stat().st_size
            if size == meta.get("size_bytes"):
                return Fetched(url=url, path=path, identity=str(meta.get("identity")), size_bytes=size,
                               downloaded=False)
            meta_path.unlink(missing_ok=True)  # the copy changed on disk: ask again without conditions
            return fetch(url, cache, timeout_s=timeout_s)
        raise ForecastError(f"{url}: HTTP {exc.code} {exc.reason}; expected a netCDF forecast file at that URL") from None
    except urllib.error.URLError as exc:
        raise ForecastError(f"{url}: cannot download ({exc.reason}); check the URL and the network") from None
    except (OSError, ValueError) as exc:  # timeouts, resets, a malformed response
        raise ForecastError(f"{url}: download failed ({type(exc).__name__}: {exc}); try again") from None
    record = {"url": url, "identity": identity, "size_bytes": size, "etag": etag, "last_modified": modified,
              "fetched_utc": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")}
    write_atomic(meta_path, (json.dumps(record, indent=1) + "\n").encode())
    return Fetched(url=url, path=path, identity=identity, size_bytes=size, downloaded=True)


def _cached_meta(meta_path: Path, url: str) -> dict[str, object]:
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError):
        return {}
    return meta if isinstance(meta, dict) and meta.get("url") == url else {}


def _download(response: http.client.HTTPResponse, url: str, path: Path) -> tuple[str, int]:
    """Stream the body to ``path`` atomically; (identity, bytes). Refuse a body that is not netCDF or is cut short."""
    read, headers = response.read, response.headers
    digest = hashlib.sha256()
    size = 0
    with atomic_target(path) as tmp:
        with tmp.open("wb") as out:
            first = read(_BLOCK)
            if not any(first.startswith(m) for m in _MAGIC):
                kind = headers.get("Content-Type") or "no content type"
                shown = first[:40].decode("latin-1").encode("unicode_escape").decode("ascii")
                raise ForecastError(
                    f"{url}: the server sent {kind} starting {shown!r}, not a netCDF file; expected a netCDF-3 or "
                    "netCDF-4 file, or an OPeNDAP (DAP 2.0) dataset URL that answers URL.dds"
                )
            block = first
            while block:
                out.write(block)
                digest.update(block)
                size += len(block)
                block = read(_BLOCK)
        declared = headers.get("Content-Length")
        if declared is not None and declared.isdigit() and int(declared) != size:
            raise ForecastError(f"{url}: download cut short: {size:,} of {int(declared):,} bytes; try again")
    return "sha256:" + digest.hexdigest()[:16], size
