"""face-reid-eval-faces: the metrics on scores whose answers are known, the geometry, and one run on the fixtures."""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from conftest import FACES_DIR

from face_reid_camera.tools.eval_faces import (
    HEAD_ROI_SIDE_PER_EYE_DISTANCE,
    OpenSetSplit,
    dir_at_fpir,
    evaluate_scores,
    head_roi_for_face,
    main,
    one_photo_galleries,
    open_set_split,
    pair_scores,
    parse_eye_px,
    rank1_one_photo_gallery,
    rank1_rate,
    roc_auc,
    score_matrix,
    shrink_to_eye_distance,
    tar_at_far,
    threshold_at_rate,
    z_normalised,
)

# ------------------------------------------------------------------------------------------------ metrics


def test_threshold_lets_exactly_the_rate_of_impostors_through() -> None:
    impostors = np.random.default_rng(1).permutation(np.arange(1000.0))
    for rate, expected in ((1e-2, 989.0), (1e-3, 998.0), (0.0, 999.0)):
        t = threshold_at_rate(impostors, rate)
        assert t == expected
        assert np.mean(impostors > t) == pytest.approx(rate)
    assert threshold_at_rate(impostors, 1.0) == -math.inf
    assert threshold_at_rate(np.zeros(0), 0.01) == math.inf
    with pytest.raises(ValueError):
        threshold_at_rate(impostors, 1.5)


def test_tar_at_far_counts_genuine_scores_above_the_threshold() -> None:
    impostors = np.arange(1000.0)
    genuine = np.array([985.0, 989.0, 990.0, 995.0, 1000.0, 2000.0])
    assert tar_at_far(genuine, impostors, 1e-2) == pytest.approx(4 / 6)  # > 989
    assert tar_at_far(genuine, impostors, 1e-3) == pytest.approx(2 / 6)  # > 998
    assert tar_at_far(-genuine, -impostors, 1e-2) == 0.0  # reversed scores accept nothing
    assert math.isnan(tar_at_far(np.zeros(0), impostors, 1e-2))


def test_tar_at_far_of_two_gaussians_matches_the_normal_quantiles() -> None:
    rng = np.random.default_rng(0)
    impostors = rng.normal(0.0, 1.0, 400_000)
    genuine = rng.normal(3.0, 1.0, 400_000)
    # threshold = the 99 % / 99.9 % quantile of N(0, 1): 2.3263 / 3.0902 -> TAR = Phi(3 - q)
    assert tar_at_far(genuine, impostors, 1e-2) == pytest.approx(0.7468, abs=0.005)
    assert tar_at_far(genuine, impostors, 1e-3) == pytest.approx(0.4641, abs=0.01)
    # AUC of two unit normals 3 apart = Phi(3 / sqrt(2))
    assert roc_auc(genuine[:20_000], impostors[:20_000]) == pytest.approx(0.98305, abs=0.003)


def test_roc_auc_counts_ties_half_and_is_reversed_by_negated_scores() -> None:
    genuine, impostors = np.array([1.0, 2.0, 3.0]), np.array([0.0, 2.0])
    assert roc_auc(genuine, impostors) == pytest.approx(4.5 / 6)
    assert roc_auc(-genuine, -impostors) == pytest.approx(1.5 / 6)
    assert roc_auc(np.array([5.0]), np.array([1.0, 2.0])) == 1.0
    assert math.isnan(roc_auc(np.zeros(0), impostors))


def test_score_matrices() -> None:
    x = np.array([[0.0, 0.0], [3.0, 4.0], [1.0, 0.0]])
    l2 = score_matrix(x, "neg_l2")
    assert l2 == pytest.approx(-np.linalg.norm(x[:, None] - x[None], axis=2))
    assert np.all(np.diag(l2) == 0.0)
    cos = score_matrix(np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]]), "cosine")
    assert cos == pytest.approx(np.array([[1, 0, 0.70710678], [0, 1, 0.70710678], [0.70710678, 0.70710678, 1]]))
    with pytest.raises(ValueError):
        score_matrix(x, "dot")


