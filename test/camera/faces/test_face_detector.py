"""Tests of the YuNet face detector core: decoder vs OpenCV, batched head-ROI detection, bad input."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import REPO_ROOT

from face_reid_camera.common.errors import ModelLoadError
from face_reid_camera.faces.detector import FaceDetection, YuNetDetector

REPO = REPO_ROOT
MODELS_DIR = REPO / "models"
FIXED_MODEL = MODELS_DIR / "face_detection_yunet_2023mar.onnx"
DYNAMIC_MODEL = MODELS_DIR / "face_detection_yunet_2023mar_dynamic.onnx"
FACES_DIR = REPO / "test" / "data" / "faces"
DESK_FRAME = next((REPO / "test" / "data" / "rgbd" / "pcl_desk").glob("*_rgb.png"))  # real frame, no face

ALL_PHOTOS = sorted(FACES_DIR.glob("*/*.jpg"))

cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)


@pytest.fixture(scope="module")
def detector() -> YuNetDetector:
    return YuNetDetector()


def _read(path: Path) -> np.ndarray:
    image = cv2.imread(str(path))
    assert image is not None, path
    return image


def _reference_faces(image: np.ndarray) -> np.ndarray:
    """cv2.FaceDetectorYN (fixed 640x640 model, input size = image size) rows, by decreasing score."""
    height, width = image.shape[:2]
    reference = cv2.FaceDetectorYN.create(str(FIXED_MODEL), "", (width, height), 0.6, 0.3, 5000)
    _, faces = reference.detect(image)
    faces = np.zeros((0, 15), dtype=np.float32) if faces is None else faces
    return faces[np.argsort(-faces[:, 14], kind="stable")]


def _paste_face(
    canvas: np.ndarray, detector: YuNetDetector, photo: Path, face_px: float, centre_xy: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Paste a photo's head window so its face box is face_px wide and centred at centre_xy (clipped
    at the canvas border). Returns the expected (4,) box and (5, 2) landmarks in canvas pixels."""
    image = _read(photo)
    face = detector.detect(image)[0]
    scale = face_px / float(face.box_xywh[2])
    small = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    face_centre = (face.box_xywh[:2] + face.box_xywh[2:] / 2) * scale
    shift = np.asarray(centre_xy, dtype=np.float64) - face_centre  # photo pixel -> canvas pixel
    half = int(1.2 * face_px)
    x_lo, y_lo = (int(v) for v in np.maximum(face_centre - half, 0))
    x_hi = min(small.shape[1], int(face_centre[0]) + half)
    y_hi = min(small.shape[0], int(face_centre[1]) + half)
    dst_x, dst_y = x_lo + round(shift[0]), y_lo + round(shift[1])
    shift = np.array([dst_x - x_lo, dst_y - y_lo], dtype=np.float64)  # the integer shift actually used
    src_x0, src_y0 = x_lo + max(0, -dst_x), y_lo + max(0, -dst_y)
    dst_x0, dst_y0 = max(0, dst_x), max(0, dst_y)
    width = min(x_hi - src_x0, canvas.shape[1] - dst_x0)
    height = min(y_hi - src_y0, canvas.shape[0] - dst_y0)
    canvas[dst_y0 : dst_y0 + height, dst_x0 : dst_x0 + width] = small[
        src_y0 : src_y0 + height, src_x0 : src_x0 + width
    ]
    box = np.concatenate([face.box_xywh[:2] * scale + shift, face.box_xywh[2:] * scale])
    return box, face.landmarks * scale + shift


def _interocular_px(landmarks: np.ndarray) -> float:
    return float(np.linalg.norm(landmarks[0] - landmarks[1]))


# --------------------------------------------------------------------------- decoder vs OpenCV


def test_decoder_reproduces_opencv_face_detector_yn(detector: YuNetDetector) -> None:
    photos = ALL_PHOTOS[::6]  # ~30 photos from all three sources, various sizes and aspect ratios
    compared = 0
    for photo in photos:
        image = _read(photo)
        ours = detector.detect(image)
        reference = _reference_faces(image)
        assert len(ours) == len(reference), photo
        for face, row in zip(ours, reference, strict=True):
            np.testing.assert_allclose(face.box_xywh, row[:4], atol=0.01, err_msg=str(photo))
            np.testing.assert_allclose(face.landmarks.reshape(-1), row[4:14], atol=0.01, err_msg=str(photo))
            assert face.score == pytest.approx(float(row[14]), abs=1e-5)
            compared += 1
    assert compared >= len(photos)  # every photo has at least one face: the comparison is not vacuous


