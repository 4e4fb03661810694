"""World model of the scenario simulator: a room, wall-mounted RGB-D cameras, walking people, visibility.

Pure numpy, no I/O. The room is a rectangle centred on the world origin (floor z = 0, z up, the
conventions of :mod:`face_reid_camera.camera_model`); cameras hang on its walls looking into it, and
doors in its walls lead to an uncovered outside where people wait before coming back. People walk
between random waypoints (0.6-1.4 m/s), turn before walking, pause and look around, and sometimes
leave through a door; a person's motion is a piecewise-linear :class:`Trajectory` (knots of time,
position, facing), so it can be sampled exactly at any camera's frame stamps.

Visibility for one camera (:func:`camera_visibility`) is analytic: a person is detectable when in the
room, within range, with head top, shoulders and both sides of the head inside the image, and the line
of sight to the head not blocked by someone nearer (people are vertical cylinders); the face is
visible when, in addition, the person faces the camera within ``max_face_angle_deg`` and is within
``max_face_range_m``. A track loss (:func:`count_losses`) is a time span longer than ``min_gap_s``
during which a person, seen before, is detectable by no camera.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = [
    "Door",
    "LossSummary",
    "MotionConfig",
    "Room",
    "SimCamera",
    "Trajectory",
    "Visibility",
    "VisibilityConfig",
    "World",
    "camera_visibility",
    "count_losses",
    "coverage_fraction",
    "glance_ids",
    "make_world",
    "plan_trajectory",
    "room_size_for",
    "sample_trajectories",
]

# Reference installation: the paper's 3 Kinects over a ~10 x 8 m room for 6 people.
_REFERENCE_AREA_M2 = 80.0
_REFERENCE_CAMERAS = 3
_ASPECT = 1.25  # width / depth of generated rooms


def _finite(value: object) -> bool:
    real = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    return real and math.isfinite(float(value))  # type: ignore[arg-type]


def _check_range(name: str, pair: tuple[float, float], low: float, high: float) -> None:
    """``pair`` must be (a, b) with low <= a <= b <= high."""
    if len(pair) != 2 or not all(_finite(v) for v in pair) or not low <= pair[0] <= pair[1] <= high:
        raise ValueError(f"{name} must be (min, max) with {low} <= min <= max <= {high}, got {pair!r}")


def _wrap(angle: float) -> float:
    """An angle wrapped into [-pi, pi)."""
    return (float(angle) + math.pi) % (2.0 * math.pi) - math.pi


def _wrap_array(angles: FloatArray) -> FloatArray:
    """Angles wrapped into [-pi, pi)."""
    return (angles + np.pi) % (2.0 * np.pi) - np.pi


# ---------------------------------------------------------------------------------------------------
# Room, doors, cameras


@dataclass(frozen=True)
class Room:
    """A rectangular room centred on the world origin: x in [-width/2, width/2], y in [-depth/2, depth/2]."""

    width_m: float
    depth_m: float

    def __post_init__(self) -> None:
        for name in ("width_m", "depth_m"):
            value = getattr(self, name)
            if not (_finite(value) and 3.0 <= value <= 200.0):
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
    _check_range("camera_height_range_m", camera_height_range_m, 1.0, 5.0)
    _check_range("camera_tilt_range_deg", camera_tilt_range_deg, 0.0, 60.0)
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
    xs, ys = np.arange(-half[0] + step / 2, half[0], step), np.arange(-half[1] + step / 2, half[1], step)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 1, 2)
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
            yaw = float(_wrap(centre_yaw + dyaw))
            xyz_rpy = (float(pos_xy[0]), float(pos_xy[1]), z, 0.0, pitch, yaw)
            cam = SimCamera(f"camera{k + 1}", intr, CameraPose.from_xyz_rpy(*xyz_rpy), xyz_rpy)
            seen = _lone_person_detectable(cam, grid)
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


# ---------------------------------------------------------------------------------------------------
# Motion


@dataclass(frozen=True)
class MotionConfig:
    """How people move (seconds, metres, m/s, rad/s). Defaults tuned for ~50 losses per 200 s with 6 people
    and 3 cameras (see the simulator's report)."""

    speed_range_mps: tuple[float, float] = (0.6, 1.4)
    pause_probability: float = 0.5
    pause_range_s: tuple[float, float] = (1.0, 6.0)
    look_hold_range_s: tuple[float, float] = (0.4, 2.0)
    look_around_max_rad: float = 2.1
    turn_rate_rad_s: float = 3.5
    exit_probability: float = 0.12
    outside_range_s: tuple[float, float] = (2.0, 15.0)
    start_inside_probability: float = 0.6
    initial_outside_max_s: float = 15.0
    waypoint_margin_m: float = 1.0
    height_range_m: tuple[float, float] = (1.55, 1.90)

    def __post_init__(self) -> None:
        _check_range("speed_range_mps", self.speed_range_mps, 0.05, 5.0)
        _check_range("pause_range_s", self.pause_range_s, 0.0, 600.0)
        _check_range("look_hold_range_s", self.look_hold_range_s, 0.05, 600.0)
        _check_range("outside_range_s", self.outside_range_s, 0.0, 3600.0)
        _check_range("height_range_m", self.height_range_m, 1.0, 2.3)
        for name in ("pause_probability", "exit_probability", "start_inside_probability"):
            value = getattr(self, name)
            if not (_finite(value) and 0.0 <= value <= 1.0):
                raise ValueError(f"MotionConfig.{name} must be a probability in [0, 1], got {value!r}")
        for name in ("turn_rate_rad_s", "look_around_max_rad"):
            value = getattr(self, name)
            if not (_finite(value) and value > 0):
                raise ValueError(f"MotionConfig.{name} must be positive, got {value!r}")
        for name in ("initial_outside_max_s", "waypoint_margin_m"):
            value = getattr(self, name)
            if not (_finite(value) and value >= 0):
                raise ValueError(f"MotionConfig.{name} must be >= 0, got {value!r}")


@dataclass(frozen=True)
class Trajectory:
    """Piecewise-linear motion of one person: knots (time s, floor x/y m, facing rad, unwrapped).

    Between knots position and facing are interpolated linearly; before the first / after the last
    knot they hold. ``height_m`` is the person's standing height.
    """

    t_s: FloatArray
    xy: FloatArray
    facing_rad: FloatArray
    height_m: float

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=np.float64)
        xy = np.asarray(self.xy, dtype=np.float64)
        facing = np.asarray(self.facing_rad, dtype=np.float64)
        if t.ndim != 1 or t.size == 0 or xy.shape != (t.size, 2) or facing.shape != t.shape:
            raise ValueError(
                f"Trajectory needs t (K,), xy (K, 2), facing (K,), got {t.shape} {xy.shape} {facing.shape}"
            )
        if not (np.isfinite(t).all() and np.isfinite(xy).all() and np.isfinite(facing).all()):
            raise ValueError("Trajectory knots must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError("Trajectory knot times must be strictly increasing")
        if not (_finite(self.height_m) and 1.0 <= self.height_m <= 2.3):
            raise ValueError(f"Trajectory.height_m must be in [1.0, 2.3] m, got {self.height_m!r}")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "facing_rad", facing)

    def sample(self, t_s: NDArray[np.floating]) -> tuple[FloatArray, FloatArray]:
        """Positions (n, 2) and facings (n,) wrapped to [-pi, pi) at times ``t_s`` (n,)."""
        t = np.asarray(t_s, dtype=np.float64)
        x = np.interp(t, self.t_s, self.xy[:, 0])
        y = np.interp(t, self.t_s, self.xy[:, 1])
        facing = np.interp(t, self.t_s, self.facing_rad)
        return np.stack([x, y], axis=-1), _wrap_array(facing)


