"""The master core end to end on generated frames with real face embeddings.

A person walks through two cameras' views, leaves every view long enough for the track to die and
comes back: the new track must get the SAME face id (the face table, not the tracker, restores the
identity), and the predefined-people gallery names it.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from conftest import FACES_DIR

from face_reid_camera.faces.detector import YuNetDetector
from face_reid_camera.faces.embedder import FaceEmbedder
from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.records import STATE_CONFIRMED, CameraFrameRecord, PersonRecord
from face_reid_master.tracking.config import TrackerConfig

IDS = ["lfw_Tony_Blair", "lfw_Colin_Powell", "lfw_Hugo_Chavez"]


@pytest.fixture(scope="module")
def embeddings() -> dict[str, np.ndarray]:
    """identity -> (n_photos, 128) real embeddings of the fixture photos."""
    detector, embedder = YuNetDetector(), FaceEmbedder()
    out = {}
    for ident in IDS:
        rows = []
        for path in sorted((FACES_DIR / ident).glob("*.jpg")):
            photo = cv2.imread(str(path))
            best = max(detector.detect(photo), key=lambda d: float(d.box_xywh[2] * d.box_xywh[3]))
            rows.append(embedder.embed_faces(photo, [best.landmarks])[0])
        out[ident] = np.stack(rows)
    return out


def _walk(core: MasterCore, who: dict[str, tuple[np.ndarray, np.ndarray | None]], t0: float, t1: float,
          rate_hz: float = 10.0, cameras: tuple[str, ...] = ("cam_a", "cam_b")) -> float:
    """Feed frames: who = name -> (start xy, embedding rows or None); people walk +x at 0.5 m/s."""
    t = t0
    k = 0
    while t < t1:
        cam = cameras[k % len(cameras)]
        people = []
        for start, embs in who.values():
            pos = np.array([start[0] + 0.5 * (t - t0), start[1], 0.0])
            emb = embs[k % len(embs)] if embs is not None else None
            people.append(PersonRecord(pos, 0.05, 1.75, emb, 0.9, 0.8))
        core.process_frame(CameraFrameRecord(cam, t, tuple(people)))
        k += 1
        t = t0 + k / rate_hz
    return t


def _config(**kw) -> MasterConfig:
    """Fast timeouts; the dlib space (the fixtures' embeddings) unless a test says otherwise."""
    kw.setdefault("embedding_space", "dlib_resnet_v1")
    return MasterConfig(tracker=TrackerConfig(lost_after_s=0.5, delete_after_s=1.0), **kw)


@pytest.mark.parametrize("method", ["bayes", "threshold"])
def test_leave_and_return_keeps_the_face_id(embeddings, method: str) -> None:
    core = MasterCore(_config(method=method))
    a, b = embeddings[IDS[0]], embeddings[IDS[1]]
    # both people visible with their first 5 photos
    t = _walk(core, {"a": (np.array([0.0, 0.0]), a[:5]), "b": (np.array([0.0, 2.0]), b[:5])}, 0.0, 4.0)
    first = {tr.face_id: tr for tr in core.tracks()}
    assert len(first) == 2 and 0 not in first, core.tracks()
    face_of_a = next(tr.face_id for tr in core.tracks() if abs(tr.position_xy[1]) < 0.5)
    track_of_a = next(tr.track_id for tr in core.tracks() if tr.face_id == face_of_a)
    # everybody leaves: no detections for 3 s -> tracks deleted, faces released
    _walk(core, {}, t, t + 3.0)
    assert core.tracks() == []
    # A comes back alone, with OTHER photos of the same person
    _walk(core, {"a": (np.array([5.0, -1.0]), a[5:])}, t + 3.0, t + 7.0)
    (back,) = core.tracks()
    assert back.track_id != track_of_a
    assert back.face_id == face_of_a
    assert back.state == STATE_CONFIRMED
    assert core.stats.faces_reidentified >= 1 and core.stats.faces_created == 2


def test_an_unknown_person_gets_a_new_face_id(embeddings) -> None:
    core = MasterCore(_config())
    t = _walk(core, {"a": (np.array([0.0, 0.0]), embeddings[IDS[0]][:5])}, 0.0, 3.0)
    _walk(core, {}, t, t + 3.0)
    _walk(core, {"c": (np.array([1.0, 0.0]), embeddings[IDS[2]])}, t + 3.0, t + 7.0)
    (track,) = core.tracks()
    assert track.face_id not in (0, 1)
    assert core.stats.faces_created == 2 and core.stats.faces_reidentified == 0


def test_predefined_person_is_named(embeddings) -> None:
    gallery = {"Tony": embeddings[IDS[0]][8:], "Colin": embeddings[IDS[1]][8:]}
    core = MasterCore(_config(), gallery=gallery)
    _walk(core, {"a": (np.array([0.0, 0.0]), embeddings[IDS[0]][:8]),
                 "x": (np.array([0.0, 2.0]), embeddings[IDS[2]][:8])}, 0.0, 5.0)
    names = {round(float(tr.position_xy[1])): tr.name for tr in core.tracks()}
    assert names == {0: "Tony", 2: ""}


def test_bad_input_is_counted_not_raised(embeddings) -> None:
    core = MasterCore(_config(known_camera_ids=("cam_a",)))
    good = embeddings[IDS[0]][0]
    frames = [
        CameraFrameRecord("cam_zzz", 1.0, (PersonRecord(np.zeros(3), 0.1, 1.7, good),)),
        CameraFrameRecord("cam_a", math.nan, ()),
        CameraFrameRecord("cam_a", 1.0, (PersonRecord(np.array([np.nan, 0, 0]), 0.1),)),
        CameraFrameRecord("cam_a", 1.1, (PersonRecord(np.zeros(3), 0.1, 1.7, good[:100]),)),
        CameraFrameRecord("cam_a", 1.2, (PersonRecord(np.zeros(3), 0.1, 1.7, np.full(128, np.nan, np.float32)),)),
        CameraFrameRecord("cam_a", 1.3, (PersonRecord(np.zeros(3), -1.0),)),
    ]
    outcomes = [core.process_frame(f, now_s=1.3) for f in frames]
    assert [o.accepted for o in outcomes] == [False, False, True, True, True, True]
    assert "unknown camera" in outcomes[0].reason
    # stamps far in the past or future relative to now
    assert not core.process_frame(CameraFrameRecord("cam_a", -100.0, ()), now_s=1.3).accepted
    assert not core.process_frame(CameraFrameRecord("cam_a", 500.0, ()), now_s=1.3).accepted
    s = core.stats
    assert (s.frames_rejected_unknown_camera, s.frames_rejected_bad_stamp) == (1, 1)
    assert (s.frames_rejected_stale, s.frames_rejected_future) == (1, 1)
    assert s.detections_rejected_position == 2
    assert (s.embeddings_rejected_length, s.embeddings_rejected_nonfinite) == (1, 1)
    assert s.embeddings_used == 0


@pytest.mark.parametrize("bad", [(math.nan, 0.0), (0.0, math.inf), (-math.inf, math.nan), (1.0,), ()])
def test_bad_positions_are_rejected_and_counted_the_others_tracked(bad: tuple[float, ...]) -> None:
    # The core is the one place a frame is validated: the tracker only ever sees the valid rows.
    core = MasterCore(_config())
    people = (PersonRecord(np.array([1.0, 1.0, 0.0]), 0.05), PersonRecord(np.array(bad), 0.05),
              PersonRecord(np.array([3.0, 3.0, 0.0]), 0.05))
    out = core.process_frame(CameraFrameRecord("cam_a", 0.0, people))
    assert out.accepted and sorted(out.track_of_person) == [0, 2] and len(out.tracks_created) == 2
    assert (core.stats.detections_received, core.stats.detections_rejected_position) == (3, 1)
    assert core.tracker.stats.detections_received == 2
    assert all(np.isfinite(s.position_xy).all() for s in core.tracker.snapshots())


@pytest.mark.parametrize("std", [0.0, -0.1, math.nan, math.inf])
def test_bad_position_std_is_rejected_and_counted(std: float) -> None:
    core = MasterCore(_config())
    out = core.process_frame(CameraFrameRecord("cam_a", 0.0, (PersonRecord(np.array([1.0, 1.0, 0.0]), std),)))
    assert out.accepted and out.track_of_person == {} and out.tracks_created == ()
    assert core.stats.detections_rejected_position == 1 and core.tracker.num_tracks == 0


def test_a_camera_id_that_is_not_a_str_is_rejected_and_counted() -> None:
    core = MasterCore(_config())
    out = core.process_frame(CameraFrameRecord(7, 0.0, (PersonRecord(np.zeros(3), 0.05),)))  # type: ignore[arg-type]
    assert not out.accepted and "str" in out.reason
    assert core.stats.frames_rejected_unknown_camera == 1 and core.tracker.stats.frames_processed == 0


def test_config_validation() -> None:
    with pytest.raises(ValueError):
        MasterConfig(method="magic")
    with pytest.raises(ValueError):
        MasterConfig(max_stamp_age_s=-1)
    with pytest.raises(ValueError, match="release_after_inconsistent needs learn_only_consistent_features"):
        MasterConfig(learn_only_consistent_features=False)  # the default releases swapped tracks
    assert MasterConfig(learn_only_consistent_features=False, release_after_inconsistent=0).method == "bayes"


def test_faces_survive_a_restart_and_can_be_forgotten(embeddings, tmp_path) -> None:
    from face_reid_master.storage.face_store import FaceStore

    db = tmp_path / "faces.db"
    with FaceStore(db) as store:
        core = MasterCore(_config(), store=store)
        _walk(core, {"a": (np.array([0.0, 0.0]), embeddings[IDS[0]][:5])}, 0.0, 3.0)
        (face_a,) = {t.face_id for t in core.tracks()}
        assert face_a != 0
    # a new master process on the same database recognises the person at once
    with FaceStore(db) as store:
        core = MasterCore(_config(), store=store)
        assert core.identity.face_ids() == [face_a]
        _walk(core, {"a": (np.array([3.0, 1.0]), embeddings[IDS[0]][5:])}, 100.0, 103.0)
        assert {t.face_id for t in core.tracks()} == {face_a}
        # forgetting deletes the face from memory and disk; its id is never reused
        assert core.forget_face(face_a)
        assert store.load_faces() == [] and core.identity.face_ids() == []
        _walk(core, {}, 103.0, 106.0)
        _walk(core, {"a": (np.array([3.0, 1.0]), embeddings[IDS[0]][5:])}, 106.0, 109.0)
        (again,) = {t.face_id for t in core.tracks()}
        assert again not in (0, face_a)


def test_embeddings_of_another_space_are_not_compared_and_noticed_once_per_camera(embeddings) -> None:
    """A dlib master: an SFace camera's faces are refused (positions tracked, one notice); a camera running
    both embedders is used through its dlib half."""
    core = MasterCore(_config())
    a = embeddings[IDS[0]]
    rng = np.random.default_rng(0)
    notices: list[str] = []
    for k in range(40):
        t = k / 10.0
        pos = np.array([0.5 * t, 0.0, 0.0])
        if k % 2:
            sface = rng.normal(size=128).astype(np.float32)
            person = PersonRecord(pos, 0.05, 1.75, sface / np.linalg.norm(sface), 0.9, 0.8, "sface_2021dec")
            cam = "cam_sface"
        else:
            joint = np.concatenate([a[k // 2 % 5], rng.normal(size=128).astype(np.float32)])
            person = PersonRecord(pos, 0.05, 1.75, joint, 0.9, 0.8, "dlib_resnet_v1+sface_2021dec")
            cam = "cam_both"
        outcome = core.process_frame(CameraFrameRecord(cam, t, (person,)))
        assert outcome.accepted
        notices.extend(outcome.notices)
    assert core.stats.embeddings_rejected_space == 20
    assert core.stats.embeddings_used == 20
    assert len(notices) == 1 and "cam_sface" in notices[0] and "'sface_2021dec'" in notices[0], notices
    (track,) = core.tracks()  # one person, tracked from both cameras
    assert track.face_id != 0 and track.face_observations == 20
    learned = core.identity.faces.features(track.face_id)
    assert learned.shape[1] == 128  # the dlib half only
    assert np.min(np.linalg.norm(learned[:, None, :] - a[None, :5, :], axis=2), axis=1).max() < 1e-5


def test_a_joint_space_master_needs_both_networks(embeddings) -> None:
    core = MasterCore(_config(embedding_space="dlib_resnet_v1+sface_2021dec"), likelihood=_joint_stub_likelihood())
    a = embeddings[IDS[0]]
    outcome = core.process_frame(CameraFrameRecord("cam_dlib", 0.0, (PersonRecord(np.zeros(3), 0.05, 1.7, a[0]),)))
    assert core.stats.embeddings_rejected_space == 1 and "cam_dlib" in outcome.notices[0]
    wrong_len = PersonRecord(np.zeros(3), 0.05, 1.7, a[0], embedding_space="dlib_resnet_v1+sface_2021dec")
    core.process_frame(CameraFrameRecord("cam_both", 0.1, (wrong_len,)))
    assert core.stats.embeddings_rejected_length == 1
    unknown = PersonRecord(np.zeros(3), 0.05, 1.7, a[0], embedding_space="openface_v9")
    outcome = core.process_frame(CameraFrameRecord("cam_x", 0.2, (unknown,)))
    assert core.stats.embeddings_rejected_space == 2 and "unknown embedding space" in outcome.notices[0]


def _joint_stub_likelihood():
    from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal

    return LikelihoodModel(SkewNormal(0.0, 0.8, 0.2), SkewNormal(0.0, 1.6, 0.2))


def test_frames_deferred_to_one_identity_update_per_cycle_give_the_same_identities(embeddings) -> None:
    """A node applies a cycle's frames with defer_identity and then finish_frames: the events come from
    finish_frames only, and leave-and-return gives the same faces as one identity update per frame."""
    a, b = embeddings[IDS[0]], embeddings[IDS[1]]

    def run(cycle: int) -> tuple[list[tuple[int, int]], int, int]:
        core, events, k = MasterCore(_config()), 0, 0
        scenes = [({"a": (np.array([0.0, 0.0]), a[:5]), "b": (np.array([0.0, 2.0]), b[:5])}, 0.0, 4.0),
                  ({}, 4.0, 7.0), ({"a": (np.array([5.0, -1.0]), a[5:])}, 7.0, 11.0)]
        for who, t0, t1 in scenes:
            for j, t in enumerate(np.arange(t0, t1, 0.1)):
                people = tuple(PersonRecord(np.array([s[0] + 0.5 * (t - t0), s[1], 0.0]), 0.05, 1.75,
                                            e[j % len(e)], 0.9, 0.8) for s, e in who.values())
                out = core.process_frame(CameraFrameRecord(("cam_a", "cam_b")[k % 2], float(t), people),
                                         defer_identity=cycle > 1)
                assert out.accepted and (cycle == 1 or out.identity_events == ())
                events += len(out.identity_events)
                k += 1
                if k % cycle == 0:
                    events += len(core.finish_frames())
        events += len(core.finish_frames())
        return sorted((tr.track_id, tr.face_id) for tr in core.tracks()), len(core.identity.face_ids()), events

    per_frame = run(1)
    assert per_frame[0] and per_frame[0][0][1] != 0 and per_frame[1] == 2 and per_frame[2] > 0
    assert run(3) == per_frame


def test_a_decided_track_publishes_its_decision_through_the_confidence_map(embeddings) -> None:
    """identity_confidence is what the map says decisions like this one are worth, not the raw posterior: a
    new face is looked up as "face_new", the person's return (re-identified) as "face_known"."""
    from face_reid_master.identity.confidence_map import ConfidenceMap

    published = {}
    mapped = ConfidenceMap((0.0, 1.0), {"face_known": (0.42,), "face_new": (0.31,), "body": (0.17,)})
    for name, cmap in (("mapped", mapped), ("raw", ConfidenceMap.identity())):
        core = MasterCore(_config(), confidence_map=cmap)
        _walk(core, {"a": (np.array([0.0, 0.0]), embeddings[IDS[0]][:2])}, 0.0, 0.2)  # 2 faces: undecided
        _walk(core, {"a": (np.array([0.1, 0.0]), None)}, 0.2, 1.0)  # confirmed, no face
        (undecided,) = core.tracks()
        assert undecided.face_id == 0 and undecided.identity_confidence == 0.0  # no claim, no confidence
        assert core.identity.confidence_of(undecided.track_id) > 0.0  # though its candidates have posteriors
        _walk(core, {"a": (np.array([0.5, 0.0]), embeddings[IDS[0]][:5])}, 1.0, 3.0)
        (first,) = core.tracks()
        assert first.face_id and first.identity_evidence == "face" and core.identity.decided_new(first.track_id)
        _walk(core, {}, 3.0, 6.0)  # gone long enough for the track to be deleted
        _walk(core, {"a": (np.array([3.0, 1.0]), embeddings[IDS[0]][5:])}, 6.0, 9.0)
        (back,) = core.tracks()
        assert back.face_id == first.face_id and back.track_id != first.track_id
        assert not core.identity.decided_new(back.track_id)
        published[name] = (first.identity_confidence, back.identity_confidence)
    assert published["mapped"] == (0.31, 0.42)
    assert min(published["raw"]) > 0.9  # the decisions' posteriors


def test_a_track_the_tracker_swapped_onto_another_person_is_published_under_a_new_id(embeddings) -> None:
    """The person on track T is face A for 3 s; then the track carries B's face (the tracker swapped people):
    once the faces release A, T ends on the output and the same tracker track goes on under a new id that
    starts at the split, so a robot following T as A does not follow B."""
    a, b = embeddings[IDS[0]], embeddings[IDS[1]]
    core = MasterCore(_config())
    _walk(core, {"p": (np.array([0.0, 0.0]), a[:5])}, 0.0, 3.0)
    (before,) = core.tracks()
    assert before.face_id != 0
    events = []
    t, k = 3.0, 0
    while t < 8.0:  # the same tracker track, now showing B's face
        pos = np.array([0.5 * t, 0.0, 0.0])
        out = core.process_frame(CameraFrameRecord("cam_a", t, (PersonRecord(pos, 0.05, 1.75, b[k % 5], 0.9, 0.8),)))
        events.extend(out.identity_events)
        k += 1
        t = 3.0 + k / 10.0
    (after,) = core.tracks()
    assert core.tracker.track_ids() == [before.track_id]  # one tracker track throughout
    swaps = [e for e in events if e.kind.value == "swapped"]
    assert [(e.track_id, e.face_id) for e in swaps] == [(before.track_id, before.face_id)]
    assert after.track_id not in (0, before.track_id) and core.public_id(before.track_id) == after.track_id
    assert after.face_id not in (0, before.face_id)  # B, decided afresh on the new id
    assert after.first_seen_s >= swaps[0].stamp_s > before.first_seen_s
    assert core.stats.faces_released_swapped == 1


def test_an_unidentified_track_that_strayed_onto_someone_else_is_classified_afresh(embeddings) -> None:
    """An undecided track shows two of A's faces; the tracker then says its detection is more likely someone it was
    not following: A's faces are dropped, so that they do not decide whoever it follows now. The track keeps its
    published id: it claimed nobody, so no consumer can carry a person over."""
    a = embeddings[IDS[0]]
    core = MasterCore(_config())
    _walk(core, {"p": (np.array([0.0, 0.0]), a[:2])}, 0.0, 0.2)  # two faces: undecided
    _walk(core, {"p": (np.array([0.1, 0.0]), None)}, 0.2, 1.0)
    (before,) = core.tracks()
    record = core.identity.tracks.record(before.track_id)
    assert before.face_id == 0 and record is not None and record.slot is not None  # A's faces are buffered
    core.identity.crossings.strayed(before.track_id, 0.3)
    core.tick(1.05)
    assert record.slot is not None and core.identity.stats.tracks_restarted == 0  # less likely than not
    core.identity.crossings.strayed(before.track_id, 0.4)  # 1 - 0.7 x 0.6 = 0.58 that it is someone else
    core.tick(1.1)
    (after,) = core.tracks()
    assert after.track_id == before.track_id and after.face_id == 0
    assert record.slot is None and record.bayes_row == 0 and core.identity.stats.tracks_restarted == 1
    assert core.identity.crossings.doubt_of(before.track_id) == 0.0  # its strays are spent
