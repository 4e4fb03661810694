"""Body evidence: face galleries that expire, faceless tracks decided by their body, never a new face by body."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal
from face_reid_master.identity.records import IdentityEventKind

BODY_LIKELIHOOD = LikelihoodModel(SkewNormal(0.0, 0.4, 0.15), SkewNormal(0.0, 1.2, 0.25))  # N_p = N_n near 0.75
DIM = 4
RED, BLUE = np.array([[1.0, 0, 0, 0]], np.float32), np.array([[0, 1.0, 0, 0]], np.float32)  # 1.41 apart


def _evidence(**kwargs) -> BodyEvidence:
    return BodyEvidence(BODY_LIKELIHOOD, **{"window_s": 100.0, "min_observations": 3, "max_log_ratio": 3.0, **kwargs})


def test_a_faceless_track_is_decided_for_the_face_whose_person_wears_the_same() -> None:
    body = _evidence()
    body.add_face_bodies(1, RED, 0.0)
    body.add_face_bodies(2, BLUE, 0.0)
    for k in range(2):
        body.observe(7, RED + 0.05, 1.0 + k, [1, 2])
    assert body.decide([1, 2], 2.0) == []  # 2 observations: fewer than min_observations
    body.observe(7, RED + 0.05, 3.0, [1, 2])
    ((track, face, p),) = body.decide([1, 2], 3.0)
    assert (track, face) == (7, 1) and p > 0.99
    post = body.posterior(7, [1, 2], 3.0)
    assert post[1] > post[2] and post[1] > post[0]
    assert body.decide([2], 3.0) == []  # face 1 is held by another track: not a candidate


def test_bodies_expire_and_forgotten_faces_lose_theirs() -> None:
    body = _evidence()
    body.add_face_bodies(1, RED, 0.0)
    for k in range(5):
        body.observe(7, RED, 200.0 + k, [1])  # the person's clothes were seen 200 s ago: longer than the window
    assert body.decide([1], 205.0) == [] and body.face_bodies(1, 205.0).shape[0] == 0
    body.add_face_bodies(1, RED, 201.0)
    body.observe(8, RED, 202.0, [1])
    body.forget_face(1)
    assert body.posterior(8, [1], 202.0) == {0: 1.0}


def test_one_face_goes_to_one_track_the_most_confident_first() -> None:
    body = _evidence()
    body.add_face_bodies(1, RED, 0.0)
    for k in range(4):
        body.observe(7, RED, 1.0 + k, [1])
        body.observe(8, RED + 0.3, 1.0 + k, [1])  # 0.6 away: weaker evidence
    assert [(t, f) for t, f, _ in body.decide([1], 5.0)] == [(7, 1)]


def test_two_faces_of_one_person_add_up_and_only_such_faces() -> None:
    body = _evidence(posterior_threshold=0.99)
    for face in (1, 2):  # one person learned twice (a second face while another track held the first)
        body.add_face_bodies(face, RED, 0.0)
    body.add_face_bodies(3, BLUE, 0.0)
    for k in range(4):
        body.observe(7, RED, 1.0 + k, [1, 2, 3])
    post = body.posterior(7, [1, 2, 3], 5.0)
    assert 0.4 < post[1] < 0.6 and post[1] + post[2] > 0.99  # split between the two faces: neither passes
    assert body.decide([1, 2, 3], 5.0) == []
    different = lambda a, others: [False] * len(others)  # noqa: E731
    assert body.decide([1, 2, 3], 5.0, different) == []  # different people: still undecided
    one_person = lambda a, others: [{a, b} == {1, 2} for b in others]  # noqa: E731
    ((track, face, p),) = body.decide([1, 2, 3], 5.0, one_person)
    assert track == 7 and face in (1, 2) and p > 0.99
    ((_, face, _),) = body.decide([2, 3], 5.0, one_person)  # face 1 is held: its twin is given
    assert face == 2


def _manager() -> BayesIdentityManager:
    return BayesIdentityManager(BODY_LIKELIHOOD, embedding_dim=DIM, min_observations=2,
                                body_evidence=_evidence())


def _face(k: int) -> np.ndarray:
    return np.eye(DIM, dtype=np.float32)[k][None, :] * 0.1  # faces 0.14 apart in the face space (of the test)


def test_the_identity_layer_gives_a_faceless_track_its_face_by_body_and_its_face_can_confirm_it() -> None:
    ids = _manager()
    ids.add_observations(1, np.repeat(_face(0), 3, axis=0), 0.0)  # Alice shows her face, in red
    ids.add_body_observations(1, RED, 0.0)
    ids.step(0.0)
    (alice,) = ids.face_ids()
    assert ids.evidence_of(1) == "face"
    ids.track_deleted(1, 1.0)  # she leaves; her red clothes stay with her face
    ids.step(1.0)
    events = []
    for k in range(3):  # she comes back showing only her back: her body, no face
        ids.add_body_observations(2, RED + 0.05, 2.0 + k)
        events += ids.step(2.0 + k)
    assert [(e.kind, e.track_id, e.face_id, e.evidence) for e in events] == \
        [(IdentityEventKind.ASSIGNED_KNOWN, 2, alice, "body")]
    assert ids.face_id_of(2) == alice and ids.evidence_of(2) == "body" and ids.stats.assigned_by_body == 1
    ids.add_observations(2, _face(0), 6.0)  # then she turns round: her face agrees
    ids.step(6.0)
    assert ids.evidence_of(2) == "both"


def test_body_evidence_never_creates_a_face_nor_decides_a_track_that_showed_a_face() -> None:
    ids = _manager()
    for k in range(5):  # a stranger's body, nobody learned yet
        ids.add_body_observations(1, BLUE, float(k))
        assert ids.step(float(k)) == []
    assert ids.face_ids() == [] and ids.face_id_of(1) is None
    ids.add_observations(2, np.repeat(_face(0), 3, axis=0), 10.0)
    ids.add_body_observations(2, RED, 10.0)
    ids.step(10.0)
    ids.track_deleted(2, 11.0)
    ids.step(11.0)
    ids.add_observations(3, _face(1), 12.0)  # a track that showed a face (one: undecided) wears red
    for k in range(4):
        ids.add_body_observations(3, RED, 12.0 + k)
        ids.step(12.0 + k)
    assert ids.face_id_of(3) is None  # its face decides, not its body


def test_the_identity_layer_takes_two_close_faces_for_one_person_only() -> None:
    ids = BayesIdentityManager(BODY_LIKELIHOOD, embedding_dim=DIM, min_observations=2, body_evidence=_evidence(),
                               feature_gate_distance=0.75)  # alike: closer than 0.375
    ids.add_observations(1, np.repeat(_face(0), 3, axis=0), 0.0)  # Alice, in red
    ids.add_body_observations(1, RED, 0.0)
    ids.step(0.0)
    ids.add_observations(2, np.repeat(_face(0) * 1.2, 3, axis=0), 0.5)  # a duplicate track of her: 0.02 away,
    ids.add_body_observations(2, RED, 0.5)  # but her face is held by track 1, so a second face is learned
    ids.step(0.5)
    assert len(ids.face_ids()) == 2
    first, second = ids.face_ids()
    assert ids._faces_alike(first, [second]) == [True]  # much closer than half the decision distance
    ids.add_observations(3, np.repeat(_face(1) * 5, 3, axis=0), 0.6)  # Bob: another person, 0.51 away
    ids.step(0.6)
    (bob,) = set(ids.face_ids()) - {ids.face_id_of(1), ids.face_id_of(2)}
    assert ids._faces_alike(ids.face_id_of(1), [bob, 999]) == [False, False]  # 999: no such face
    for tid in (1, 2, 3):
        ids.track_deleted(tid, 1.0)
    ids.step(1.0)
    for k in range(3):  # she comes back, faceless: the two faces split her body evidence
        ids.add_body_observations(4, RED, 2.0 + k)
        ids.step(2.0 + k)
    assert ids.face_id_of(4) in (ids.face_ids()[0], ids.face_ids()[1]) and ids.evidence_of(4) == "body"


@pytest.mark.parametrize("bad", [{"window_s": 0.0}, {"posterior_threshold": 1.0}, {"min_observations": 0}])
def test_arguments_are_checked(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        BodyEvidence(BODY_LIKELIHOOD, **bad)


def test_a_faceless_track_seen_alongside_a_face_s_track_is_not_given_that_face_and_it_is_counted() -> None:
    ids = _manager()
    ids.add_observations(1, np.repeat(_face(0), 3, axis=0), 0.0)  # Alice shows her face, in red
    for t in (0.0, 1.0, 2.0):  # beside her, someone else in red
        ids.add_body_observations(1, RED, t)
        ids.add_body_observations(2, RED + 0.05, t)
        ids.step(t)
    (alice,) = ids.face_ids()
    ids.track_deleted(1, 3.0)  # Alice leaves: her face is free
    ids.step(3.0)
    for t in (4.0, 5.0, 6.0):
        ids.add_body_observations(2, RED + 0.05, t)
        assert not ids.step(t)
    assert ids.face_id_of(2) is None and ids.stats.decisions_excluded_co_seen == 3
    assert alice in ids.faces.available


@pytest.mark.parametrize("learn_confidence", [0.0, 1.0])
def test_a_face_decision_below_learn_confidence_teaches_its_face_no_bodies_and_counts_them(
        learn_confidence: float) -> None:
    ids = BayesIdentityManager(BODY_LIKELIHOOD, embedding_dim=DIM, min_observations=2, body_evidence=_evidence(),
                               learn_confidence=learn_confidence)  # 1.0: no decision is that certain
    ids.add_observations(1, np.repeat(_face(0), 3, axis=0), 0.0)  # Alice: a new face (a new face always teaches)
    ids.add_body_observations(1, RED, 0.0)
    ids.step(0.0)
    ids.track_deleted(1, 1.0)
    ids.step(1.0)
    (alice,) = ids.face_ids()
    ids.add_observations(2, np.repeat(_face(0), 3, axis=0), 2.0)  # taken for Alice (known: below 1.0)
    ids.add_body_observations(2, BLUE, 2.0)  # queued with the faces that decide it
    ids.step(2.0)
    assert ids.face_id_of(2) == alice
    ids.add_body_observations(2, np.repeat(BLUE, 2, axis=0), 3.0)  # and after it
    ids.step(3.0)
    gallery = ids.body_evidence.face_bodies(alice, 3.0)
    taught = learn_confidence == 0.0
    assert gallery.shape[0] == (4 if taught else 1)  # RED, and BLUE only from a decision that teaches
    assert ids.stats.cue_observations_not_learned_uncertain == (0 if taught else 3)


def test_a_track_whose_uncertainly_decided_face_was_forgotten_while_lent_gathers_bodies_again() -> None:
    ids = BayesIdentityManager(BODY_LIKELIHOOD, embedding_dim=DIM, min_observations=2, body_evidence=_evidence(),
                               learn_confidence=1.0, lend_lost_faces=True)  # 1.0: every known-face decision uncertain
    ids.add_observations(1, np.repeat(_face(0), 3, axis=0), 0.0)  # Alice: a new face
    ids.step(0.0)
    ids.track_deleted(1, 1.0)
    ids.step(1.0)
    (alice,) = ids.face_ids()
    ids.add_observations(2, np.repeat(_face(0), 3, axis=0), 2.0)  # taken for Alice, below learn_confidence
    ids.step(2.0)
    ids.track_lost(2)  # it lends Alice's face, which is then deleted ("forget this person")
    assert ids.forget_face(alice) and ids.face_id_of(2) is None
    ids.add_body_observations(2, np.repeat(BLUE, 2, axis=0), 3.0)  # faceless now: what it wears is its own evidence
    ids.step(3.0)
    assert ids.stats.cue_observations_not_learned_uncertain == 0
