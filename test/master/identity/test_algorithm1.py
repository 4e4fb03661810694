"""Tests of Algorithm 1: track / face bookkeeping, release, forget, export / import, invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import DATA_DIR, FACES_DIR
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from identity_test_helpers import (
    ASSIGNED,
    CENTRES,
    DIM,
    NEW,
    RELEASED,
    SWAPPED,
    event_kinds,
    feed_one,
    manager_with_faces,
    person_obs,
)

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.methods import make_identity_manager
from face_reid_master.identity.records import LearnedFace

YUNET_PATH = DATA_DIR.parents[1] / "models" / "face_detection_yunet_2023mar.onnx"


def test_known_person_is_assigned_after_min_observations() -> None:
    rng = np.random.default_rng(1)
    m = manager_with_faces(3, rng, min_observations=3)
    assert feed_one(m, 10, 1, rng, 0.0) == []
    assert m.posterior_of(10)[2] > 0.95  # already confident ...
    assert feed_one(m, 10, 1, rng, 0.1) == []  # ... but only 2 observations
    assert m.face_id_of(10) is None
    events = feed_one(m, 10, 1, rng, 0.2)
    assert event_kinds(events) == [(ASSIGNED, 10, 2)]
    assert events[0].confidence > 0.95 and events[0].stamp_s == 0.2
    assert m.face_id_of(10) == 2 and m.confidence_of(10) == events[0].confidence
    assert m.faces.available_ids() == [1, 3]
    assert len(m.faces.features(2)) == 5 + 3  # the track's observations joined the face
    assert m.posterior_of(10) == {}


def test_unknown_person_gets_a_new_face_id() -> None:
    rng = np.random.default_rng(2)
    m = manager_with_faces(3, rng, min_observations=3)
    events = []
    for i in range(3):
        events += feed_one(m, 10, 5, rng, 0.1 * i)
    assert event_kinds(events) == [(NEW, 10, 4)]
    assert m.face_ids() == [1, 2, 3, 4] and m.faces.available_ids() == [1, 2, 3]
    assert len(m.faces.features(4)) == 3


def test_first_person_ever_becomes_face_1() -> None:
    rng = np.random.default_rng(3)
    m = BayesIdentityManager(min_observations=2)
    assert feed_one(m, 7, 0, rng, 0.0) == []
    assert m.posterior_of(7) == {0: pytest.approx(1 - 1e-3)}
    assert event_kinds(feed_one(m, 7, 0, rng, 0.1)) == [(NEW, 7, 1)]


def test_track_death_releases_the_face_which_is_assignable_again() -> None:
    rng = np.random.default_rng(4)
    m = manager_with_faces(3, rng, min_observations=3)
    for i in range(3):
        feed_one(m, 10, 1, rng, 0.1 * i)
    assert m.face_id_of(10) == 2
    m.track_deleted(10, 1.0)
    events = m.step(1.0)
    assert event_kinds(events) == [(RELEASED, 10, 2)]
    assert m.face_id_of(10) is None and m.faces.available_ids() == [1, 3, 2]
    events = []
    for i in range(3):
        events += feed_one(m, 11, 1, rng, 2.0 + 0.1 * i)
    assert event_kinds(events) == [(ASSIGNED, 11, 2)]


def test_face_of_a_live_track_is_not_assignable_to_a_simultaneous_track() -> None:
    rng = np.random.default_rng(5)
    m = manager_with_faces(3, rng, min_observations=3)
    for i in range(3):
        feed_one(m, 10, 1, rng, 0.1 * i)
    assert m.face_id_of(10) == 2
    events = []
    for i in range(4):  # the same person seen by a second, simultaneous track (e.g. a tracker split)
        events += feed_one(m, 11, 1, rng, 1.0 + 0.1 * i)
        assert 2 not in m.posterior_of(11)
    assert m.face_id_of(11) != 2 and (ASSIGNED, 11, 2) not in event_kinds(events)
    assert m.assigned_tracks()[10] == 2


def test_a_decision_below_learn_confidence_teaches_its_face_nothing() -> None:
    rng = np.random.default_rng(1)
    m = manager_with_faces(3, rng, min_observations=3, learn_confidence=1.0)  # no decision is that certain
    for i in range(3):
        feed_one(m, 10, 1, rng, 0.1 * i)
    assert m.face_id_of(10) == 2 and len(m.faces.features(2)) == 5  # identified; its 3 faces not learned
    feed_one(m, 10, 1, rng, 0.3)
    assert len(m.faces.features(2)) == 5 and m.stats.observations_not_learned_uncertain == 4
    m.track_deleted(10, 0.4)
    m.step(0.4)
    for i in range(3):  # the next track of the person: decided again, the face still what it was
        feed_one(m, 11, 1, rng, 1.0 + 0.1 * i)
    assert m.face_id_of(11) == 2 and len(m.faces.features(2)) == 5
    m.learn_confidence = 0.0
    m.track_deleted(11, 2.0)
    m.step(2.0)
    for i in range(3):
        feed_one(m, 12, 1, rng, 3.0 + 0.1 * i)
    assert m.face_id_of(12) == 2 and len(m.faces.features(2)) == 5 + 3  # a certain enough decision teaches


def test_assigned_track_keeps_extending_its_face_within_the_bound() -> None:
    rng = np.random.default_rng(6)
    m = manager_with_faces(2, rng, min_observations=1, max_features_per_face=8)
    feed_one(m, 10, 0, rng, 0.0)
    assert m.face_id_of(10) == 1 and len(m.faces.features(1)) == 6
    m.add_observations(10, person_obs(0, 2, rng), 0.1)
    m.step(0.1)
    assert len(m.faces.features(1)) == 8
    for i in range(10):
        feed_one(m, 10, 0, rng, 0.2 + 0.1 * i)
    assert len(m.faces.features(1)) == 8
    faces = {f.face_id: f for f in m.faces.export_all()}
    assert faces[1].n_observations == 1 + 2 + 10  # the import said 0 observations
    assert faces[1].last_seen_s == pytest.approx(1.1)


def test_several_observations_and_calls_in_one_step_are_pooled() -> None:
    rng = np.random.default_rng(7)
    m = manager_with_faces(3, rng, min_observations=3)
    m.add_observations(10, person_obs(2, 2, rng), 0.0)
    m.add_observations(10, person_obs(2, 1, rng), 0.0)
    assert event_kinds(m.step(0.0)) == [(ASSIGNED, 10, 3)]


def test_decided_and_deleted_in_the_same_step_gives_new_then_released() -> None:
    rng = np.random.default_rng(8)
    m = BayesIdentityManager(min_observations=2)
    m.add_observations(10, person_obs(0, 2, rng), 0.0)
    m.track_deleted(10, 0.0)
    assert event_kinds(m.step(0.0)) == [(NEW, 10, 1), (RELEASED, 10, 1)]
    assert m.faces.available_ids() == [1]


def test_late_observations_of_deleted_tracks_are_ignored() -> None:
    rng = np.random.default_rng(9)
    m = BayesIdentityManager(min_observations=2)
    m.add_observations(10, person_obs(0, 1, rng), 0.0)
    m.track_deleted(10, 0.1)
    assert m.step(0.1) == []
    assert m.add_observations(10, person_obs(0, 1, rng), 0.2) is False
    assert m.step(0.2) == [] and list(m.tracks.entries) == []
    assert m.stats.observations_ignored_dead_track == 1
    assert m.posterior_table()[1] == []


@pytest.mark.parametrize(
    "emb",
    [
        np.zeros((1, 127), np.float32),
        np.zeros(128, np.float32),
        np.full((2, 128), np.nan, np.float32),
        np.full((1, 128), np.inf),
        np.zeros((1, 128), bool),
        np.array([["a"] * 128]),
    ],
)
def test_bad_embeddings_raise_value_error(emb: np.ndarray) -> None:
    m = BayesIdentityManager()
    with pytest.raises(ValueError):
        m.add_observations(1, emb, 0.0)
    assert list(m.tracks.entries) == []


@pytest.mark.parametrize("track_id", [1.5, "3", True, None])
def test_bad_track_ids_raise(track_id: object) -> None:
    with pytest.raises(ValueError):
        BayesIdentityManager().add_observations(track_id, np.zeros((1, DIM)), 0.0)  # type: ignore[arg-type]


def test_bad_stamp_raises() -> None:
    with pytest.raises(ValueError):
        BayesIdentityManager().step(math.nan)


def test_export_import_roundtrip_continues_face_ids() -> None:
    rng = np.random.default_rng(15)
    m = BayesIdentityManager(min_observations=2)
    for t in range(2):
        feed_one(m, 1, 0, rng, t)
        feed_one(m, 2, 1, rng, t)
    m.faces.set_name(2, "Ada")
    exported = m.faces.export_all()
    assert [f.face_id for f in exported] == [1, 2] and exported[1].name == "Ada"
    fresh = BayesIdentityManager(min_observations=2)
    fresh.faces.import_faces(exported)
    assert fresh.face_ids() == [1, 2] and fresh.faces.name(2) == "Ada"
    np.testing.assert_array_equal(fresh.faces.features(1), m.faces.features(1))
    events = []
    for t in range(3):
        events += feed_one(fresh, 9, 1, rng, t)  # person 1 again: known
        events += feed_one(fresh, 8, 3, rng, t)  # someone new: id 3
    assert sorted(event_kinds(events)) == sorted([(ASSIGNED, 9, 2), (NEW, 8, 3)])
    with pytest.raises(ValueError, match="already exists"):
        fresh.faces.import_faces([LearnedFace(1, np.zeros((1, DIM), np.float32))])
    with pytest.raises(ValueError, match="dim"):
        fresh.faces.import_faces([LearnedFace(7, np.zeros((1, 64), np.float32))])
    with pytest.raises(ValueError):
        LearnedFace(0, np.zeros((1, DIM)))
    with pytest.raises(ValueError):
        LearnedFace(3, np.full((1, DIM), np.nan))


def test_shortlist_mode_still_identifies_people() -> None:
    rng = np.random.default_rng(19)
    m = manager_with_faces(8, rng, exact_search_max_features=10, shortlist_faces=2, min_observations=3)
    events = []
    for i in range(3):
        events += feed_one(m, 1, 6, rng, i)
    assert event_kinds(events) == [(ASSIGNED, 1, 7)] and m.stats.shortlist_searches > 0


OPS = st.lists(
    st.one_of(
        st.tuples(st.just("obs"), st.integers(0, 5), st.integers(0, 4), st.integers(1, 3)),
        st.tuples(st.just("del"), st.integers(0, 5), st.just(0), st.just(0)),
        st.tuples(st.just("step"), st.just(0), st.just(0), st.just(0)),
    ),
    min_size=1,
    max_size=40,
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ops=OPS, method=st.sampled_from(["bayes", "threshold"]), seed=st.integers(0, 1000))
def test_random_operation_sequences_keep_invariants(ops: list, method: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    kw = {"min_observations": 2} if method == "bayes" else {"n_votes": 2}
    m = make_identity_manager(method, max_features_per_face=4, **kw)
    dead: set[int] = set()
    t = 0.0
    for op, track, person, n in [*ops, ("step", 0, 0, 0)]:
        t += 0.1
        if op == "obs":
            accepted = m.add_observations(
                track + 100 * len([d for d in dead if d % 100 == track]), person_obs(person, n, rng), t
            )
            assert accepted
        elif op == "del":
            tid = track + 100 * len([d for d in dead if d % 100 == track])
            m.track_deleted(tid, t)
            dead.add(tid)
        else:
            m.step(t)
        assigned = m.assigned_tracks()
        faces = list(assigned.values())
        assert len(faces) == len(set(faces))  # one face per live track, never shared
        assert set(m.faces.available_ids()) == set(m.face_ids()) - set(faces)
        assert m.face_ids() == list(range(1, len(m.face_ids()) + 1))  # stable ids from 1
        for f in m.face_ids():
            assert 1 <= len(m.faces.features(f)) <= 4
        for tid in list(m.tracks.entries):
            assert 0.0 <= m.confidence_of(tid) <= 1.0
        if isinstance(m, BayesIdentityManager):
            p, rows, cols = m.posterior_table()
            assert p.shape == (1 + len(rows), 1 + len(cols)) and cols == m.faces.available_ids()
            assert not set(rows) & set(assigned)
            assert p[0, 0] == 0.0 and np.all((p >= 0.0) & (p <= 1.0))
            if m.is_normalised and rows:
                slack = 1e-6 + (len(cols) + 1) * m.clamp_probability
                assert np.all(np.abs(p[1:].sum(axis=1) - 1.0) <= slack)
                assert np.all(np.abs(p[:, 1:].sum(axis=0) - 1.0) <= slack)


@pytest.fixture(scope="module")
def lfw_embeddings() -> dict[str, np.ndarray]:
    """identity -> (10, 128) embeddings of the committed LFW photos (largest face of each)."""
    cv2 = pytest.importorskip("cv2")
    try:
        from face_reid_camera.faces.alignment import align_face
        from face_reid_camera.faces.embedder import FaceEmbedder
    except ImportError:
        pytest.skip("face_reid_camera.faces.embedder not available")
    detector = cv2.FaceDetectorYN.create(str(YUNET_PATH), "", (320, 320), 0.6, 0.3, 50)
    embedder = FaceEmbedder(num_threads=1)
    out = {}
    for folder in sorted(FACES_DIR.glob("lfw_*")):
        chips = []
        for path in sorted(folder.glob("*.jpg")):
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            detector.setInputSize((image.shape[1], image.shape[0]))
            _, faces = detector.detect(image)
            largest = faces[int(np.argmax(faces[:, 2] * faces[:, 3]))]
            chips.append(align_face(image, largest[4:14].reshape(5, 2)))
        out[folder.name] = embedder.embed(np.stack(chips))
    return out


@pytest.mark.parametrize("method", ["bayes", "threshold"])
def test_real_faces_are_reidentified_across_visits(
    lfw_embeddings: dict[str, np.ndarray], method: str
) -> None:
    m = make_identity_manager(method)
    people = sorted(lfw_embeddings)
    first_face: dict[str, int] = {}
    t = 0.0
    # visit 1: photos 0..4, one per frame, then the person leaves; visit 2: photos 5..9
    for visit, photos in enumerate((range(0, 5), range(5, 10))):
        for k, person in enumerate(people):
            tid = 1000 * visit + k
            events = []
            for i in photos:
                m.add_observations(tid, lfw_embeddings[person][i : i + 1], t)
                events += m.step(t)
                t += 0.1
            m.track_deleted(tid, t)
            events += m.step(t)
            decided = [e for e in events if e.kind != RELEASED]
            assert len(decided) == 1, (person, events)
            if visit == 0:
                assert decided[0].kind == NEW
                first_face[person] = decided[0].face_id
            else:
                assert decided[0].kind == ASSIGNED and decided[0].face_id == first_face[person], person
    assert sorted(first_face.values()) == list(range(1, len(people) + 1))


def test_forget_available_face_removes_it_and_its_table_column() -> None:
    rng = np.random.default_rng(30)
    m = manager_with_faces(3, rng, min_observations=3)
    feed_one(m, 10, 1, rng, 0.0)  # an unassigned track with evidence for face 2
    assert m.posterior_of(10)[2] > 0.5
    assert m.forget_face(2) is True
    assert m.face_ids() == [1, 3] and m.faces.available_ids() == [1, 3]
    assert 2 not in m.posterior_of(10) and m.posterior_table()[2] == [1, 3]
    assert [f.face_id for f in m.faces.export_all()] == [1, 3]
    with pytest.raises(KeyError):
        m.faces.features(2)
    assert m.forget_face(2) is False and m.forget_face(99) is False
    assert m.stats.faces_forgotten == 1
    # person 1 is now a stranger: a new id, never the forgotten one, holding only the new observations
    events = feed_one(m, 10, 1, rng, 0.1) + feed_one(m, 10, 1, rng, 0.2)
    assert event_kinds(events) == [(NEW, 10, 4)]
    assert len(m.faces.features(4)) == 3
    with pytest.raises(ValueError):
        m.forget_face("2")  # type: ignore[arg-type]


def test_forget_face_of_a_live_track_makes_the_track_unidentified_again() -> None:
    rng = np.random.default_rng(31)
    m = manager_with_faces(3, rng, min_observations=3)
    for i in range(3):
        feed_one(m, 10, 1, rng, 0.1 * i)
    assert m.face_id_of(10) == 2
    m.add_observations(10, person_obs(1, 2, rng), 0.5)  # queued before the forget: dropped with the face
    assert m.forget_face(2)
    assert m.face_id_of(10) is None and m.assigned_tracks() == {} and m.confidence_of(10) == 0.0
    assert m.face_ids() == [1, 3] and m.faces.available_ids() == [1, 3]
    assert 10 in list(m.tracks.entries)
    assert m.step(0.6) == []  # the queued observations were dropped: nothing to classify
    assert m.posterior_of(10) == {}
    events = []
    for i in range(3):  # still in view: learned again, from scratch, under a new id
        events += feed_one(m, 10, 1, rng, 1.0 + 0.1 * i)
    assert event_kinds(events) == [(NEW, 10, 4)]
    assert len(m.faces.features(4)) == 3 and m.faces.export_all()[-1].n_observations == 3
    m.track_deleted(10, 2.0)
    assert event_kinds(m.step(2.0)) == [(RELEASED, 10, 4)]
    assert m.faces.available_ids() == [1, 3, 4]


def test_forget_face_of_a_track_being_deleted_emits_no_release() -> None:
    rng = np.random.default_rng(32)
    m = manager_with_faces(1, rng, min_observations=2)
    for i in range(2):
        feed_one(m, 10, 0, rng, 0.1 * i)
    assert m.face_id_of(10) == 1
    m.track_deleted(10, 1.0)
    assert m.forget_face(1)
    assert m.step(1.0) == [] and m.face_ids() == [] and list(m.tracks.entries) == []


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ops=st.lists(
        st.one_of(
            st.tuples(st.just("obs"), st.integers(0, 4), st.integers(0, 4)),
            st.tuples(st.just("del"), st.integers(0, 4), st.just(0)),
            st.tuples(st.just("forget"), st.integers(1, 6), st.just(0)),
            st.tuples(st.just("step"), st.just(0), st.just(0)),
        ),
        min_size=1,
        max_size=40,
    ),
    method=st.sampled_from(["bayes", "threshold"]),
)
def test_random_sequences_with_forget_keep_invariants(ops: list, method: str) -> None:
    rng = np.random.default_rng(len(ops))
    kw = {"min_observations": 2} if method == "bayes" else {"n_votes": 2}
    m = make_identity_manager(method, max_features_per_face=4, **kw)
    generation = dict.fromkeys(range(5), 0)
    forgotten: set[int] = set()
    t = 0.0
    for op, a, b in [*ops, ("step", 0, 0)]:
        t += 0.1
        if op == "obs":
            m.add_observations(a + 100 * generation[a], person_obs(b, 1, rng), t)
        elif op == "del":
            m.track_deleted(a + 100 * generation[a], t)
            generation[a] += 1
        elif op == "forget":
            known = a in m.face_ids()
            assert m.forget_face(a) is known
            if known:
                forgotten.add(a)
        else:
            m.step(t)
        faces = list(m.assigned_tracks().values())
        assert len(faces) == len(set(faces))
        assert set(m.faces.available_ids()) == set(m.face_ids()) - set(faces)
        assert not forgotten & set(m.face_ids())  # a forgotten id never comes back
        for f in m.face_ids():
            assert 1 <= len(m.faces.features(f)) <= 4
        if isinstance(m, BayesIdentityManager):
            p, rows, cols = m.posterior_table()
            assert p.shape == (1 + len(rows), 1 + len(cols)) and cols == m.faces.available_ids()
            assert not set(rows) & set(m.assigned_tracks())


def test_export_face_snapshots_one_face() -> None:
    rng = np.random.default_rng(34)
    m = BayesIdentityManager(min_observations=2)
    for t in range(2):
        feed_one(m, 1, 0, rng, 10.0 + t)
    one = m.faces.export(1)
    (all_,) = m.faces.export_all()
    assert (one.face_id, one.name, one.created_s, one.last_seen_s, one.n_observations) == (1, None, 11.0, 11.0, 2)
    assert one.features.tobytes() == all_.features.tobytes() and one.n_observations == all_.n_observations
    one.features[:] = 0.0  # a copy: the manager is unaffected
    assert np.any(m.faces.features(1) != 0.0)
    feed_one(m, 1, 0, rng, 12.0)
    assert m.faces.export(1).n_observations == 3 and m.faces.export(1).last_seen_s == 12.0
    m.forget_face(1)
    with pytest.raises(KeyError):
        m.faces.export(1)


@pytest.mark.parametrize("method", ["bayes", "threshold"])
def test_feature_gate_keeps_a_swapped_persons_features_out_of_the_face(method: str) -> None:
    """A track identified as person 0 that the tracker then puts on person 1: with the gate, face 1
    learns nothing of person 1 (and person 1's later track is not mistaken for it); without, it does."""
    learned = {}
    for gate in (None, 0.6):
        rng = np.random.default_rng(11)
        m = make_identity_manager(method, min_observations=1, feature_gate_distance=gate) if method == "bayes" \
            else make_identity_manager(method, n_votes=1, feature_gate_distance=gate)
        m.faces.import_faces([LearnedFace(1, person_obs(0, 5, rng))])
        feed_one(m, 10, 0, rng, 0.0)
        assert m.face_id_of(10) == 1
        for i in range(6):  # swapped: the track now follows person 1
            feed_one(m, 10, 1, rng, 0.1 * (i + 1))
        feats = m.faces.features(1)
        learned[gate] = feats
        of_person_1 = (np.linalg.norm(feats - CENTRES[1][None, :], axis=1)
                       < np.linalg.norm(feats - CENTRES[0][None, :], axis=1))
        if gate is None:
            assert of_person_1.sum() == 6  # the paper: the face absorbed person 1
        else:
            assert of_person_1.sum() == 0 and m.stats.observations_not_learned_inconsistent == 6
            assert len(feats) == 5 + 1
    assert len(learned[None]) == 5 + 1 + 6


@pytest.mark.parametrize("method", ["bayes", "threshold"])
def test_a_swapped_track_gives_its_face_back_and_is_identified_afresh(method: str) -> None:
    """Track 10 is face 1 (person 0); the tracker puts it on person 1 (face 2, not in view): after
    ``release_after_inconsistent`` faces beyond the gate in a row it loses face 1 (SWAPPED, since the first
    of them) and, from those faces, becomes face 2. An odd face in between does not release it."""
    rng = np.random.default_rng(5)
    kw = {"min_observations": 3} if method == "bayes" else {"n_votes": 3}
    m = make_identity_manager(method, feature_gate_distance=0.6, release_after_inconsistent=3, **kw)
    m.faces.import_faces([LearnedFace(1, person_obs(0, 5, rng)), LearnedFace(2, person_obs(1, 5, rng))])
    events = [e for t in range(3) for e in feed_one(m, 10, 0, rng, 0.1 * t)]
    assert event_kinds(events) == [(ASSIGNED, 10, 1)]
    for t, person in ((0.3, 1), (0.4, 1), (0.5, 0), (0.6, 1), (0.7, 1)):  # two odd faces, then the face again
        assert feed_one(m, 10, person, rng, t) == []
    assert m.face_id_of(10) == 1
    events = feed_one(m, 10, 1, rng, 0.8)  # the third of person 1 in a row
    kinds = event_kinds(events)
    assert kinds[0] == (SWAPPED, 10, 1) and events[0].since_s == pytest.approx(0.6)
    assert kinds[1:] == [(ASSIGNED, 10, 2)]  # the three faces of person 1 decide at once
    assert m.stats.swaps_released == 1 and m.face_id_of(10) == 2 and 1 in m.faces.available_ids()
    feats = m.faces.features(1)
    assert np.all(np.linalg.norm(feats - CENTRES[0][None, :], axis=1) < 0.5)  # face 1 kept person 0 only


def test_release_after_inconsistent_needs_the_gate_and_zero_never_releases() -> None:
    with pytest.raises(ValueError, match="release_after_inconsistent"):
        make_identity_manager("bayes", release_after_inconsistent=3)
    with pytest.raises(ValueError, match="release_after_inconsistent"):
        make_identity_manager("bayes", feature_gate_distance=0.6, release_after_inconsistent=-1)
    rng = np.random.default_rng(6)
    m = make_identity_manager("bayes", feature_gate_distance=0.6, release_after_inconsistent=0)
    m.faces.import_faces([LearnedFace(1, person_obs(0, 5, rng))])
    for t in range(3):
        feed_one(m, 10, 0, rng, 0.1 * t)
    for t in range(10):
        assert feed_one(m, 10, 1, rng, 1.0 + 0.1 * t) == []
    assert m.face_id_of(10) == 1 and m.stats.swaps_released == 0


def test_a_lost_tracks_face_goes_to_the_persons_new_track() -> None:
    """The tracker lost track 10 (face 2) and the person came back as track 11: track 11 gets face 2, not a
    new id, and track 10 holds nothing any more; a lost track found again before that keeps its face."""
    rng = np.random.default_rng(11)
    m = manager_with_faces(3, rng, min_observations=3, lend_lost_faces=True)
    for i in range(3):
        feed_one(m, 10, 1, rng, 0.1 * i)
    assert m.face_id_of(10) == 2 and 2 not in m.faces.available_ids()
    m.track_lost(10)
    assert 2 in m.faces.available_ids() and m.face_id_of(10) == 2  # lent, still its
    m.track_recovered(10)
    assert 2 not in m.faces.available_ids() and m.face_id_of(10) == 2
    m.track_lost(10)
    events = []
    for i in range(3):
        events += feed_one(m, 11, 1, rng, 1.0 + 0.1 * i)
    assert sorted(event_kinds(events)) == sorted([(ASSIGNED, 11, 2), (RELEASED, 10, 2)])
    assert m.face_id_of(11) == 2 and m.face_id_of(10) is None and m.stats.lent_faces_taken == 1
    m.track_recovered(10)  # too late: the face has moved on
    assert m.face_id_of(10) is None and m.face_id_of(11) == 2
    m.track_deleted(10, 2.0)
    m.step(2.0)
    assert 2 not in m.faces.available_ids() and m.face_id_of(11) == 2


def test_a_lost_track_deleted_while_its_face_is_lent_gives_it_back_once() -> None:
    rng = np.random.default_rng(12)
    m = manager_with_faces(3, rng, min_observations=3, lend_lost_faces=True)
    for i in range(3):
        feed_one(m, 10, 1, rng, 0.1 * i)
    m.track_lost(10)
    m.track_deleted(10, 1.0)
    m.step(1.0)
    assert m.faces.available_ids().count(2) == 1 and m.face_id_of(10) is None
    m.track_lost(10)  # late news of a deleted track: nothing happens
    assert m.faces.available_ids().count(2) == 1
