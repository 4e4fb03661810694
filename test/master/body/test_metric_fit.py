"""The body metric fit (XQDA per feature, distance unit, held-out likelihoods) and its file: round trip,
space check, missing and damaged files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from face_reid_camera.common.errors import ModelLoadError
from face_reid_master.body.metric_file import BodyMetricModel, load_body_metric, save_body_metric
from face_reid_master.training.body.metric_fit import fit_feature_metrics, pair_distances
from face_reid_master.training.body.model_selection import Choice, identity_folds


def test_pair_distances_take_every_same_person_pair_and_different_people_within_a_group() -> None:
    d = np.arange(16, dtype=float).reshape(4, 4)
    labels = np.array(["a", "a", "b", "c"])
    groups = np.array(["x", "x", "x", "y"])
    pos, neg = pair_distances(d, labels, groups, 10, np.random.default_rng(0))
    assert pos.tolist() == [1.0]  # (0, 1)
    assert sorted(neg.tolist()) == [2.0, 6.0]  # (0, 2), (1, 2); c is alone in group y
    _, few = pair_distances(d, labels, groups, 1, np.random.default_rng(0))
    assert few.size == 1 and few[0] in (2.0, 6.0)


def _wire(rng: np.random.Generator, people: int = 24, shots: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """12 wire values (hsv 0-7, siltp 8-11): identity in 3 + 2 directions, a large per-crop nuisance elsewhere."""
    labels = np.repeat([f"p{i:02d}" for i in range(people)], shots)
    wire = rng.normal(0, 3.0, (labels.size, 12))
    ident = np.repeat(rng.normal(size=(people, 5)), shots, axis=0)
    wire[:, [0, 1, 2, 8, 9]] = ident + rng.normal(0, 0.2, (labels.size, 5))
    return wire, labels


def _fit(wire: np.ndarray, labels: np.ndarray) -> BodyMetricModel:
    slices = {"hsv": slice(0, 8), "siltp": slice(8, 12)}
    choice = Choice(1e-3, None, 0.0, 0.0)
    folds = identity_folds(labels, 3, np.random.default_rng(0))
    fits = fit_feature_metrics(wire, labels, np.zeros(labels.size), slices, dict.fromkeys(("hsv", "siltp", "fused"),
                                                                                          choice),
                               folds, 5000, np.random.default_rng(1))
    for name, fit in fits.items():
        d = fit.metric.decision_distance
        # held-out same-person distances mostly below the N_p = N_n crossing, different people above
        assert np.mean(fit.positive < d) > 0.8 and np.mean(fit.negative > d) > 0.8, name
        assert fit.positive.size == 24 * 10  # every same-person pair, each in its held-out fold
    return BodyMetricModel("body_pca_test", 12, (("hsv", 0, 8), ("siltp", 8, 12)),
                           {n: f.metric for n, f in fits.items()}, {"note": "test"})


def test_fitted_metric_ranks_the_same_person_first_in_units_of_a_stranger(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    wire, labels = _wire(rng)
    model = _fit(wire, labels)
    fused = model.features["fused"]
    assert fused.columns.tolist() == list(range(12)) and model.features["siltp"].columns.tolist() == [8, 9, 10, 11]
    d = fused.distances(wire, wire)
    same = labels[:, None] == labels[None, :]
    off = ~np.eye(labels.size, dtype=bool)
    assert np.median(d[~same]) == pytest.approx(1.0, rel=0.05)  # the unit: a typical stranger
    assert np.median(d[same & off]) < 0.5
    # new people (not fitted on): the nearest other crop is nearly always the same person's
    new, new_labels = _wire(rng, people=10)
    dn = fused.distances(new, new) + np.diag(np.full(new_labels.size, np.inf))
    assert np.mean(new_labels[np.argmin(dn, axis=1)] == new_labels) > 0.9
    assert fused.parameters["held_out_pairs"]["positive"] == 240

    path = save_body_metric(model, tmp_path / "m.json")
    loaded = load_body_metric(path)
    assert loaded.space == "body_pca_test" and loaded.length == 12 and loaded.metadata == {"note": "test"}
    for name, f in model.features.items():
        g = loaded.features[name]
        np.testing.assert_allclose(g.distances(new, new), f.distances(new, new), rtol=1e-6, atol=1e-6)
        assert g.decision_distance == pytest.approx(f.decision_distance, rel=1e-9)
        assert g.parameters == json.loads(json.dumps(f.parameters))
    assert save_body_metric(loaded, tmp_path / "again.json").read_bytes() == path.read_bytes()  # same model, bytes
    assert loaded.space == "body_pca_test"


def test_missing_and_damaged_metric_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="face-reid-fit-body"):
        load_body_metric(tmp_path / "none.json")
    wire, labels = _wire(np.random.default_rng(3))
    good = save_body_metric(_fit(wire, labels), tmp_path / "good.json")
    doc = json.loads(good.read_text())

    def broken(name: str, text: str) -> Path:
        p = tmp_path / name
        p.write_text(text)
        return p

    truncated = broken("truncated.json", good.read_text()[:500])
    other = broken("other.json", json.dumps({**doc, "format": "face_reid_likelihood/2"}))
    no_fused = broken("no_fused.json", json.dumps({**doc, "features": {k: v for k, v in doc["features"].items()
                                                                       if k != "fused"}}))
    bad_w = json.loads(json.dumps(doc))
    bad_w["features"]["hsv"]["W"] = bad_w["features"]["hsv"]["W"][:-1]  # 7 rows for 8 columns
    shape = broken("shape.json", json.dumps(bad_w))
    moved = json.loads(json.dumps(doc))
    moved["features"]["siltp"]["decision_distance"] += 0.1
    crossing = broken("crossing.json", json.dumps(moved))
    for path, reason in ((truncated, "Expecting|Unterminated"), (other, "not a face-reid-body-metric"),
                         (no_fused, "fused"), (shape, "columns"), (crossing, "decision_distance")):
        with pytest.raises(ModelLoadError, match=f"{path.name} is unusable: .*({reason})"):
            load_body_metric(path)
