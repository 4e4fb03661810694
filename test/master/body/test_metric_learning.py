"""Pair covariances, XQDA and KISSME against closed forms, and the CMC / mAP scores by hand."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from face_reid_master.body.linear_metric import LinearMetric, euclidean_metric
from face_reid_master.training.body.cmc import rank_scores
from face_reid_master.training.body.kissme import fit_kissme, kissme_from_covariances
from face_reid_master.training.body.pair_covariance import pair_covariances
from face_reid_master.training.body.xqda import fit_xqda, xqda_for_dims


def test_pair_covariances_equal_the_average_over_every_ordered_pair() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(9, 3))
    y = np.array([0, 0, 0, 1, 1, 2, 2, 2, 2])
    cov = pair_covariances(x, y)
    same = [np.outer(x[i] - x[j], x[i] - x[j]) for i, j in itertools.permutations(range(9), 2) if y[i] == y[j]]
    diff = [np.outer(x[i] - x[j], x[i] - x[j]) for i, j in itertools.permutations(range(9), 2) if y[i] != y[j]]
    assert (cov.n_intra_pairs, cov.n_extra_pairs) == (len(same), len(diff)) == (6 + 2 + 12, 81 - (9 + 4 + 16))
    np.testing.assert_allclose(cov.intra, np.mean(same, axis=0), atol=1e-12)
    np.testing.assert_allclose(cov.extra, np.mean(diff, axis=0), atol=1e-12)
    with pytest.raises(ValueError, match="two samples"):
        pair_covariances(x[[0, 3, 5]], y[[0, 3, 5]])
    with pytest.raises(ValueError, match="one person"):
        pair_covariances(x[:3], y[:3])


def _two_people() -> tuple[np.ndarray, np.ndarray]:
    """Two people 4 apart along axis 0; each person's samples spread +-1 along axis 1 and +-0.5 along 0."""
    base = np.array([[a, b] for a in (-0.5, 0.5) for b in (-1.0, 1.0)])
    x = np.vstack([base, base + np.array([4.0, 0.0])])
    return x, np.array([0] * 4 + [1] * 4)


def test_xqda_on_two_people_keeps_the_axis_that_separates_them_with_the_closed_form_metric() -> None:
    x, y = _two_people()
    cov = pair_covariances(x, y)
    # by hand: a person's 12 ordered pairs differ by +-1 along axis 0 in 8 of them (mean square 8/12) and by
    # +-2 along axis 1 in 8 of them (32/12)
    np.testing.assert_allclose(np.diag(cov.intra), [8 / 12, 32 / 12])
    metric = fit_xqda(x, y, regularisation=0.0)
    w = metric.projection
    assert w.shape == (2, 1) and abs(w[1, 0]) < 1e-9  # only axis 0 separates the people
    lam = cov.extra[0, 0] / cov.intra[0, 0]  # the generalised eigenvalue along axis 0
    assert metric.info["eigenvalues"] == pytest.approx([lam])
    # W^T Sigma_I W = 1, W^T Sigma_E W = lam: M = 1 - 1 / lam
    assert metric.metric[0, 0] == pytest.approx(1.0 - 1.0 / lam)
    d = metric.distances(x[:1], x)
    assert d[0, 1:4].max() < d[0, 4:].min()  # same person nearer than the other one, whatever axis 1 says
    assert d[0, 1] == pytest.approx(0.0, abs=1e-9)  # x1 differs from x0 only along axis 1: ignored
    assert euclidean_metric(2).distances(x[:1], x)[0, 1] == pytest.approx(2.0)


def test_kissme_is_the_clipped_inverse_covariance_difference() -> None:
    x, y = _two_people()
    cov = pair_covariances(x, y)
    m = fit_kissme(x, y, regularisation=0.0)
    expected = np.linalg.inv(cov.intra) - np.linalg.inv(cov.extra)
    values, vectors = np.linalg.eigh(expected)
    np.testing.assert_allclose(m.metric, (vectors * np.maximum(values, 0)) @ vectors.T, atol=1e-12)
    assert np.linalg.eigvalsh(m.metric).min() >= -1e-12
    pca = fit_kissme(x, y, pca_dims=1)
    assert pca.projection.shape == (2, 1) and abs(pca.projection[0, 0]) > 0.99  # the widest spread: axis 0


