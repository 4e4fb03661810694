"""Camera-true simulator: a face or a body never shows more pixels than the camera's geometry gives.

Faces: each observation's photo is down-sampled to the eye distance the colour focal length, the range and the
face's angle give, re-detected and re-embedded with the real models (cached per photo, change and eye level).
Bodies: a crop is described at no more rows than the person spans in the colour image. On the licensed fixture
faces, small scenarios."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import copy_fixture_faces

from face_reid_camera.body.descriptor import body_descriptor
from face_reid_camera.body.projection import BodyProjection, fit_pca_block
from face_reid_master.sim.bodies import BodyBank, BodySimConfig, BodyWorld, feature_bodies, make_measures
from face_reid_master.sim.feature_level import EYE_DISTANCE_M, KINECT_FX_PX
from face_reid_master.sim.photos import (
    EYE_LEVEL_STEP,
    MIN_EYE_PX,
    NATIVE_LEVEL,
    TOO_SMALL_LEVEL,
    PhotoBank,
    eye_level,
    level_eye_px,
)
from face_reid_master.sim.scenario_files import load_scenario, write_scenario
from face_reid_master.sim.simulate import SimConfig, simulate
from face_reid_master.sim.world import make_world

IDENTITIES = ("lfw_Colin_Powell", "lfw_Tony_Blair", "deepface_id02")


@pytest.fixture(scope="module")
def faces(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return copy_fixture_faces(tmp_path_factory.mktemp("faces"), IDENTITIES, 3)


def test_no_face_shows_more_eye_pixels_than_the_geometry_gives(faces: Path, tmp_path: Path) -> None:
    """Every face observation of a small scenario (640x480 colour): the eye distance its embedding shows is at
    most focal x IPD / range (range >= the horizontal distance from the camera to the true position, ground truth
    at 100 Hz), within a pixel; the fixture photos (40-60 px between the eyes) are all reduced, and scenario.json
    records what the camera gave."""
    cfg = SimConfig(num_people=3, num_cameras=2, duration_s=20.0, seed=4, embedder="dlib", ground_truth_rate_hz=100.0)
    write_scenario(simulate(faces, cfg, cache_path=tmp_path / "cache.npz"), tmp_path / "S")
    s = load_scenario(tmp_path / "S")
    g = s.ground_truth
    cams = {c.camera_id: c for c in s.cameras}
    shown, bound = [], []
    for f, gts in zip(s.frames, s.frame_gt_ids, strict=True):
        for p, gt in zip(f.people, gts, strict=True):
            if p.embedding is None:
                continue
            xy = np.array([np.interp(f.stamp_s, g.t_s, g.xy[int(gt), :, k]) for k in range(2)])
            horizontal = float(np.linalg.norm(xy - cams[f.camera_id].position[:2]))
            shown.append(p.face_eye_distance_px)
            bound.append(KINECT_FX_PX * EYE_DISTANCE_M / horizontal)
    shown_a, bound_a = np.array(shown), np.array(bound)
    assert shown_a.size > 50
    assert np.all(shown_a <= bound_a + 1.0), np.max(shown_a - bound_a)
    assert np.all(shown_a >= MIN_EYE_PX) and np.median(shown_a) < 20.0
    record = s.document["summary"]["camera_true"]
    assert record["camera_true"] is True and record["focal_px"] == KINECT_FX_PX
    assert record["face_eye_px_shown"]["median"] <= record["face_eye_px_geometry"]["median"]
    assert record["faces_at_photo_size"] == 0.0 and 0.0 < record["faces_redetected"] <= 1.0


def test_eye_levels_never_exceed_the_eye_distance_and_never_enlarge() -> None:
    eye = np.array([2.0, 3.0, 5.5, 9.49, 17.0, 41.0, 80.0])
    native = np.full(eye.size, 42.0)
    levels = eye_level(eye, native)
    shown = level_eye_px(levels, native)
    assert levels[0] == TOO_SMALL_LEVEL and shown[0] == 0.0
    assert levels[-1] == NATIVE_LEVEL and shown[-1] == 42.0  # the photo's own size, never enlarged
    ok = levels != TOO_SMALL_LEVEL
    assert np.all(shown[ok] <= eye[ok] + 1e-9)
    reduced = levels >= 0  # down-sampled: at most one EYE_LEVEL_STEP below the geometry's eye distance
    assert reduced.sum() == 5 and np.all(shown[reduced] >= eye[reduced] / EYE_LEVEL_STEP - 1e-9)


def test_camera_views_are_real_reduced_embeddings_and_cached(faces: Path, tmp_path: Path) -> None:
    """A view at 8 px between the eyes is re-embedded by the real models and differs from the photo's own
    embedding (the down-sampling really happens); asking again, or from a new bank on the saved cache, hits the
    cache without loading any model."""
    cache = tmp_path / "cache.npz"
    bank = PhotoBank(faces, cache, embedder="dlib", variants=False)
    ident = bank.load_identity(IDENTITIES[0])
    assert ident is not None
    photo = ident.photos[0]
    assert photo.eye_px > 30 and photo.landmarks is not None
    level = int(eye_level(np.array([8.0]), np.array([photo.eye_px]))[0])
    small, _ = bank.camera_view(photo, 0, level)
    native = photo.embeddings[0]
    assert small.shape == native.shape and np.all(np.isfinite(small))
    assert np.linalg.norm(small - native) > 0.1  # dlib: same person, other pixels
    assert np.linalg.norm(small - native) < 0.8
    assert (bank.view_stats.made, bank.view_stats.cached) == (1, 0)
    again, _ = bank.camera_view(photo, 0, level)
    assert np.array_equal(again, small) and (bank.view_stats.made, bank.view_stats.cached) == (1, 1)
    nearer, _ = bank.camera_view(photo, 0, int(eye_level(np.array([20.0]), np.array([photo.eye_px]))[0]))
    assert np.linalg.norm(nearer - native) < np.linalg.norm(small - native)
    bank.save_cache()
    fresh = PhotoBank(faces, cache, embedder="dlib", variants=False)
    photo2 = fresh.load_identity(IDENTITIES[0]).photos[0]  # type: ignore[union-attr]
    cached, _ = fresh.camera_view(photo2, 0, level)
    assert np.array_equal(cached, small) and fresh.view_stats.made == 0 and fresh._embedder is None


def _crops(root: Path) -> Path:
    rng = np.random.default_rng(1)
    for i in range(3):
        (root / f"id_{i}").mkdir(parents=True)
        for j in range(2):
            crop = rng.integers(0, 256, size=(128, 48, 3)).astype(np.uint8)
            crop[20:70, 12:36] = rng.integers(0, 256, 3)
            cv2.imwrite(str(root / f"id_{i}" / f"{j}.png"), crop)
    return root


def test_no_body_crop_is_described_taller_than_the_person_spans(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """One person in front of a camera at 2-6 m, colour focal lengths of 525 and 50 px: every crop is described at
    no more rows than focal x height / range (and never more than its own 128)."""
    root = _crops(tmp_path / "crops")
    descs = [body_descriptor(cv2.imread(str(p))) for p in sorted(root.glob("*/*.png"))]
    projection = BodyProjection((fit_pca_block("hsv", np.array([d.hsv for d in descs]), 3),
                                 fit_pca_block("siltp", np.array([d.siltp for d in descs]), 3)))
    bank = BodyBank(root, projection)
    clothes = bank.choose(1, np.random.default_rng(0))[0]
    cfg = BodySimConfig(min_visible_fraction=0.0)
    heights = np.array([1.7])
    bodies = BodyWorld(bank, cfg, {(0, 1): clothes}, make_measures(heights, np.random.default_rng(0)),
                       np.ones((1, 3)))
    camera = make_world(1, np.random.default_rng(0)).cameras[0]
    yaw = camera.xyz_rpy[5]
    rows_seen: list[int] = []
    original = BodyBank.descriptor

    def spy(self: BodyBank, index: int, gains: np.ndarray, light_key: tuple[int, ...], bands_seen: int, bands: int,
            rows: int, silhouette: float, variant: int = 0) -> np.ndarray:
        rows_seen.append(rows)
        return original(self, index, gains, light_key, bands_seen, bands, rows, silhouette, variant)

    monkeypatch.setattr(BodyBank, "descriptor", spy)
    checked = 0
    for focal in (KINECT_FX_PX, 50.0):
        for range_m in (2.0, 3.0, 4.5, 6.0):
            xy = (camera.position[:2] + range_m * np.array([np.cos(yaw), np.sin(yaw)]))[None, None, :]
            facing = np.array([[yaw + np.pi]])
            rows_seen.clear()
            rows = feature_bodies(bodies, camera, 0, 1, [0], np.zeros(1), xy, facing, heights, np.ones((1, 1), bool),
                                  np.ones((1, 1), bool), np.array([0]), np.array([0]), heights,
                                  np.full((1, 1), range_m), focal, 0.5, np.random.default_rng(2))
            assert rows.described.all() and len(rows_seen) == 1
            assert rows_seen[0] <= min(focal * heights[0] / range_m, 128)
            checked += 1
    assert checked == 8
