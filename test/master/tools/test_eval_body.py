"""face-reid-eval-body on a small generated crops folder: the JSON report and the exit status."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from face_reid_master.tools.eval_body import main


def _crops(root: Path) -> None:
    """8 people (shirt / trousers colours) x 2 cameras (a light change) x 2 crops, Market-1501 names."""
    rng = np.random.default_rng(0)
    for pid in range(8):
        shirt, trousers = rng.integers(0, 256, 3), rng.integers(0, 256, 3)
        folder = root / f"p{pid}"
        folder.mkdir(parents=True)
        for cam, gain in ((1, 1.0), (2, 0.8)):
            for k in range(2):
                img = np.zeros((128, 64, 3))
                img[:60], img[60:] = shirt, trousers
                img = np.clip(img * gain + rng.normal(0, 6, img.shape), 0, 255).astype(np.uint8)
                cv2.imwrite(str(folder / f"{pid:04d}_c{cam}s1_{k:06d}_00.jpg"), img)


def test_eval_body_reports_every_feature_and_metric(tmp_path: Path, capsys) -> None:
    _crops(tmp_path / "crops")
    out = tmp_path / "r.json"
    assert main([str(tmp_path / "crops"), "--splits", "2", "--quiet", "--out", str(out),
                 "--plot", str(tmp_path / "cmc.png")]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads(out.read_text())
    assert (printed["crops"], printed["identities"], printed["crops_with_camera"]) == (32, 8, 32)
    assert set(printed["results"]) == {"hsv", "siltp", "fused"}
    for by_method in printed["results"].values():
        assert set(by_method) == {"euclidean", "kissme", "xqda"}
    assert printed["results"]["hsv"]["euclidean"]["rank5"] > 0.7  # distinct colours: easy
    assert (tmp_path / "cmc.png").stat().st_size > 1000
    assert main([str(tmp_path / "missing"), "--quiet"]) == 2
    assert main([str(tmp_path / "crops"), "--splits", "0", "--quiet"]) == 2
