"""Online body-metric update (second seed, Algorithm 1): the re-fit, embedding conversion, the pair budget that
bounds a wrong face decision, background re-fits and the mining of error pairs."""

from __future__ import annotations

import time

import numpy as np
import pytest

from face_reid_master.body.metric_file import default_body_metric
from face_reid_master.body.online_metric import (
    MinedPair,
    OnlineBodyMetric,
    PairPool,
    embedding_change,
    refit_metric,
    subspace_prior,
    to_subspace,
)
from face_reid_master.identity.body_evidence import BodyEvidence

FUSED = default_body_metric().features["fused"]
R = FUSED.metric.metric.shape[0]


def _wire(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.normal(size=(n, default_body_metric().length)).astype(np.float32)


def test_without_pairs_the_refit_is_the_shipped_metric() -> None:
    new = refit_metric(FUSED, np.zeros((0, R)), np.zeros((0, R)), prior_pairs=200.0)
    assert np.allclose(new.metric.metric, FUSED.metric.metric, rtol=1e-6, atol=1e-9)
    # the offline XQDA left Sigma_E diagonal in its own subspace: the prior is read back exactly
    prior = subspace_prior(FUSED)
    assert np.allclose(prior, np.diag(np.diag(prior)), atol=1e-8) and np.all(np.diag(prior) > 1.0)


def test_old_embeddings_convert_exactly_to_the_new_metric() -> None:
    rng = np.random.default_rng(0)
    new = refit_metric(FUSED, rng.normal(size=(40, R)), 3.0 * rng.normal(size=(40, R)), prior_pairs=50.0)
    x = _wire(rng, 6)
    change = embedding_change(FUSED, new)
    assert np.allclose(FUSED.embed(x) @ change, new.embed(x), atol=1e-4)
    assert np.allclose(to_subspace(FUSED, FUSED.embed(x)), x[:, FUSED.columns] @ FUSED.metric.projection, atol=1e-4)
    assert not np.allclose(new.embed(x), FUSED.embed(x), atol=1e-2)  # the pairs did change the metric


def test_same_person_differences_along_a_direction_make_it_count_less() -> None:
    rng = np.random.default_rng(1)
    axis = np.zeros(R)
    axis[0] = 1.0
    positive = np.outer(rng.normal(scale=5.0, size=100), axis)  # one person's bodies differ along z_0 only
    new = refit_metric(FUSED, positive, np.zeros((0, R)), prior_pairs=50.0)
    def weight(feature):  # share of the metric on z_0 (the scale is kept: compare shares)
        m = feature.metric.metric
        return m[0, 0] / np.trace(m)
    assert weight(new) < 0.5 * weight(FUSED)


def test_a_track_takes_part_in_a_bounded_number_of_pairs_and_its_pairs_go_with_it() -> None:
    pool = PairPool(3, capacity=100, max_pairs_per_track=4)
    kept = [pool.add(np.ones(3), True, (1, 1), (7, 100 + k), float(k)) for k in range(10)]
    assert sum(kept) == 4 and pool.count == 4  # track 7: its share, whatever else it sees
    assert pool.add(np.ones(3), False, (1, 2), (8, 9), 20.0)
    assert not pool.add(np.full(3, np.nan), False, (1, 2), (8, 9), 21.0)  # not finite: refused
    assert pool.remove_track(7) == 4 and pool.count == 1
    assert pool.remove_face(2) == 1 and pool.count == 0
    assert all(pool.add(np.ones(3), True, (1, 1), (-1, -1), 30.0) for _ in range(6))  # restored: no live track


def test_the_pool_forgets_its_oldest_pairs_first() -> None:
    pool = PairPool(2, capacity=3, max_pairs_per_track=10)
    for k in range(5):
        pool.add(np.full(2, float(k)), True, (1, 1), (k, 50 + k), float(k))
    assert pool.count == 3 and sorted(pool.stamps[:3].tolist()) == [2.0, 3.0, 4.0]


def _gallery_world(online: OnlineBodyMetric) -> BodyEvidence:
    """Face 1 wore red, face 2 blue (each seen by one earlier, face-verified track)."""
    body = BodyEvidence(FUSED.likelihood, window_s=1000.0, online=online, mine_interval_s=1.0)
    red, blue = np.zeros((1, R), np.float32), np.zeros((1, R), np.float32)
    red[0, 0], blue[0, 1] = 3.0, 3.0
    body.add_face_bodies(1, red, 0.0, track_id=10)
    body.add_face_bodies(2, blue, 0.0, track_id=20)
    return body


def test_mining_takes_the_pairs_the_ranking_gets_wrong_only() -> None:
    online = OnlineBodyMetric(FUSED, background=False, max_pairs_per_track=50)
    body = _gallery_world(online)
    differ = lambda a, b: True  # noqa: E731
    red_like = np.zeros(R, np.float32)
    red_like[0] = 2.8
    assert body.mine(1, 30, red_like, 1.0, differ) == 0  # face 1's person nearest to face 1: nothing to learn
    blue_like = np.zeros(R, np.float32)
    blue_like[1] = 2.8
    assert body.mine(1, 31, blue_like, 2.0, differ) == 2  # face 1 ranked 2nd: one error positive, one negative
    assert online.pairs_mined == {"positive": 1, "negative": 1}
    assert body.mine(1, 32, blue_like, 3.0, lambda a, b: False) == 1  # faces not surely different: no negative


def test_a_wrong_face_decision_teaches_the_metric_a_bounded_number_of_pairs() -> None:
    """Track 40 was given face 1 but is face 2's person: however long it lives, it adds at most
    max_pairs_per_track pairs, and once its face is released they are gone."""
    online = OnlineBodyMetric(FUSED, background=False, max_pairs_per_track=3)
    body = _gallery_world(online)
    blue_like = np.zeros((1, R), np.float32)
    blue_like[0, 1] = 2.9
    for k in range(200):
        t = 1.0 + 1.5 * k
        if body.wants_probe(40, t):
            body.mine(1, 40, blue_like[0], t, lambda a, b: True)
        body.add_face_bodies(1, blue_like, t, track_id=40)  # its bodies join face 1's gallery too
    in_pool = (online.pool.tracks[: online.pool.count] == 40).any(axis=1).sum()
    assert 0 < in_pool <= 3
    body.track_unverified(40)
    assert not (online.pool.tracks[: online.pool.count] == 40).any()


def test_a_background_refit_is_installed_at_a_later_poll_and_converts_galleries() -> None:
    rng = np.random.default_rng(2)
    online = OnlineBodyMetric(FUSED, background=True, min_new_pairs=1, interval_s=0.0)
    body = BodyEvidence(FUSED.likelihood, window_s=1000.0, online=online)
    wire = _wire(rng, 5)
    body.add_face_bodies(3, FUSED.embed(wire), 0.0, track_id=1)
    pairs = [MinedPair(d, bool(k % 2), 1, 1 if k % 2 else 2, 100 + k, 200 + k, 0.0)
             for k, d in enumerate(rng.normal(size=(12, R)).astype(np.float32))]
    assert online.add(pairs) == 12
    assert online.poll(0.0, body.conversion_snapshot, BodyEvidence.convert_snapshot) is None  # started, not waited
    late = _wire(rng, 2)  # written after the snapshot the worker converts: converted when installed
    body.add_face_bodies(3, FUSED.embed(late), 0.5, track_id=1)
    body.add_face_bodies(4, FUSED.embed(late), 0.5, track_id=2)
    deadline = time.monotonic() + 30.0
    done = None
    while done is None and time.monotonic() < deadline:
        time.sleep(0.01)
        done = online.poll(1.0, body.conversion_snapshot, BodyEvidence.convert_snapshot)
    assert done is not None, "the background re-fit never finished"
    new, change, converted = done
    assert online.current is new and online.refits == 1
    body.change_metric(change, converted)
    assert np.allclose(body.face_bodies(3, 0.0), new.embed(np.concatenate([wire, late])), atol=1e-3)
    assert np.allclose(body.face_bodies(4, 0.0), new.embed(late), atol=1e-3)
    online.close()


def test_the_update_refuses_a_metric_it_cannot_handle() -> None:
    from face_reid_master.body.linear_metric import euclidean_metric
    from face_reid_master.body.metric_file import BodyFeatureMetric

    plain = BodyFeatureMetric("fused", FUSED.columns, euclidean_metric(FUSED.metric.input_dim), FUSED.likelihood)
    with pytest.raises(ValueError, match="XQDA metric with a distance_scale"):
        OnlineBodyMetric(plain)
