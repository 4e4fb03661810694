"""The static world of a scenario: a rectangular room, doors to an uncovered outside, wall-mounted cameras.

Pure numpy, no I/O. The room is centred on the world origin (floor z = 0, z up, the conventions of
:mod:`face_reid_camera.camera_model`); cameras hang on its walls looking into it; people leave and come
back through the doors (:mod:`face_reid_master.sim.motion`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.checks import is_finite_number
from face_reid_master.sim.visibility import BoolArray, FloatArray, floor_grid, lone_person_visibility

__all__ = [
    "Door",
    "Room",
    "SimCamera",
    "World",
    "check_min_max",
    "make_world",
    "room_size_for",
    "wrap_angle",
    "wrap_angles",
]

# Reference installation: the paper's 3 Kinects over a ~10 x 8 m room for 6 people.
_REFERENCE_AREA_M2 = 80.0
_REFERENCE_CAMERAS = 3
_ASPECT = 1.25  # width / depth of generated rooms


def check_min_max(name: str, pair: tuple[float, float], low: float, high: float) -> None:
    """``pair`` must be (a, b) with low <= a <= b <= high."""
    if len(pair) != 2 or not all(is_finite_number(v) for v in pair) or not low <= pair[0] <= pair[1] <= high:
        raise ValueError(f"{name} must be (min, max) with {low} <= min <= max <= {high}, got {pair!r}")


def wrap_angle(angle: float) -> float:
    """An angle wrapped into [-pi, pi)."""
    return (float(angle) + math.pi) % (2.0 * math.pi) - math.pi


def wrap_angles(angles: FloatArray) -> FloatArray:
    """Angles wrapped into [-pi, pi)."""
    return (angles + np.pi) % (2.0 * np.pi) - np.pi


@dataclass(frozen=True)
class Room:
    """A rectangular room centred on the world origin: x in [-width/2, width/2], y in [-depth/2, depth/2]."""

    width_m: float
    depth_m: float

    def __post_init__(self) -> None:
        for name in ("width_m", "depth_m"):
            value = getattr(self, name)
            if not (is_finite_number(value) and 3.0 <= value <= 200.0):
                raise ValueError(f"Room.{name} must be within [3, 200] m, got {value!r}")

    @property
    def half_extents(self) -> FloatArray:
        return np.array([self.width_m / 2.0, self.depth_m / 2.0])

    @property
    def perimeter_m(self) -> float:
        return 2.0 * (self.width_m + self.depth_m)

    def contains(self, xy: NDArray[np.floating], margin_m: float = 0.0) -> BoolArray:
        """Which (..., 2) floor points are inside the room, at least ``margin_m`` from the walls."""
        pts = np.asarray(xy, dtype=np.float64)
        half = self.half_extents - margin_m
        return (np.abs(pts[..., 0]) <= half[0]) & (np.abs(pts[..., 1]) <= half[1])

    def wall_point(self, s_m: float) -> tuple[FloatArray, FloatArray]:
        """Point at arc length ``s_m`` along the walls (counter-clockwise from the (-w/2, -d/2) corner) and
        the inward unit normal of its wall."""
        w, d = self.width_m, self.depth_m
        s = float(s_m) % self.perimeter_m
        hw, hd = w / 2.0, d / 2.0
        if s < w:
            return np.array([-hw + s, -hd]), np.array([0.0, 1.0])
        s -= w
        if s < d:
            return np.array([hw, -hd + s]), np.array([-1.0, 0.0])
        s -= d
        if s < w:
            return np.array([hw - s, hd]), np.array([0.0, -1.0])
        s -= w
        return np.array([-hw, hd - s]), np.array([1.0, 0.0])


def room_size_for(num_cameras: int) -> Room:
    """A room scaled so that each camera covers a similar share: 10 x 8 m for 3 cameras (area ~ cameras)."""
    if not isinstance(num_cameras, (int, np.integer)) or isinstance(num_cameras, bool) or num_cameras < 1:
        raise ValueError(f"num_cameras must be an integer >= 1, got {num_cameras!r}")
    area = _REFERENCE_AREA_M2 * max(num_cameras, 1) / _REFERENCE_CAMERAS
    depth = max(4.0, round(math.sqrt(area / _ASPECT), 1))
    width = max(5.0, round(area / depth, 1))
    return Room(width, depth)


@dataclass(frozen=True)
class Door:
    """An opening in a wall: people walk inside_xy <-> door centre <-> outside_xy (uncovered, out of view)."""

    centre_xy: FloatArray
    inward_normal: FloatArray
    width_m: float = 1.0
    outside_distance_m: float = 1.5
    inside_distance_m: float = 0.6

    @property
    def inside_xy(self) -> FloatArray:
        return self.centre_xy + self.inside_distance_m * self.inward_normal

    @property
    def outside_xy(self) -> FloatArray:
        return self.centre_xy - self.outside_distance_m * self.inward_normal

    def in_corridor(self, xy: NDArray[np.floating], tolerance_m: float = 1e-6) -> BoolArray:
        """Which (..., 2) points lie in the door's passage: through the opening, out to ``outside_xy``."""
        rel = np.asarray(xy, dtype=np.float64) - self.centre_xy
        along = rel @ self.inward_normal  # > 0 inside the room
        tangent = np.array([-self.inward_normal[1], self.inward_normal[0]])
        lateral = np.abs(rel @ tangent)
        return (along >= -self.outside_distance_m - tolerance_m) & (along <= tolerance_m) & (
            lateral <= self.width_m / 2.0 + tolerance_m
        )


