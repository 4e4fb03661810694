"""The write-behind face store: saves never wait for the disk, and every other call sees them in order."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from face_reid_master.identity.records import LearnedFace
from face_reid_master.storage.face_store import FaceStore, FaceStoreLockedError
from face_reid_master.storage.write_behind import WriteBehindStore

DIM = 128


def _face(face_id: int, seed: int, k: int = 5, dim: int = DIM) -> LearnedFace:
    return LearnedFace(face_id, np.random.default_rng(seed).normal(0.0, 0.1, (k, dim)).astype(np.float32))


class _GatedStore(FaceStore):
    """A store whose saves wait until the test opens the gate (a disk that is slow to commit)."""

    gate = threading.Event()

    def save_faces(self, faces):  # type: ignore[no-untyped-def]
        assert self.gate.wait(10.0)
        return super().save_faces(faces)


def test_saves_return_before_the_commit_and_later_calls_see_them(tmp_path: Path) -> None:
    _GatedStore.gate.clear()
    store = WriteBehindStore(lambda: _GatedStore(tmp_path / "faces.db"))
    try:
        assert store.save_faces([_face(1, 1), _face(2, 2)]) == 2  # returns while the worker waits on the gate
        assert store.save_faces([_face(1, 3)]) == 1
        _GatedStore.gate.set()
        loaded = {f.face_id: f for f in store.load_faces()}  # runs on the worker after the saves
        assert sorted(loaded) == [1, 2]
        assert loaded[1].features.tobytes() == _face(1, 3).features.tobytes()  # the newest snapshot
        assert store.write_failures == 0
        assert store.path == (tmp_path / "faces.db").absolute()  # attributes read as they are
    finally:
        _GatedStore.gate.set()
        store.close()
    with FaceStore(tmp_path / "faces.db") as reopened:  # closed: the lock is free, everything committed
        assert [f.face_id for f in reopened.load_faces()] == [1, 2]


def test_a_face_forgotten_after_its_save_stays_forgotten(tmp_path: Path) -> None:
    store = WriteBehindStore(lambda: FaceStore(tmp_path / "faces.db"))
    try:
        for k in range(20):
            store.save_faces([_face(1, k), _face(2, 100 + k)])
            if k == 10:
                assert store.forget(1)
                store.save_faces([_face(3, 7)])
        store.forget(1)
        assert [f.face_id for f in store.load_faces()] == [2, 3]
    finally:
        store.close()
    store.close()  # idempotent


def test_a_failed_save_is_counted_and_later_saves_still_work(tmp_path: Path) -> None:
    store = WriteBehindStore(lambda: FaceStore(tmp_path / "faces.db"))
    try:
        store.save_faces([_face(1, 1, dim=64)])  # the wrong length: the worker's save raises
        store.flush()
        assert store.write_failures == 1
        store.save_faces([_face(2, 2)])
        store.flush()
        assert store.write_failures == 1 and [f.face_id for f in store.load_faces()] == [2]
    finally:
        store.close()
    with pytest.raises(ValueError, match="closed"):
        store.load_faces()


def test_an_opening_error_is_raised_by_the_constructor(tmp_path: Path) -> None:
    with FaceStore(tmp_path / "faces.db"), pytest.raises(FaceStoreLockedError):
        WriteBehindStore(lambda: FaceStore(tmp_path / "faces.db"))