class _Planner:
    """Appends knots while a person walks, turns, pauses and goes out and back in."""

    def __init__(self, world: World, rng: np.random.Generator, config: MotionConfig, t0: float,
                 xy: FloatArray, facing: float) -> None:
        self.world, self.rng, self.cfg = world, rng, config
        self.t = [t0]
        self.xy = [np.asarray(xy, dtype=np.float64)]
        self.facing = [float(facing)]

    @property
    def now(self) -> float:
        return self.t[-1]

    def _add(self, dt: float, xy: FloatArray, facing: float) -> None:
        if dt <= 1e-6:  # merge: a zero-length step just replaces the last knot's state
            self.xy[-1], self.facing[-1] = np.asarray(xy, dtype=np.float64), float(facing)
            return
        self.t.append(self.now + dt)
        self.xy.append(np.asarray(xy, dtype=np.float64))
        self.facing.append(float(facing))

    def turn_to(self, heading: float) -> None:
        current = self.facing[-1]
        delta = _wrap(heading - current)
        self._add(abs(delta) / self.cfg.turn_rate_rad_s, self.xy[-1], current + delta)

    def hold(self, dt: float) -> None:
        self._add(dt, self.xy[-1], self.facing[-1])

    def walk_to(self, target: FloatArray, speed: float) -> None:
        delta = np.asarray(target) - self.xy[-1]
        dist = float(np.hypot(*delta))
        if dist < 1e-6:
            return
        self.turn_to(math.atan2(delta[1], delta[0]))
        self._add(dist / speed, target, self.facing[-1])

    def look_around(self, duration: float) -> None:
        end = self.now + duration
        base = self.facing[-1]
        while self.now < end - 1e-6:
            self.hold(min(float(self.rng.uniform(*self.cfg.look_hold_range_s)), end - self.now))
            if self.now >= end - 1e-6:
                break
            heading = base + float(self.rng.uniform(-self.cfg.look_around_max_rad, self.cfg.look_around_max_rad))
            self.turn_to(heading)

    def speed(self) -> float:
        return float(self.rng.uniform(*self.cfg.speed_range_mps))

    def waypoint(self) -> FloatArray:
        half = self.world.room.half_extents - self.cfg.waypoint_margin_m
        return self.rng.uniform(-half, half)


