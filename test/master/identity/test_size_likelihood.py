"""Likelihoods per embedder space and face size: buckets, per-row evidence, the file format."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal, save_likelihood_model
from face_reid_master.identity.size_likelihood import FaceLikelihood, load_face_likelihood, save_face_likelihood

SHARP = LikelihoodModel(SkewNormal(0.0, 0.4, 0.08), SkewNormal(0.0, 0.9, 0.1))  # large faces: decisive
BLUNT = LikelihoodModel(SkewNormal(0.0, 0.55, 0.15), SkewNormal(0.0, 0.85, 0.15))  # small faces: weak evidence


def _model(**kw) -> FaceLikelihood:
    return FaceLikelihood(SHARP, eye_px_edges=(12.0,), by_size=(BLUNT, SHARP), name_threshold=0.45,
                          threshold_distance=0.6, **kw)


def test_buckets_by_eye_distance_and_unknown_sizes_use_the_pooled_fit() -> None:
    m = _model()
    np.testing.assert_array_equal(m.bucket_of([5.0, 11.99, 12.0, 40.0, 0.0, np.nan]), [0, 0, 1, 1, -1, -1])
    d = np.array([[0.45], [0.45], [0.45]])
    lr = m.log_ratio_rows(d, np.ones((1, 1)), m.bucket_of([8.0, 30.0, 0.0]))
    assert lr[0, 0] == pytest.approx(BLUNT.log_likelihood_ratio(0.45)[()])
    assert lr[1, 0] == pytest.approx(SHARP.log_likelihood_ratio(0.45)[()])
    assert lr[2, 0] == pytest.approx(SHARP.log_likelihood_ratio(0.45)[()])  # pooled
    assert 0 < lr[0, 0] < lr[1, 0]  # the same distance from a small face is weaker evidence
    assert not m.pooled_only().conditioned and m.pooled_only().bucket_of([8.0])[0] == -1


def test_a_small_face_moves_the_posterior_less(tmp_path: Path) -> None:
    """Same distances, two face sizes: the Bayes table is surer after large-face observations."""
    rng = np.random.default_rng(0)
    face = rng.normal(size=(1, 128)).astype(np.float32)
    posteriors = []
    for eye in (8.0, 30.0):
        table = BayesIdentityManager(_model(), min_observations=1, posterior_threshold=0.99)
        table.add_observations(1, face, 0.0)
        table.step(0.0)
        table.track_deleted(1, 0.1)
        table.step(0.1)
        close = face + np.float32(0.45 / np.sqrt(128))  # L2 distance 0.45 from the stored feature
        table.add_observations(2, close, 1.0, eye_px=[eye])
        table.step(1.0)
        posteriors.append(table.confidence_of(2))
    assert posteriors[0] < posteriors[1]


def test_file_round_trip_and_version_1_files(tmp_path: Path) -> None:
    m = _model(space="dlib_resnet_v1+sface_2021dec", component_weights=(1.2, 0.7), metadata={"data": "x"})
    path = tmp_path / "m.json"
    save_face_likelihood(m, path)
    back = load_face_likelihood(path)
    assert back == m and back.metadata["data"] == "x"
    scaled = back.scale(np.ones((1, 256), dtype=np.float32))
    assert scaled[0, 0] == pytest.approx(1.2) and scaled[0, 200] == pytest.approx(0.7)
    v1 = tmp_path / "v1.json"
    save_likelihood_model(SHARP, v1)
    old = load_face_likelihood(v1)
    assert old.space == "dlib_resnet_v1" and not old.conditioned and old.name_threshold is None
    (tmp_path / "bad.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="not a face likelihood model"):
        load_face_likelihood(tmp_path / "bad.json")


@pytest.mark.parametrize("kwargs, match", [
    ({"eye_px_edges": (20.0, 12.0), "by_size": (SHARP, SHARP, SHARP)}, "increase"),
    ({"eye_px_edges": (12.0,), "by_size": (SHARP,)}, "needs 2 models"),
    ({"component_weights": (1.0,), "space": "dlib_resnet_v1+sface_2021dec"}, "needs 2 values"),
    ({"space": "openface"}, "unknown embedding space"),
    ({"name_threshold": -1.0}, "name_threshold"),
])
def test_bad_models_are_refused_with_the_field_named(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        FaceLikelihood(SHARP, **kwargs)


@pytest.mark.parametrize("space", ["dlib_resnet_v1", "sface_2021dec", "dlib_resnet_v1+sface_2021dec"])
def test_every_space_ships_a_fit_with_its_derived_distances(space: str) -> None:
    from face_reid_master.core import MasterConfig, MasterCore
    from face_reid_master.identity.size_likelihood import default_face_likelihood

    m = default_face_likelihood(space)
    assert m.space == space and m.name_threshold is not None and m.threshold_distance is not None
    assert m.name_threshold < m.threshold_distance  # naming is stricter than "same face"
    if "+" in space:
        assert len(m.component_weights) == 2
    if space == "sface_2021dec":  # fitted per face size: small faces' same-person distances spread further
        # (the dlib and joint fits are pooled: on the development scenarios the buckets did not help, README)
        assert m.conditioned
        small, large = m.by_size[0], m.by_size[-1]
        assert small.decision_distance > large.decision_distance
        close = 0.6 * m.decision_distance  # a typical same-person distance: weaker evidence from a small face
        lr = m.log_ratio_rows(np.full((2, 1), close), np.ones((1, 1)), m.bucket_of([8.0, 40.0]))
        assert 0 < lr[0, 0] < lr[1, 0]
    core = MasterCore(MasterConfig(embedding_space=space))  # the defaults load it
    assert core.name_threshold == m.name_threshold
