"""Tests of the skew-normal distance likelihoods (face_reid_master.identity.likelihood)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA_DIR, FACES_DIR
from scipy import stats

from face_reid_camera.common.resources import model_path
from face_reid_master.identity.likelihood import (
    LikelihoodModel,
    SkewNormal,
    fit_likelihood_model,
    fit_min_of_k_exponent,
    fit_skewnormal,
    load_likelihood_model,
    save_likelihood_model,
)
from face_reid_master.identity.size_likelihood import (
    default_face_likelihood,
    default_likelihood_file,
    load_face_likelihood,
)

YUNET_PATH = DATA_DIR.parents[1] / "models" / "face_detection_yunet_2023mar.onnx"

PARAMS = [
    (1.595, 0.365, 0.0945),
    (1.919, 0.707, 0.124),
    (-3.14, 1.547, 0.281),
    (0.0, 0.5, 0.2),
    (-1.1, 0.92, 0.12),
]


# ------------------------------------------------------------------------------------------ SkewNormal
@pytest.mark.parametrize(("alpha", "xi", "omega"), PARAMS)
def test_pdf_and_logpdf_equal_scipy(alpha: float, xi: float, omega: float) -> None:
    d = np.linspace(0.0, 2.0, 401)
    sn = SkewNormal(alpha, xi, omega)
    ref = stats.skewnorm(alpha, loc=xi, scale=omega)
    np.testing.assert_allclose(sn.pdf(d), ref.pdf(d), rtol=1e-10, atol=1e-300)
    ok = np.isfinite(ref.logpdf(d))
    np.testing.assert_allclose(sn.logpdf(d)[ok], ref.logpdf(d)[ok], rtol=1e-9)


def test_logpdf_stays_finite_where_pdf_underflows() -> None:
    sn = SkewNormal(1.595, 0.365, 0.0945)
    assert sn.pdf([5.0])[0] == 0.0  # exp underflow
    lp = sn.logpdf([3.0, 5.0])
    assert np.all(np.isfinite(lp)) and lp[1] < lp[0] < -300
    # independent value at d = 3: log(2/omega) + log phi(z) + log Phi(alpha z), Phi(alpha z) = 1 here
    z = (3.0 - 0.365) / 0.0945
    expected = math.log(2 / 0.0945) - 0.5 * z * z - 0.5 * math.log(2 * math.pi)
    assert lp[0] == pytest.approx(expected, rel=1e-12)
    assert math.exp(lp[0]) == pytest.approx(sn.pdf([3.0])[0], rel=1e-9)


@pytest.mark.parametrize(
    ("alpha", "xi", "omega"),
    [(1.0, 0.5, 0.0), (1.0, 0.5, -0.1), (math.nan, 0.5, 0.1), (1.0, math.inf, 0.1), (True, 0.5, 0.1)],
)
def test_skewnormal_rejects_bad_parameters(alpha: float, xi: float, omega: float) -> None:
    with pytest.raises(ValueError):
        SkewNormal(alpha, xi, omega)


def test_pdf_rejects_nan() -> None:
    with pytest.raises(ValueError, match="finite"):
        SkewNormal(1.0, 0.5, 0.1).pdf([0.3, math.nan])


# ------------------------------------------------------------------------------------------ fitting
def test_fit_skewnormal_recovers_parameters() -> None:
    true = (2.0, 0.35, 0.12)
    sample = stats.skewnorm.rvs(*true, size=20000, random_state=np.random.default_rng(3))
    sn = fit_skewnormal(sample)
    assert sn.alpha == pytest.approx(true[0], rel=0.15)
    assert sn.xi == pytest.approx(true[1], abs=0.01)
    assert sn.omega == pytest.approx(true[2], rel=0.05)


@pytest.mark.parametrize("bad", [[0.5] * 20, [0.1, 0.2], np.zeros((5, 5)), [0.1] * 9 + [math.nan]])
def test_fit_skewnormal_rejects_bad_samples(bad: object) -> None:
    with pytest.raises(ValueError):
        fit_skewnormal(bad)  # type: ignore[arg-type]


def test_fit_likelihood_model_records_counts() -> None:
    rng = np.random.default_rng(0)
    pos = stats.skewnorm.rvs(1.5, 0.35, 0.1, size=300, random_state=rng)
    neg = stats.skewnorm.rvs(0.5, 0.8, 0.1, size=700, random_state=rng)
    m = fit_likelihood_model(pos, neg, metadata={"embedder": "test"})
    assert m.metadata["n_positive_pairs"] == 300 and m.metadata["n_negative_pairs"] == 700
    assert m.metadata["embedder"] == "test"
    assert m.positive.xi < m.negative.xi
    assert m.k_exponent_positive == 0.0 and m.k_exponent_negative == 0.0


def test_save_load_roundtrip(tmp_path: Path) -> None:
    m = LikelihoodModel(
        SkewNormal(1.5, 0.36, 0.09), SkewNormal(1.9, 0.7, 0.12), 1.5, 0.5, 0.3, metadata={"n": 3}
    )
    path = tmp_path / "lik.json"
    save_likelihood_model(m, path)
    back = load_likelihood_model(path)
    assert back == m
    assert back.metadata == {"n": 3}
    assert json.loads(path.read_text())["k_exponent_negative"] == 0.3


@pytest.mark.parametrize(
    "content",
    [
        "not json",
        json.dumps({"format": "something/else"}),
        json.dumps({"format": "face_reid_likelihood/1", "positive": {"alpha": 1}}),
        json.dumps(
            {
                "format": "face_reid_likelihood/1",
                "positive": {"alpha": 1, "xi": 0.4, "omega": -1},
                "negative": {"alpha": 1, "xi": 0.8, "omega": 0.1},
            }
        ),
    ],
)
def test_load_rejects_malformed_files(tmp_path: Path, content: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(ValueError):
        load_likelihood_model(path)


# ------------------------------------------------------------------------------------------ the model
def test_default_model_is_the_shipped_file_and_discriminates_at_dlib_distances() -> None:
    shipped = model_path(default_likelihood_file("dlib_resnet_v1"))
    assert shipped.is_file()
    m = default_face_likelihood().pooled
    assert m == load_face_likelihood(shipped).pooled
    assert m.metadata["n_positive_pairs"] > 500
    lr = m.log_likelihood_ratio([0.3, 0.45, 0.75, 0.9])
    assert lr[0] > lr[1] > 0 > lr[2] > lr[3]  # dlib: same person ~0.45, different ~0.8+
    with pytest.raises(FileNotFoundError, match="No such file"):  # no built-in copy of the fitted numbers
        load_face_likelihood(Path("/nonexistent/face_likelihood.json"))


def test_log_ratio_is_clipped_where_fitted_tails_turn_back_up() -> None:
    # wider positive than negative: log N_p/N_n grows again far right (a stranger would look like a match)
    m = LikelihoodModel(SkewNormal(1.729, 0.383, 0.143), SkewNormal(-1.1, 0.922, 0.119))
    raw = m.positive.logpdf([3.0]) - m.negative.logpdf([3.0])
    assert raw[0] > 0  # the unclipped ratio is absurd here
    _, hi = m.monotone_distance_range
    assert 0.9 < hi < 1.5
    d = np.linspace(0.0, 3.0, 3001)
    lr = m.log_likelihood_ratio(d)
    assert np.all(np.diff(lr) <= 1e-12)
    assert m.log_likelihood_ratio(np.inf) == pytest.approx(float(m.log_likelihood_ratio(hi)))


def test_swapped_model_is_rejected() -> None:
    with pytest.raises(ValueError, match="discriminative"):
        LikelihoodModel(SkewNormal(0.0, 0.9, 0.1), SkewNormal(0.0, 0.4, 0.1))


@pytest.mark.parametrize(
    "bad",
    [
        {"new_person_scale_c": 0.0},
        {"new_person_scale_c": math.inf},
        {"k_exponent_positive": -0.1},
        {"k_exponent_negative": 1.5},
    ],
)
def test_model_rejects_bad_constants(bad: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        LikelihoodModel(SkewNormal(0.0, 0.4, 0.1), SkewNormal(0.0, 0.9, 0.1), **bad)


def test_log_ratio_rejects_nan_and_bad_counts() -> None:
    m = default_face_likelihood().pooled
    with pytest.raises(ValueError):
        m.log_likelihood_ratio([math.nan])
    with pytest.raises(ValueError):
        m.log_likelihood_ratio([0.5], n_features=0)


def test_min_of_k_likelihood_matches_order_statistic_density() -> None:
    # exponent 1 = K independent pairs: p(min = d) = K f(d) S(d)^(K-1); compare with scipy directly
    p, n = SkewNormal(1.6, 0.37, 0.095), SkewNormal(1.9, 0.71, 0.124)
    m = LikelihoodModel(p, n, k_exponent_positive=1.0, k_exponent_negative=1.0)
    sp = stats.skewnorm(p.alpha, p.xi, p.omega)
    sn = stats.skewnorm(n.alpha, n.xi, n.omega)
    for d, k in [(0.3, 1), (0.3, 5), (0.5, 20), (0.62, 50), (0.8, 3)]:
        expected = (sp.logpdf(d) + (k - 1) * sp.logsf(d)) - (sn.logpdf(d) + (k - 1) * sn.logsf(d))
        assert float(m.log_likelihood_ratio(d, k)) == pytest.approx(
            expected, abs=2e-4 * max(1.0, abs(expected))
        )
    # the paper's form (exponents 0) ignores K
    plain = LikelihoodModel(p, n)
    assert float(plain.log_likelihood_ratio(0.5, 50)) == pytest.approx(float(plain.log_likelihood_ratio(0.5)))


def test_min_of_k_makes_many_features_demand_a_closer_match() -> None:
    # the shipped model uses the paper's pair form (exponents 0: the stored features of a face are correlated)
    shipped = default_face_likelihood().pooled
    assert shipped.k_exponent_positive == shipped.k_exponent_negative == 0.0
    m = dataclasses.replace(shipped, k_exponent_positive=0.54,
                            k_exponent_negative=0.34)  # exponents fitted on independent photos
    # the same distance is weaker evidence against a face that has many features to take the minimum over
    assert float(m.log_likelihood_ratio(0.55, 50)) < float(m.log_likelihood_ratio(0.55, 1))


def test_fit_min_of_k_exponent_recovers_independent_and_fully_correlated_cases() -> None:
    rng = np.random.default_rng(5)
    pair = SkewNormal(1.9, 0.71, 0.124)
    draws = {
        k: stats.skewnorm.rvs(pair.alpha, pair.xi, pair.omega, size=(1500, k), random_state=rng)
        for k in (1, 3, 9)
    }
    independent = {k: v.min(axis=1) for k, v in draws.items()}  # K_eff = K
    identical = {k: v[:, 0] for k, v in draws.items()}  # all K features equal: K_eff = 1
    assert fit_min_of_k_exponent(independent, pair) == pytest.approx(1.0, abs=0.1)
    assert fit_min_of_k_exponent(identical, pair) == pytest.approx(0.0, abs=0.1)
    with pytest.raises(ValueError):
        fit_min_of_k_exponent({1: independent[1]}, pair)


# ------------------------------------------------------------------------------------------ real faces
@pytest.fixture(scope="module")
def fixture_embeddings() -> tuple[np.ndarray, np.ndarray]:
    """Embeddings of every committed fixture photo (largest face), with identities."""
    cv2 = pytest.importorskip("cv2")
    try:
        from face_reid_camera.faces.alignment import align_face
        from face_reid_camera.faces.embedder import FaceEmbedder
    except ImportError:
        pytest.skip("face_reid_camera.faces.embedder not available")
    detector = cv2.FaceDetectorYN.create(str(YUNET_PATH), "", (320, 320), 0.6, 0.3, 50)
    chips, identities = [], []
    for path in sorted(FACES_DIR.glob("*/*.jpg")):
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        detector.setInputSize((image.shape[1], image.shape[0]))
        _, faces = detector.detect(image)
        if faces is None or len(faces) == 0:
            continue
        largest = faces[int(np.argmax(faces[:, 2] * faces[:, 3]))]
        chips.append(align_face(image, largest[4:14].reshape(5, 2)))
        identities.append(path.parent.name)
    embedder = FaceEmbedder(num_threads=1)
    batch = np.stack(chips)
    emb = np.concatenate([embedder.embed(batch[i : i + 32]) for i in range(0, len(batch), 32)])
    return emb, np.array(identities)


def test_default_model_classifies_real_fixture_pairs(
    fixture_embeddings: tuple[np.ndarray, np.ndarray],
) -> None:
    emb, ids = fixture_embeddings
    e = emb.astype(np.float64)
    d = np.sqrt(np.maximum(((e[:, None, :] - e[None, :, :]) ** 2).sum(-1), 0.0))
    iu = np.triu_indices(len(e), 1)
    same = ids[iu[0]] == ids[iu[1]]
    lr = default_face_likelihood().pooled.log_likelihood_ratio(d[iu])
    assert same.sum() > 500
    assert np.mean(lr[same] > 0) > 0.95
    assert np.mean(lr[~same] < 0) > 0.95
