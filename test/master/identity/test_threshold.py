"""Tests of the paper's threshold baseline (nearest face + majority vote)."""

from __future__ import annotations

import numpy as np
import pytest
from identity_test_helpers import ASSIGNED, NEW, event_kinds, person_obs

from face_reid_master.identity.methods import make_identity_manager
from face_reid_master.identity.records import LearnedFace
from face_reid_master.identity.threshold import ThresholdIdentityManager


def test_threshold_baseline_decides_by_majority_after_n_votes() -> None:
    rng = np.random.default_rng(13)
    m = ThresholdIdentityManager(distance_threshold=0.6, n_votes=5)
    m.faces.import_faces([LearnedFace(j + 1, person_obs(j, 5, rng)) for j in range(3)])
    far = [person_obs(6, 1, rng), person_obs(7, 1, rng)]  # 2 votes "new"
    near = [person_obs(1, 1, rng) for _ in range(3)]  # 3 votes for face 2
    for i, o in enumerate([near[0], far[0], near[1], far[1]]):
        m.add_observations(10, o, 0.1 * i)
        assert m.step(0.1 * i) == []
    assert m.confidence_of(10) == pytest.approx(0.5)
    m.add_observations(10, near[2], 0.5)
    events = m.step(0.5)
    assert event_kinds(events) == [(ASSIGNED, 10, 2)] and events[0].confidence == pytest.approx(0.6)
    # a stranger: all votes "new"
    for i in range(5):
        m.add_observations(11, person_obs(5, 1, rng), 1.0 + i)
        events = m.step(1.0 + i)
    assert event_kinds(events) == [(NEW, 11, 4)]


def test_threshold_baseline_tie_goes_to_new_face() -> None:
    rng = np.random.default_rng(14)
    m = make_identity_manager("threshold", distance_threshold=0.6, n_votes=4)
    m.faces.import_faces([LearnedFace(1, person_obs(0, 5, rng))])
    m.add_observations(3, np.concatenate([person_obs(0, 2, rng), person_obs(4, 2, rng)]), 0.0)
    assert event_kinds(m.step(0.0)) == [(NEW, 3, 2)]


def test_threshold_forget_face_drops_votes_for_it() -> None:
    rng = np.random.default_rng(33)
    m = ThresholdIdentityManager(distance_threshold=0.6, n_votes=3)
    m.faces.import_faces([LearnedFace(j + 1, person_obs(j, 5, rng)) for j in range(3)])
    for i in range(2):
        m.add_observations(10, person_obs(1, 1, rng), 0.1 * i)
        assert m.step(0.1 * i) == []
    assert m.confidence_of(10) == 1.0  # 2 votes for face 2
    assert m.forget_face(2)
    assert m.confidence_of(10) == 0.0  # its votes are gone
    events = []
    for i in range(3):
        m.add_observations(10, person_obs(1, 1, rng), 1.0 + 0.1 * i)
        events += m.step(1.0 + 0.1 * i)
    assert event_kinds(events) == [(NEW, 10, 4)]