def test_z_normalisation_uses_the_pairs_only() -> None:
    s = score_matrix(np.random.default_rng(2).normal(size=(30, 8)), "neg_l2")
    z = z_normalised(s)
    pairs = z[np.triu_indices(30, k=1)]
    assert pairs.mean() == pytest.approx(0.0, abs=1e-12)
    assert pairs.std() == pytest.approx(1.0)
    assert np.allclose(z, z.T)


def test_pair_scores_split_same_and_different_identities() -> None:
    s = np.array([[0.0, 1.0, 2.0], [1.0, 0.0, 3.0], [2.0, 3.0, 0.0]])
    genuine, impostors = pair_scores(s, np.array([7, 7, 9]))
    assert genuine.tolist() == [1.0]
    assert sorted(impostors.tolist()) == [2.0, 3.0]


def test_rank1_on_a_hand_made_matrix() -> None:
    labels = np.array([0, 0, 1, 2, 0])
    s = np.array([
        [9.0, 0.8, 0.1, 0.2, 0.3],  # photo 0: nearest other is 1 (same identity) -> right (diagonal ignored)
        [0.8, 9.0, 0.9, 0.2, 0.1],  # photo 1: nearest is 2 (identity 1) -> wrong
        [0.1, 0.9, 9.0, 0.5, 0.0],  # identities 1 and 2 have one photo: not probes, still in the gallery
        [0.2, 0.2, 0.5, 9.0, 0.0],
        [0.3, 0.1, 0.0, 0.0, 9.0],  # photo 4: nearest is 0 -> right
    ])
    rate, probes = rank1_rate(s, labels)
    assert probes == 3
    assert rate == pytest.approx(2 / 3)
    assert rank1_rate(-s, labels)[0] == pytest.approx(1 / 3)  # reversed: only photo 1's farthest is of its identity
    assert s[0, 0] == 9.0  # the input is not modified