def test_detect_returns_sorted_faces_with_typed_fields(detector: YuNetDetector) -> None:
    # A two-person canvas: both faces found, best first, fields in the documented form.
    canvas = _read(DESK_FRAME)
    _paste_face(canvas, detector, ALL_PHOTOS[0], 80, (160, 240))
    _paste_face(canvas, detector, ALL_PHOTOS[-1], 80, (480, 240))
    faces = detector.detect(canvas)
    assert len(faces) == 2
    assert faces[0].score >= faces[1].score >= detector.score_threshold
    assert sorted(float(f.box_xywh[0] + f.box_xywh[2] / 2) // 320 for f in faces) == [0, 1]
    for face in faces:
        assert face.box_xywh.dtype == np.float32 and face.box_xywh.shape == (4,)
        assert face.landmarks.dtype == np.float32 and face.landmarks.shape == (5, 2)
        assert isinstance(face.score, float)
        assert not face.box_xywh.flags.writeable
        with pytest.raises(dataclasses.FrozenInstanceError):
            face.score = 0.0  # type: ignore[misc]


def test_detect_on_grey_equals_detect_on_grey_as_bgr(detector: YuNetDetector) -> None:
    grey = cv2.cvtColor(_read(ALL_PHOTOS[3]), cv2.COLOR_BGR2GRAY)
    as_grey = detector.detect(grey)
    as_bgr = detector.detect(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR))
    assert len(as_grey) == len(as_bgr) >= 1
    np.testing.assert_allclose(as_grey[0].box_xywh, as_bgr[0].box_xywh, atol=1e-4)
    assert detector.detect(grey[:, :, None])[0].score == pytest.approx(as_grey[0].score, abs=1e-6)


def test_detect_finds_nothing_in_a_real_frame_without_people(detector: YuNetDetector) -> None:
    assert detector.detect(_read(DESK_FRAME)) == []


# --------------------------------------------------------------------------- head ROIs


@pytest.fixture(scope="module")
def scene(detector: YuNetDetector) -> dict[str, object]:
    """A real 640x480 desk frame with three real faces (50-70 px) pasted in, one by the left edge."""
    canvas = _read(DESK_FRAME)
    photos = [FACES_DIR / "lfw_Tony_Blair", FACES_DIR / "facerec_obama", FACES_DIR / "deepface_id03"]
    placements = [(60.0, (330, 150)), (70.0, (520, 330)), (50.0, (40, 260))]
    expected = []
    for folder, (face_px, centre) in zip(photos, placements, strict=True):
        photo = sorted(folder.glob("*.jpg"))[0]
        box, landmarks = _paste_face(canvas, detector, photo, face_px, centre)
        expected.append((box, landmarks))
    rois = []
    offsets = [(0.1, -0.1), (-0.1, 0.1), (-0.2, 0.0)]  # ROI centre offsets from the face, x ROI side
    for (box, _), offset in zip(
        expected, offsets, strict=True
    ):  # a head ROI about twice the face, off-centre
        side = 2.0 * box[2]
        centre = box[:2] + box[2:] / 2 + np.array(offset) * side
        rois.append((int(centre[0] - side / 2), int(centre[1] - side / 2), int(side), int(side)))
    return {"image": canvas, "expected": expected, "face_rois": rois}


