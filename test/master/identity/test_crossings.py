"""Crossings (identity.crossings): the doubt a tracker's possible swap leaves on two identities; it lowers what is
published, never moves an identity."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal

DIM = 16
LIKELIHOOD = LikelihoodModel(SkewNormal(0.0, 0.3, 0.1), SkewNormal(0.0, 1.0, 0.2))


def _face(k: int, n: int, rng: np.random.Generator) -> np.ndarray:
    centre = np.zeros(DIM, np.float32)
    centre[k] = 0.7
    return (centre + rng.normal(0.0, 0.02, (n, DIM))).astype(np.float32)


def _alice_and_bob() -> tuple[BayesIdentityManager, np.random.Generator]:
    rng = np.random.default_rng(3)
    ids = BayesIdentityManager(LIKELIHOOD, embedding_dim=DIM, feature_gate_distance=0.5, release_after_inconsistent=3)
    ids.add_observations(1, _face(0, 3, rng), 0.0)
    ids.add_observations(2, _face(1, 3, rng), 0.0)
    ids.step(0.0)
    assert ids.assigned_tracks() == {1: 1, 2: 2}
    return ids, rng


def test_a_crossing_leaves_doubt_that_the_association_alone_never_makes_likelier_than_not() -> None:
    ids, _ = _alice_and_bob()
    assert ids.crossings.doubt_of(1) == 0.0
    ids.crossings.crossed(1, 2, 0.3, 1.0)
    assert ids.crossings.doubt_of(1) == pytest.approx(0.3) and ids.crossings.doubt_of(2) == pytest.approx(0.3)
    for k in range(20):  # side by side for a long while: a coin at most
        ids.crossings.crossed(1, 2, 0.9, 1.0 + k)
    assert ids.crossings.doubt_of(1) == pytest.approx(0.5)
    assert ids.assigned_tracks() == {1: 1, 2: 2}  # doubt never moves an identity


def test_a_decision_of_the_track_on_what_it_showed_since_clears_its_doubt() -> None:
    ids, rng = _alice_and_bob()
    ids.crossings.crossed(1, 3, 0.4, 1.0)  # Alice's track and a new one, unidentified yet
    assert ids.crossings.doubt_of(1) == pytest.approx(0.4) and ids.crossings.doubt_of(3) == pytest.approx(0.4)
    ids.add_observations(3, _face(2, 3, rng), 2.0)  # Carol shows her face on the new track: decided new
    ids.step(2.0)
    assert ids.assigned_tracks() == {1: 1, 2: 2, 3: 3}
    assert ids.crossings.doubt_of(1) == 0.0 and ids.crossings.doubt_of(3) == 0.0


def test_a_crossing_probability_outside_0_1_is_refused() -> None:
    ids, _ = _alice_and_bob()
    with pytest.raises(ValueError):
        ids.crossings.crossed(1, 2, float("nan"), 1.0)
    with pytest.raises(ValueError):
        ids.crossings.crossed(1, 2, 1.5, 1.0)


def test_a_crossing_of_two_unidentified_tracks_is_no_doubt_and_a_deleted_partner_leaves_it() -> None:
    ids, _ = _alice_and_bob()
    ids.crossings.crossed(7, 8, 0.5, 1.0)  # neither carries an identity
    assert ids.crossings.doubt_of(7) == 0.0 and 7 not in ids.tracks.entries
    ids.crossings.crossed(1, 9, 0.4, 1.0)  # track 9 has shown nothing yet
    assert ids.crossings.doubt_of(1) == pytest.approx(0.4)
    ids.track_deleted(9, 2.0)
    ids.step(2.0)
    assert ids.crossings.doubt_of(1) == pytest.approx(0.4)  # its end says nothing of a swap before it
    ids.crossings.crossed(1, 9, 0.4, 3.0)  # a late report about the deleted track changes nothing
    assert ids.crossings.doubt_of(1) == pytest.approx(0.4)


def test_the_master_publishes_an_identity_more_likely_wrong_than_right_as_undecided() -> None:
    from face_reid_master.core import MasterCore
    from face_reid_master.identity.evidence import Evidence

    core = MasterCore()
    track = core.identity.tracks.seen(5, 0.0)
    track.give(3, 0.99, Evidence.FACE, new=False)
    assert core.published_face_id(5) == 3
    full = core.published_confidence(5)
    track.crossed[6] = 0.3
    assert core.published_face_id(5) == 3 and core.published_confidence(5) == pytest.approx(0.7 * full)
    track.crossed[7] = 0.4  # two crossings: 1 - 0.7 * 0.6 = 0.58 that it is someone else
    assert core.published_face_id(5) == 0 and core.published_confidence(5) == 0.0


def test_a_track_more_likely_someone_else_is_released_and_its_face_is_free_once_even_when_lent() -> None:
    from face_reid_master.identity.records import IdentityEventKind

    rng = np.random.default_rng(4)
    ids = BayesIdentityManager(LIKELIHOOD, embedding_dim=DIM, lend_lost_faces=True)
    for k in (1, 2, 3):
        ids.add_observations(k, _face(k - 1, 3, rng), 0.0)
    ids.step(0.0)
    ids.track_lost(1)  # Alice's track is lost: her face is lent to face_list
    assert ids.faces.available == [1]
    ids.crossings.crossed(1, 2, 0.45, 1.0)
    ids.crossings.crossed(1, 3, 0.45, 1.0)  # 0.70 that it is someone else now
    events = ids.step(1.0)
    assert [(e.kind, e.track_id, e.face_id) for e in events] == [(IdentityEventKind.SWAPPED, 1, 1)]
    assert ids.faces.available == [1] and ids.face_id_of(1) is None  # in face_list once, nobody holds it
    ids.track_recovered(1)  # found again: it has no face to take back
    ids.add_observations(4, _face(0, 3, rng), 2.0)  # Alice shows her face on another track
    ids.step(2.0)
    assert ids.assigned_tracks() == {2: 2, 3: 3, 4: 1}


def test_a_track_that_may_have_strayed_onto_a_newcomer_is_doubted_beyond_one_half_and_released() -> None:
    ids, rng = _alice_and_bob()
    ids.crossings.strayed(3, 0.9)  # a track the manager holds nothing of: nothing to doubt
    assert ids.crossings.doubt_of(3) == 0.0
    ids.crossings.strayed(1, 0.3)
    ids.crossings.strayed(1, 0.4)  # nobody else to have swapped with: not bounded by one half
    assert ids.crossings.doubt_of(1) == pytest.approx(1.0 - 0.7 * 0.6)
    assert ids.crossings.withholds(1) and not ids.crossings.withholds(2)
    events = ids.step(1.2)
    assert [(e.kind.value, e.track_id, e.face_id) for e in events] == [("swapped", 1, 1)]
    assert ids.assigned_tracks() == {2: 2}
    assert ids.crossings.doubt_of(1) == 0.0 and ids.stats.tracks_restarted == 0  # the release spent its strays
    ids.add_observations(1, _face(0, 3, rng), 2.0)  # Alice after all: decided afresh, the doubt is gone
    ids.step(2.0)
    assert ids.assigned_tracks() == {1: 1, 2: 2} and ids.crossings.doubt_of(1) == 0.0
    with pytest.raises(ValueError):
        ids.crossings.strayed(1, float("nan"))