@dataclass(frozen=True)
class SimCamera:
    """One simulated RGB-D camera: id, intrinsics, pose (camera -> world) and the xyz/rpy it was built from."""

    camera_id: str
    intrinsics: CameraIntrinsics
    pose: CameraPose
    xyz_rpy: tuple[float, float, float, float, float, float]

    @property
    def position(self) -> FloatArray:
        return self.pose.translation


@dataclass(frozen=True)
class World:
    """The static part of a scenario: room, cameras and doors."""

    room: Room
    cameras: tuple[SimCamera, ...]
    doors: tuple[Door, ...]

    def allowed(self, xy: NDArray[np.floating], tolerance_m: float = 1e-6) -> BoolArray:
        """Which (..., 2) points a person may occupy: the room or a door passage."""
        ok = self.room.contains(xy, -tolerance_m)
        for door in self.doors:
            ok |= door.in_corridor(xy, tolerance_m)
        return ok


def make_world(
    num_cameras: int,
    rng: np.random.Generator,
    room: Room | None = None,
    num_doors: int | None = None,
    camera_height_range_m: tuple[float, float] = (2.2, 2.6),
    camera_tilt_range_deg: tuple[float, float] = (15.0, 25.0),
    intrinsics: CameraIntrinsics | None = None,
) -> World:
    """Cameras evenly spread along the walls (jittered), each aimed into the room where it adds the most
    coverage, and doors half-way between cameras (``num_doors`` default: 1 per 2 cameras, 1 to 4)."""
    if not isinstance(num_cameras, (int, np.integer)) or isinstance(num_cameras, bool) or not 1 <= num_cameras <= 64:
        raise ValueError(f"num_cameras must be an integer in [1, 64], got {num_cameras!r}")
    check_min_max("camera_height_range_m", camera_height_range_m, 1.0, 5.0)
    check_min_max("camera_tilt_range_deg", camera_tilt_range_deg, 0.0, 60.0)
    room = room if room is not None else room_size_for(num_cameras)
    if num_doors is None:
        num_doors = min(4, max(1, round(num_cameras / 2)))
    if not isinstance(num_doors, (int, np.integer)) or isinstance(num_doors, bool) or not 1 <= num_doors <= 16:
        raise ValueError(f"num_doors must be an integer in [1, 16], got {num_doors!r}")
    intr = intrinsics if intrinsics is not None else CameraIntrinsics.kinect_default()
    perim = room.perimeter_m
    spacing = perim / num_cameras
    offset = float(rng.uniform(0.0, spacing))
    arc = [offset + k * spacing + float(rng.uniform(-0.1, 0.1)) * spacing for k in range(num_cameras)]
    cameras: list[SimCamera] = []
    half = room.half_extents
    step = max(0.25, min(room.width_m, room.depth_m) / 16.0)
    grid = floor_grid(half, step)
    covered = np.zeros(grid.shape[0], dtype=bool)
    for k, s in enumerate(arc):
        wall_xy, normal = room.wall_point(s)
        pos_xy = wall_xy + 0.05 * normal
        z = float(rng.uniform(*camera_height_range_m))
        pitch = math.radians(float(rng.uniform(*camera_tilt_range_deg)))
        # aim: the yaw (within +-70 deg of the room centre's direction) that adds the most coverage to the
        # cameras already placed, as an installer would; ties go to the direction nearest the centre
        centre_yaw = math.atan2(-pos_xy[1], -pos_xy[0])
        best: tuple[float, float, SimCamera, np.ndarray] | None = None
        for dyaw in np.radians(np.arange(-70.0, 71.0, 10.0)) + float(rng.uniform(-0.05, 0.05)):
            yaw = float(wrap_angle(centre_yaw + dyaw))
            xyz_rpy = (float(pos_xy[0]), float(pos_xy[1]), z, 0.0, pitch, yaw)
            cam = SimCamera(f"camera{k + 1}", intr, CameraPose.from_xyz_rpy(*xyz_rpy), xyz_rpy)
            seen = lone_person_visibility(cam, grid).detectable[:, 0]
            gain = float((seen & ~covered).sum())
            key = (gain, -abs(float(dyaw)))
            if best is None or key > best[:2]:
                best = (gain, -abs(float(dyaw)), cam, seen)
        assert best is not None
        cameras.append(best[2])
        covered |= best[3]
    doors = []
    order = np.sort(np.asarray(arc) % perim)
    gaps = np.diff(np.concatenate([order, [order[0] + perim]]))
    for k in range(num_doors):
        # in the middle of the walls between cameras, kept >= 1 m from the corners
        i = round(k * num_cameras / num_doors) % num_cameras
        s = (order[i] + 0.5 * gaps[i]) % perim
        wall_xy, normal = room.wall_point(s)
        tangent = np.array([-normal[1], normal[0]])
        limit = float(abs(tangent @ half)) - 1.0
        along = float(np.clip(tangent @ wall_xy, -limit, limit)) if limit > 0 else 0.0
        centre = wall_xy - (tangent @ wall_xy) * tangent + along * tangent
        doors.append(Door(centre, normal))
    return World(room, tuple(cameras), tuple(doors))
