"""Pinhole intrinsics and rigid camera pose: the geometry every camera-side core shares.

Conventions (used everywhere in face-reid):
- camera frame = ROS optical frame: x right, y down, z forward (metres);
- world frame: z up, the floor is z = 0 (metres);
- ``CameraPose`` maps camera-frame points into the world frame: p_world = R @ p_cam + t.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of a (registered) depth/colour image, in pixels."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite focal length in pixels, got {value!r}")
        for name in ("cx", "cy"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")

    @classmethod
    def kinect_default(cls, width: int = 640, height: int = 480) -> CameraIntrinsics:
        """The classic Kinect v1 intrinsics (fx = fy = 525 px) scaled to ``width`` x ``height``."""
        scale = width / 640.0
        return cls(525.0 * scale, 525.0 * scale, (width - 1) / 2.0, (height - 1) / 2.0, width, height)

    def project(self, points_cam: FloatArray) -> FloatArray:
        """Project (N, 3) camera-frame points to (N, 2) pixel coordinates (u, v)."""
        pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        z = pts[:, 2]
        u = self.fx * pts[:, 0] / z + self.cx
        v = self.fy * pts[:, 1] / z + self.cy
        return np.stack([u, v], axis=1)

    def scaled(self, width: int, height: int) -> CameraIntrinsics:
        """The same camera at another image resolution (e.g. colour vs depth of one sensor)."""
        sx, sy = width / self.width, height / self.height
        return CameraIntrinsics(
            self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5, width, height
        )


def _rotation_from_rpy(roll: float, pitch: float, yaw: float) -> FloatArray:
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


# Rotation taking optical-frame axes (x right, y down, z forward) to a body frame
# (x forward, y left, z up): the standard ROS camera_link <- camera_optical_frame rotation.
_BODY_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class CameraPose:
    """Rigid transform world <- camera optical frame: p_world = rotation @ p_cam + translation."""

    rotation: FloatArray = field(default_factory=lambda: np.eye(3))
    translation: FloatArray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        rot = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        trans = np.asarray(self.translation, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(rot)) and np.all(np.isfinite(trans))):
            raise ValueError("camera pose must be finite")
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise ValueError("camera pose rotation must be a proper rotation matrix")
        object.__setattr__(self, "rotation", rot)
        object.__setattr__(self, "translation", trans)

    @classmethod
    def from_xyz_rpy(cls, x: float, y: float, z: float, roll: float, pitch: float, yaw: float) -> CameraPose:
        """Pose of a camera body (x forward, y left, z up) at (x, y, z) m with roll/pitch/yaw in radians.

        pitch > 0 tilts the camera down towards the floor (ROS convention, rotation about body y).
        """
        world_from_body = _rotation_from_rpy(roll, pitch, yaw)
        return cls(world_from_body @ _BODY_FROM_OPTICAL, np.array([x, y, z], dtype=np.float64))

    @classmethod
    def from_position_quaternion(cls, xyz: tuple[float, float, float],
                                 xyzw: tuple[float, float, float, float]) -> CameraPose:
        """The pose a geometry_msgs/Pose of the optical frame describes (the inverse of :meth:`quaternion_xyzw`)."""
        x, y, z, w = (float(v) for v in xyzw)
        n = math.sqrt(x * x + y * y + z * z + w * w)
        if not (math.isfinite(n) and n > 1e-9):
            raise ValueError("camera pose quaternion must be finite and non-zero")
        x, y, z, w = x / n, y / n, z / n, w / n
        rot = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])
        return cls(rot, np.asarray(xyz, dtype=np.float64))

    def xyz_rpy(self) -> tuple[float, float, float, float, float, float]:
        """(x, y, z, roll, pitch, yaw) of the camera body (the inverse of :meth:`from_xyz_rpy`; radians)."""
        body = self.rotation @ _BODY_FROM_OPTICAL.T
        pitch = math.asin(max(-1.0, min(1.0, -float(body[2, 0]))))
        roll = math.atan2(float(body[2, 1]), float(body[2, 2]))
        yaw = math.atan2(float(body[1, 0]), float(body[0, 0]))
        x, y, z = (float(v) for v in self.translation)
        return x, y, z, roll, pitch, yaw

    @classmethod
    def looking_at(cls, position: FloatArray, target: FloatArray) -> CameraPose:
        """Camera at ``position`` (world, m) whose optical axis points at ``target``; image 'up' is world +z."""
        pos = np.asarray(position, dtype=np.float64)
        forward = np.asarray(target, dtype=np.float64) - pos
        norm = float(np.linalg.norm(forward))
        if norm < 1e-9:
            raise ValueError("camera target must differ from its position")
        z_axis = forward / norm
        right = np.cross(z_axis, np.array([0.0, 0.0, 1.0]))
        if np.linalg.norm(right) < 1e-6:
            raise ValueError("camera cannot look straight up or down with world z as image up")
        x_axis = right / np.linalg.norm(right)
        y_axis = np.cross(z_axis, x_axis)
        return cls(np.stack([x_axis, y_axis, z_axis], axis=1), pos)

    def to_world(self, points_cam: FloatArray) -> FloatArray:
        """Map (N, 3) camera-frame points to the world frame."""
        pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        return pts @ self.rotation.T + self.translation

    def to_camera(self, points_world: FloatArray) -> FloatArray:
        """Map (N, 3) world-frame points to the camera frame."""
        pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        return (pts - self.translation) @ self.rotation

    def quaternion_xyzw(self) -> tuple[float, float, float, float]:
        """The rotation as a unit quaternion (x, y, z, w), e.g. for geometry_msgs/Pose."""
        m = self.rotation
        trace = float(m[0, 0] + m[1, 1] + m[2, 2])
        if trace > 0:
            s = 2.0 * math.sqrt(trace + 1.0)
            w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
        else:
            i = int(np.argmax(np.diag(m)))
            j, k = (i + 1) % 3, (i + 2) % 3
            s = 2.0 * math.sqrt(max(1e-12, 1.0 + m[i, i] - m[j, j] - m[k, k]))
            q = [0.0, 0.0, 0.0]
            q[i] = 0.25 * s
            q[j] = (m[j, i] + m[i, j]) / s
            q[k] = (m[k, i] + m[i, k]) / s
            w = (m[k, j] - m[j, k]) / s
            x, y, z = q
        if w < 0:
            x, y, z, w = -x, -y, -z, -w
        return float(x), float(y), float(z), float(w)

    @property
    def up_in_camera(self) -> FloatArray:
        """World +z expressed in the camera frame (the floor normal a seeded RANSAC expects)."""
        return self.rotation[2, :].copy()


def depth_to_points(depth_m: NDArray[np.floating], intrinsics: CameraIntrinsics, stride: int = 1) -> FloatArray:
    """Back-project a depth image (metres; 0 or NaN = invalid) to (N, 3) camera-frame points.

    ``stride`` subsamples rows and columns (a cheap first down-sampling). Invalid pixels are dropped.
    """
    if depth_m.ndim != 2:
        raise ValueError(f"depth image must be 2-D, got shape {depth_m.shape}")
    if depth_m.shape != (intrinsics.height, intrinsics.width):
        raise ValueError(
            f"depth image is {depth_m.shape[1]}x{depth_m.shape[0]} but intrinsics are "
            f"{intrinsics.width}x{intrinsics.height}"
        )
    sub = depth_m[::stride, ::stride].astype(np.float32, copy=False)
    rows = np.arange(0, depth_m.shape[0], stride, dtype=np.float32)
    cols = np.arange(0, depth_m.shape[1], stride, dtype=np.float32)
    valid = np.isfinite(sub) & (sub > 0)
    r_idx, c_idx = np.nonzero(valid)
    z = sub[r_idx, c_idx]
    x = (cols[c_idx] - np.float32(intrinsics.cx)) * z / np.float32(intrinsics.fx)
    y = (rows[r_idx] - np.float32(intrinsics.cy)) * z / np.float32(intrinsics.fy)
    return np.stack([x, y, z], axis=1).astype(np.float64)
