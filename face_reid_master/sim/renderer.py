"""Synthetic registered RGB-D frames of people on a floor, with real face photos on their heads.

Used by tests (and the scenario simulator) to drive the real camera pipeline - depth clustering,
head ROI, face detection, alignment, embedding - without recorded data. Geometry is analytic ray
casting of a few primitives per person (vertical elliptic cylinders and ellipsoids) over every pixel
of a pinhole camera, vectorised with numpy and culled to each primitive's projected bounding box.
Depth and colour share one set of intrinsics (a registered pair); depth is the camera-frame z.

Faces: a face crop (see :func:`crop_face_for_rendering`) is projected orthographically along the
person's facing direction onto the front of the head, so a face detector sees a face of real size at
the right place on the head, foreshortened when the person turns, and hidden exactly where the
z-buffer says the head is hidden.

Bodies: flat colours by default; with ``body_texture_bgr`` (a person crop, top of the head to the feet,
e.g. from a re-id dataset) every body primitive (neck, shoulders, torso, arms, legs) takes its colour from
the crop as a billboard facing the camera: a hit point's lateral offset from the body axis (across the
line of sight) gives the crop column, its height above the floor the row (the crop's height spans the
person's). Colour and depth stay consistent: the texture only colours surfaces the ray caster hit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from statistics import NormalDist

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.checks import check_bgr_image, is_finite_number

F32 = NDArray[np.float32]

# --- Body model (metres, person frame: forward, left, up). Limbs scale with height, the head does not.
HEAD_SEMI_AXES_M = (0.10, 0.08, 0.12)  # cranium ellipsoid: 0.20 deep x 0.16 wide x 0.24 tall
_JAW_SEMI_AXES_M = (0.09, 0.072)  # face/jaw: a vertical elliptic cylinder, flat-fronted like a real face
_JAW_UP_RANGE_M = (-0.118, 0.0)  # relative to the head centre (chin ... eye line)
_NECK_RADIUS_M = 0.055
_ARM_RADIUS_M = 0.045
_LEG_SEMI_AXES_M = (0.075, 0.065)
_LEG_OFFSET_M = 0.085  # lateral offset of each leg's axis
_TORSO_DEPTH_SEMI_M = 0.12
_SHOULDER_SEMI_HEIGHT_M = 0.07

# --- Face placement. YuNet's box on real photos: eye distance / box height = 0.346 (median over the
# 176 fixture photos), eye line at 0.385 of the box height from its top. With a 0.063 m interpupillary
# distance that is a ~0.18 m tall, 0.135 m wide box whose centre is 0.02 m below the eyes; the eyes sit
# at mid-height of the head, so the box bottom (chin) is near the bottom of the head.
FACE_BOX_HEIGHT_M = 0.18
FACE_BOX_WIDTH_M = 0.135
FACE_BOX_CENTRE_UP_M = -0.02  # box centre height relative to the head centre
_FACE_FRONT_M = 0.09  # forward offset of the plane on which the expected face box is reported

_NEAR_M = 0.05
_REMAP_COLUMNS = 4096
_DEFAULT_SKIN_BGR = (120, 150, 200)

_PART_CRANIUM, _PART_JAW, _PART_NECK, _PART_SHOULDERS, _PART_TORSO, _PART_ARM, _PART_LEG = range(7)
_HEAD_PARTS = (_PART_CRANIUM, _PART_JAW)


@dataclass(frozen=True)
class SyntheticPerson:
    """One standing person: position on the floor (m), height, facing and appearance.

    ``facing_rad`` is the direction the person faces in the world xy plane (0 = +x, pi/2 = +y).
    ``face_image_bgr`` is a face crop as made by :func:`crop_face_for_rendering` with margin
    ``face_crop_margin`` (detector box centred, crop side = box height * (1 + 2 margin)); None renders a
    plain head. ``body_texture_bgr`` is a person crop (head top to feet, the person centred; square pixels)
    mapped onto the body as a billboard facing the camera (choose the crop whose orientation matches the
    view); None: flat ``body_color_bgr`` / ``legs_color_bgr``.
    """

    x_m: float
    y_m: float
    height_m: float = 1.75
    facing_rad: float = 0.0
    face_image_bgr: NDArray[np.uint8] | None = field(default=None, compare=False, repr=False)
    shoulder_width_m: float = 0.45
    body_color_bgr: tuple[int, int, int] = (150, 80, 40)
    legs_color_bgr: tuple[int, int, int] = (60, 50, 45)
    hair_color_bgr: tuple[int, int, int] = (30, 40, 55)
    face_crop_margin: float = 0.15
    body_texture_bgr: NDArray[np.uint8] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "facing_rad", "height_m", "shoulder_width_m", "face_crop_margin"):
            value = getattr(self, name)
            if not is_finite_number(value):
                raise ValueError(f"SyntheticPerson.{name} must be a finite number, got {value!r}")
        if not 1.0 <= self.height_m <= 2.3:
            raise ValueError(f"SyntheticPerson.height_m must be in [1.0, 2.3] m, got {self.height_m!r}")
        if not 0.3 <= self.shoulder_width_m <= 0.8:
            raise ValueError(
                f"SyntheticPerson.shoulder_width_m must be in [0.3, 0.8] m, got {self.shoulder_width_m!r}"
            )
        if not 0.0 <= self.face_crop_margin <= 1.0:
            raise ValueError(
                f"SyntheticPerson.face_crop_margin must be in [0, 1], got {self.face_crop_margin!r}"
            )
        for name in ("body_color_bgr", "legs_color_bgr", "hair_color_bgr"):
            _check_colour(getattr(self, name), f"SyntheticPerson.{name}")
        face = self.face_image_bgr
        if face is not None:
            _check_bgr(face, "SyntheticPerson.face_image_bgr")
            if min(face.shape[:2]) < 16:
                raise ValueError(
                    f"SyntheticPerson.face_image_bgr is too small ({face.shape[1]}x{face.shape[0]} px), "
                    "need >= 16 px"
                )
        texture = self.body_texture_bgr
        if texture is not None:
            _check_bgr(texture, "SyntheticPerson.body_texture_bgr")
            if texture.shape[0] < 16 or texture.shape[1] < 4:
                raise ValueError(f"SyntheticPerson.body_texture_bgr is too small ({texture.shape[1]}x"
                                 f"{texture.shape[0]} px), need >= 4x16 px")

    @property
    def head_centre_world(self) -> NDArray[np.float64]:
        """Centre of the head (cranium ellipsoid, eye height) in the world frame (m)."""
        return np.array([self.x_m, self.y_m, self.height_m - HEAD_SEMI_AXES_M[2]], dtype=np.float64)


@dataclass(frozen=True)
class RenderedFrame:
    """A registered colour + depth frame and per-person ground truth.

    ``depth_mm``: camera-frame z in millimetres, 0 = no return. ``face_visible[i]``: person i has a
    face pasted (face image given, facing the camera within the angle limit) that is mostly unoccluded
    and inside the image. ``face_boxes_xywh[i]``: where a face detector's box should be (pixels, NaN
    when not visible). ``person_ids``: index of the person seen at each pixel (-1 = none).
    """

    rgb_bgr: NDArray[np.uint8]
    depth_mm: NDArray[np.uint16]
    face_visible: list[bool]
    head_centres_world: NDArray[np.float64]
    face_boxes_xywh: NDArray[np.float64]
    person_ids: NDArray[np.int16]


@dataclass(frozen=True)
class SceneObject:
    """A static object part in the world (m): a vertical elliptic cylinder (``centre`` its mid-height axis point)
    or an ellipsoid, axis-aligned in the world, with a flat colour. Person-sized clutter is made of these."""

    shape: str  # "cylinder" or "ellipsoid"
    centre: tuple[float, float, float]
    semi_axes: tuple[float, float, float]  # (x, y, z half-extents) m
    color_bgr: tuple[int, int, int] = (90, 110, 120)

    def __post_init__(self) -> None:
        if self.shape not in ("cylinder", "ellipsoid"):
            raise ValueError(f"SceneObject.shape must be 'cylinder' or 'ellipsoid', got {self.shape!r}")
        if len(self.centre) != 3 or not all(is_finite_number(v) for v in self.centre):
            raise ValueError(f"SceneObject.centre must be 3 finite numbers (m), got {self.centre!r}")
        if len(self.semi_axes) != 3 or not all(is_finite_number(v) and v > 0 for v in self.semi_axes):
            raise ValueError(f"SceneObject.semi_axes must be 3 positive numbers (m), got {self.semi_axes!r}")
        _check_colour(self.color_bgr, "SceneObject.color_bgr")


CLUTTER_KINDS = ("coat_stand", "plant", "floor_lamp", "pillar", "door_frame", "cabinet")


def clutter_object(kind: str, x_m: float, y_m: float) -> list[SceneObject]:
    """The parts of one person-sized static object at (x, y) on the floor: a coat stand with coats, a potted
    plant, a floor lamp, a pillar, a door frame (along x) or a tall cabinet."""
    dark, wood, green, white = (40, 40, 45), (60, 90, 130), (50, 120, 60), (200, 205, 210)
    if kind == "coat_stand":
        return [SceneObject("cylinder", (x_m, y_m, 0.9), (0.025, 0.025, 0.9), dark),
                SceneObject("ellipsoid", (x_m, y_m, 1.78), (0.06, 0.06, 0.05), dark),
                SceneObject("ellipsoid", (x_m + 0.05, y_m, 1.3), (0.16, 0.22, 0.38), (90, 60, 50)),
                SceneObject("ellipsoid", (x_m - 0.05, y_m + 0.05, 1.35), (0.15, 0.18, 0.33), (60, 60, 110))]
    if kind == "plant":
        return [SceneObject("cylinder", (x_m, y_m, 0.2), (0.18, 0.18, 0.2), wood),
                SceneObject("ellipsoid", (x_m, y_m, 0.95), (0.35, 0.3, 0.55), green),
                SceneObject("ellipsoid", (x_m + 0.1, y_m, 1.45), (0.15, 0.15, 0.2), green)]
    if kind == "floor_lamp":
        return [SceneObject("cylinder", (x_m, y_m, 0.02), (0.15, 0.15, 0.02), dark),
                SceneObject("cylinder", (x_m, y_m, 0.8), (0.02, 0.02, 0.8), dark),
                SceneObject("cylinder", (x_m, y_m, 1.7), (0.2, 0.2, 0.12), white)]
    if kind == "pillar":
        return [SceneObject("cylinder", (x_m, y_m, 1.5), (0.2, 0.2, 1.5), white)]
    if kind == "door_frame":
        return [SceneObject("cylinder", (x_m - 0.45, y_m, 1.05), (0.04, 0.06, 1.05), wood),
                SceneObject("cylinder", (x_m + 0.45, y_m, 1.05), (0.04, 0.06, 1.05), wood),
                SceneObject("cylinder", (x_m, y_m, 2.14), (0.49, 0.06, 0.04), wood)]
    if kind == "cabinet":
        return [SceneObject("cylinder", (x_m, y_m, 0.85), (0.3, 0.22, 0.85), wood)]
    raise ValueError(f"clutter kind must be one of {', '.join(CLUTTER_KINDS)}, got {kind!r}")


def _check_colour(value: object, name: str) -> None:
    """Colours are hashable (B, G, R) tuples of ints in [0, 255]."""
    if (
        not isinstance(value, tuple)
        or len(value) != 3
        or not all(is_finite_number(c) and float(c).is_integer() and 0 <= c <= 255 for c in value)
    ):
        raise ValueError(f"{name} must be 3 integers in [0, 255] (B, G, R), got {value!r}")


def _check_bgr(image: object, name: str) -> None:
    """A non-empty HxWx3 uint8 array (:func:`check_bgr_image`, colour only)."""
    if check_bgr_image(image, name).ndim != 3:
        raise ValueError(f"{name} must be an HxWx3 uint8 BGR array, got shape {np.shape(image)}")


@dataclass
class _Primitive:
    """A vertical elliptic cylinder (open bottom, capped top) or an ellipsoid in a person's frame."""

    is_ellipsoid: bool
    centre: NDArray[np.float64]  # world; for a cylinder the mid-height point of its axis
    semi_axes: tuple[float, float, float]  # (forward, lateral, vertical half-extent) m
    part: int
    albedo: NDArray[np.float64]


