"""The per-frame camera pipeline on rendered scenes with real faces and on real Kinect frames."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from conftest import DATA_DIR

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.faces.detector import YuNetDetector
from face_reid_camera.faces.embedder import FaceEmbedder
from face_reid_camera.pipeline import (
    CameraPipeline,
    CameraPipelineConfig,
    FaceQualityConfig,
    face_pose_from_landmarks,
    face_quality,
)
from face_reid_master.sim.renderer import SyntheticPerson, crop_face_for_rendering, render_scene

DATA = DATA_DIR
INTR = CameraIntrinsics.kinect_default()
POSE = CameraPose.from_xyz_rpy(0.0, 0.0, 2.2, 0.0, 0.3, 0.0)
IDS = ["lfw_Tony_Blair", "lfw_Colin_Powell", "lfw_Hugo_Chavez"]


@pytest.fixture(scope="module")
def models() -> tuple[YuNetDetector, FaceEmbedder]:
    return YuNetDetector(), FaceEmbedder()


@pytest.fixture(scope="module")
def faces(models: tuple[YuNetDetector, FaceEmbedder]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """identity -> (face crop for rendering, embedding of the source photo)."""
    detector, embedder = models
    out = {}
    for ident in IDS:
        photo = cv2.imread(str(sorted((DATA / "faces" / ident).glob("*.jpg"))[0]))
        best = max(detector.detect(photo), key=lambda d: float(d.box_xywh[2] * d.box_xywh[3]))
        out[ident] = (crop_face_for_rendering(photo, best.box_xywh), embedder.embed_faces(photo, [best.landmarks])[0])
    return out


def _depth_m(depth_mm: np.ndarray) -> np.ndarray:
    return np.where(depth_mm > 0, depth_mm / 1000.0, np.nan).astype(np.float32)


def test_people_faces_and_identities(models, faces) -> None:
    spots = [(2.3, -0.9), (2.7, 0.0), (2.4, 0.9)]
    people = [
        SyntheticPerson(x, y, 1.75, math.atan2(-y, -x), faces[ident][0])
        for (x, y), ident in zip(spots, IDS, strict=True)
    ]
    people.append(SyntheticPerson(3.6, -0.45, 1.8, 0.0))  # facing away: a person without a face
    frame = render_scene(people, INTR, POSE, rng=np.random.default_rng(1))
    pipeline = CameraPipeline(CameraPipelineConfig(camera_id="c"), POSE, *models)
    result = pipeline.process(frame.rgb_bgr, _depth_m(frame.depth_mm), INTR)
    assert result.ground_plane_found
    assert len(result.people) == 4
    truth = np.array([[p.x_m, p.y_m] for p in people])
    for obs in result.people:
        i = int(np.argmin(np.linalg.norm(truth - obs.position_world[:2], axis=1)))
        assert np.linalg.norm(truth[i] - obs.position_world[:2]) < 0.15
        assert abs(obs.position_world[2]) < 0.05  # on the floor
        assert obs.height_m == pytest.approx(people[i].height_m, abs=0.08)
        if i < 3:
            assert obs.face is not None, f"no face for {IDS[i]}"
            assert obs.face.embedding.shape == (128,) and obs.face.embedding.dtype == np.float32
            refs = np.stack([faces[ident][1] for ident in IDS])
            assert int(np.argmin(np.linalg.norm(refs - obs.face.embedding, axis=1))) == i
            x, y, w, _h = obs.head_roi_xywh
            bx, by, bw, _bh = obs.face.detection.box_xywh
            assert x - 4 <= bx and bx + bw <= x + w + 4 and y - 4 <= by  # the face is in the head ROI
            assert 0 < obs.face.quality <= 1
        else:
            assert obs.face is None
    assert result.num_faces == 3
    assert set(result.timings_ms) >= {"people_ms", "face_detect_ms", "embed_ms", "total_ms"}


def test_face_budget_goes_to_the_nearest_people(models, faces) -> None:
    people = [
        SyntheticPerson(2.2, -0.6, 1.75, math.atan2(0.6, -2.2), faces[IDS[0]][0]),
        SyntheticPerson(3.4, 0.8, 1.75, math.atan2(-0.8, -3.4), faces[IDS[1]][0]),
    ]
    frame = render_scene(people, INTR, POSE, rng=np.random.default_rng(2))
    pipeline = CameraPipeline(CameraPipelineConfig(max_faces_per_frame=1), POSE, *models)
    result = pipeline.process(frame.rgb_bgr, _depth_m(frame.depth_mm), INTR)
    with_face = [p for p in result.people if p.face is not None]
    assert len(result.people) == 2 and len(with_face) == 1
    assert with_face[0].position_world[0] < 2.8


def test_embedding_budget_refreshes_every_face_in_turn(models, faces) -> None:
    """A budget of one face per frame: all three faces are found every frame; the first frame (cost not yet
    measured) embeds all, then each face is embedded every third frame."""
    spots = [(2.3, -0.9), (2.7, 0.0), (2.4, 0.9)]
    people = [SyntheticPerson(x, y, 1.75, math.atan2(-y, -x), faces[ident][0])
              for (x, y), ident in zip(spots, IDS, strict=True)]
    frame = render_scene(people, INTR, POSE, rng=np.random.default_rng(1))
    pipeline = CameraPipeline(CameraPipelineConfig(camera_id="c", embed_budget_ms=1e-3), POSE, *models)
    embedded_at: dict[int, list[int]] = {0: [], 1: [], 2: []}
    truth = np.array([[p.x_m, p.y_m] for p in people])
    for k in range(7):
        result = pipeline.process(frame.rgb_bgr, _depth_m(frame.depth_mm), INTR, stamp_s=k * 0.1)
        assert result.num_faces == 3 and result.num_embedded == (3 if k == 0 else 1)
        for obs in result.people:
            assert obs.face is not None
            i = int(np.argmin(np.linalg.norm(truth - obs.position_world[:2], axis=1)))
            if obs.face.embedding is not None:
                assert obs.face.embedding_space == "dlib_resnet_v1"
                embedded_at[i].append(k)
            else:
                assert obs.face.embedding_space == ""
    assert sorted(len(v) for v in embedded_at.values()) == [3, 3, 3]
    assert all(v[0] == 0 and v[2] - v[1] == 3 and 1 <= v[1] <= 3 for v in embedded_at.values())


def test_real_desk_frames_have_no_people(models) -> None:
    pipeline = CameraPipeline(CameraPipelineConfig(), CameraPose(), *models, seed_ground_from_pose=False)
    for depth_path in sorted((DATA / "rgbd" / "pcl_desk").glob("*_depth_mm.png")):
        raw = cv2.imread(str(depth_path), cv2.IMREAD_UNCHANGED)
        color = cv2.imread(str(depth_path).replace("_depth_mm", "_rgb"))
        result = pipeline.process(color, _depth_m(raw), INTR)
        assert result.ground_plane_found and result.people == []


def test_all_nan_depth_is_an_empty_frame(models) -> None:
    pipeline = CameraPipeline(CameraPipelineConfig(), POSE, *models)
    depth = np.full((INTR.height, INTR.width), np.nan, np.float32)
    result = pipeline.process(np.zeros((480, 640, 3), np.uint8), depth, INTR)
    assert result.people == [] and not result.ground_plane_found


def test_wrong_depth_size_is_rejected(models) -> None:
    pipeline = CameraPipeline(CameraPipelineConfig(), POSE, *models)
    with pytest.raises(ValueError):
        pipeline.process(None, np.ones((240, 320), np.float32), INTR)


def test_faces_need_models() -> None:
    with pytest.raises(ValueError, match="face detector"):
        CameraPipeline(CameraPipelineConfig(), POSE)
    # people only works without any model
    CameraPipeline(CameraPipelineConfig(detect_faces=False), POSE)


def test_face_pose_from_landmarks() -> None:
    frontal = np.array([[40, 50], [80, 50], [60, 70], [45, 90], [75, 90]], float)
    yaw, eye = face_pose_from_landmarks(frontal)
    assert yaw == pytest.approx(0.0, abs=1e-9) and eye == pytest.approx(40.0)
    turned = frontal.copy()
    turned[2, 0] = 70  # nose towards image right: subject turned to their left
    yaw_left, _ = face_pose_from_landmarks(turned)
    assert yaw_left == pytest.approx(30.0, abs=0.5)
    q = FaceQualityConfig()
    assert face_quality(0.9, 40.0, 0.0, q) == pytest.approx(0.9)
    assert face_quality(0.9, 40.0, 30.0, q) < face_quality(0.9, 40.0, 0.0, q)
    assert face_quality(0.9, 5.0, 0.0, q) == 0.0


@pytest.mark.parametrize("kwargs", [
    {"head_roi_size_m": 0.0}, {"camera_id": ""}, {"max_faces_per_frame": -1}, {"min_face_quality": 2.0},
])
def test_config_validation(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        CameraPipelineConfig(**kwargs)


def test_bodies_of_the_nearest_people_within_the_cap() -> None:
    from face_reid_camera.body.descriptor import BodyDescriptorConfig
    from face_reid_camera.body.projection import BodyProjection, fit_pca_block

    rng = np.random.default_rng(0)
    c = BodyDescriptorConfig()
    projection = BodyProjection((fit_pca_block("hsv", rng.random((30, c.hsv_length)), 6),
                                 fit_pca_block("siltp", rng.random((30, c.siltp_length)), 3)))
    people = [SyntheticPerson(2.6, -0.7, 1.65, math.pi), SyntheticPerson(3.4, 0.6, 1.85, math.pi),
              SyntheticPerson(4.3, -0.2, 1.75, 0.0)]
    frame = render_scene(people, INTR, POSE, rng=np.random.default_rng(2))
    depth = _depth_m(frame.depth_mm)
    config = CameraPipelineConfig(camera_id="c", detect_faces=False)
    result = CameraPipeline(config, POSE, body_projection=projection).process(frame.rgb_bgr, depth, INTR)
    assert len(result.people) == 3 and result.timings_ms["body_ms"] > 0
    for obs in result.people:
        assert obs.body is not None and obs.body.descriptor.shape == (9,) and obs.body.space == projection.space
        assert obs.body.geometry.height_m == pytest.approx(obs.height_m)
        assert obs.to_json()["body"]["descriptor_length"] == 9
    capped = CameraPipeline(CameraPipelineConfig(camera_id="c", detect_faces=False, max_bodies_per_frame=1), POSE,
                            body_projection=projection).process(frame.rgb_bgr, depth, INTR)
    described = [obs for obs in capped.people if obs.body is not None]
    assert len(described) == 1 and described[0].position_world[0] == pytest.approx(2.6, abs=0.2)  # the nearest
    off = CameraPipeline(CameraPipelineConfig(camera_id="c", detect_faces=False, describe_bodies=False), POSE,
                         body_projection=projection).process(frame.rgb_bgr, depth, INTR)
    assert all(obs.body is None for obs in off.people) and off.timings_ms["body_ms"] == 0.0
    no_colour = CameraPipeline(config, POSE, body_projection=projection).process(None, depth, INTR)
    assert len(no_colour.people) == 3 and all(obs.body is None for obs in no_colour.people)
    with pytest.raises(ValueError, match="body_projection"):
        CameraPipeline(config, POSE, body_projection="models/body_projection.npz")  # type: ignore[arg-type]