def test_rank1_with_one_gallery_photo_per_identity() -> None:
    labels = np.array([0, 0, 0, 1, 1])
    s = np.array([
        [9.0, 0.9, 0.1, 0.5, 0.2],
        [0.9, 9.0, 0.3, 0.8, 0.1],
        [0.1, 0.3, 9.0, 0.2, 0.6],
        [0.5, 0.8, 0.2, 9.0, 0.7],
        [0.2, 0.1, 0.6, 0.7, 9.0],
    ])
    # gallery (0, 3): probe 1 -> 0 (0.9) right, 2 -> 3 (0.2 > 0.1) wrong, 4 -> 3 right: 2/3
    # gallery (1, 4): probe 0 -> 1 right, 2 -> 4 (0.6 > 0.3) wrong, 3 -> 1 (0.8 > 0.7) wrong: 1/3
    assert rank1_one_photo_gallery(s, labels, np.array([[0, 3]])) == pytest.approx(2 / 3)
    assert rank1_one_photo_gallery(s, labels, np.array([[0, 3], [1, 4]])) == pytest.approx(0.5)
    galleries = one_photo_galleries(np.repeat(np.arange(4), 5), np.random.default_rng(0), repeats=7)
    assert galleries.shape == (7, 4)
    assert np.array_equal(galleries // 5, np.tile(np.arange(4), (7, 1)))  # one photo of each identity, in order


def test_open_set_split_is_seeded_and_partitions_the_photos() -> None:
    labels = np.repeat(np.arange(6), 3)
    split = open_set_split(labels, np.random.default_rng(5))
    again = open_set_split(labels, np.random.default_rng(5))
    assert all(np.array_equal(a, b) for a, b in zip(
        (split.gallery, split.known, split.unknown), (again.gallery, again.known, again.unknown), strict=True))
    enrolled = set(labels[split.gallery].tolist())
    assert len(split.gallery) == len(enrolled) == 3
    assert set(labels[split.known].tolist()) == enrolled and len(split.known) == 6
    assert not enrolled & set(labels[split.unknown].tolist()) and len(split.unknown) == 9
    everything = np.concatenate([split.gallery, split.known, split.unknown])
    assert sorted(everything.tolist()) == list(range(18))


def test_dir_at_fpir_on_constructed_scores() -> None:
    # photos 0, 1: gallery of identities 0 and 1; 2-4 known probes; 5-104 unknown probes of identity 9.
    n = 105
    labels = np.array([0, 1, 0, 1, 0] + [9] * 100)
    s = np.zeros((n, n))
    s[5:, 0] = np.arange(100) / 100.0  # unknown best scores 0.00 .. 0.99 -> threshold at FPIR 1 %: 0.98
    s[2, 0], s[2, 1] = 0.99, 0.2  # right identity, above the threshold: counts
    s[3, 0], s[3, 1] = 0.995, 0.9  # best match is the wrong identity: does not count
    s[4, 0], s[4, 1] = 0.5, 0.1  # right identity but below the threshold: does not count
    s = np.maximum(s, s.T)
    split = OpenSetSplit(np.array([0, 1]), np.array([2, 3, 4]), np.arange(5, n))
    assert dir_at_fpir(s, labels, split, 1e-2) == pytest.approx(1 / 3)
    assert dir_at_fpir(s, labels, split, 0.5) == pytest.approx(2 / 3)  # threshold 0.49: probe 4 passes too
    assert dir_at_fpir(-s, labels, split, 1e-2) == 0.0
    assert math.isnan(dir_at_fpir(s, labels, OpenSetSplit(np.array([0]), np.zeros(0, int), np.arange(5, n))))


def test_evaluate_scores_on_perfectly_separated_embeddings() -> None:
    rng = np.random.default_rng(3)
    centres = rng.normal(size=(10, 16)) * 10.0
    labels = np.repeat(np.arange(10), 4)
    x = centres[labels] + rng.normal(scale=0.1, size=(40, 16))
    m = evaluate_scores(score_matrix(x, "neg_l2"), labels, open_set_split(labels, rng))
    assert m.tar_at_far == {"0.001": 1.0, "0.01": 1.0}
    assert m.rank1 == 1.0 and m.dir_at_fpir == 1.0 and math.isnan(m.rank1_one_photo_gallery) and m.roc_auc == 1.0
    assert (m.n_genuine_pairs, m.n_impostor_pairs, m.n_rank1_probes) == (60, 720, 40)


# ----------------------------------------------------------------------------------------------- geometry


def test_parse_eye_px() -> None:
    assert parse_eye_px("full,14,10") == ["full", "14", "10"]
    assert parse_eye_px(" FULL , 12.50 ") == ["full", "12.5"]
    for bad in ("", "0", "-3", "big", "14,14.0", "nan"):
        with pytest.raises(ValueError):
            parse_eye_px(bad)


def test_shrink_and_head_roi() -> None:
    image = np.zeros((200, 300, 3), dtype=np.uint8)
    small, factor = shrink_to_eye_distance(image, 40.0, 10.0)
    assert small.shape == (50, 75, 3) and factor == pytest.approx([0.25, 0.25])
    same, one = shrink_to_eye_distance(image, 8.0, 10.0)  # already smaller: unshrunk
    assert same is image and one.tolist() == [1.0, 1.0]
    assert shrink_to_eye_distance(image, 40.0, None)[0] is image
    side = HEAD_ROI_SIDE_PER_EYE_DISTANCE * 10.0
    assert side == pytest.approx(47.6, abs=0.1)
    x, y, w, h = head_roi_for_face(np.array([100.0, 100.0]), 10.0, 300, 200)
    assert abs(w - side) <= 1.5 and abs(h - side) <= 1.5
    assert x + w / 2 == pytest.approx(100.5, abs=1.0) and y + h / 2 == pytest.approx(100.5, abs=1.0)
    assert head_roi_for_face(np.array([5.0, 195.0]), 10.0, 300, 200)[:2] == (0, 171)  # clipped
    x, y, w, h = head_roi_for_face(np.array([5.0, 195.0]), 10.0, 300, 200)
    assert x + w <= 300 and y + h == 200


# --------------------------------------------------------------------------------------------- end to end


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def fixture_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], str, Path]:
    """All fixture photos (28 identities) at full size and 12 px, every embedder, with a cache."""
    tmp = tmp_path_factory.mktemp("eval_faces")
    code, out, err = _run([str(FACES_DIR), "--eye-px", "full,12", "--json", str(tmp / "r.json"),
                           "--cache", str(tmp / "c.npz"), "--quiet"])
    assert code == 0, err
    return json.loads((tmp / "r.json").read_text()), out, tmp


