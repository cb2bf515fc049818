"""Atomic writes: a path that cannot take a file is refused by its own name, and nothing is left behind."""

from __future__ import annotations

from pathlib import Path

import pytest

from planner.contract.atomic import atomic_target, write_atomic


def test_a_file_is_written_and_replaced_whole(tmp_path: Path) -> None:
    target = tmp_path / "deep" / "table.lrpt"
    write_atomic(target, b"first")
    write_atomic(target, b"second")
    assert target.read_bytes() == b"second"
    assert sorted(p.name for p in target.parent.iterdir()) == ["table.lrpt"]


def test_a_folder_given_as_the_file_is_refused_by_its_name(tmp_path: Path) -> None:
    with pytest.raises(IsADirectoryError) as caught:
        write_atomic(tmp_path, b"x")
    assert caught.value.filename == str(tmp_path)
    assert "expected a file name" in caught.value.strerror
    assert list(tmp_path.iterdir()) == []


def test_an_empty_path_is_refused() -> None:
    with pytest.raises(FileNotFoundError, match="empty"):
        write_atomic("", b"x")


def test_a_file_where_a_folder_should_be_is_named(tmp_path: Path) -> None:
    (tmp_path / "forecast.nc").write_bytes(b"kept")
    with pytest.raises(NotADirectoryError) as caught:
        write_atomic(tmp_path / "forecast.nc" / "table.lrpt", b"x")
    assert caught.value.filename == str(tmp_path / "forecast.nc")
    assert (tmp_path / "forecast.nc").read_bytes() == b"kept"


def test_a_failure_while_writing_names_the_target_not_the_temporary_file(tmp_path: Path) -> None:
    target = tmp_path / "table.lrpt"
    target.write_bytes(b"good")
    with pytest.raises(OSError) as caught, atomic_target(target) as tmp:
        tmp.write_bytes(b"half")
        tmp.unlink()  # the temporary file vanishes before it replaces the target
    assert caught.value.filename == str(target)
    assert target.read_bytes() == b"good"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.lrpt"]