def test_detect_in_rois_finds_each_face_and_nothing_elsewhere(
    detector: YuNetDetector, scene: dict[str, object]
) -> None:
    image = scene["image"]
    face_rois = scene["face_rois"]
    assert face_rois[2][0] < 0  # the third ROI sticks out of the left border: partially outside
    empty_rois = [(200, 300, 120, 120), (40, 30, 140, 140)]  # laptop and floor: no face
    outside_rois = [(-300, -200, 120, 120), (700, 100, 80, 80), (100, 480, 60, 60)]
    results = detector.detect_in_rois(image, face_rois + empty_rois + outside_rois)
    assert len(results) == len(face_rois) + len(empty_rois) + len(outside_rois)
    for found, roi, (box, landmarks) in zip(
        results[: len(face_rois)], face_rois, scene["expected"], strict=True
    ):
        assert found is not None, roi
        x, y, w, h = roi
        centre = found.box_xywh[:2] + found.box_xywh[2:] / 2
        assert x <= centre[0] <= x + w and y <= centre[1] <= y + h
        assert found.box_xywh[0] >= x - 2 and found.box_xywh[0] + found.box_xywh[2] <= x + w + 2
        assert found.box_xywh[1] >= y - 2 and found.box_xywh[1] + found.box_xywh[3] <= y + h + 2
        # Eyes in the right places: right eye (subject's) on the image's left, both above the mouth.
        right_eye, left_eye, nose, right_mouth, left_mouth = found.landmarks
        assert right_eye[0] < nose[0] < left_eye[0]
        assert max(right_eye[1], left_eye[1]) < nose[1] < min(right_mouth[1], left_mouth[1])
        iod = _interocular_px(landmarks)
        assert np.linalg.norm(found.landmarks - landmarks, axis=1).max() < 0.25 * iod
        np.testing.assert_allclose(found.box_xywh, box, atol=0.2 * box[2])
    assert results[len(face_rois) :] == [None] * (len(empty_rois) + len(outside_rois))


def test_detect_in_rois_batched_equals_one_roi_at_a_time(
    detector: YuNetDetector, scene: dict[str, object]
) -> None:
    image, rois = scene["image"], scene["face_rois"]
    batched = detector.detect_in_rois(image, np.asarray(rois, dtype=np.float64))
    for roi, together in zip(rois, batched, strict=True):
        (alone,) = detector.detect_in_rois(image, [roi])
        assert alone is not None and together is not None
        np.testing.assert_allclose(together.box_xywh, alone.box_xywh, atol=1e-3)
        np.testing.assert_allclose(together.landmarks, alone.landmarks, atol=1e-3)
        assert together.score == pytest.approx(alone.score, abs=1e-5)


def test_unscaled_roi_equals_full_detection_of_the_crop(
    detector: YuNetDetector, scene: dict[str, object]
) -> None:
    # An ROI exactly roi_input_size_px wide needs no resizing: its best face must equal detect() on the
    # crop (checked against OpenCV above), shifted by the ROI's origin.
    image = scene["image"]
    side = detector.roi_input_size_px
    box, _ = scene["expected"][0]
    x, y = (int(v) for v in box[:2] + box[2:] / 2 - side / 2)
    (found,) = detector.detect_in_rois(image, [(x, y, side, side)])
    best = detector.detect(np.ascontiguousarray(image[y : y + side, x : x + side]))[0]
    assert found is not None
    np.testing.assert_allclose(found.box_xywh, best.box_xywh + np.array([x, y, 0, 0]), atol=1e-3)
    np.testing.assert_allclose(found.landmarks, best.landmarks + np.array([x, y]), atol=1e-3)
    assert found.score == pytest.approx(best.score, abs=1e-6)


def test_detect_in_rois_accepts_grey_images(detector: YuNetDetector, scene: dict[str, object]) -> None:
    grey = cv2.cvtColor(scene["image"], cv2.COLOR_BGR2GRAY)
    results = detector.detect_in_rois(grey, scene["face_rois"])
    for found, (_, landmarks) in zip(results, scene["expected"], strict=True):
        assert found is not None
        assert np.linalg.norm(found.landmarks - landmarks, axis=1).max() < 0.3 * _interocular_px(landmarks)


def test_detect_in_rois_recall_on_fixture_faces_in_head_sized_rois(detector: YuNetDetector) -> None:
    # Each fixture face shown at 40 or 80 px inside a ~0.35 m head ROI (2x the face, off-centre by up
    # to 15 %) on a real background frame.
    rng = np.random.default_rng(7)
    background = _read(DESK_FRAME)
    hits, errors = 0, []
    trials = 0
    for index, photo in enumerate(ALL_PHOTOS[::3]):
        face_px = 40.0 if index % 2 else 80.0
        canvas = background.copy()
        box, landmarks = _paste_face(canvas, detector, photo, face_px, (320, 240))
        side = 2.0 * face_px
        centre = box[:2] + box[2:] / 2 + rng.uniform(-0.15, 0.15, 2) * side
        (found,) = detector.detect_in_rois(canvas, [(*(centre - side / 2), side, side)])
        trials += 1
        if found is not None:
            error = np.linalg.norm(found.landmarks - landmarks, axis=1).mean() / _interocular_px(landmarks)
            errors.append(error)
            hits += error < 0.3
    assert trials >= 55
    assert hits / trials >= 0.95
    assert float(np.median(errors)) < 0.15


