"""A face id is never handed out twice: the master publishes a new face id only once it is reserved durably in the
face store (database and id ledger, a block at a time); while the store cannot write (disk full) new people stay
undecided, counted and said on /diagnostics, and after a restart new faces get ids above every reserved block."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.core.face_memory import ID_BLOCK
from face_reid_master.health import MasterHealthWatch
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.storage.face_store import FaceStore, FaceStoreError
from face_reid_master.storage.id_ledger import IdLedger
from face_reid_master.storage.write_behind import WriteBehindStore
from face_reid_master.tracking.config import TrackerConfig

SPACE = "dlib_resnet_v1"
DIM = 128
PEOPLE = np.random.default_rng(11).normal(size=(12, DIM))
PEOPLE *= 1.4 / np.linalg.norm(PEOPLE, axis=1, keepdims=True)  # dlib's embedding length: the master checks it


def _config() -> MasterConfig:
    return MasterConfig(embedding_space=SPACE, body_appearance_tracking=False,
                        tracker=TrackerConfig(lost_after_s=0.5, delete_after_s=1.0))


def _visit(core: MasterCore, k: int, t0: float) -> tuple[float, set[int]]:
    """Person k alone in view for 1.5 s at 10 Hz, then nobody until the track is deleted: the end time and every
    face id published meanwhile (0: undecided)."""
    rng = np.random.default_rng(100 + k)
    published: set[int] = set()
    for i in range(15):
        v = PEOPLE[k] + rng.normal(0.0, 0.03, DIM)
        person = PersonRecord(np.array([0.1 * i, 0.0, 0.0]), 0.05, 1.75, (v * 1.4 / np.linalg.norm(v)).astype(
            np.float32), 0.9, 0.8)
        core.process_frame(CameraFrameRecord("cam", t0 + i / 10, (person,)))
        published |= {t.face_id for t in core.tracks()}
    t = t0 + 3.5
    core.tick(t)
    assert core.tracks() == []
    return t, published


@pytest.fixture
def disk_full(monkeypatch: pytest.MonkeyPatch) -> Callable[[bool], None]:
    """``disk_full(True)``: every write of the face store fails as on a full disk (its SQLite transactions say
    "database or disk is full", its id ledger file ENOSPC); ``disk_full(False)``: the space is back."""

    def full_transaction(self: FaceStore) -> None:
        raise FaceStoreError(f"face store {self.path}: database or disk is full")

    def full_ledger(self: IdLedger) -> None:
        raise FaceStoreError(f"face store {self.db_path}: cannot write the id ledger: [Errno 28] No space left on "
                             "device")

    def switch(full: bool) -> None:
        if full:
            monkeypatch.setattr(FaceStore, "_transaction", full_transaction)
            monkeypatch.setattr(IdLedger, "write", full_ledger)
        else:
            monkeypatch.undo()

    return switch


def test_an_id_published_while_the_disk_was_full_is_never_given_again_after_a_restart(
        tmp_path: Path, disk_full: Callable[[bool], None]) -> None:
    db = tmp_path / "faces.db"
    published: set[int] = set()
    with FaceStore(db, embedding_space=SPACE) as store:
        core = MasterCore(_config(), store=store)
        t = 0.0
        for k in range(4):
            t, seen = _visit(core, k, t)
            published |= seen
        assert published - {0} == {1, 2, 3, 4}
        disk_full(True)  # the robots still see ids handed out now: none may come back
        for k in (4, 5):
            t, seen = _visit(core, k, t)
            published |= seen
        disk_full(False)
    assert published - {0} == {1, 2, 3, 4, 5, 6}  # within the block reserved before the disk filled up
    with FaceStore(db, embedding_space=SPACE) as store:
        assert store.lost_face_ids == []  # 5 and 6 were never saved: nothing was lost
        core = MasterCore(_config(), store=store)
        _, seen = _visit(core, 6, 100.0)
    (new,) = seen - {0}
    assert new not in published and new > ID_BLOCK  # above the whole block reserved before the restart


@pytest.mark.parametrize("write_behind", [False, True])
def test_no_new_face_id_is_handed_out_while_it_cannot_be_reserved(
        tmp_path: Path, disk_full: Callable[[bool], None], write_behind: bool) -> None:
    db = tmp_path / "faces.db"
    store = WriteBehindStore(lambda: FaceStore(db, embedding_space=SPACE)) if write_behind \
        else FaceStore(db, embedding_space=SPACE)
    try:
        core = MasterCore(_config(), store=store)
        disk_full(True)
        t, seen = _visit(core, 0, 0.0)
        assert seen == {0}  # undecided all along: no face id was published
        assert core.identity.face_ids() == [] and core.stats.faces_created == 0
        assert core.stats.faces_refused_no_id >= 1 and "disk is full" in core.memory.id_error
        verdict = MasterHealthWatch().verdict(t, faces_refused_no_id=core.stats.faces_refused_no_id,
                                              face_id_error=core.memory.id_error)
        (error,) = verdict.errors
        assert "new people get no face id" in error and "disk full" in error, error
        disk_full(False)
        core.tick(t + 2.0)  # the space is back: the reservation is retried without waiting for a new person
        assert core.memory.id_error == ""
        t, seen = _visit(core, 0, t + 2.0)  # the same person is learned now
        (given,) = seen - {0}
        assert store.max_face_id() >= given  # durable before it was published
    finally:
        store.close()
    with FaceStore(db, embedding_space=SPACE) as store:
        assert store.max_face_id() == given + ID_BLOCK - 1  # the block reserved when it was given
        core = MasterCore(_config(), store=store)
        _, seen = _visit(core, 1, 100.0)
    assert seen - {0} == {given + ID_BLOCK}


def test_a_reservation_is_durable_in_the_database_and_in_the_ledger(tmp_path: Path) -> None:
    db = tmp_path / "faces.db"
    with FaceStore(db, embedding_space=SPACE) as store:
        store.reserve_face_ids(16)
        assert store.max_face_id() == 16
        store.reserve_face_ids(3)  # never lowered
        assert store.max_face_id() == 16
    assert IdLedger(db).read() == (16, set())
    with FaceStore(db, embedding_space=SPACE) as store:
        assert store.max_face_id() == 16
    Path(str(db) + ".ids").unlink()  # the ledger lost: the database still has it
    with FaceStore(db, embedding_space=SPACE) as store:
        assert store.max_face_id() == 16
    with FaceStore(db, embedding_space=SPACE, read_only=True) as store, \
            pytest.raises(FaceStoreError, match="read-only"):
        store.reserve_face_ids(40)


def test_a_reservation_that_cannot_be_written_reserves_nothing(tmp_path: Path,
                                                                disk_full: Callable[[bool], None]) -> None:
    db = tmp_path / "faces.db"
    with FaceStore(db, embedding_space=SPACE) as store:
        disk_full(True)
        with pytest.raises(FaceStoreError, match="disk is full"):
            store.reserve_face_ids(16)
        disk_full(False)
        assert store.max_face_id() == 0
    ledger = IdLedger(db)
    ledger.reconcile(set(), 0, write=False)
    disk_full(True)
    with pytest.raises(FaceStoreError, match="No space"):
        ledger.reserve(32)
    assert ledger.max_id == 0  # not reserved: the master must not hand these ids out