def plan_trajectory(
    world: World, rng: np.random.Generator, duration_s: float, config: MotionConfig | None = None,
    start_s: float = 0.0, height_m: float | None = None,
) -> Trajectory:
    """Random motion of one person over [start_s, start_s + duration_s] (knots may run past the end).

    The person starts inside (random spot, facing anywhere) with ``start_inside_probability``, else
    outside a random door, entering within ``initial_outside_max_s``. Then, repeatedly: with
    ``exit_probability`` leave through a random door, wait outside ``outside_range_s`` and come back
    through the same door (walking outside between doors would cross the room's footprint); otherwise
    walk to a random waypoint and, with ``pause_probability``, pause there looking around.
    """
    cfg = config if config is not None else MotionConfig()
    if not (_finite(duration_s) and 0 < duration_s <= 7 * 24 * 3600.0):
        raise ValueError(f"duration_s must be positive (at most a week), got {duration_s!r}")
    if not _finite(start_s):
        raise ValueError(f"start_s must be finite, got {start_s!r}")
    height = float(rng.uniform(*cfg.height_range_m)) if height_m is None else float(height_m)
    end = float(start_s) + float(duration_s)
    doors = world.doors
    door = doors[0] if doors else None
    if rng.uniform() < cfg.start_inside_probability or door is None:
        half = world.room.half_extents - cfg.waypoint_margin_m
        plan = _Planner(world, rng, cfg, float(start_s), rng.uniform(-half, half), float(rng.uniform(-np.pi, np.pi)))
        inside = True
    else:
        door = doors[int(rng.integers(len(doors)))]
        inward = math.atan2(door.inward_normal[1], door.inward_normal[0])
        plan = _Planner(world, rng, cfg, float(start_s), door.outside_xy, inward)
        plan.hold(float(rng.uniform(0.0, cfg.initial_outside_max_s)))
        inside = False
    while plan.now < end:
        if not inside:  # back in through the door last used (``door``)
            speed = plan.speed()
            plan.walk_to(door.centre_xy, speed)
            plan.walk_to(door.inside_xy, speed)
            inside = True
            continue
        if door is not None and rng.uniform() < cfg.exit_probability:
            door = doors[int(rng.integers(len(doors)))]
            speed = plan.speed()
            plan.walk_to(door.inside_xy, speed)
            plan.walk_to(door.centre_xy, speed)
            plan.walk_to(door.outside_xy, speed)
            plan.hold(float(rng.uniform(*cfg.outside_range_s)))
            inside = False
            continue
        plan.walk_to(plan.waypoint(), plan.speed())
        if rng.uniform() < cfg.pause_probability:
            plan.look_around(float(rng.uniform(*cfg.pause_range_s)))
    return Trajectory(np.array(plan.t), np.array(plan.xy), np.array(plan.facing), height)