@pytest.mark.slow
def test_report_structure(fixture_run: tuple[dict[str, Any], str, Path]) -> None:
    result, out, _ = fixture_run
    counts = result["counts"]
    assert counts["identities_listed"] == 28 and counts["photos_listed"] == 177
    assert counts["grey_photos"] == 0 and counts["photos_evaluated"] == 177
    assert counts["photos_scored"] + counts["no_face"] <= 177 and counts["photos_scored"] >= 170
    assert [s["eye_px"] for s in result["sizes"]] == ["full", "12"]
    assert result["open_set"]["gallery"] == 14
    for size in result["sizes"]:
        assert set(size["metrics"]) == {"dlib", "sface", "both"}
        for m in size["metrics"].values():
            assert set(m["tar_at_far"]) == {"0.001", "0.01"}
            assert m["ms_per_face"] > 0
            for key in ("rank1", "rank1_one_photo_gallery", "dir_at_fpir", "roc_auc"):
                assert 0 <= m[key] <= 1, key
    twelve = result["sizes"][1]
    assert twelve["median_eye_px_seen"] == pytest.approx(12.0, abs=1.5)  # the photos were shrunk as asked
    assert result["sizes"][0]["median_eye_px_seen"] > 30
    assert "| eye distance | dlib TAR@FAR 1e-3 / rank-1 | SFace TAR@FAR 1e-3 / rank-1 |" in out
    assert "| 12 px (median 1" in out and "| both (sum of z-scores) |" in out and "full photo (median" in out
    assert "DIR@FPIR 1e-2" in out and "ROC AUC" in out and "enrol failures" in out


@pytest.mark.slow
def test_accuracy_is_high(fixture_run: tuple[dict[str, Any], str, Path]) -> None:
    """Right colour order, alignment and score sign give near-perfect results on these photos.

    Measured on these fixtures (TAR@FAR 1e-3, full / 12 px): dlib 0.979 / 0.912, SFace 1.000 / 0.995, both
    1.000 / 0.997.  Feeding the embedders BGR chips instead gives dlib 0.948 / 0.821, SFace 0.995 / 0.976,
    both 0.998 / 0.979 (the 12 px bounds below catch it); reversed scores give TAR 0 and AUC ~0.
    """
    full, twelve = (size["metrics"] for size in fixture_run[0]["sizes"])
    for name in ("dlib", "sface", "both"):
        m = full[name]
        assert m["rank1"] >= 0.98, name
        assert m["rank1_one_photo_gallery"] >= 0.97, name
        assert m["tar_at_far"]["0.01"] >= 0.98, name
        assert m["roc_auc"] >= 0.998, name
        assert m["dir_at_fpir"] >= 0.85, name
    assert full["dlib"]["tar_at_far"]["0.001"] >= 0.965
    assert full["sface"]["tar_at_far"]["0.001"] >= 0.99
    assert full["both"]["tar_at_far"]["0.001"] >= 0.99
    assert twelve["dlib"]["tar_at_far"]["0.001"] >= 0.87
    assert twelve["sface"]["tar_at_far"]["0.001"] >= 0.985
    assert twelve["both"]["tar_at_far"]["0.001"] >= 0.99
    # smaller faces are harder for dlib; both at least as good as dlib
    assert twelve["dlib"]["tar_at_far"]["0.001"] < full["dlib"]["tar_at_far"]["0.001"]
    assert twelve["both"]["tar_at_far"]["0.001"] >= twelve["dlib"]["tar_at_far"]["0.001"]


