"""face-reid-fit-body end to end on generated crops: the three files, their round trip and provenance, the
metric ranking each person's own crops first, the same bytes twice, a kept projection and scenario clothes."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from face_reid_camera.body.projection import load_body_projection
from face_reid_master.body.metric_file import load_body_metric
from face_reid_master.sim.scenario_files import FORMAT_NAME, FORMAT_VERSION
from face_reid_master.tools.fit_body import main, scenario_clothes
from face_reid_master.training.body.crop_descriptors import describe_crops
from face_reid_master.training.body.crops import list_crops

FILES = ("body_projection.npz", "body_metric.json", "body_metric_fit.png")
EPOCH = "1767225600"  # 2026-01-01T00:00:00Z


def _person(shirt: np.ndarray, trousers: np.ndarray, stripes: np.ndarray | None, gain: float,
            rng: np.random.Generator) -> np.ndarray:
    """A 128x64 crop: grey background, skin head, shirt (striped or plain), trousers; a camera gain, a few
    pixels of shift and sensor noise."""
    img = np.full((128, 64, 3), 110.0)
    dx = int(rng.integers(-3, 4))
    img[4:24, 24 + dx:40 + dx] = (110, 150, 200)
    img[24:66, 14 + dx:50 + dx] = shirt
    if stripes is not None:
        for row in range(28, 66, 8):
            img[row:row + 4, 14 + dx:50 + dx] = stripes
    img[66:124, 18 + dx:46 + dx] = trousers
    return np.clip(img * gain + rng.normal(0, 5, img.shape), 0, 255).astype(np.uint8)


def _crops(root: Path, people: int = 12) -> Path:
    """Half PKU-Reid-style (``CC_O.png``), half Market-1501-style identities; 2 cameras x 3 crops each."""
    rng = np.random.default_rng(0)
    for pid in range(people):
        shirt, trousers = rng.integers(0, 256, 3), rng.integers(0, 256, 3)
        stripes = rng.integers(0, 256, 3) if pid % 2 else None
        name = f"pkureid_{pid:03d}" if pid < people // 2 else f"market1501_{pid:04d}"
        (root / name).mkdir(parents=True)
        for cam, gain in ((1, 1.0), (2, 0.75)):
            for k in range(3):
                file = f"{cam:02d}_{k + 1}.png" if name.startswith("pku") else f"{pid:04d}_c{cam}s1_{k:06d}_00.png"
                cv2.imwrite(str(root / name / file), _person(shirt, trousers, stripes, gain, rng))
    return root


@pytest.fixture(scope="module")
def crops_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _crops(tmp_path_factory.mktemp("bodies") / "crops")


@pytest.mark.slow
def test_fit_writes_the_projection_metric_and_plot_that_rank_each_person_first(
        crops_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", EPOCH)
    out = tmp_path / "models"
    assert main([str(crops_dir), "--out-dir", str(out), "--max-length", "32", "--quiet"]) == 0
    assert "32 float32 values per person (hsv 16, siltp 16)" in capsys.readouterr().out
    projection = load_body_projection(out / FILES[0])
    metric = load_body_metric(out / FILES[1])
    assert metric.space == projection.space
    assert metric.length == projection.length == 32 and (out / FILES[2]).stat().st_size > 10_000
    for meta in (projection.metadata, metric.metadata):
        assert (meta["n_identities"], meta["n_crops"]) == (12, 72)
        assert meta["fitted_utc"] == "2026-01-01T00:00:00+00:00"
        assert meta["command"] == (f"face-reid-fit-body {crops_dir.as_posix()} --max-length 32 --folds 3 "
                                   "--max-negative-pairs 20000 --seed 0")
        assert meta["by_source"] == {"market1501": {"identities": 6, "crops": 36},
                                     "pkureid": {"identities": 6, "crops": 36}}
        assert len(meta["identities"]) == 12 and len(meta["crops_sha256"]) == 64
    assert projection.metadata["pca_dims"] == {"hsv": 16, "siltp": 16}
    assert "cross-validation" in projection.metadata["pca_dims_chosen_by"]
    assert metric.metadata["projection"]["space"] == projection.space

    # the shipped files, as a camera and the master use them: each crop's nearest crop of the other camera is
    # its own person's, and same-person distances lie below the decision distance, different people above
    described = describe_crops(list_crops(crops_dir), projection.descriptor_config)
    wire = projection.project_many(described.features)
    labels, cams = described.labels, np.array(described.cameras)
    for name, f in metric.features.items():
        d = f.distances(wire, wire)
        d[cams[:, None] == cams[None, :]] = np.inf
        assert np.mean(labels[np.argmin(d, axis=1)] == labels) >= 0.9, name
        same, other = labels[:, None] == labels[None, :], labels[:, None] != labels[None, :]
        assert np.median(d[same & np.isfinite(d)]) < f.decision_distance < np.median(d[other & np.isfinite(d)]), name

    again = tmp_path / "again"
    assert main([str(crops_dir), "--out-dir", str(again), "--max-length", "32", "--quiet"]) == 0
    for name in FILES:  # same inputs and SOURCE_DATE_EPOCH: the same bytes
        assert (again / name).read_bytes() == (out / name).read_bytes(), name


def _scenario(path: Path, identities: list[dict]) -> Path:
    path.mkdir()
    (path / "scenario.json").write_text(json.dumps({"format": FORMAT_NAME, "version": FORMAT_VERSION,
                                                    "identities": identities}))
    return path


@pytest.mark.slow
def test_a_kept_projection_and_scenario_clothes_refit_only_the_metric(crops_dir: Path, tmp_path: Path) -> None:
    first = tmp_path / "first"
    assert main([str(crops_dir), "--out-dir", str(first), "--pca-dims", "hsv=6,siltp=5", "--quiet"]) == 0
    projection = load_body_projection(first / FILES[0])
    scenario = _scenario(tmp_path / "scenario", [
        {"name": "lfw_a", "clothes": {"1": "pkureid_001", "2": "market1501_0007"}},
        {"name": "lfw_b"},  # no body: nothing to exclude
    ])
    plain = _scenario(tmp_path / "plain", [{"name": "lfw_c"}])
    assert scenario_clothes([scenario, plain]) == {"pkureid_001", "market1501_0007"}
    refit = tmp_path / "refit"
    assert main([str(crops_dir), "--out-dir", str(refit), "--projection", str(first / FILES[0]),
                 "--exclude-scenario", str(scenario), "--exclude-scenario", str(plain), "--quiet"]) == 0
    assert not (refit / FILES[0]).exists()  # the cameras' projection is kept, not rewritten
    metric = load_body_metric(refit / FILES[1])
    assert metric.space == projection.space
    meta = metric.metadata
    assert meta["excluded"]["scenario_crop_identities"] == ["market1501_0007", "pkureid_001"]
    assert meta["n_identities"] == 10 and not {"pkureid_001", "market1501_0007"} & set(meta["identities"])
    assert meta["projection"]["sha256"] and meta["projection"]["file"].endswith(FILES[0])
    assert f"--exclude-scenario {scenario.as_posix()}" in meta["command"]
    assert meta["selection"]["pca_dims"] == {"hsv": 6, "siltp": 5}


def test_unusable_input_is_refused(crops_dir: Path, tmp_path: Path) -> None:
    assert main([str(tmp_path / "missing"), "--out-dir", str(tmp_path), "--quiet"]) == 2
    assert main([str(crops_dir), "--out-dir", str(tmp_path), "--exclude-scenario", str(crops_dir), "--quiet"]) == 2
    assert main([str(crops_dir), "--out-dir", str(tmp_path), "--projection", str(tmp_path / "none.npz"),
                 "--quiet"]) == 2
    assert main([str(crops_dir), "--out-dir", str(tmp_path), "--include", "pkureid_00[0-3]", "--quiet"]) == 2
    bad = _scenario(tmp_path / "bad", [{"name": "x", "clothes": {"1": 5}}])
    assert main([str(crops_dir), "--out-dir", str(tmp_path), "--exclude-scenario", str(bad), "--quiet"]) == 2
    with pytest.raises(SystemExit):
        main([str(crops_dir), "--projection", "p.npz", "--pca-dims", "hsv=4,siltp=4"])
    with pytest.raises(SystemExit):
        main([str(crops_dir), "--folds", "1"])
    assert not list(tmp_path.glob("*.json"))