@dataclass
class _Hit:
    """Pixels where a primitive is hit (nearest entering root): flat image indices, depth, surface."""

    flat: NDArray[np.intp]
    depth: F32
    closer: NDArray[np.bool_]  # nearer than everything cast before it
    local: NDArray[np.float64]  # (3, n) hit points, person frame, relative to the primitive centre
    normal: NDArray[np.float64]  # (3, n) unit normals, person frame


class _Caster:
    """Rays through the pixel centres of one camera, cast against primitives inside their pixel boxes.

    With the ray direction d = M (xn, yn, 1) in a primitive's unit frame, |d|^2 and o.d are quadratic
    and linear forms of the normalised pixel coordinates, so each costs a few broadcast operations.
    The ray parameter is the camera-frame z, i.e. the depth image value.
    """

    def __init__(self, intrinsics: CameraIntrinsics, pose: CameraPose) -> None:
        self.intr = intrinsics
        self.pose = pose
        self.xn = (np.arange(intrinsics.width) - intrinsics.cx) / intrinsics.fx
        self.yn = (np.arange(intrinsics.height) - intrinsics.cy) / intrinsics.fy
        self.xn32, self.yn32 = self.xn.astype(np.float32), self.yn.astype(np.float32)
        self.xn2, self.yn2 = self.xn32 * self.xn32, self.yn32 * self.yn32
        signs = [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
        self._signs = np.array(signs, dtype=np.float64)

    def pixel_boxes(self, centres: NDArray[np.float64], halves: NDArray[np.float64]) -> NDArray[np.int64]:
        """(N, 4) image boxes (r0, r1, c0, c1) covering world boxes centre +- half; r0 = -1: not visible."""
        corners = centres[:, None, :] + self._signs[None] * halves[:, None, :]
        cam = (corners - self.pose.translation) @ self.pose.rotation
        w, h = self.intr.width, self.intr.height
        z = cam[..., 2]
        in_front = z > _NEAR_M
        zs = np.where(in_front, z, 1.0)
        u = self.intr.fx * cam[..., 0] / zs + self.intr.cx
        v = self.intr.fy * cam[..., 1] / zs + self.intr.cy
        boxes = np.stack([np.floor(v.min(axis=1)) - 1, np.ceil(v.max(axis=1)) + 2,
                          np.floor(u.min(axis=1)) - 1, np.ceil(u.max(axis=1)) + 2], axis=1)
        boxes = np.clip(boxes, 0, [h, h, w, w]).astype(np.int64)
        partly = in_front.any(axis=1) & ~in_front.all(axis=1)
        boxes[partly] = [0, h, 0, w]
        hidden = ~in_front.any(axis=1) | (boxes[:, 0] >= boxes[:, 1]) | (boxes[:, 2] >= boxes[:, 3])
        boxes[hidden] = -1
        return boxes

    def cast(self, prim: _Primitive, box: NDArray[np.int64], mat: NDArray[np.float64],
             org: NDArray[np.float64], zflat: F32, all_hits: bool) -> _Hit | None:
        """Hits of one primitive in its box; only those nearer than ``zflat`` unless ``all_hits``."""
        r0, r1, c0, c1 = (int(v) for v in box)
        xs, ys = self.xn32[c0:c1], self.yn32[r0:r1]
        k = 3 if prim.is_ellipsoid else 2
        sub, o = mat[:k], org[:k]
        c_term = float(o @ o) - 1.0  # > 0: camera outside the ellipsoid / the infinite cylinder
        above_top = not prim.is_ellipsoid and org[2] > 1.0
        if c_term <= 0.0 and not above_top:  # camera inside the primitive: not rendered
            return None
        q = (sub.T @ sub).tolist()
        lb = (sub.T @ o).tolist()
        aa = np.multiply.outer(ys * (2.0 * q[0][1]), xs)
        aa += q[0][0] * self.xn2[c0:c1] + (2.0 * q[0][2]) * xs
        aa += (q[1][1] * self.yn2[r0:r1] + (2.0 * q[1][2]) * ys + q[2][2])[:, None]
        bb = np.add.outer(lb[1] * ys + lb[2], lb[0] * xs)
        disc = bb * bb
        disc -= c_term * aa
        valid = disc > 0.0
        np.maximum(disc, 0.0, out=disc)
        root = np.sqrt(disc, out=disc)
        t = bb + root
        t /= aa
        np.negative(t, out=t)
        valid &= t > _NEAR_M
        cap = None
        if not prim.is_ellipsoid:
            m2 = mat[2].tolist()
            dz = np.add.outer(m2[1] * ys + m2[2], m2[0] * xs)
            z_side = t * dz
            z_side += float(org[2])
            valid &= np.abs(z_side) <= 1.0
            if above_top:  # the top cap: where the ray crosses the top plane inside the ellipse
                with np.errstate(divide="ignore", invalid="ignore"):
                    t_cap = (1.0 - float(org[2])) / dz
                inside = aa * t_cap
                inside += 2.0 * bb
                inside *= t_cap
                inside += c_term  # |o_xy + t d_xy|^2 - 1 at t_cap
                cap = (dz < 0.0) & (t_cap > _NEAR_M) & (inside <= 0.0) & ~valid
                t = np.where(cap, t_cap, t)
                valid |= cap
        rr, cc = np.nonzero(valid)
        if rr.size == 0:
            return None
        depth = t[rr, cc]
        flat = (rr + r0) * self.intr.width + (cc + c0)
        closer = depth < zflat[flat]
        if not all_hits:
            rr, cc, depth, flat = rr[closer], cc[closer], depth[closer], flat[closer]
            closer = np.ones(rr.size, dtype=bool)
        dirs = mat @ np.stack([self.xn[cc + c0], self.yn[rr + r0], np.ones(rr.size)])
        unit = org[:, None] + depth * dirs
        scale = np.array(prim.semi_axes)[:, None]
        normal = unit / scale
        if not prim.is_ellipsoid:
            normal[2] = 0.0
            if cap is not None:
                normal[:, cap[rr, cc]] = [[0.0], [0.0], [1.0]]
        normal /= np.maximum(np.sqrt((normal * normal).sum(axis=0)), 1e-12)
        return _Hit(flat, depth, closer, unit * scale, normal)


def _person_rotation(person: SyntheticPerson) -> NDArray[np.float64]:
    """World <- person frame (columns: forward, left, up)."""
    cf, sf = math.cos(person.facing_rad), math.sin(person.facing_rad)
    return np.array([[cf, -sf, 0.0], [sf, cf, 0.0], [0.0, 0.0, 1.0]])


def _person_primitives(person: SyntheticPerson) -> list[_Primitive]:
    """Primitives of one person: cranium, jaw, neck, shoulders, torso, arms, legs."""
    h = person.height_m
    s = h / 1.75
    rot = _person_rotation(person)
    base = np.array([person.x_m, person.y_m, 0.0])
    half_w = person.shoulder_width_m / 2.0
    hip_z = 0.50 * h
    shoulder_z = h - 0.30 * s - _SHOULDER_SEMI_HEIGHT_M  # centre of the shoulder ellipsoid
    head = person.head_centre_world
    body = np.array(person.body_color_bgr, dtype=np.float64)
    legs = np.array(person.legs_color_bgr, dtype=np.float64)
    hair = np.array(person.hair_color_bgr, dtype=np.float64)

    def at(fwd: float, lat: float, z: float) -> NDArray[np.float64]:
        return base + rot @ np.array([fwd, lat, z])

    def cyl(z0: float, z1: float, lat: float, semi: tuple[float, float], part: int,
            albedo: NDArray[np.float64]) -> _Primitive:
        semi_axes = (semi[0], semi[1], 0.5 * (z1 - z0))
        return _Primitive(False, at(0.0, lat, 0.5 * (z0 + z1)), semi_axes, part, albedo)

    jaw_lo, jaw_hi = head[2] + _JAW_UP_RANGE_M[0], head[2] + _JAW_UP_RANGE_M[1]
    prims = [
        _Primitive(True, head, HEAD_SEMI_AXES_M, _PART_CRANIUM, hair),
        cyl(jaw_lo, jaw_hi, 0.0, _JAW_SEMI_AXES_M, _PART_JAW, hair),
        cyl(shoulder_z, head[2] - 0.04, 0.0, (_NECK_RADIUS_M, _NECK_RADIUS_M), _PART_NECK, body),
        _Primitive(True, at(0.0, 0.0, shoulder_z), (_TORSO_DEPTH_SEMI_M, half_w, _SHOULDER_SEMI_HEIGHT_M),
                   _PART_SHOULDERS, body),
        cyl(hip_z - 0.05, shoulder_z, 0.0, (_TORSO_DEPTH_SEMI_M, half_w - 0.09), _PART_TORSO, body),
    ]
    arm_lat = half_w - _ARM_RADIUS_M - 0.005
    for side in (-1.0, 1.0):
        arm = (_ARM_RADIUS_M, _ARM_RADIUS_M)
        prims.append(cyl(hip_z - 0.08 * s, shoulder_z, side * arm_lat, arm, _PART_ARM, body))
        prims.append(cyl(0.0, hip_z + 0.05, side * _LEG_OFFSET_M, _LEG_SEMI_AXES_M, _PART_LEG, legs))
    return prims


_ENV_CACHE: dict[tuple[object, ...], tuple[F32, NDArray[np.uint8]]] = {}
_ENV_CACHE_SIZE = 8


def _environment(
    caster: _Caster, floor_size_m: float, walls: bool, wall_height_m: float,
    background_bgr: tuple[int, int, int] | NDArray[np.uint8],
) -> tuple[F32, NDArray[np.uint8]]:
    """Depth (inf = nothing) and colour of floor, walls and background; cached: a static camera pays once."""
    image_background = isinstance(background_bgr, np.ndarray)
    key = (caster.intr, caster.pose.rotation.tobytes(), caster.pose.translation.tobytes(), floor_size_m,
           walls, wall_height_m, None if image_background else tuple(int(c) for c in background_bgr))
    cached = _ENV_CACHE.get(key)
    if cached is None:
        depth, colour = _render_environment(caster, floor_size_m, walls, wall_height_m)
        if not image_background:
            colour[~np.isfinite(depth)] = background_bgr
        cached = (depth, colour)
        if len(_ENV_CACHE) >= _ENV_CACHE_SIZE:
            _ENV_CACHE.pop(next(iter(_ENV_CACHE)))
        _ENV_CACHE[key] = cached
    depth, colour = cached[0].copy(), cached[1].copy()
    if image_background:
        miss = ~np.isfinite(depth)
        colour[miss] = background_bgr[miss]
    return depth, colour


def _render_environment(
    caster: _Caster, floor_size_m: float, walls: bool, wall_height_m: float
) -> tuple[F32, NDArray[np.uint8]]:
    """Textured floor square centred on the world origin, plus optional walls on its edges."""
    rot = caster.pose.rotation
    ox, oy, oz = (float(v) for v in caster.pose.translation)
    xn, yn = caster.xn32, caster.yn32
    dx, dy, dz = (np.add.outer(float(r[1]) * yn + float(r[2]), float(r[0]) * xn) for r in rot)
    half = floor_size_m / 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -oz / dz
    on_floor = (dz < -1e-9) & (t > _NEAR_M)
    t = np.where(on_floor, t, np.float32(0.0))
    hx, hy = t * dx + np.float32(ox), t * dy + np.float32(oy)
    on_floor &= (np.abs(hx) <= half) & (np.abs(hy) <= half)
    depth = np.where(on_floor, t, np.float32(np.inf))
    # 0.5 m tiles with a per-tile tone, grout lines and a fine grain, so the floor is not texture-less;
    # computed on the floor pixels only, in float32
    idx = np.flatnonzero(on_floor)
    fx_, fy_ = hx.reshape(-1)[idx] * np.float32(2.0), hy.reshape(-1)[idx] * np.float32(2.0)  # tile units
    ix, iy = np.floor(fx_), np.floor(fy_)
    fx_ -= ix
    fy_ -= iy
    tone = ((ix * 7.0 + iy * 13.0) % 5.0) * np.float32(0.05) + np.float32(0.85)
    grout = (np.minimum(fx_, 1.0 - fx_) < 0.02) | (np.minimum(fy_, 1.0 - fy_) < 0.02)
    gx, gy = (fx_ + ix) * np.float32(0.5), (fy_ + iy) * np.float32(0.5)  # back to metres
    grain = np.float32(0.06) * np.sin(gx * np.float32(41.0) + np.sin(gy * np.float32(23.0)) * np.float32(2.0))
    grain *= np.cos(gy * np.float32(37.0))
    gain = np.where(grout, np.float32(0.55), tone + grain)
    colour = np.zeros((*depth.shape, 3), dtype=np.uint8)
    floor_albedo = np.array([150.0, 165.0, 175.0], dtype=np.float32)
    colour.reshape(-1, 3)[idx] = np.clip(gain[:, None] * floor_albedo, 0, 255).astype(np.uint8)
    if walls:
        wall_albedo = np.array([205.0, 210.0, 215.0], dtype=np.float32)
        specs = ((half, dx, ox, dy, oy, 0.95), (-half, dx, ox, dy, oy, 0.85),
                 (half, dy, oy, dx, ox, 0.9), (-half, dy, oy, dx, ox, 0.8))
        for wall_at, d_across, o_across, d_along, o_along, wall_tone in specs:
            with np.errstate(divide="ignore", invalid="ignore"):
                tw = np.float32(wall_at - o_across) / d_across
            on_wall = (tw > _NEAR_M) & (tw < depth)
            tw = np.where(on_wall, tw, np.float32(0.0))
            zw = tw * dz
            zw += np.float32(oz)
            on_wall &= np.abs(tw * d_along + np.float32(o_along)) <= half
            on_wall &= (zw >= 0.0) & (zw <= wall_height_m)
            depth = np.where(on_wall, tw, depth)
            idx = np.flatnonzero(on_wall)
            shade = np.float32(wall_tone) - np.float32(0.1 / wall_height_m) * zw.reshape(-1)[idx]
            colour.reshape(-1, 3)[idx] = (shade[:, None] * wall_albedo).astype(np.uint8)
    return depth, colour


_NORMAL_TABLE: list[F32] = []


def _gaussian_noise(rng: np.random.Generator, n: int) -> F32:
    """n standard-normal samples, fast: 16 random bits index a 65536-entry inverse-CDF table."""
    if not _NORMAL_TABLE:
        dist = NormalDist()
        quantiles = [dist.inv_cdf((i + 0.5) / 65536) for i in range(65536)]
        _NORMAL_TABLE.append(np.array(quantiles, dtype=np.float32))
    index = np.frombuffer(rng.bytes(2 * n), dtype=np.uint16)
    return _NORMAL_TABLE[0][index]


def _face_texture(person: SyntheticPerson, pixels_per_m: float) -> tuple[NDArray[np.uint8], float]:
    """The face crop resampled to about 2 texels per rendered pixel, and its side in metres."""
    crop = person.face_image_bgr
    assert crop is not None
    side_m = FACE_BOX_HEIGHT_M * (1.0 + 2.0 * person.face_crop_margin)
    longest = max(crop.shape[:2])
    target = int(np.clip(2.0 * side_m * pixels_per_m, 24, longest))
    if target < longest:
        scale = target / longest
        size = (max(round(crop.shape[1] * scale), 8), max(round(crop.shape[0] * scale), 8))
        crop = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
    return crop, side_m


def _skin_colour(face: NDArray[np.uint8] | None) -> NDArray[np.float64]:
    """Median colour of the cheeks/nose area of the face crop, for the head skin around the pasted face."""
    if face is None:
        return np.array(_DEFAULT_SKIN_BGR, dtype=np.float64)
    h, w = face.shape[:2]
    centre = face[int(0.45 * h): int(0.65 * h), int(0.35 * w): int(0.65 * w)].reshape(-1, 3)
    return np.median(centre, axis=0).astype(np.float64)


def _shade(normal: NDArray[np.float64], light_local: NDArray[np.float64]) -> NDArray[np.float64]:
    """Ambient + Lambert shading factor in [0.45, 1]."""
    return 0.45 + 0.55 * np.clip(light_local @ normal, 0.0, 1.0)


def _head_colours(
    hits: list[tuple[_Hit, NDArray[np.float64], int]],
    person: SyntheticPerson,
    light_local: NDArray[np.float64],
    face: tuple[NDArray[np.uint8], float] | None,
) -> tuple[list[NDArray[np.float64]], list[NDArray[np.bool_]]]:
    """Colours of each head primitive's hits (hair, skin, projected face) and which hits are face core."""
    hair = np.array(person.hair_color_bgr, dtype=np.float64)
    skin = _skin_colour(person.face_image_bgr)
    colours, cores = [], []
    for hit, offset, _part in hits:
        fwd, lat, up = hit.local + offset[:, None]
        shade = _shade(hit.normal, light_local)
        is_hair = (up > 0.06) | (fwd < -0.03) | ((up > 0.0) & (fwd < 0.03))
        base = np.where(is_hair[:, None], hair, skin) * shade[:, None]
        rel_up = up - FACE_BOX_CENTRE_UP_M
        ell = np.hypot(lat / (0.52 * FACE_BOX_WIDTH_M), rel_up / (0.55 * FACE_BOX_HEIGHT_M))
        front = fwd > 0.0
        cores.append(front & (ell <= 0.9) & (hit.normal[0] > 0.2))
        if face is None:
            colours.append(base)
            continue
        texture, side_m = face
        th, tw = texture.shape[:2]
        map_x = ((0.5 + lat / side_m) * tw - 0.5).astype(np.float32)[None, :]
        map_y = ((0.5 - rel_up / side_m) * th - 0.5).astype(np.float32)[None, :]
        sampled = cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0]
        alpha = np.clip((1.15 - ell) / 0.25, 0.0, 1.0) * np.clip(hit.normal[0] * 4.0, 0.0, 1.0) * front
        pasted = sampled.astype(np.float64) * (0.7 + 0.3 * shade)[:, None]
        colours.append(alpha[:, None] * pasted + (1.0 - alpha[:, None]) * base)
    return colours, cores


