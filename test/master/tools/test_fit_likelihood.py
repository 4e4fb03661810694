"""Tests of face-reid-fit-likelihood (face_reid_master.tools.fit_likelihood): pairs, min-of-K queries, camera
views, the command on real fixture photos, and (with the shared development faces) that it regenerates the
shipped models/face_likelihood.json."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
from math import comb
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import DATA_DIR, REPO_ROOT

from face_reid_camera.common.resources import model_path
from face_reid_camera.faces.photos import PhotoEmbedder
from face_reid_master.identity.likelihood import fit_likelihood_model
from face_reid_master.identity.size_likelihood import default_likelihood_file, load_face_likelihood
from face_reid_master.tools.fit_likelihood import (
    build_pair_distances,
    camera_view_draws,
    excluded_from_fit,
    identity_source,
    main,
    naming_distances,
    sample_min_of_k_distances,
)

DATA_DIR = DATA_DIR
FACES_DIR = DATA_DIR / "faces"
DESK_FRAME = sorted((DATA_DIR / "rgbd" / "pcl_desk").glob("*_rgb.png"))[0]
SUBSET = (  # 6 identities, 54 photos: 4 x 10 lfw, 8 deepface, 6 facerec
    "lfw_Tony_Blair",
    "lfw_Colin_Powell",
    "lfw_Hugo_Chavez",
    "lfw_Ariel_Sharon",
    "deepface_id01",
    "facerec_obama",
)


def _count(identity: str) -> int:
    return len(list((FACES_DIR / identity).glob("*.jpg")))


@pytest.fixture(scope="module")
def subset_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The 6 identities, plus one corrupt jpg and one face-less photo (a PCL desk crop)."""
    root = tmp_path_factory.mktemp("faces")
    for identity in SUBSET:
        shutil.copytree(FACES_DIR / identity, root / identity)
    (root / "lfw_Tony_Blair" / "zz_corrupt.jpg").write_bytes(b"\xff\xd8\xff\xe0 this is no jpeg")
    cv2.imwrite(str(root / "facerec_obama" / "zz_desk.jpg"), cv2.imread(str(DESK_FRAME))[80:400, 120:520])
    return root


@pytest.fixture(scope="module")
def subset_embeddings(subset_dir: Path) -> dict[str, np.ndarray]:
    result = PhotoEmbedder().embed_folder_tree(subset_dir)
    return {name: np.stack([e.embedding for e in embs]) for name, embs in result.identities.items()}