def sample_trajectories(
    trajectories: Sequence[Trajectory], t_s: NDArray[np.floating]
) -> tuple[FloatArray, FloatArray]:
    """Positions (T, P, 2) and facings (T, P) of every person at times ``t_s`` (T,)."""
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    xy = np.empty((t.size, len(trajectories), 2))
    facing = np.empty((t.size, len(trajectories)))
    for p, traj in enumerate(trajectories):
        xy[:, p], facing[:, p] = traj.sample(t)
    return xy, facing


# ---------------------------------------------------------------------------------------------------
# Visibility


@dataclass(frozen=True)
class VisibilityConfig:
    """When a camera detects a person and sees their face (metres, degrees, pixels)."""

    min_range_m: float = 0.5
    max_range_m: float = 6.0
    max_face_angle_deg: float = 50.0
    max_face_range_m: float = 4.5
    head_half_width_m: float = 0.12
    shoulder_drop_m: float = 0.35
    occluder_radius_m: float = 0.22
    image_margin_px: float = 2.0

    def __post_init__(self) -> None:
        if not (_finite(self.min_range_m) and _finite(self.max_range_m) and 0 <= self.min_range_m < self.max_range_m):
            raise ValueError(f"need 0 <= min_range_m < max_range_m, got {self.min_range_m!r}, {self.max_range_m!r}")
        if not (_finite(self.max_face_angle_deg) and 0 < self.max_face_angle_deg <= 90):
            raise ValueError(f"max_face_angle_deg must be in (0, 90], got {self.max_face_angle_deg!r}")
        for name in ("max_face_range_m", "head_half_width_m", "shoulder_drop_m", "occluder_radius_m"):
            value = getattr(self, name)
            if not (_finite(value) and value > 0):
                raise ValueError(f"VisibilityConfig.{name} must be positive, got {value!r}")
        if not (_finite(self.image_margin_px) and self.image_margin_px >= 0):
            raise ValueError(f"image_margin_px must be >= 0, got {self.image_margin_px!r}")


@dataclass(frozen=True)
class Visibility:
    """Per (time, person) for one camera: detectable, face visible, range (m, camera to head), face angle
    (deg, between facing and the direction to the camera), occluded (line of sight to the shoulders
    blocked: the depth detector needs the upper body; the face needs the line to the head clear too)."""

    detectable: BoolArray
    face_visible: BoolArray
    range_m: FloatArray
    face_angle_deg: FloatArray
    occluded: BoolArray


def _in_image(camera: SimCamera, points_world: FloatArray, margin_px: float) -> BoolArray:
    """Which (..., 3) world points project inside the image (in front of the camera)."""
    shape = points_world.shape[:-1]
    cam = camera.pose.to_camera(points_world.reshape(-1, 3))
    intr = camera.intrinsics
    z = cam[:, 2]
    front = z > 0.05
    zs = np.where(front, z, 1.0)
    u = intr.fx * cam[:, 0] / zs + intr.cx
    v = intr.fy * cam[:, 1] / zs + intr.cy
    ok = front & (u >= margin_px) & (u <= intr.width - 1 - margin_px)
    ok &= (v >= margin_px) & (v <= intr.height - 1 - margin_px)
    return ok.reshape(shape)


