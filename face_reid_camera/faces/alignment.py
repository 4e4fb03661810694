"""Face alignment: warp a face to an embedder's chip (dlib 150x150, SFace 112x112) from YuNet's five landmarks.

A least-squares similarity transform (rotation, uniform scale, translation; closed-form Umeyama, so it is
deterministic, unlike RANSAC) maps the detected landmarks onto the embedder's template — for dlib
:data:`ALIGN_TEMPLATE_150`, fitted against dlib's own ``get_face_chip`` (padding 0.25); for SFace
:data:`ALIGN_TEMPLATE_SFACE_112`, the template of OpenCV's ``FaceRecognizerSF.alignCrop`` — and the face
is resampled bilinearly.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import check_bgr_image

__all__ = [
    "ALIGN_TEMPLATE_150",
    "ALIGN_TEMPLATE_SFACE_112",
    "CHIP_SIZE_PX",
    "SFACE_CHIP_SIZE_PX",
    "align_face",
    "align_faces",
    "estimate_similarity",
]

CHIP_SIZE_PX = 150

# (x, y) in the 150x150 chip, YuNet's landmark order: right eye, left eye, nose tip, right mouth corner,
# left mouth corner (the subject's right is on the image's left).
ALIGN_TEMPLATE_150: NDArray[np.float64] = np.array(
    [
        [47.15, 46.17],
        [102.09, 44.71],
        [75.0, 78.7],
        [52.9, 103.27],
        [100.66, 101.74],
    ],
    dtype=np.float64,
)
ALIGN_TEMPLATE_150.setflags(write=False)

SFACE_CHIP_SIZE_PX = 112
# OpenCV's FaceRecognizerSF.alignCrop destination points (the ArcFace 112x112 template), same order.
ALIGN_TEMPLATE_SFACE_112: NDArray[np.float64] = np.array(
    [
        [38.2946, 51.6963],
        [73.5318, 51.5014],
        [56.0252, 71.7366],
        [41.5493, 92.3655],
        [70.7299, 92.2041],
    ],
    dtype=np.float64,
)
ALIGN_TEMPLATE_SFACE_112.setflags(write=False)

# Landmark sets spanning less than this (RMS distance to their centroid, pixels) are degenerate.
_MIN_LANDMARK_SPREAD_PX = 1.0


def _validate_landmarks(landmarks5: np.ndarray) -> NDArray[np.float64]:
    points = np.asarray(landmarks5)
    if points.shape != (5, 2):
        raise ValueError(f"landmarks5 must have shape (5, 2), got {points.shape}")
    if not np.issubdtype(points.dtype, np.number) or np.issubdtype(points.dtype, np.complexfloating):
        raise ValueError(f"landmarks5 must be real numbers, got dtype {points.dtype}")
    points = points.astype(np.float64)
    if not np.isfinite(points).all():
        raise ValueError("landmarks5 contains NaN or infinite values")
    spread = float(np.sqrt(((points - points.mean(axis=0)) ** 2).sum(axis=1).mean()))
    if spread < _MIN_LANDMARK_SPREAD_PX:
        raise ValueError(f"landmarks5 are degenerate (spread {spread:.3g} px < {_MIN_LANDMARK_SPREAD_PX} px)")
    return points


def estimate_similarity(src: np.ndarray, dst: np.ndarray) -> NDArray[np.float64]:
    """Least-squares similarity (Umeyama 1991) mapping ``src`` (K,2) onto ``dst`` (K,2): 2x3 matrix."""
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    src_mean = src.mean(axis=0)
    dst_mean = dst.mean(axis=0)
    src_c = src - src_mean
    dst_c = dst - dst_mean
    src_var = (src_c**2).sum() / len(src)
    if src_var <= 0.0:
        raise ValueError("cannot estimate a similarity from coincident points")
    cov = dst_c.T @ src_c / len(src)
    u, sing, vt = np.linalg.svd(cov)
    sign = np.ones(2)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:  # forbid reflections
        sign[-1] = -1.0
    rotation = u @ np.diag(sign) @ vt
    scale = float((sing * sign).sum() / src_var)
    matrix = np.empty((2, 3), dtype=np.float64)
    matrix[:, :2] = scale * rotation
    matrix[:, 2] = dst_mean - matrix[:, :2] @ src_mean
    return matrix


def _warp_to_rgb(image: np.ndarray, matrix: NDArray[np.float64], size: int) -> NDArray[np.uint8]:
    chip = cv2.warpAffine(
        image,
        matrix,
        (size, size),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )
    if chip.ndim == 2:
        return cv2.cvtColor(chip, cv2.COLOR_GRAY2RGB)
    if chip.shape[2] == 4:
        return cv2.cvtColor(chip, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(chip, cv2.COLOR_BGR2RGB)


def align_face(image_bgr: np.ndarray, landmarks5: np.ndarray, template: NDArray[np.float64] = ALIGN_TEMPLATE_150,
               chip_size_px: int = CHIP_SIZE_PX) -> NDArray[np.uint8]:
    """Return the chip_size x chip_size x 3 uint8 RGB chip of the face whose 5 YuNet landmarks (pixels) are given.

    ``image_bgr``: uint8 HxWx3 BGR (HxW grey and HxWx4 BGRA are accepted too). Parts of the chip that
    fall outside the image are black. Raises ValueError on a bad image or bad landmarks (wrong shape,
    non-finite, degenerate).
    """
    image = check_bgr_image(image_bgr, allow_bgra=True)
    matrix = estimate_similarity(_validate_landmarks(landmarks5), template)
    return _warp_to_rgb(image, matrix, chip_size_px)


def align_faces(
    image_bgr: np.ndarray, landmarks_list: Sequence[np.ndarray] | np.ndarray,
    template: NDArray[np.float64] = ALIGN_TEMPLATE_150, chip_size_px: int = CHIP_SIZE_PX,
) -> NDArray[np.uint8]:
    """Align several faces of one image: returns [N, chip, chip, 3] uint8 RGB (N may be 0)."""
    image = check_bgr_image(image_bgr, allow_bgra=True)
    if isinstance(landmarks_list, np.ndarray) and landmarks_list.ndim != 3 and landmarks_list.size > 0:
        raise ValueError(f"landmarks_list must be [N, 5, 2], got shape {landmarks_list.shape}")
    chips = np.empty((len(landmarks_list), chip_size_px, chip_size_px, 3), dtype=np.uint8)
    for index, landmarks in enumerate(landmarks_list):
        matrix = estimate_similarity(_validate_landmarks(landmarks), template)
        chips[index] = _warp_to_rgb(image, matrix, chip_size_px)
    return chips