def test_learned_metrics_beat_euclidean_when_a_nuisance_dimension_dominates() -> None:
    rng = np.random.default_rng(1)
    people, shots, dim = 30, 4, 6
    centres = rng.normal(size=(people, dim)) * [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]
    x = np.repeat(centres, shots, axis=0) + rng.normal(size=(people * shots, dim)) * np.array([0.2] * 3 + [3.0] * 3)
    y = np.repeat(np.arange(people), shots)
    train, test = y < 15, y >= 15
    probe = test & (np.arange(y.size) % shots == 0)
    gallery = test & ~probe
    scores = {}
    for name, metric in (("euclidean", euclidean_metric(dim)), ("kissme", fit_kissme(x[train], y[train])),
                         ("xqda", fit_xqda(x[train], y[train]))):
        scores[name] = rank_scores(metric.distances(x[probe], x[gallery]), y[probe], y[gallery]).rank(1)
    assert scores["xqda"] >= 0.9 and scores["kissme"] >= 0.9 and scores["euclidean"] < 0.6, scores


def test_rank_scores_by_hand() -> None:
    # probe A: gallery order by distance B, A, A -> first hit at rank 2, AP = (1/2 + 2/3) / 2
    # probe B: B first -> rank 1, AP = 1; probe C: not in the gallery -> left out
    d = np.array([[0.5, 0.1, 0.7], [0.9, 0.2, 0.3], [0.1, 0.2, 0.3]])
    s = rank_scores(d, ["A", "B", "C"], ["A", "B", "A"])
    assert (s.probes, s.probes_without_match) == (2, 1)
    np.testing.assert_allclose(s.cmc, [0.5, 1.0, 1.0])
    assert s.rank(1) == 0.5 and s.rank(20) == 1.0
    assert s.mean_average_precision == pytest.approx(((1 / 2 + 2 / 3) / 2 + 1.0) / 2)
    with pytest.raises(ValueError, match="gallery"):
        rank_scores(d[:, :2], ["A", "B", "C"], ["A", "B", "A"])
    # the B entry of probe A does not count (e.g. the probe's own camera): A's first hit moves to rank 1
    valid = np.ones((3, 3), bool)
    valid[0, 1] = False
    masked = rank_scores(d, ["A", "B", "C"], ["A", "B", "A"], valid)
    np.testing.assert_allclose(masked.cmc, [1.0, 1.0, 1.0])
    assert masked.mean_average_precision == pytest.approx(1.0)


def test_linear_metric_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError, match="projection"):
        LinearMetric(np.eye(3), np.eye(2))
    with pytest.raises(ValueError, match="features"):
        euclidean_metric(3).distances(np.zeros((2, 4)), np.zeros((2, 3)))


def test_covariance_subset_and_fits_from_covariances_match_the_fits_on_those_columns() -> None:
    rng = np.random.default_rng(4)
    x = rng.normal(size=(40, 6)) + np.repeat(rng.normal(size=(8, 6)) * 2, 5, axis=0)
    y = np.repeat(np.arange(8), 5)
    cols = [4, 1, 2]
    sub = pair_covariances(x, y).subset(cols)
    direct = pair_covariances(x[:, cols], y)
    np.testing.assert_allclose(sub.intra, direct.intra, atol=1e-12)
    np.testing.assert_allclose(sub.extra, direct.extra, atol=1e-12)
    with pytest.raises(ValueError, match="index"):
        pair_covariances(x, y).subset([6])
    capped = xqda_for_dims(sub, regularisation=1e-3, max_dims=[1, None])
    for cap, metric in zip((1, None), capped, strict=True):
        alone = fit_xqda(x[:, cols], y, regularisation=1e-3, max_dims=cap)
        np.testing.assert_allclose(np.abs(metric.projection), np.abs(alone.projection), atol=1e-9)  # signs free
        np.testing.assert_allclose(metric.distances(x[:5, cols], x[:, cols]), alone.distances(x[:5, cols], x[:, cols]),
                                   atol=1e-6)  # sqrt of rounding: 1e-15 -> 3e-8
    assert capped[0].projection.shape[1] == 1 and capped[1].projection.shape[1] >= 1
    assert capped[0].info["eigenvalues"] == capped[1].info["eigenvalues"][:1]  # the leading direction of both
    k = kissme_from_covariances(sub, regularisation=1e-2)
    np.testing.assert_allclose(k.metric, fit_kissme(x[:, cols], y, regularisation=1e-2).metric, atol=1e-12)
    with pytest.raises(ValueError, match="max_dims"):
        xqda_for_dims(sub, regularisation=1e-3, max_dims=[4])
