"""face-reid-eval-body: the JSON report and exit status on generated crops, and the PCA-then-metric evaluation
(projection fitted on the training people only, learned metrics against a nuisance that fools Euclidean)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from face_reid_master.tools import eval_body
from face_reid_master.tools.eval_body import METHODS, evaluate, main
from face_reid_master.training.body.model_selection import SearchGrid


def _crops(root: Path, people: int = 12) -> None:
    """``people`` (shirt / trousers colours) x 2 cameras (a light change) x 2 crops, Market-1501 names; one
    identity folder 'other_x' too."""
    rng = np.random.default_rng(0)
    for pid in range(people):
        shirt, trousers = rng.integers(0, 256, 3), rng.integers(0, 256, 3)
        folder = root / (f"p{pid:02d}" if pid else "other_x")
        folder.mkdir(parents=True)
        for cam, gain in ((1, 1.0), (2, 0.8)):
            for k in range(2):
                img = np.zeros((128, 64, 3))
                img[:60], img[60:] = shirt, trousers
                img = np.clip(img * gain + rng.normal(0, 6, img.shape), 0, 255).astype(np.uint8)
                cv2.imwrite(str(folder / f"{pid:04d}_c{cam}s1_{k:06d}_00.jpg"), img)


def test_eval_body_reports_every_feature_and_method(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _crops(tmp_path / "crops")
    out = tmp_path / "r.json"
    assert main([str(tmp_path / "crops"), "--include", "p*", "--splits", "2", "--quiet", "--out", str(out),
                 "--pca-dims", "hsv=6,siltp=4", "--folds", "2", "--plot", str(tmp_path / "cmc.png")]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads(out.read_text())
    assert (printed["crops"], printed["identities"], printed["crops_with_camera"]) == (44, 11, 44)  # 'other_x' out
    assert set(printed["results"]) == {"hsv", "siltp", "fused"}
    for by_method in printed["results"].values():
        assert tuple(by_method) == METHODS
    assert printed["results"]["hsv"]["euclidean_raw"]["rank5"] > 0.7  # distinct colours: easy
    assert printed["feature_dims"] == {"hsv": 2048, "siltp": 648, "fused": 2696}
    hp = printed["hyperparameters"]
    assert hp["chosen_counts"]["pca_dims"] == {"hsv6_siltp4": 2} and len(hp["per_split"]) == 2
    assert hp["per_split"][0]["pca_dims"] == {"hsv": 6, "siltp": 4}
    assert (tmp_path / "cmc.png").stat().st_size > 1000
    assert main([str(tmp_path / "missing"), "--quiet"]) == 2
    assert main([str(tmp_path / "crops"), "--splits", "0", "--quiet"]) == 2
    assert main([str(tmp_path / "crops"), "--include", "nobody_*", "--quiet"]) == 2
    assert main([str(tmp_path / "crops"), "--pca-dims", "hsv=6", "--quiet"]) == 2


def _nuisance_features(rng: np.random.Generator, people: int = 24, shots: int = 6
                       ) -> tuple[dict[str, np.ndarray], np.ndarray, list[str]]:
    """Descriptor-sized vectors: per block, identity in 6 directions (spread 1, 0.15 within a person) and a
    per-crop nuisance 4x larger in 4 other directions; 2 cameras."""
    labels = np.repeat([f"id{i:02d}" for i in range(people)], shots)
    features = {}
    for name, dim in (("hsv", 2048), ("siltp", 648)):
        x = np.zeros((labels.size, dim))
        x[:, :6] = np.repeat(rng.normal(size=(people, 6)), shots, axis=0) + rng.normal(0, 0.15, (labels.size, 6))
        x[:, 6:10] = rng.normal(0, 4.0, (labels.size, 4))
        x[:, 10:40] = rng.normal(0, 0.05, (labels.size, 30))
        features[name] = x
    cameras = ["1", "2"] * (labels.size // 2)
    return features, labels, cameras


def test_pca_then_metric_evaluation_fits_on_training_people_and_beats_euclidean(
        monkeypatch: pytest.MonkeyPatch) -> None:
    features, labels, cameras = _nuisance_features(np.random.default_rng(3))
    fitted_rows = []
    real_fit = eval_body.fit_projection

    def spy(train_features, dims, *args, **kwargs):
        fitted_rows.append(len(train_features["hsv"]))
        return real_fit(train_features, dims, *args, **kwargs)

    monkeypatch.setattr(eval_body, "fit_projection", spy)
    grid = SearchGrid(((4, 4), (10, 10)), regularisations=(1e-3,), subspace_dims=(None,))
    results, selections, _ = evaluate(features, labels, cameras, n_splits=2, seed=0, grid=grid, folds=3)
    assert set(fitted_rows) == {12 * 6}  # half of the 24 people: the projection never sees a test person
    # 4 components hold the nuisance (the largest variance) only: cross-validation must take 10
    assert all(s["pca_dims"] == {"hsv": 10, "siltp": 10} for s in selections)
    assert all(s["xqda_subspace_dims"]["hsv"] == 6 for s in selections)  # the identity's 6 directions, no more
    for name in ("hsv", "siltp", "fused"):
        r = results[name]
        assert r["xqda"]["rank1"] >= 0.9 and r["kissme"]["rank1"] >= 0.9, (name, r)
        assert r["euclidean_raw"]["rank1"] < 0.6 and r["euclidean_pca"]["rank1"] < 0.6, (name, r)
        assert r["xqda"]["map"] > r["euclidean_raw"]["map"] + 0.3


def _mars_crops(root: Path, cameras_per_person: list[int], shots: int = 3) -> None:
    """One identity folder per entry, seen by that many cameras (a light change each), ``shots`` crops per
    camera, MARS names (``0003C4T0003F010.jpg``)."""
    rng = np.random.default_rng(0)
    for pid, n_cams in enumerate(cameras_per_person, start=1):
        shirt, trousers = rng.integers(0, 256, 3), rng.integers(0, 256, 3)
        folder = root / f"mars_{pid:04d}"
        folder.mkdir(parents=True)
        for cam in range(1, n_cams + 1):
            for k in range(shots):
                img = np.zeros((128, 64, 3))
                img[:60], img[60:] = shirt, trousers
                img = np.clip(img * (1.0 - 0.1 * cam) + rng.normal(0, 6, img.shape), 0, 255).astype(np.uint8)
                cv2.imwrite(str(folder / f"{pid:04d}C{cam}T{cam:04d}F{k:03d}.jpg"), img)


# 4 people seen by 2-3 cameras, 8 by one camera only: some folds / splits hold no person another camera saw
MIXED_CAMERAS = [2, 3, 2, 3, 1, 1, 1, 1, 1, 1, 1, 1]


def _run(crops: Path, seed: int, capsys: pytest.CaptureFixture[str]) -> dict:
    assert main([str(crops), "--splits", "3", "--seed", str(seed), "--pca-dims", "hsv=6,siltp=4", "--quiet"]) == 0
    return json.loads(capsys.readouterr().out)


def test_eval_body_leaves_out_and_counts_folds_without_a_cross_camera_match(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Seed 2: one cross-validation fold of every split holds two one-camera people only (the old code stopped
    with 'fold 3 of 3: no probe's person is in the gallery')."""
    _mars_crops(tmp_path / "crops", MIXED_CAMERAS)
    r = _run(tmp_path / "crops", 2, capsys)
    left = r["left_out"]
    assert (left["identities_not_seen_by_two_cameras"], left["splits_evaluated"], left["splits_skipped"]) == (8, 3, [])
    per_split = r["hyperparameters"]["per_split"]
    assert [s["folds_skipped"] for s in per_split] == [
        ["fold 3 of 3: none of its 2 people is seen by two cameras"],
        ["fold 1 of 3: none of its 2 people is seen by two cameras"],
        ["fold 3 of 3: none of its 2 people is seen by two cameras"]]
    assert left["cv_folds_skipped"] == 3
    # every one-camera training person's 3 crops are no probe: 4 such people per split
    assert [s["cv_probes_without_match"] for s in per_split] == [12, 12, 12] and left["cv_probes_without_match"] == 36
    assert [s["cv_probes"] for s in per_split] == [12, 15, 18]  # the 2-3 camera people's crops are scored
    assert left["test_probes_without_match"] == 0
    fused = r["results"]["fused"]
    assert all(m["probes_per_split"] == 2.0 for m in fused.values())  # the 2 test people seen by two cameras
    assert r["results"]["hsv"]["euclidean_raw"]["rank1"] == 1.0  # distinct colours