def _body_texture_colours(hit: _Hit, prim: _Primitive, person: SyntheticPerson, rot: NDArray[np.float64],
                          across: NDArray[np.float64], shade: NDArray[np.float64]) -> NDArray[np.float64]:
    """Colours of a body primitive's hits from the person's crop, mapped as a billboard facing the camera.

    ``across``: the horizontal unit vector pointing to the image's right at the person (world frame).
    """
    texture = person.body_texture_bgr
    assert texture is not None
    th, tw = texture.shape[:2]
    world = prim.centre[:, None] + rot @ hit.local  # (3, n) hit points
    lateral = (world[0] - person.x_m) * across[0] + (world[1] - person.y_m) * across[1]
    width_m = person.height_m * tw / th  # square pixels: the crop's width in metres at the person
    n = lateral.size
    if n == 0:
        return np.zeros((0, 3))
    rows = -(-n // _REMAP_COLUMNS)  # cv2.remap maps must be narrower than 32767: fold the hits into rows
    map_x = np.zeros(rows * _REMAP_COLUMNS, dtype=np.float32)
    map_y = np.zeros_like(map_x)
    map_x[:n] = (0.5 + lateral / width_m) * tw - 0.5
    map_y[:n] = (1.0 - world[2] / person.height_m) * th - 0.5
    sampled = cv2.remap(texture, map_x.reshape(rows, -1), map_y.reshape(rows, -1), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE).reshape(-1, 3)[:n]
    return sampled.astype(np.float64) * (0.7 + 0.3 * shade)[:, None]


def _expected_face_box(
    person: SyntheticPerson, intrinsics: CameraIntrinsics, pose: CameraPose
) -> NDArray[np.float64] | None:
    """Projected bounding box (x, y, w, h) of the face box on the head's front; None if not in the image."""
    rot = _person_rotation(person)
    corners = np.array([
        person.head_centre_world + rot @ np.array([_FACE_FRONT_M, sl * FACE_BOX_WIDTH_M / 2,
                                                   FACE_BOX_CENTRE_UP_M + su * FACE_BOX_HEIGHT_M / 2])
        for sl in (-1, 1) for su in (-1, 1)
    ])
    cam = pose.to_camera(corners)
    if np.any(cam[:, 2] <= _NEAR_M):
        return None
    uv = intrinsics.project(cam)
    (x0, y0), (x1, y1) = uv.min(axis=0), uv.max(axis=0)
    if x0 < 0 or y0 < 0 or x1 > intrinsics.width - 1 or y1 > intrinsics.height - 1:
        return None
    return np.array([x0, y0, x1 - x0, y1 - y0])


def _facing_angle_deg(person: SyntheticPerson, camera_xy: NDArray[np.float64]) -> float:
    """Angle in the floor plane between where the person faces and the direction to the camera."""
    to_cam = camera_xy - np.array([person.x_m, person.y_m])
    dist = float(np.linalg.norm(to_cam))
    if dist < 1e-6:
        return 180.0
    facing = np.array([math.cos(person.facing_rad), math.sin(person.facing_rad)])
    return math.degrees(math.acos(float(np.clip(facing @ to_cam / dist, -1.0, 1.0))))


def _render_objects(caster: _Caster, objects: list[SceneObject], zflat: F32,
                    colour_flat: NDArray[np.uint8]) -> None:
    """Z-buffer static objects (world-aligned primitives, lit from above the camera) into the frame."""
    for i, obj in enumerate(objects):
        if not isinstance(obj, SceneObject):
            raise TypeError(f"objects[{i}] must be a SceneObject, got {type(obj).__name__}")
    if not objects:
        return
    centres = np.array([o.centre for o in objects], dtype=np.float64)
    semi = np.array([o.semi_axes for o in objects], dtype=np.float64)
    boxes = caster.pixel_boxes(centres, semi)
    rot = caster.pose.rotation
    for n, obj in enumerate(objects):
        if boxes[n, 0] < 0:
            continue
        prim = _Primitive(obj.shape == "ellipsoid", centres[n], obj.semi_axes, -1,
                          np.array(obj.color_bgr, dtype=np.float64))
        hit = caster.cast(prim, boxes[n], rot / semi[n][:, None], (caster.pose.translation - centres[n]) / semi[n],
                          zflat, all_hits=False)
        if hit is None:
            continue
        zflat[hit.flat] = hit.depth
        light = caster.pose.translation - centres[n] + np.array([0.0, 0.0, 1.5])
        shade = _shade(hit.normal, light / np.linalg.norm(light))
        colour_flat[hit.flat] = np.clip(prim.albedo * shade[:, None], 0, 255).astype(np.uint8)


def render_scene(
    people: Sequence[SyntheticPerson],
    intrinsics: CameraIntrinsics,
    camera_pose: CameraPose,
    *,
    rng: np.random.Generator | None = None,
    depth_noise: bool = True,
    depth_noise_coeff_per_m: float = 1.5e-3,
    min_range_m: float = 0.5,
    max_range_m: float = 8.0,
    max_face_angle_deg: float = 60.0,
    min_visible_face_fraction: float = 0.7,
    floor_size_m: float = 16.0,
    walls: bool = False,
    wall_height_m: float = 3.0,
    background_bgr: tuple[int, int, int] | NDArray[np.uint8] = (70, 70, 70),
    objects: Sequence[SceneObject] = (),
) -> RenderedFrame:
    """Render a registered colour + depth frame of ``people`` standing on the floor.

    The floor is a textured square of side ``floor_size_m`` centred on the world origin (``walls`` on
    its edges, ``wall_height_m`` tall). Depth noise is Gaussian with std ``depth_noise_coeff_per_m *
    z^2`` (Kinect-like), quantised to mm; returns outside [``min_range_m``, ``max_range_m``] are
    dropped (0). ``rng`` drives the noise (None = a fixed seed, so a call is reproducible).
    ``background_bgr`` colours pixels that hit nothing: a BGR triple or an HxWx3 uint8 image. A face
    is pasted when the person faces the camera within ``max_face_angle_deg``; it counts as visible
    when at least ``min_visible_face_fraction`` of its core is unoccluded and its box is in the image.
    ``objects``: static clutter (:func:`clutter_object`), drawn before the people (person id -1).
    """
    if not isinstance(intrinsics, CameraIntrinsics):
        raise TypeError(f"intrinsics must be a CameraIntrinsics, got {type(intrinsics).__name__}")
    if not isinstance(camera_pose, CameraPose):
        raise TypeError(f"camera_pose must be a CameraPose, got {type(camera_pose).__name__}")
    people = list(people)
    for i, person in enumerate(people):
        if not isinstance(person, SyntheticPerson):
            raise TypeError(f"people[{i}] must be a SyntheticPerson, got {type(person).__name__}")
    if rng is not None and not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator or None, got {type(rng).__name__}")
    if not (math.isfinite(depth_noise_coeff_per_m) and depth_noise_coeff_per_m >= 0):
        raise ValueError(f"depth_noise_coeff_per_m must be finite and >= 0, got {depth_noise_coeff_per_m!r}")
    if not (0.0 <= min_range_m < max_range_m <= 65.0):
        raise ValueError(f"need 0 <= min_range_m < max_range_m <= 65 m, got {min_range_m!r}, {max_range_m!r}")
    if not 0.0 <= max_face_angle_deg <= 90.0:
        raise ValueError(f"max_face_angle_deg must be in [0, 90], got {max_face_angle_deg!r}")
    if not 0.0 < min_visible_face_fraction <= 1.0:
        raise ValueError(f"min_visible_face_fraction must be in (0, 1], got {min_visible_face_fraction!r}")
    if not (math.isfinite(floor_size_m) and floor_size_m > 0):
        raise ValueError(f"floor_size_m must be a positive size in metres, got {floor_size_m!r}")
    if not (math.isfinite(wall_height_m) and wall_height_m > 0):
        raise ValueError(f"wall_height_m must be a positive height in metres, got {wall_height_m!r}")
    h, w = intrinsics.height, intrinsics.width
    if isinstance(background_bgr, np.ndarray):
        if background_bgr.shape != (h, w, 3) or background_bgr.dtype != np.uint8:
            raise ValueError(
                f"background image must be {h}x{w}x3 uint8, got {background_bgr.shape} {background_bgr.dtype}"
            )
    else:
        _check_colour(background_bgr, "background_bgr")

    caster = _Caster(intrinsics, camera_pose)
    zbuf, colour = _environment(
        caster, float(floor_size_m), bool(walls), float(wall_height_m), background_bgr
    )
    zflat, colour_flat = zbuf.reshape(-1), colour.reshape(-1, 3)
    ids = np.full(h * w, -1, dtype=np.int16)
    parts = np.full(h * w, -1, dtype=np.int8)
    _render_objects(caster, list(objects), zflat, colour_flat)

    # geometry of everyone, batched: primitives, their pixel boxes and their ray transforms
    prims = [(i, prim) for i, person in enumerate(people) for prim in _person_primitives(person)]
    rots = [_person_rotation(p) for p in people]
    lights = []
    for person, rot in zip(people, rots, strict=True):
        chest = np.array([person.x_m, person.y_m, 0.75 * person.height_m])
        light = camera_pose.translation - chest + np.array([0.0, 0.0, 1.5])  # a lamp above the camera
        lights.append(rot.T @ (light / np.linalg.norm(light)))
    semi = np.array([prim.semi_axes for _, prim in prims]).reshape(-1, 3)
    centres = np.array([prim.centre for _, prim in prims]).reshape(-1, 3)
    lateral = np.maximum(semi[:, 0], semi[:, 1])
    boxes = caster.pixel_boxes(centres, np.stack([lateral, lateral, semi[:, 2]], axis=1))
    person_rot_t = np.array([rots[i].T for i, _ in prims]).reshape(-1, 3, 3)  # person <- world
    mats = (person_rot_t @ camera_pose.rotation) / semi[:, :, None]  # optical ray -> unit frame
    orgs = np.einsum("nij,nj->ni", person_rot_t, camera_pose.translation - centres) / semi

    # pass 1: z-buffer everyone; bodies are coloured now, heads once all occluders are known
    head_hits: list[list[tuple[_Hit, NDArray[np.float64], int]]] = [[] for _ in people]
    for n, (index, prim) in enumerate(prims):
        if boxes[n, 0] < 0:
            continue
        is_head = prim.part in _HEAD_PARTS
        hit = caster.cast(prim, boxes[n], mats[n], orgs[n], zflat, all_hits=is_head)
        if hit is None:
            continue
        flat = hit.flat[hit.closer]
        zflat[flat] = hit.depth[hit.closer]
        ids[flat] = index
        parts[flat] = prim.part
        if is_head:
            offset = rots[index].T @ (prim.centre - people[index].head_centre_world)
            head_hits[index].append((hit, offset, prim.part))
        else:
            shade = _shade(hit.normal, lights[index])
            person = people[index]
            if person.body_texture_bgr is None:
                colour_flat[flat] = np.clip(prim.albedo * shade[:, None], 0, 255).astype(np.uint8)
            else:
                to_person = np.array([person.x_m, person.y_m]) - camera_pose.translation[:2]
                norm = float(np.linalg.norm(to_person))
                across = np.array([to_person[1], -to_person[0]]) / norm if norm > 1e-9 else np.array([1.0, 0.0])
                colours = _body_texture_colours(hit, prim, person, rots[index], across, shade)
                colour_flat[flat] = np.clip(colours, 0, 255).astype(np.uint8)

    # pass 2: heads (hair, skin, pasted faces) where still visible; face occlusion test
    face_visible: list[bool] = []
    face_boxes = np.full((len(people), 4), np.nan)
    for index, (person, hits) in enumerate(zip(people, head_hits, strict=True)):
        face = None
        if person.face_image_bgr is not None and hits and \
                _facing_angle_deg(person, camera_pose.translation[:2]) <= max_face_angle_deg:
            depth_head = float(camera_pose.to_camera(person.head_centre_world[None])[0, 2])
            face = _face_texture(person, intrinsics.fx / max(depth_head, _NEAR_M))
        colours, cores = _head_colours(hits, person, lights[index], face)
        core_flat, seen_flat = [], []
        for (hit, _offset, part), col, core in zip(hits, colours, cores, strict=True):
            hit_ids, hit_parts = ids[hit.flat], parts[hit.flat]
            own = (hit_ids == index) & (hit_parts == part)
            colour_flat[hit.flat[own]] = np.clip(col[own], 0, 255).astype(np.uint8)
            on_head = (hit_ids == index) & ((hit_parts == _PART_CRANIUM) | (hit_parts == _PART_JAW))
            core_flat.append(hit.flat[core])
            seen_flat.append(hit.flat[core & on_head])
        n_core = np.unique(np.concatenate(core_flat)).size if core_flat else 0
        n_seen = np.unique(np.concatenate(seen_flat)).size if seen_flat else 0
        box = _expected_face_box(person, intrinsics, camera_pose) if face is not None else None
        unoccluded = n_core > 0 and n_seen >= min_visible_face_fraction * n_core
        ok = face is not None and box is not None and unoccluded
        face_visible.append(bool(ok))
        if ok:
            face_boxes[index] = box

    with np.errstate(invalid="ignore", over="ignore"):
        depth_m = zbuf
        if depth_noise and depth_noise_coeff_per_m > 0:
            gen = rng if rng is not None else np.random.default_rng(0)
            depth_m = _gaussian_noise(gen, h * w).reshape(h, w)
            depth_m *= np.float32(depth_noise_coeff_per_m)
            depth_m *= zbuf
            depth_m *= zbuf
            depth_m += zbuf  # inf (no return) stays non-finite
        valid = depth_m >= min_range_m
        valid &= depth_m <= max_range_m
        depth_m *= np.float32(1000.0)  # in place: the z-buffer is not needed any more
        np.rint(depth_m, out=depth_m)
        depth_m[~valid] = 0.0
        depth_mm = depth_m.astype(np.uint16)
    heads = np.array([p.head_centre_world for p in people]) if people else np.zeros((0, 3))
    return RenderedFrame(colour, depth_mm, face_visible, heads, face_boxes, ids.reshape(h, w))


def crop_face_for_rendering(
    photo_bgr: NDArray[np.uint8], box_xywh: Sequence[float] | NDArray[np.floating], margin: float = 0.15
) -> NDArray[np.uint8]:
    """Square crop of a detected face for :class:`SyntheticPerson`: box centred, side max(w, h)(1 + 2 margin).

    Parts of the square outside the photo are filled by replicating its border.
    """
    _check_bgr(photo_bgr, "photo_bgr")
    box = np.asarray(box_xywh, dtype=np.float64).reshape(-1)
    if box.size < 4 or not np.all(np.isfinite(box[:4])):
        raise ValueError(f"box_xywh must start with 4 finite numbers (x, y, w, h), got {box_xywh!r}")
    x, y, bw, bh = box[:4]
    if bw <= 0 or bh <= 0:
        raise ValueError(f"box width and height must be positive, got {bw} x {bh}")
    if not (math.isfinite(margin) and 0.0 <= margin <= 1.0):
        raise ValueError(f"margin must be in [0, 1], got {margin!r}")
    ph, pw = photo_bgr.shape[:2]
    if x + bw <= 0 or y + bh <= 0 or x >= pw or y >= ph:
        raise ValueError(f"box {box[:4].tolist()} lies outside the {pw}x{ph} photo")
    side = round(max(bw, bh) * (1.0 + 2.0 * margin))
    if side < 16:
        raise ValueError(f"face box too small to render ({bw:.0f}x{bh:.0f} px)")
    x0 = round(x + bw / 2.0 - side / 2.0)
    y0 = round(y + bh / 2.0 - side / 2.0)
    pad = max(0, -x0, -y0, x0 + side - pw, y0 + side - ph)
    src = cv2.copyMakeBorder(photo_bgr, pad, pad, pad, pad, cv2.BORDER_REPLICATE) if pad else photo_bgr
    return np.ascontiguousarray(src[y0 + pad: y0 + pad + side, x0 + pad: x0 + pad + side])


def synthetic_clothes(shirt_bgr: Sequence[int], trousers_bgr: Sequence[int], stripes: bool,
                      rng: np.random.Generator) -> NDArray[np.uint8]:
    """A made-up person crop (256 x 96, head top to feet) for :attr:`SyntheticPerson.body_texture_bgr`: skin
    head, a shirt (white stripes or plain), trousers with a fine weave, a little sensor noise (``rng``)."""
    img = np.empty((256, 96, 3), np.uint8)
    img[:40] = (60, 90, 140)
    img[40:128] = np.asarray(shirt_bgr, dtype=np.uint8)
    if stripes:
        for row in range(44, 128, 16):
            img[row: row + 6] = (235, 235, 235)
    img[128:] = np.asarray(trousers_bgr, dtype=np.uint8)
    weave = (np.add.outer(np.arange(128), np.arange(96)) % 4 < 2)[:, :, None]
    img[128:] = np.where(weave, img[128:], (img[128:] * 0.7).astype(np.uint8))
    return np.clip(img + rng.normal(0.0, 4.0, img.shape), 0, 255).astype(np.uint8)

