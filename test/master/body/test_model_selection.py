"""Cross-validated choice of the body metric's parameters: candidates, identity folds, and choices that must
follow where the identity information lies."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_master.training.body.model_selection import (
    NoCrossCameraMatch,
    SearchGrid,
    dims_candidates,
    identity_folds,
    select_parameters,
)


def test_dims_candidates_fit_the_wire_budget() -> None:
    assert dims_candidates((16, 32, 64), 64) == ((16, 16), (16, 32), (32, 16), (32, 32))
    assert max(sum(p) for p in dims_candidates()) == 128
    with pytest.raises(ValueError, match="fits"):
        dims_candidates((64,), 100)


def test_identity_folds_partition_the_identities() -> None:
    labels = np.repeat(np.arange(9), 3)
    folds = identity_folds(labels, 3, np.random.default_rng(0))
    assert np.array_equal(np.sum(folds, axis=0), np.ones(27))  # every crop in exactly one fold
    for mask in folds:
        ids = set(labels[mask].tolist())
        assert len(ids) == 3 and not ids & set(labels[~mask].tolist())  # whole identities
    with pytest.raises(ValueError, match="identities"):
        identity_folds(labels, 5, np.random.default_rng(0))


def _scores(rng: np.random.Generator, people: int = 18, shots: int = 4) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """PCA-like scores: the hsv block's identity lies in its columns 2-3 (0-1 hold a large per-crop nuisance),
    the siltp block's in its column 0 (1-3 hold the nuisance)."""
    labels = np.repeat(np.arange(people), shots)
    ident = np.repeat(rng.normal(size=(people, 3)), shots, axis=0)
    hsv = np.hstack([rng.normal(0, 5, (labels.size, 2)), ident[:, :2] + rng.normal(0, 0.1, (labels.size, 2))])
    siltp = np.hstack([ident[:, 2:] + rng.normal(0, 0.1, (labels.size, 1)), rng.normal(0, 5, (labels.size, 3))])
    return {"hsv": hsv, "siltp": siltp}, labels


def test_selection_takes_the_components_that_hold_the_identity() -> None:
    scores, labels = _scores(np.random.default_rng(1))
    cameras = ["1", "2"] * (labels.size // 2)
    grid = SearchGrid(((2, 1), (4, 1), (2, 4)), regularisations=(1e-3, 1e-1), subspace_dims=(1, None))
    sel = select_parameters(scores, labels, cameras, grid, 3, np.random.default_rng(0))
    assert sel.pca_dims == {"hsv": 4, "siltp": 1}  # hsv needs 4 (its identity is in 2-3); siltp's is in 0
    assert set(sel.fused_by_dims) == {"hsv2_siltp1", "hsv4_siltp1", "hsv2_siltp4"}
    assert sel.fused_by_dims["hsv4_siltp1"] > sel.fused_by_dims["hsv2_siltp1"] + 0.3
    assert sel.xqda["fused"].rank1 == pytest.approx(sel.fused_by_dims["hsv4_siltp1"]) and sel.xqda["fused"].rank1 > 0.9
    assert sel.xqda["hsv"].max_dims is None  # r = 1 cannot hold 2 identity directions
    assert sel.kissme["siltp"].max_dims is None
    doc = sel.to_dict()
    assert doc["pca_dims"] == {"hsv": 4, "siltp": 1} and set(doc["xqda"]) == {"hsv", "siltp", "fused"}
    with pytest.raises(ValueError, match=r"scores\['hsv'\]"):
        select_parameters({"hsv": scores["hsv"][:, :3], "siltp": scores["siltp"]}, labels, cameras, grid, 3,
                          np.random.default_rng(0))


def test_search_grid_checks_its_values() -> None:
    with pytest.raises(ValueError, match="pca_dims"):
        SearchGrid(((4,),))
    with pytest.raises(ValueError, match="regularisations"):
        SearchGrid(((4, 4),), regularisations=(-1.0,))
    with pytest.raises(ValueError, match="subspace_dims"):
        SearchGrid(((4, 4),), subspace_dims=(0,))
    assert SearchGrid(((4, 8), (16, 2))).max_dims() == {"hsv": 16, "siltp": 8}


def test_selection_leaves_out_folds_without_a_cross_camera_match() -> None:
    scores, labels = _scores(np.random.default_rng(1))
    grid = SearchGrid(((2, 1),), regularisations=(1e-3,), subspace_dims=(None,))
    one_camera = ["1"] * labels.size
    with pytest.raises(NoCrossCameraMatch, match="no cross-validation fold has a person seen by two cameras"):
        select_parameters(scores, labels, one_camera, grid, 3, np.random.default_rng(0))
    # people 0-2 seen by cameras 1 and 2, 3-17 by camera 1 only: at least 3 of 6 folds hold none of 0-2
    cameras = [("1", "2")[k % 2] if p < 3 else "1" for k, p in enumerate(labels.tolist())]
    sel = select_parameters(scores, labels, cameras, grid, 6, np.random.default_rng(0))
    assert (sel.probes, sel.probes_without_match) == (3 * 4, 15 * 4)
    assert 3 <= len(sel.folds_skipped) < 6
    assert all(s.endswith(": none of its 3 people is seen by two cameras") for s in sel.folds_skipped)
    assert sel.to_dict()["folds_skipped"] == list(sel.folds_skipped)
