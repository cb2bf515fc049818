"""Atomic file writes: a temporary file in the target's folder, fsync, then ``os.replace``.

Standard library only (the executive uses it through ``planner.contract.table``). A
failure leaves the old file untouched and no temporary file behind.
"""

from __future__ import annotations

import errno
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def check_file_target(path: str | os.PathLike[str]) -> None:
    """Raise now what writing a file at ``path`` later would: a folder there, or a file where a folder of its path
    should be. A command checks its outputs before its work, not after."""
    if not str(path):
        raise FileNotFoundError(errno.ENOENT, "expected a file name; got an empty one", "''")
    if Path(path).is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a folder: expected a file name", str(path))
    _check_parents(Path(path).parent)


def check_folder_target(path: str | os.PathLike[str]) -> None:
    """Raise now what writing files into the folder ``path`` later would: a file there or in its path."""
    _check_parents(Path(path))


def _check_parents(folder: Path) -> None:
    for part in (folder, *folder.parents):
        if part.exists():
            if not part.is_dir():
                raise NotADirectoryError(errno.ENOTDIR, "is a file: expected a folder", str(part))
            return


@contextmanager
def atomic_target(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path`` (mode 0644).

    A folder that cannot hold the file is refused before anything is written, and an error of the
    temporary file's names ``path``: the user gave that name, not the temporary one.
    """
    check_file_target(path)
    target = Path(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError as exc:  # a file stands where a folder of the path should be
        raise NotADirectoryError(errno.ENOTDIR, "is a file: expected a folder", exc.filename) from None
    try:
        fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise OSError(exc.errno, f"cannot write a file here: {exc.strerror}", str(target)) from None
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb") as handle:
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if exc.filename not in (str(tmp), name):
            raise
        raise OSError(exc.errno, exc.strerror, str(target)) from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_atomic(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    with atomic_target(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)