def test_eval_body_leaves_out_a_split_without_probes_and_fails_only_when_nothing_is_left(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Seed 4: split 2's test people are all seen by one camera (the old code: 'no probe's person is in the
    gallery'); rank-1 averages the 2 other splits. A folder of one-camera people only: a clear error."""
    _mars_crops(tmp_path / "crops", MIXED_CAMERAS)
    r = _run(tmp_path / "crops", 4, capsys)
    left = r["left_out"]
    assert left["splits_skipped"] == [{"split": 2, "reason": "no test person is seen by two cameras"}]
    assert left["splits_evaluated"] == 2 and len(r["hyperparameters"]["per_split"]) == 2
    assert left["cv_folds_skipped"] == 1
    # a left-out split counted as a miss would give 2/3
    assert r["results"]["hsv"]["euclidean_raw"]["rank1"] == 1.0
    assert r["results"]["hsv"]["euclidean_raw"]["probes_per_split"] == 1.0
    _mars_crops(tmp_path / "single", [1] * 8)
    assert main([str(tmp_path / "single"), "--splits", "2", "--pca-dims", "hsv=6,siltp=4", "--quiet"]) == 2
    assert ("error: no person is seen by two cameras (8 identities, each seen by one camera or in one crop): "
            "nothing to evaluate") in capsys.readouterr().err