@pytest.mark.slow
def test_cache_gives_the_same_numbers_without_embedding(fixture_run: tuple[dict[str, Any], str, Path]) -> None:
    result, _, tmp = fixture_run
    code, _, err = _run([str(FACES_DIR), "--eye-px", "12", "--embedders", "sface,dlib", "--json", str(tmp / "r2.json"),
                         "--cache", str(tmp / "c.npz"), "--quiet"])
    assert code == 0, err
    again = json.loads((tmp / "r2.json").read_text())
    assert again["photos_computed"] == 0
    assert again["sizes"][0]["metrics"]["sface"] == result["sizes"][1]["metrics"]["sface"]
    assert again["sizes"][0]["metrics"]["dlib"] == result["sizes"][1]["metrics"]["dlib"]


def test_grey_photos_and_excludes(tmp_path: Path) -> None:
    root = tmp_path / "faces"
    for identity in ("lfw_Tony_Blair", "lfw_Colin_Powell", "deepface_id02"):
        (root / identity).mkdir(parents=True)
        for p in sorted((FACES_DIR / identity).glob("*.jpg"))[:3]:
            shutil.copy(p, root / identity / p.name)
    grey = cv2.cvtColor(cv2.imread(str(sorted((FACES_DIR / "lfw_George_W_Bush").glob("*.jpg"))[0])),
                        cv2.COLOR_BGR2GRAY)
    (root / "grey_only").mkdir()
    cv2.imwrite(str(root / "grey_only" / "a.png"), grey)  # a single-channel file
    cv2.imwrite(str(root / "grey_only" / "b.png"), cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR))  # three equal channels
    cv2.imwrite(str(root / "lfw_Tony_Blair" / "zz_grey.png"), grey)
    common = ["--eye-px", "full", "--embedders", "sface", "--quiet"]

    code, out, err = _run([str(root), *common, "--json", str(tmp_path / "a.json")])
    assert code == 0, err
    counts = json.loads((tmp_path / "a.json").read_text())["counts"]
    assert (counts["identities_listed"], counts["photos_listed"]) == (4, 12)
    assert counts["grey_photos"] == 3 and counts["grey_identities"] == ["grey_only"]
    assert (counts["identities_evaluated"], counts["photos_evaluated"]) == (3, 9)
    assert "3 grey photos dropped" in out

    code, _, err = _run([str(root), *common, "--all-photos", "--exclude", "deepface_*", "--exclude", "*/zz_*",
                         "--json", str(tmp_path / "b.json")])
    assert code == 0, err
    counts = json.loads((tmp_path / "b.json").read_text())["counts"]
    assert counts["grey_photos"] == 0 and counts["excluded_identities"] == ["deepface_id02"]
    assert counts["excluded_photos"] == 4 and (counts["identities_evaluated"], counts["photos_evaluated"]) == (3, 8)

    code, _, err = _run([str(root), *common, "--max-identities", "2", "--json", str(tmp_path / "c.json")])
    assert code == 0, err
    assert json.loads((tmp_path / "c.json").read_text())["counts"]["identities_evaluated"] == 2


def test_clear_errors(tmp_path: Path) -> None:
    code, out, err = _run([str(tmp_path / "missing")])
    assert code == 2 and out == "" and err.count("\n") == 1 and "does not exist" in err
    (tmp_path / "empty" / "someone").mkdir(parents=True)
    code, _, err = _run([str(tmp_path / "empty")])
    assert code == 2 and err.count("\n") == 1 and "no photos" in err
    code, _, err = _run([str(tmp_path / "empty"), "--embedders", "openface"])
    assert code == 2 and err.count("\n") == 1 and "--embedders" in err
    code, _, err = _run([str(tmp_path / "empty"), "--eye-px", "full,abc"])
    assert code == 2 and err.count("\n") == 1 and "--eye-px" in err
