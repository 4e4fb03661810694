"""Crop folders: cameras from file names (Market-1501, MARS, PKU-Reid, cameras.csv) and the re-id splits."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from face_reid_master.training.body.crops import Crop, camera_of, list_crops, reid_splits, same_camera


@pytest.mark.parametrize(("name", "expected"), [
    ("0004_c3s3_065819_03.jpg", ("3", 0)),  # Market-1501
    ("-1_c1s1_000401_03.jpg", ("1", 0)),  # Market-1501 junk id
    ("0003C4T0003F010.jpg", ("4", 0)),  # MARS / DukeMTMC-VideoReID
    ("01_5.png", ("1", 5)),  # PKU-Reid: camera 01, orientation 5
    ("photo.jpg", ("", 0)),
])
def test_camera_from_file_name(name: str, expected: tuple[str, int]) -> None:
    assert camera_of(name) == expected


def test_list_crops_reads_folders_and_cameras_csv_overrides(tmp_path: Path) -> None:
    img = np.zeros((8, 4, 3), np.uint8)
    for ident, files in {"a": ["0001_c1s1_000001_00.jpg", "x.jpg"], "b": ["01_2.png"]}.items():
        (tmp_path / ident).mkdir()
        for f in files:
            cv2.imwrite(str(tmp_path / ident / f), img)
    (tmp_path / "cameras.csv").write_text("file,camera\na/x.jpg,7\n")
    crops = list_crops(tmp_path)
    assert [(c.identity, c.path.name, c.camera, c.orientation) for c in crops] == [
        ("a", "0001_c1s1_000001_00.jpg", "1", 0), ("a", "x.jpg", "7", 0), ("b", "01_2.png", "1", 2)]
    with pytest.raises(ValueError, match="crops folder"):
        list_crops(tmp_path / "missing")
    (tmp_path / "cameras.csv").write_text("name,cam\n")
    with pytest.raises(ValueError, match="file,camera"):
        list_crops(tmp_path)


def test_splits_keep_training_people_apart_and_probe_against_other_cameras() -> None:
    crops = [Crop(f"p{i}", Path(f"{i}_{c}_{k}"), str(c)) for i in range(10) for c in (1, 2) for k in range(3)]
    crops += [Crop("q", Path("q1"), ""), Crop("q", Path("q2"), ""), Crop("lone", Path("l"), "1")]
    splits = reid_splits(crops, 5, np.random.default_rng(0))
    assert len(splits) == 5
    for s in splits:
        train_ids = {crops[i].identity for i in s.train}
        test_ids = {crops[i].identity for i in np.concatenate([s.probe, s.gallery])}
        assert not train_ids & test_ids and len(train_ids) == 6  # half of 12 identities
        masked = same_camera(crops, s.probe, s.gallery)
        for row, p in enumerate(s.probe):
            same = [k for k, g in enumerate(s.gallery) if crops[g].identity == crops[p].identity]
            assert p not in s.gallery and any(not masked[row, k] for k in same)  # another camera's crop counts
            assert all(masked[row, k] == (crops[s.gallery[k]].camera == crops[p].camera != "")
                       for k in range(len(s.gallery)))
        assert {crops[i].identity for i in s.probe} <= test_ids - {"lone"}  # one crop: gallery only
    assert len({tuple(s.train) for s in splits}) > 1  # random
    with pytest.raises(ValueError, match="identities"):
        reid_splits(crops[:6], 1, np.random.default_rng(0))
