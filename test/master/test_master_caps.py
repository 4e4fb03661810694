"""Caps of the master core: at most max_faces learned faces (the least recently seen unnamed evicted, named never,
new faces refused when nothing can go), degenerate embeddings refused, face ids range-checked, a feature bank whose
memory follows what it stores."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.identity.feature_bank import FeatureBank
from face_reid_master.identity.records import MAX_FACE_ID, LearnedFace
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.storage.face_store import FaceStore
from face_reid_master.tracking.config import TrackerConfig

SPACE = "dlib_resnet_v1"
DIM = 128
RNG = np.random.default_rng(7)
PEOPLE = RNG.normal(size=(12, DIM))
PEOPLE *= 1.4 / np.linalg.norm(PEOPLE, axis=1, keepdims=True)  # dlib's embedding length: the master checks it


def _look(k: int, rng: np.random.Generator) -> np.ndarray:
    """One embedding of person k (their direction, a little noise, dlib's length)."""
    v = PEOPLE[k] + rng.normal(0.0, 0.03, DIM)
    return (v * 1.4 / np.linalg.norm(v)).astype(np.float32)


def _config(**kw: object) -> MasterConfig:
    return MasterConfig(embedding_space=SPACE, body_appearance_tracking=False, min_face_features_for_name=1,
                        tracker=TrackerConfig(lost_after_s=0.5, delete_after_s=1.0), **kw)


def _visit(core: MasterCore, k: int, t0: float, seconds: float = 1.5) -> float:
    """Person k alone in view for ``seconds`` at 10 Hz, then nobody until their track is deleted; the end time."""
    rng = np.random.default_rng(k)
    n = int(seconds * 10)
    for i in range(n):
        person = PersonRecord(np.array([0.1 * i, 0.0, 0.0]), 0.05, 1.75, _look(k, rng), 0.9, 0.8)
        core.process_frame(CameraFrameRecord("cam", t0 + i / 10, (person,)))
    t = t0 + n / 10 + 2.0
    core.tick(t)
    assert core.tracks() == []
    return t


def _faces_seen(core: MasterCore) -> dict[int, str]:
    return {fid: core.face_name(fid) for fid in core.identity.face_ids()}


def test_the_least_recently_seen_unnamed_faces_are_evicted_beyond_max_faces() -> None:
    core = MasterCore(_config(max_faces=3))
    t = 0.0
    for k in range(6):
        t = _visit(core, k, t)
    assert core.stats.faces_created == 6
    assert len(core.identity.face_ids()) == 3
    assert core.stats.faces_evicted == 3
    assert core.identity.face_ids() == [4, 5, 6]  # the three seen last


def test_named_faces_are_never_evicted() -> None:
    gallery = {"Ann": np.stack([_look(0, np.random.default_rng(100 + i)) for i in range(5)])}
    core = MasterCore(_config(max_faces=2), gallery=gallery)
    t = _visit(core, 0, 0.0)  # Ann: face 1, named
    assert _faces_seen(core) == {1: "Ann"}
    for k in range(1, 5):
        t = _visit(core, k, t)
    faces = _faces_seen(core)
    assert len(faces) == 2 and faces[1] == "Ann", faces  # the oldest face, kept: it has a name
    assert core.stats.faces_evicted == 3


def test_new_unnamed_faces_are_refused_and_counted_when_every_face_is_named() -> None:
    gallery = {name: np.stack([_look(k, np.random.default_rng(100 + i)) for i in range(5)])
               for k, name in enumerate(("Ann", "Bob"))}
    core = MasterCore(_config(max_faces=2), gallery=gallery)
    t = _visit(core, 0, 0.0)
    t = _visit(core, 1, t)
    assert sorted(_faces_seen(core).values()) == ["Ann", "Bob"]
    _visit(core, 2, t)  # a stranger: no room, nothing may go
    assert sorted(_faces_seen(core).values()) == ["Ann", "Bob"]
    assert core.stats.faces_refused_cap >= 1 and core.stats.faces_evicted == 0


def test_the_cap_evicts_from_the_store_too_and_applies_to_a_store_loaded_over_it(tmp_path) -> None:
    db = tmp_path / "faces.db"
    with FaceStore(db, embedding_space=SPACE) as store:
        store.save_faces([LearnedFace(k + 1, _look(k, RNG)[None, :], "Ann" if k == 0 else None, 0.0, float(k), 1)
                          for k in range(5)])
        core = MasterCore(_config(max_faces=3), store=store)
        assert core.identity.face_ids() == [1, 4, 5]  # named 1 + the two unnamed seen last
        assert store.face_ids() == [1, 4, 5] and core.stats.faces_evicted == 2
        _visit(core, 9, 10.0)  # a new face: the least recently seen unnamed (4) goes, in the store too
        assert core.identity.face_ids() == [1, 5, 6]
        assert store.face_ids() == [1, 5, 6]


def test_feature_bank_memory_follows_what_it_stores() -> None:
    dim, faces, per_face = 256, 2000, 8
    bank = FeatureBank(dim, 50)
    rows = RNG.normal(size=(per_face, dim)).astype(np.float32)
    for _ in range(faces):
        bank.new_slot(rows)
    stored = faces * per_face * (dim + 1) * 4
    held = bank.feats.nbytes + bank.pd2.nbytes  # what grows with faces
    assert held < 2.0 * stored, (held, stored)  # was 8.6x: 50 rows (and 50 x 50 distances) reserved per face
    slot = bank.new_slot(RNG.normal(size=(50, dim)).astype(np.float32))  # one full face widens every slot
    assert bank.features(slot).shape == (50, dim) and bank.nbytes >= held
    assert np.array_equal(bank.features(0), rows)


@pytest.mark.parametrize("bad", [np.zeros(DIM), np.full(DIM, 1.4 / np.sqrt(DIM)),
                                 np.r_[np.nan, np.ones(DIM - 1)], np.r_[np.inf, np.zeros(DIM - 1)]])
def test_add_person_refuses_degenerate_embeddings(bad: np.ndarray) -> None:
    core = MasterCore(_config())
    with pytest.raises(ValueError, match="degenerate"):
        core.add_person("Eve", np.stack([_look(0, RNG), bad]).astype(np.float32))
    assert "Eve" not in core.people.names()


def test_constant_embeddings_in_frames_are_counted_and_not_used() -> None:
    core = MasterCore(_config())
    constant = np.full(DIM, 1.4 / np.sqrt(DIM), np.float32)  # a plausible length, no face
    for i in range(20):
        core.process_frame(CameraFrameRecord("cam", i / 10, (PersonRecord(np.zeros(3), 0.05, 1.75, constant),)))
    assert core.stats.embeddings_rejected_degenerate == 20
    assert core.stats.embeddings_used == 0 and core.identity.face_ids() == []


@pytest.mark.parametrize("face_id", [0, -1, MAX_FACE_ID + 1, 2**64 - 1])
def test_forget_face_range_checks_the_id(face_id: int, tmp_path) -> None:
    with FaceStore(tmp_path / "faces.db", embedding_space=SPACE) as store:
        core = MasterCore(_config(), store=store)
        with pytest.raises(ValueError, match=f"face id must be between 1 and {MAX_FACE_ID}"):
            core.forget_face(face_id)
        with pytest.raises(ValueError, match="face id must be between 1 and"):
            store.forget(face_id)
    assert not MasterCore(_config()).forget_face(MAX_FACE_ID)  # the largest id is a valid (unknown) one
