"""Head region of interest in the colour image from a 3-D head centre (the paper's top-down face search).

Koide et al. project a rectangle of fixed metric size at each person cluster's top into the image and
run the face detector only there. Here the square is centred on the estimated head centre and lies
perpendicular to the viewing ray (it "faces the camera"), so its image is right also near the image
borders; the ROI is the bounding box of its four projected corners, clipped to the image.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from face_reid_camera.camera_model import CameraIntrinsics

__all__ = ["head_roi_px"]

_MIN_DEPTH_M = 1e-3


def _in_colour_frame(head: np.ndarray, rotation: ArrayLike | None, translation_m: ArrayLike | None) -> np.ndarray:
    """A depth-frame point in the colour camera's frame (p_colour = R p_depth + t; None: identity / zero)."""
    if rotation is not None:
        rot = np.asarray(rotation, dtype=np.float64)
        if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
            raise ValueError("depth_to_colour_rotation must be a finite 3x3 matrix")
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise ValueError("depth_to_colour_rotation must be a proper rotation matrix")
        head = rot @ head
    if translation_m is not None:
        trans = np.asarray(translation_m, dtype=np.float64).reshape(-1)
        if trans.shape != (3,) or not np.all(np.isfinite(trans)):
            raise ValueError("depth_to_colour_translation_m must be a finite (3,) vector")
        head = head + trans
    return head


def head_roi_px(
    head_cam: ArrayLike,
    intrinsics: CameraIntrinsics,
    head_roi_size_m: float = 0.3,
    *,
    depth_to_colour_rotation: ArrayLike | None = None,
    depth_to_colour_translation_m: ArrayLike | None = None,
) -> tuple[int, int, int, int] | None:
    """Pixel box (x, y, w, h) in the colour image of a ``head_roi_size_m`` square around ``head_cam``.

    ``head_cam`` is the head centre in the depth camera frame (metres). ``intrinsics`` are the colour
    camera's; for an unregistered sensor pass the depth->colour extrinsic (p_colour = R p_depth + t),
    otherwise depth and colour frames are identical (registered). Returns None when the square is not
    entirely in front of the camera or falls completely outside the image.
    """
    head = np.asarray(head_cam, dtype=np.float64).reshape(-1)
    if head.shape != (3,) or not np.all(np.isfinite(head)):
        raise ValueError(f"head_cam must be a finite (3,) point, got {head_cam!r}")
    if not isinstance(intrinsics, CameraIntrinsics):
        raise ValueError(f"intrinsics must be CameraIntrinsics, got {type(intrinsics).__name__}")
    if not (
        isinstance(head_roi_size_m, (int, float)) and math.isfinite(head_roi_size_m) and head_roi_size_m > 0
    ):
        raise ValueError(f"head_roi_size_m must be a positive finite size in metres, got {head_roi_size_m!r}")
    head = _in_colour_frame(head, depth_to_colour_rotation, depth_to_colour_translation_m)
    distance = float(np.linalg.norm(head))
    if head[2] <= _MIN_DEPTH_M or distance < 1e-9:
        return None
    ray = head / distance
    # In-plane axes of a square perpendicular to the ray: "right" ~ image x, "down" ~ image y.
    right = np.cross(np.array([0.0, 1.0, 0.0]), ray)
    if np.linalg.norm(right) < 1e-9:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(ray, right)
    half = 0.5 * head_roi_size_m
    signs = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    corners = head + half * (signs[:, :1] * right + signs[:, 1:] * down)
    if np.any(corners[:, 2] <= _MIN_DEPTH_M):
        return None
    uv = intrinsics.project(corners)
    # Pixel i covers [i - 0.5, i + 0.5): convert continuous bounds to covered pixel indices.
    x0 = max(0, math.floor(uv[:, 0].min() + 0.5))
    y0 = max(0, math.floor(uv[:, 1].min() + 0.5))
    x1 = min(intrinsics.width, math.ceil(uv[:, 0].max() + 0.5))
    y1 = min(intrinsics.height, math.ceil(uv[:, 1].max() + 0.5))
    if x1 <= x0 or y1 <= y0:
        return None
    return int(x0), int(y0), int(x1 - x0), int(y1 - y0)
