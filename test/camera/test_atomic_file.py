"""Files written whole or not at all, through a temporary file of the writer's own (common.atomic_file)."""

from __future__ import annotations

import stat
from pathlib import Path

import numpy as np
import pytest

from face_reid_camera.common.atomic_file import write_atomically, write_npz


def test_npz_files_are_written_through_a_temporary_file_of_their_own(tmp_path: Path) -> None:
    target = tmp_path / "cache.npz"
    (tmp_path / "cache.npz.tmp").mkdir()  # where a fixed temporary name would collide (another writer's file)
    write_npz(target, {"a": np.arange(3)})
    write_npz(target, {"a": np.arange(4)})  # a second writer replaces it whole
    with np.load(target) as data:
        assert data["a"].tolist() == [0, 1, 2, 3]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache.npz", "cache.npz.tmp"]  # nothing left behind
    assert stat.S_IMODE(target.stat().st_mode) == 0o644  # readable by others, not mkstemp's 0600


def test_npz_bytes_depend_only_on_the_arrays(tmp_path: Path) -> None:
    arrays = {"b": np.zeros((50, 4)), "a": np.arange(100)}
    for compress in (False, True):
        write_npz(tmp_path / "one.npz", arrays, compress=compress)
        write_npz(tmp_path / "two.npz", dict(reversed(arrays.items())), compress=compress)
        assert (tmp_path / "one.npz").read_bytes() == (tmp_path / "two.npz").read_bytes()
    stored = tmp_path / "stored.npz"
    write_npz(stored, arrays)
    assert (tmp_path / "one.npz").stat().st_size < stored.stat().st_size  # the last pair was deflated


def test_a_failed_write_keeps_the_old_file_and_leaves_nothing(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "model.onnx"
    write_atomically(target, lambda f: f.write(b"old"))

    def broken(f: object) -> None:
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        write_atomically(target, broken)
    assert target.read_bytes() == b"old"
    assert [p.name for p in target.parent.iterdir()] == ["model.onnx"]