def test_detect_in_rois_with_no_rois_returns_empty_list(detector: YuNetDetector) -> None:
    image = _read(DESK_FRAME)
    assert detector.detect_in_rois(image, []) == []
    assert detector.detect_in_rois(image, np.zeros((0, 4))) == []


def test_detect_in_rois_sliver_inside_image_is_none(detector: YuNetDetector) -> None:
    image = _read(DESK_FRAME)
    assert detector.detect_in_rois(image, [(636, 200, 100, 100)]) == [None]  # only 4 px inside


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "image",
    [
        np.zeros((120, 160, 3), dtype=np.float32),
        np.zeros((120, 160, 3), dtype=np.uint16),
        np.zeros((120, 160, 4), dtype=np.uint8),
        np.zeros((2, 120, 160, 3), dtype=np.uint8),
        np.zeros((160,), dtype=np.uint8),
        np.zeros((0, 160, 3), dtype=np.uint8),
        [[0, 1], [2, 3]],
    ],
)
def test_bad_images_raise_value_error(detector: YuNetDetector, image: object) -> None:
    with pytest.raises(ValueError, match="image"):
        detector.detect(image)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="image"):
        detector.detect_in_rois(image, [(0, 0, 50, 50)])  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "rois",
    [
        [(0, 0, 50)],
        [(0, 0, 0, 50)],
        [(0, 0, 50, -5)],
        [(np.nan, 0, 50, 50)],
        [("a", 0, 50, 50)],
        (1, 2, 3, 4),
    ],
)
def test_bad_rois_raise_value_error(detector: YuNetDetector, rois: object) -> None:
    with pytest.raises(ValueError, match=r"ROI|rois"):
        detector.detect_in_rois(_read(DESK_FRAME), rois)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "kwargs",
    [
        {"score_threshold": 0.0},
        {"score_threshold": 1.5},
        {"score_threshold": float("nan")},
        {"nms_iou_threshold": -0.1},
        {"roi_input_size_px": 100},
        {"roi_input_size_px": 0},
        {"roi_input_size_px": 96.0},
        {"num_threads": 0},
        {"top_k": 0},
        {"top_k": True},
    ],
)
def test_invalid_constructor_arguments_raise_value_error(kwargs: dict[str, object]) -> None:
    name = next(iter(kwargs))
    with pytest.raises(ValueError, match=name):
        YuNetDetector(**kwargs)  # type: ignore[arg-type]


def test_missing_model_raises_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"nowhere\.onnx"):
        YuNetDetector(tmp_path / "nowhere.onnx")


def test_models_dir_env_var_is_honoured(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FACE_REID_MODELS_DIR", str(tmp_path))
    with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path))):
        YuNetDetector()
    monkeypatch.setenv("FACE_REID_MODELS_DIR", str(MODELS_DIR))
    assert YuNetDetector().model_path == MODELS_DIR / DYNAMIC_MODEL.name


def test_corrupt_model_raises_model_load_error(tmp_path: Path) -> None:
    truncated = tmp_path / "truncated.onnx"
    truncated.write_bytes(DYNAMIC_MODEL.read_bytes()[:5000])
    with pytest.raises(ModelLoadError):
        YuNetDetector(truncated)
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"this is not an onnx model" * 100)
    with pytest.raises(ModelLoadError):
        YuNetDetector(garbage)


def test_fixed_size_model_is_rejected_with_model_load_error() -> None:
    with pytest.raises(ModelLoadError, match="dynamic"):
        YuNetDetector(FIXED_MODEL)


def test_face_detection_rejects_wrong_shapes() -> None:
    with pytest.raises(ValueError, match="box_xywh"):
        FaceDetection(np.zeros(3), np.zeros((5, 2)), 0.9)
    with pytest.raises(ValueError, match="landmarks"):
        FaceDetection(np.zeros(4), np.zeros((4, 2)), 0.9)
