"""One record per track: everything the master keeps about a live track sits in its TrackRecord (queued faces
and bodies, Bayes row, decision, published id, face count) and one call removes it whole."""

from __future__ import annotations

import numpy as np
from identity_test_helpers import DIM, SWAPPED, event_kinds, feed_one, person_obs
from test_body_evidence import BODY_LIKELIHOOD, RED, _evidence

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.entries import TrackRecord
from face_reid_master.identity.evidence import Evidence
from face_reid_master.identity.methods import make_identity_manager
from face_reid_master.identity.records import LearnedFace


def test_a_tracks_queued_evidence_and_bayes_row_live_in_its_record_and_go_with_it() -> None:
    ids = BayesIdentityManager(BODY_LIKELIHOOD, embedding_dim=DIM, min_observations=50, body_evidence=_evidence())
    rng = np.random.default_rng(0)
    ids.add_observations(7, person_obs(0, 2, rng), 0.0)
    ids.add_body_observations(7, RED, 0.0)
    rec = ids.tracks.entries[7]
    assert isinstance(rec, TrackRecord) and len(rec.face_chunks) == 1 and len(rec.cue_queue[Evidence.BODY]) == 1
    ids.step(0.0)  # learned: the queues are empty, the track has its row of the posterior table
    assert rec.face_chunks == [] and rec.cue_queue == {} and rec.bayes_row == 1 and rec.public_id == 7
    ids.add_observations(7, person_obs(0, 1, rng), 1.0)
    ids.add_body_observations(7, RED, 1.0)
    ids.track_deleted(7, 1.5)
    ids.step(1.5)  # its last evidence is learned, then the record goes whole: no queue, no row is left
    assert 7 not in ids.tracks.entries and rec.bayes_row == 0 and ids.posterior_table()[1] == []
    assert ids.tracks.take_pending() == {} and ids.tracks.take_cue(Evidence.BODY, 0.0) == ([], 0)


def test_a_swap_changes_the_published_id_in_the_record_the_tracker_id_stays() -> None:
    """The identity layer keys the record by the tracker's id; the master's split writes the new public id
    into the same record (here by hand, as MasterCore does on a SWAPPED event)."""
    rng = np.random.default_rng(5)
    m = make_identity_manager("bayes", feature_gate_distance=0.6, release_after_inconsistent=3, min_observations=3)
    m.faces.import_faces([LearnedFace(1, person_obs(0, 5, rng)), LearnedFace(2, person_obs(1, 5, rng))])
    for t in range(3):
        feed_one(m, 10, 0, rng, 0.1 * t)
    events = [e for t in (0.3, 0.4, 0.5) for e in feed_one(m, 10, 1, rng, t)]
    assert event_kinds(events)[0] == (SWAPPED, 10, 1)
    rec = m.tracks.record(10)
    assert rec is not None and rec.track_id == 10 and rec.public_id == 10
    rec.public_id, rec.public_since_s = 99, 0.5
    assert m.tracks.entries[10].public_id == 99 and m.face_id_of(10) == 2
