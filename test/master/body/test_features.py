"""Body features on the wire (columns per feature, fused raw vectors, the PCA projection, --pca-dims) and the
crop filter."""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np
import pytest

from face_reid_camera.body.descriptor import body_descriptor
from face_reid_master.body.features import (
    feature_blocks,
    feature_columns,
    fit_projection,
    parse_pca_dims,
    raw_feature,
)
from face_reid_master.training.body.crop_descriptors import describe_crops
from face_reid_master.training.body.crops import Crop, filter_crops, list_crops


def test_feature_columns_read_their_blocks_of_the_wire_vector() -> None:
    slices = {"hsv": slice(0, 3), "siltp": slice(3, 5)}
    assert feature_columns(slices, "hsv").tolist() == [0, 1, 2]
    assert feature_columns(slices, "siltp").tolist() == [3, 4]
    assert feature_columns(slices, "fused").tolist() == [0, 1, 2, 3, 4]
    assert feature_blocks("fused") == ("hsv", "siltp")
    with pytest.raises(ValueError, match="feature must be one of"):
        feature_blocks("geometry")
    with pytest.raises(ValueError, match="siltp"):
        feature_columns({"hsv": slice(0, 3)}, "fused")


def test_raw_fused_vectors_stay_unit_length_and_the_projection_is_pca_per_block() -> None:
    rng = np.random.default_rng(0)
    feats = {"hsv": rng.normal(size=(20, 2048)), "siltp": rng.normal(size=(20, 648))}
    for name in feats:
        feats[name] /= np.linalg.norm(feats[name], axis=1, keepdims=True)
    fused = raw_feature(feats, "fused")
    assert fused.shape == (20, 2696) and np.allclose(np.linalg.norm(fused, axis=1), 1.0)
    assert np.array_equal(raw_feature(feats, "siltp"), feats["siltp"])
    projection = fit_projection(feats, {"hsv": 5, "siltp": 3})
    assert [(b.name, b.output_dim) for b in projection.blocks] == [("hsv", 5), ("siltp", 3)]
    wire = projection.project_many(feats)
    assert wire.shape == (20, 8)
    centred = feats["hsv"] - feats["hsv"].mean(axis=0)
    top = np.linalg.svd(centred, compute_uv=False)[:5]  # PCA keeps the largest singular values, in order
    np.testing.assert_allclose(np.linalg.norm(wire[:, :5], axis=0), top, rtol=1e-4)
    with pytest.raises(ValueError, match="dims"):
        fit_projection(feats, {"hsv": 5})


@pytest.mark.parametrize(("text", "match"), [
    ("hsv=64", "each of"), ("hsv=64,siltp=x", "integer"), ("hsv=0,siltp=4", ">= 1"), ("64,64", "like"),
    ("hsv=4,hsv=4", "like"), ("rgb=4,siltp=4", "like")])
def test_pca_dims_option(text: str, match: str) -> None:
    assert parse_pca_dims(" hsv=64, siltp=32") == {"hsv": 64, "siltp": 32}
    with pytest.raises(ValueError, match=match):
        parse_pca_dims(text)


def test_filter_crops_by_globs_and_names() -> None:
    crops = [Crop(n, Path(f"{n}.jpg")) for n in ("pkureid_001", "pkureid_002", "market1501_0001", "x")]
    assert [c.identity for c in filter_crops(crops, ["pkureid_*"])] == ["pkureid_001", "pkureid_002"]
    assert [c.identity for c in filter_crops(crops, ["pkureid_*", "x"], ["*_002"])] == ["pkureid_001", "x"]
    assert [c.identity for c in filter_crops(crops, exclude_identities={"x", "pkureid_001"})] == [
        "pkureid_002", "market1501_0001"]
    with pytest.raises(ValueError, match="no crop left"):
        filter_crops(crops, ["duke_*"])
    with pytest.raises(ValueError, match="include"):
        filter_crops(crops, "pkureid_*")


def test_crops_are_described_by_the_camera_code_and_unreadable_ones_skipped(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    images = {}
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        images[name] = rng.integers(0, 256, (128, 64, 3), dtype=np.uint8)
        cv2.imwrite(str(tmp_path / name / "0001_c1s1_000001_00.png"), images[name])
    (tmp_path / "b" / "0001_c2s1_000002_00.png").write_bytes(b"not an image")
    log = io.StringIO()
    described = describe_crops(list_crops(tmp_path), log=log)
    assert [c.identity for c in described.crops] == ["a", "b"] and described.labels.tolist() == ["a", "b"]
    assert described.cameras == ["1", "1"] and [p.name for p in described.skipped] == ["0001_c2s1_000002_00.png"]
    assert "skipped" in log.getvalue() and "100% (3/3)" in log.getvalue()
    for k, name in enumerate(("a", "b")):
        person = np.zeros((128, 64), bool)
        person[:, 16:48] = True  # the central half of the columns stands in for the camera's depth mask
        d = body_descriptor(images[name], person)
        assert np.array_equal(described.features["hsv"][k], d.hsv) and np.array_equal(described.features["siltp"][k],
                                                                                       d.siltp)
        assert not np.array_equal(d.hsv, body_descriptor(images[name]).hsv)
    every_pixel = describe_crops(list_crops(tmp_path), silhouette=1.0)
    assert np.array_equal(every_pixel.features["hsv"][0], body_descriptor(images["a"]).hsv)
    (tmp_path / "a" / "0001_c1s1_000001_00.png").write_bytes(b"")
    (tmp_path / "b" / "0001_c1s1_000001_00.png").write_bytes(b"")
    with pytest.raises(ValueError, match="no crop could be read"):
        describe_crops(list_crops(tmp_path))