def camera_visibility(
    camera: SimCamera,
    xy: NDArray[np.floating],
    facing_rad: NDArray[np.floating],
    heights_m: NDArray[np.floating],
    in_room: NDArray[np.bool_],
    config: VisibilityConfig | None = None,
) -> Visibility:
    """Visibility of P people at T instants for one camera: ``xy`` (T, P, 2), ``facing_rad`` (T, P),
    ``heights_m`` (P,), ``in_room`` (T, P) (people outside are invisible and occlude nobody)."""
    cfg = config if config is not None else VisibilityConfig()
    pos = np.asarray(xy, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 2:
        raise ValueError(f"xy must have shape (T, P, 2), got {pos.shape}")
    n_t, n_p = pos.shape[:2]
    facing = np.asarray(facing_rad, dtype=np.float64)
    heights = np.asarray(heights_m, dtype=np.float64).reshape(-1)
    inside = np.asarray(in_room, dtype=bool)
    if facing.shape != (n_t, n_p) or heights.shape != (n_p,) or inside.shape != (n_t, n_p):
        raise ValueError(f"facing_rad {facing.shape}, heights_m {heights.shape}, in_room {inside.shape} do not "
                         f"match xy {pos.shape}")
    cam = camera.position
    head_z = heights - 0.12  # head centre (eye height)
    head = np.concatenate([pos, np.broadcast_to(head_z[None, :, None], (n_t, n_p, 1))], axis=2)
    to_cam = cam[:2] - pos
    horiz = np.hypot(to_cam[..., 0], to_cam[..., 1])
    range_m = np.linalg.norm(head - cam, axis=2)
    # in the image: head top, shoulders, both sides of the head (perpendicular to the line of sight)
    side = np.stack([-to_cam[..., 1], to_cam[..., 0]], axis=-1) / np.maximum(horiz, 1e-9)[..., None]
    top = head.copy()
    top[..., 2] = heights
    shoulders = head.copy()
    shoulders[..., 2] = heights - cfg.shoulder_drop_m
    left, right = head.copy(), head.copy()
    left[..., :2] += cfg.head_half_width_m * side
    right[..., :2] -= cfg.head_half_width_m * side
    in_fov = np.ones((n_t, n_p), dtype=bool)
    for pts in (top, shoulders, left, right):
        in_fov &= _in_image(camera, pts, cfg.image_margin_px)
    depth = camera.pose.to_camera(shoulders.reshape(-1, 3))[:, 2].reshape(n_t, n_p)
    in_range = (depth >= cfg.min_range_m) & (depth <= cfg.max_range_m)  # depth (camera z), as a Kinect cuts off
    occluded = _occluded(cam, shoulders, pos, heights, inside, cfg.occluder_radius_m)
    face_occluded = _occluded(cam, head, pos, heights, inside, cfg.occluder_radius_m)
    detectable = inside & in_fov & in_range & ~occluded
    facing_vec = np.stack([np.cos(facing), np.sin(facing)], axis=-1)
    cos_angle = (facing_vec * to_cam).sum(axis=-1) / np.maximum(horiz, 1e-9)
    face_angle = np.degrees(np.arccos(np.clip(cos_angle, -1.0, 1.0)))
    face_visible = detectable & ~face_occluded & (face_angle <= cfg.max_face_angle_deg)
    face_visible &= range_m <= cfg.max_face_range_m
    return Visibility(detectable, face_visible, range_m, face_angle, occluded)


def _occluded(
    cam: FloatArray, head: FloatArray, pos: FloatArray, heights: FloatArray, inside: BoolArray, radius_m: float
) -> BoolArray:
    """Whether the line of sight camera -> point ``head`` (T, P, 3) of person a passes through another
    person b (a vertical cylinder of ``radius_m`` up to b's height) in front of a. (T, P).

    A high camera sees over the head of someone well in front: the ray's height is tested where it
    passes b."""
    n_p = pos.shape[1]
    if n_p < 2:
        return np.zeros(pos.shape[:2], dtype=bool)
    d = head[..., :2] - cam[:2]  # (T, P, 2) horizontal ray direction to each head
    d2 = np.maximum((d * d).sum(axis=-1), 1e-12)
    rel = pos[:, None, :, :] - cam[:2]  # (T, 1, P, 2): occluder b relative to the camera
    s = (d[:, :, None, :] * rel).sum(axis=-1) / d2[:, :, None]  # (T, A, B) closest approach along a's ray
    closest = cam[:2] + s[..., None] * d[:, :, None, :]
    dist = np.linalg.norm(closest - pos[:, None, :, :], axis=-1)
    ray_z = cam[2] + s * (head[:, :, None, 2] - cam[2])
    length = np.sqrt(d2)[:, :, None]
    in_front = (s > 0.0) & (s < 1.0 - radius_m / length)
    blocks = in_front & (dist < radius_m) & (ray_z < heights[None, None, :]) & inside[:, None, :]
    blocks &= ~np.eye(n_p, dtype=bool)[None]
    return blocks.any(axis=2)


def _lone_person_detectable(camera: SimCamera, points: FloatArray, config: VisibilityConfig | None = None,
                            height_m: float = 1.72) -> BoolArray:
    """Whether a person of ``height_m`` standing alone at each (n, 1, 2) floor point is detectable."""
    n = points.shape[0]
    vis = camera_visibility(camera, points, np.zeros((n, 1)), np.array([height_m]), np.ones((n, 1), dtype=bool),
                            config)
    return vis.detectable[:, 0]


def coverage_fraction(world: World, config: VisibilityConfig | None = None, step_m: float = 0.25,
                      height_m: float = 1.72) -> float:
    """Fraction of the room's floor where a lone person of ``height_m`` is detectable by some camera."""
    half = world.room.half_extents
    xs = np.arange(-half[0] + step_m / 2, half[0], step_m)
    ys = np.arange(-half[1] + step_m / 2, half[1], step_m)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(1, -1, 2)
    covered = np.zeros(grid.shape[1], dtype=bool)
    for camera in world.cameras:
        covered |= _lone_person_detectable(camera, grid.reshape(-1, 1, 2), config, height_m)
    return float(covered.mean())


# ---------------------------------------------------------------------------------------------------
# Losses and glances


@dataclass(frozen=True)
class LossSummary:
    """Track losses per person and the visible segments (tracks a perfect tracker would make).

    ``losses[p]``: out-of-view spans longer than the gap limit after person p was first seen.
    ``segments[p]``: (start_s, end_s) of each visible span, spans separated by short gaps merged.
    """

    losses: tuple[int, ...]
    segments: tuple[tuple[tuple[float, float], ...], ...]

    @property
    def total_losses(self) -> int:
        return int(sum(self.losses))

    @property
    def total_segments(self) -> int:
        return int(sum(len(s) for s in self.segments))


def count_losses(t_s: NDArray[np.floating], visible: NDArray[np.bool_], min_gap_s: float = 1.5) -> LossSummary:
    """Count losses from visibility ``visible`` (P, T) sampled at increasing times ``t_s`` (T,).

    A gap is the time between the last sample seen before and the first seen after (or the last sample
    when the person never comes back); gaps longer than ``min_gap_s`` are losses.
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    vis = np.asarray(visible, dtype=bool)
    if vis.ndim != 2 or vis.shape[1] != t.size:
        raise ValueError(f"visible must be (P, T) with T = {t.size}, got {vis.shape}")
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise ValueError("t_s must be strictly increasing")
    if not (_finite(min_gap_s) and min_gap_s >= 0):
        raise ValueError(f"min_gap_s must be >= 0, got {min_gap_s!r}")
    losses: list[int] = []
    segments: list[tuple[tuple[float, float], ...]] = []
    for row in vis:
        idx = np.flatnonzero(row)
        if idx.size == 0:
            losses.append(0)
            segments.append(())
            continue
        gaps = t[idx[1:]] - t[idx[:-1]]
        breaks = np.flatnonzero(gaps > min_gap_s)
        n_loss = int(breaks.size) + int(t[-1] - t[idx[-1]] > min_gap_s)
        starts = np.concatenate([[idx[0]], idx[breaks + 1]])
        ends = np.concatenate([idx[breaks], [idx[-1]]])
        losses.append(n_loss)
        segments.append(tuple((float(t[a]), float(t[b])) for a, b in zip(starts, ends, strict=True)))
    return LossSummary(tuple(losses), tuple(segments))


def glance_ids(t_s: NDArray[np.floating], visible: NDArray[np.bool_], max_gap_s: float = 0.5) -> tuple[
        NDArray[np.int64], int]:
    """Number the glances in one camera's face-visibility series of one person.

    A glance is a run of frames (times ``t_s``) with ``visible`` true; runs separated by less than
    ``max_gap_s`` are one glance. Returns per-frame glance index (-1 where not visible) and the count.
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    vis = np.asarray(visible, dtype=bool).reshape(-1)
    if vis.shape != t.shape:
        raise ValueError(f"visible {vis.shape} and t_s {t.shape} must have the same length")
    ids = np.full(t.size, -1, dtype=np.int64)
    idx = np.flatnonzero(vis)
    if idx.size == 0:
        return ids, 0
    new = np.concatenate([[True], np.diff(t[idx]) > max_gap_s])
    ids[idx] = np.cumsum(new) - 1
    return ids, int(new.sum())