@pytest.fixture(scope="module")
def cli_run(subset_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[int, Path, Path, str]:
    out_dir = tmp_path_factory.mktemp("out")
    out, plot = out_dir / "sub" / "model.json", out_dir / "fit.png"  # parent folders are created
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main([str(subset_dir), "--out", str(out), "--plot", str(plot), "--seed", "3", "--fit-min-of-k"])
    return rc, out, plot, buf.getvalue()


def _mode(sn: object) -> float:
    grid = np.linspace(0.0, 2.0, 20001)
    return float(grid[np.argmax(sn.pdf(grid))])  # type: ignore[attr-defined]


N_SUBSET_PHOTOS = sum(_count(i) for i in SUBSET)
N_SUBSET_POSITIVE = sum(comb(_count(i), 2) for i in SUBSET)


def test_fit_command_writes_a_loadable_discriminative_model(cli_run: tuple[int, Path, Path, str]) -> None:
    rc, out, _, stdout = cli_run
    assert rc == 0
    model = load_face_likelihood(out).pooled
    assert _mode(model.positive) < 0.55 < 0.65 < _mode(model.negative)
    assert model.log_likelihood_ratio(0.4) > 0 > model.log_likelihood_ratio(0.8)
    assert 0.0 < model.k_exponent_positive <= 1.0 and 0.0 < model.k_exponent_negative <= 1.0
    meta = model.metadata
    assert meta["n_images"] == N_SUBSET_PHOTOS == 54 and meta["n_identities"] == 6
    assert meta["identities"] == sorted(SUBSET)  # what face-reid-eval checks a scenario against
    assert meta["n_positive_pairs"] == N_SUBSET_POSITIVE
    assert meta["n_negative_pairs"] == comb(N_SUBSET_PHOTOS, 2) - N_SUBSET_POSITIVE  # all, below 20000
    assert meta["n_skipped_unreadable"] == 1 and meta["skipped_unreadable"] == ["lfw_Tony_Blair/zz_corrupt.jpg"]
    assert meta["n_skipped_no_face"] == 1 and meta["skipped_no_face"] == ["facerec_obama/zz_desk.jpg"]
    assert "4 ids / 40 photos" in meta["data"] and "5 identities with >= 8 photos" in meta["min_of_k_exponents"]
    assert "skipped 1 unreadable, 1 without a detectable face" in stdout
    assert 0.5 < model.decision_distance < 0.7


def test_plot_is_written(cli_run: tuple[int, Path, Path, str]) -> None:
    _, _, plot, _ = cli_run
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = cv2.imread(str(plot))
    assert image.shape == (500, 800, 3)
    assert image.std() > 20  # not blank: histograms and curves drawn


def test_pairs_counts_same_source_and_seeded_sampling(subset_embeddings: dict[str, np.ndarray]) -> None:
    n = {k: len(v) for k, v in subset_embeddings.items()}
    assert n == {i: _count(i) for i in SUBSET}
    all_pairs = build_pair_distances(subset_embeddings, 20000, np.random.default_rng(0))
    assert all_pairs.positive.size == N_SUBSET_POSITIVE
    assert all_pairs.negative.size == all_pairs.n_negative_available == comb(54, 2) - N_SUBSET_POSITIVE
    # positive pairs: exactly the within-identity distances
    tb = subset_embeddings["lfw_Tony_Blair"].astype(np.float64)
    tb_d = np.linalg.norm(tb[:, None] - tb[None], axis=2)[np.triu_indices(len(tb), 1)]
    assert np.all(np.isin(np.round(tb_d, 6), np.round(all_pairs.positive, 6)))
    assert np.median(all_pairs.positive) < 0.55 < np.median(all_pairs.negative)
    # same source: only lfw x lfw negatives (deepface_id01 and facerec_obama have no partner)
    same = build_pair_distances(subset_embeddings, 20000, np.random.default_rng(0), same_source_negatives=True)
    assert same.n_negative_available == comb(40, 2) - 4 * comb(10, 2)
    sampled = build_pair_distances(subset_embeddings, 100, np.random.default_rng(5), same_source_negatives=True)
    again = build_pair_distances(subset_embeddings, 100, np.random.default_rng(5), same_source_negatives=True)
    assert sampled.negative.size == 100 and sampled.n_negative_available == same.n_negative_available
    np.testing.assert_array_equal(sampled.negative, again.negative)
    assert np.all(np.isin(sampled.negative, same.negative))
    assert len(np.unique(sampled.negative)) == 100  # without replacement
    with pytest.raises(ValueError, match="at least 2 identities"):
        build_pair_distances({"solo": subset_embeddings["lfw_Tony_Blair"]}, 10, np.random.default_rng(0))
    with pytest.raises(ValueError, match="max_negative_pairs"):
        build_pair_distances(subset_embeddings, 0, np.random.default_rng(0))


def test_min_of_k_queries(subset_embeddings: dict[str, np.ndarray]) -> None:
    samples = sample_min_of_k_distances(subset_embeddings, np.random.default_rng(1), queries_per_k=500)
    assert samples is not None
    assert samples.identities == sorted(i for i in SUBSET if _count(i) >= 8)
    assert sorted(samples.positive) == [1, 2, 3, 5, 7]
    assert all(v.shape == (500,) for v in [*samples.positive.values(), *samples.negative.values()])
    # the minimum over more features is smaller, for the same and for other people
    assert np.median(samples.positive[7]) < np.median(samples.positive[1]) - 0.03
    assert np.median(samples.negative[7]) < np.median(samples.negative[1]) - 0.03
    assert np.median(samples.positive[7]) < 0.5 < np.median(samples.negative[7])
    # too few identities with max(K) + 1 photos: nothing to fit
    small = {k: v[:5] for k, v in subset_embeddings.items()}
    assert sample_min_of_k_distances(small, np.random.default_rng(1)) is None
    # same source: only lfw identities have partners; deepface_id01 queries never get negatives
    same = sample_min_of_k_distances(
        subset_embeddings, np.random.default_rng(1), queries_per_k=200, same_source_negatives=True
    )
    assert same is not None and same.negative[1].shape == (200,)
    assert identity_source("lfw_George_W_Bush") == "lfw" and identity_source("alice") == "alice"
    assert identity_source("yaleB10") == "yaleB" and identity_source("007") == "007"


def test_camera_view_draws_take_one_usable_view_per_photo() -> None:
    rng = np.random.default_rng(0)
    views = rng.normal(size=(3, 4, 8))
    views[0, 1:] = np.nan  # photo 0: only its first view is usable
    draws = camera_view_draws({"a": views, "b": views[1:] + 1.0}, 50, np.random.default_rng(2))
    assert len(draws) == 50 and all(d["a"].shape == (3, 8) and d["b"].shape == (2, 8) for d in draws)
    picked = {tuple(np.flatnonzero(np.all(views[1] == d["a"][1], axis=1))) for d in draws}
    assert picked == {(0,), (1,), (2,), (3,)}  # every usable view of photo 1 is drawn, always one of them
    assert all(np.array_equal(d["a"][0], views[0, 0]) for d in draws)
    assert all(np.all(np.isfinite(d["a"])) for d in draws)
    bad = views.copy()
    bad[2] = np.nan
    with pytest.raises(ValueError, match="at least one usable view"):
        camera_view_draws({"a": bad}, 1, rng)
    with pytest.raises(ValueError, match="draws"):
        camera_view_draws({"a": views}, 0, rng)


@pytest.mark.slow
def test_camera_views_widen_same_person_distances(subset_dir: Path, tmp_path: Path) -> None:
    """--camera-views fits on degraded views (faces as small / dim as a Kinect sees them): same-person
    distances grow, so N_p moves right of the clean-photo fit; --exclude leaves identities out."""
    clean, cam = tmp_path / "clean.json", tmp_path / "cam.json"
    cache = tmp_path / "cache.npz"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([str(subset_dir), "--out", str(clean), "--exclude", "facerec_*"]) == 0
        assert main([str(subset_dir), "--out", str(cam), "--exclude", "facerec_*", "--camera-views", "2",
                     "--cache", str(cache)]) == 0
    m_clean, m_cam = load_face_likelihood(clean).pooled, load_face_likelihood(cam).pooled
    assert m_cam.metadata["n_identities"] == m_clean.metadata["n_identities"] == 5
    assert m_cam.metadata["excluded"] == {"patterns": ["facerec_*"], "scenario_identities": []}
    for m in (m_clean, m_cam):  # the face-less photo is in the excluded facerec_obama folder: not reported
        assert m.metadata["skipped_no_face"] == []
        assert m.metadata["skipped_unreadable"] == ["lfw_Tony_Blair/zz_corrupt.jpg"]
    assert excluded_from_fit("facerec_obama", ["facerec_*"], set()) and excluded_from_fit("x", [], {"x"})
    assert not excluded_from_fit("lfw_Tony_Blair", ["facerec_*"], {"x"})
    assert m_cam.metadata["n_positive_pairs"] == 2 * m_clean.metadata["n_positive_pairs"]  # 2 draws, no same-photo
    assert _mode(m_cam.positive) > _mode(m_clean.positive) + 0.02
    assert m_cam.k_exponent_positive == m_cam.k_exponent_negative == 0.0  # min-of-K only on request
    assert "--camera-views 2" in m_cam.metadata["command"] and cache.is_file()
    assert 0.5 < m_cam.decision_distance < 0.75
    # naming derived on learned faces (camera views) vs galleries: far stricter than a pair quantile would be
    assert "learned faces" in load_face_likelihood(cam).metadata["thresholds"]
    assert "pair false-accept" in load_face_likelihood(clean).metadata["thresholds"]


def test_decision_distance_is_where_the_densities_cross(subset_embeddings: dict[str, np.ndarray]) -> None:
    pairs = build_pair_distances(subset_embeddings, 20000, np.random.default_rng(0))
    model = fit_likelihood_model(pairs.positive, pairs.negative)
    d = model.decision_distance
    assert float(model.positive.pdf(d)) == pytest.approx(float(model.negative.pdf(d)), rel=1e-6)


def test_unusable_folders_exit_2_with_a_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], subset_dir: Path
) -> None:
    out = tmp_path / "m.json"
    (tmp_path / "empty").mkdir()
    assert main([str(tmp_path / "empty"), "--out", str(out)]) == 2
    assert "has no photos" in capsys.readouterr().err
    assert main([str(tmp_path / "missing"), "--out", str(out)]) == 2
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "solo").mkdir()
    shutil.copytree(subset_dir / "facerec_obama", tmp_path / "solo" / "obama")
    assert main([str(tmp_path / "solo"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "at least 2 identities" in err and "no face:" in err  # the desk crop is reported too
    assert not out.exists()
    with pytest.raises(SystemExit) as exc:
        main([str(subset_dir), "--max-negative-pairs", "0"])
    assert exc.value.code == 2


SHARED_FACES = Path(os.environ.get("FACE_REID_SHARED_FACES", REPO_ROOT.parent / "shared" / "data" / "faces"))


@pytest.mark.skipif(not os.environ.get("FACE_REID_REGENERATE_LIKELIHOOD") or not SHARED_FACES.is_dir(),
                    reason="needs the shared development faces and FACE_REID_REGENERATE_LIKELIHOOD=1 (~1.5 min)")
def test_command_regenerates_the_shipped_model(tmp_path: Path) -> None:
    """The command recorded in models/face_likelihood_dlib_resnet_v1.json, on the shared development faces,
    reproduces it (the held-out scenario identities passed as --exclude names, as recorded in its metadata)."""
    shipped = json.loads(model_path(default_likelihood_file("dlib_resnet_v1")).read_text())
    meta = shipped["metadata"]
    out = tmp_path / "face_likelihood.json"
    excludes = [a for p in [*meta["excluded"]["patterns"], *meta["excluded"]["scenario_identities"]]
                for a in ("--exclude", p)]
    assert main([str(SHARED_FACES), "--same-source-negatives", "--camera-views", "4", *excludes,
                 "--out", str(out)]) == 0
    fresh = json.loads(out.read_text())
    for kind in ("positive", "negative"):
        for key, tol in (("xi", 2e-3), ("omega", 2e-3), ("alpha", 0.1)):
            assert fresh["pooled"][kind][key] == pytest.approx(shipped["pooled"][kind][key], abs=tol)
    for key in ("n_positive_pairs", "n_negative_pairs", "n_images", "n_identities", "n_skipped_no_face"):
        assert fresh["metadata"][key] == meta[key]
    assert fresh["metadata"]["min_of_k_exponents"] == meta["min_of_k_exponents"]


def test_size_buckets_take_each_pair_for_the_bucket_of_each_of_its_faces() -> None:
    from face_reid_master.tools.fit_likelihood import size_bucket_distances

    # two identities, two photos each: small faces (8 px) have noisier embeddings
    draw = {"a": np.array([[0.0, 0.0], [0.1, 0.0]]), "b": np.array([[1.0, 0.0], [1.0, 0.5]])}
    eye = {"a": np.array([8.0, 30.0]), "b": np.array([30.0, 8.0])}
    (small_pos, small_neg), (large_pos, large_neg) = size_bucket_distances(
        draw, eye, (12.0,), 100, np.random.default_rng(0))
    # positives: a0-a1 (0.1; one small, one large face), b0-b1 (0.5; one large, one small)
    np.testing.assert_allclose(np.sort(small_pos), [0.1, 0.5])
    np.testing.assert_allclose(np.sort(large_pos), [0.1, 0.5])
    # negatives: 4 pairs; a0 (small) with b0, b1; b1 (small) with a0, a1
    assert small_neg.size == 4 and large_neg.size == 4
    assert np.isclose(small_neg, np.hypot(1.0, 0.5)).sum() == 2  # a0-b1 counted for both of its small faces


def test_naming_distances_take_the_rules_minimum_over_learned_and_gallery_features() -> None:
    rng = np.random.default_rng(0)
    centres = {"a_1": 0.0, "a_2": 3.0, "b_1": 6.0, "c_1": 10.0}  # identity -> position on axis 0; sources a, b, c
    views = {}
    for name, x in centres.items():
        v = np.zeros((6, 3, 4))  # 6 photos x 3 views
        v[..., 0] = x + 0.1 * rng.standard_normal((6, 3))
        v[1, 2] = np.nan  # a view without a face
        views[name] = v
    views["d_1"] = np.zeros((2, 3, 4))  # < 3 photos: not used
    d = naming_distances(views, np.random.default_rng(1), splits=2, max_features=4)
    assert d.positive.size == 2 * 4 and d.negative.size == 2 * 4 * 3
    assert d.positive.max() < 0.6 and d.negative.min() > 2.3  # nearest other identity is 3 away
    assert d.threshold(0.0) == pytest.approx(d.negative.min())
    same = naming_distances(views, np.random.default_rng(1), splits=5, same_source_negatives=True)
    assert same.negative.size == 5 * 2  # only a_1 <-> a_2
    with pytest.raises(ValueError, match="too few"):
        naming_distances(views, np.random.default_rng(1), splits=2, same_source_negatives=True)
    with pytest.raises(ValueError, match="identities"):
        naming_distances({"a": views["a_1"]}, rng)
