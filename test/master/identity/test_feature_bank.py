"""Tests of the bounded, diverse feature sets and their eq. 4 distances."""

from __future__ import annotations

import numpy as np
from identity_test_helpers import DIM

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.feature_bank import min_distances_to_faces, select_diverse_subset
from face_reid_master.identity.records import LearnedFace


def _min_pairwise(x: np.ndarray) -> float:
    d = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    return float(d.min())


def test_diverse_subset_beats_fifo_on_a_clustered_set() -> None:
    rng = np.random.default_rng(16)
    # 5 views of a face, 30 near-duplicate frames each, seen one view after the other
    views = rng.normal(0, 0.05, (5, DIM))
    feats = np.concatenate([v + rng.normal(0, 0.003, (30, DIM)) for v in views]).astype(np.float32)
    keep = select_diverse_subset(feats, 10)
    assert len(keep) == 10 and np.all(np.diff(keep) > 0)
    fifo = feats[-10:]
    assert _min_pairwise(feats[keep]) >= _min_pairwise(fifo)
    assert len({int(i) // 30 for i in keep}) == 5  # every view kept; FIFO keeps only the last one
    # the manager's incremental bank keeps the same kind of set
    m = BayesIdentityManager(max_features_per_face=10, min_observations=1)
    for i in range(0, len(feats), 3):
        m.add_observations(1, feats[i : i + 3], float(i))
        m.step(float(i))
    stored = m.faces.features(1)
    assert len(stored) == 10 and _min_pairwise(stored) >= _min_pairwise(fifo)
    assert len({int(np.argmin(((views - s) ** 2).sum(1))) for s in stored}) == 5


def test_incremental_insertion_matches_greedy_selection() -> None:
    rng = np.random.default_rng(17)
    m = BayesIdentityManager(max_features_per_face=6, min_observations=1, embedding_dim=8)
    reference = np.zeros((0, 8), np.float32)
    for i in range(40):
        x = rng.normal(size=(1 + i % 2, 8)).astype(np.float32)
        m.add_observations(1, x, float(i))
        m.step(float(i))
        allf = np.concatenate([reference, x])
        reference = allf[select_diverse_subset(allf, 6)]
        got = m.faces.features(1)
        assert sorted(map(tuple, got.round(5))) == sorted(map(tuple, reference.round(5)))


def test_batched_insertion_for_several_identified_tracks_matches_greedy_selection() -> None:
    rng = np.random.default_rng(23)
    m = BayesIdentityManager(max_features_per_face=5, min_observations=1, embedding_dim=8)
    history: dict[int, np.ndarray] = {}
    for step in range(30):
        for tid in (1, 2, 3, 4):
            x = rng.normal(size=(1, 8)).astype(np.float32)
            m.add_observations(tid, x, float(step))
            history[tid] = np.concatenate([history.get(tid, np.zeros((0, 8), np.float32)), x])
            if step > 3:
                ref = history[tid]
                history[tid] = ref[select_diverse_subset(ref, 5)]
        m.step(float(step))
    assert sorted(m.assigned_tracks()) == [1, 2, 3, 4]
    for tid, fid in m.assigned_tracks().items():
        expected = history[tid][select_diverse_subset(history[tid], 5)]
        got = m.faces.features(fid)
        assert sorted(map(tuple, got.round(5))) == sorted(map(tuple, expected.round(5)))


def test_bank_distances_match_float64_reference_in_exact_and_shortlist_modes() -> None:
    rng = np.random.default_rng(18)
    faces = [
        (c + rng.normal(0, 0.02, (int(rng.integers(1, 9)), DIM))).astype(np.float32)
        for c in rng.normal(0, 0.06, (60, DIM))
    ]
    obs = np.concatenate([faces[3][:1], faces[40][:1], rng.normal(0, 0.06, (1, DIM))]).astype(np.float32)
    ref = min_distances_to_faces(obs, faces)
    exact = BayesIdentityManager()
    exact.faces.import_faces(LearnedFace(i + 1, f) for i, f in enumerate(faces))
    # float32 ||a||^2 + ||b||^2 - 2ab: squared distances exact to ~1e-6 (d = 0 reads as ~3e-4)
    np.testing.assert_allclose(exact.faces.distances(obs) ** 2, ref**2, atol=2e-6)
    short = BayesIdentityManager(exact_search_max_features=10, shortlist_faces=8)
    short.faces.import_faces(LearnedFace(i + 1, f) for i, f in enumerate(faces))
    d = short.faces.distances(obs)
    assert short.stats.shortlist_searches == 1
    assert np.all(np.isfinite(d).sum(axis=1) == 8)
    np.testing.assert_allclose(d[np.isfinite(d)] ** 2, ref[np.isfinite(d)] ** 2, atol=2e-6)
    assert np.all(np.argmin(d, axis=1) == np.argmin(ref, axis=1))  # the nearest face is always shortlisted


def test_own_face_distances_match_the_float64_reference_for_full_and_part_filled_slots() -> None:
    """Each observation against its own face's features only (the identified tracks' consistency check):
    padding rows of a part-filled slot never count."""
    from face_reid_master.identity.feature_bank import FeatureBank

    rng = np.random.default_rng(5)
    faces = [(c + rng.normal(0, 0.02, (n, DIM))).astype(np.float32)
             for c, n in zip(rng.normal(0, 0.06, (4, DIM)), (1, 3, 8, 8), strict=True)]
    bank = FeatureBank(DIM, 8)
    slots = [bank.new_slot(f) for f in faces]
    obs = rng.normal(0, 0.06, (6, DIM)).astype(np.float32)
    own = np.array([0, 1, 2, 3, 0, 2])
    ref = min_distances_to_faces(obs, faces)[np.arange(6), own]
    got = bank.own_min_distances(obs, np.array([slots[i] for i in own], dtype=np.intp))
    np.testing.assert_allclose(got**2, ref**2, atol=2e-6)
    assert bank.own_min_distances(obs[:0], np.zeros(0, dtype=np.intp)).shape == (0,)
