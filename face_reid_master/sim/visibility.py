"""What the cameras of a scenario see: detectability and face visibility, occlusion, coverage, losses, glances.

Analytic, pure numpy. A person is detectable by a camera when in the room, within range, with head top,
shoulders and both sides of the head inside the image, and the line of sight to the shoulders not blocked
by someone nearer (people are vertical cylinders); the face is visible when, in addition, the line to the
head is clear, the person faces the camera within ``max_face_angle_deg`` and is within
``max_face_range_m``. A track loss (:func:`count_losses`) is a span longer than ``min_gap_s`` during
which a person, seen before, is detectable by no camera.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import is_finite_number

if TYPE_CHECKING:
    from face_reid_master.sim.world import SimCamera, World

FloatArray = NDArray[np.float64]  # the simulator's array types
BoolArray = NDArray[np.bool_]

__all__ = [
    "LossSummary",
    "Visibility",
    "VisibilityConfig",
    "body_band_visibility",
    "camera_views",
    "camera_visibility",
    "count_losses",
    "coverage_fraction",
    "floor_grid",
    "glance_ids",
    "lone_person_visibility",
]


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
        if not (is_finite_number(self.min_range_m) and is_finite_number(self.max_range_m)
                and 0 <= self.min_range_m < self.max_range_m):
            raise ValueError(f"need 0 <= min_range_m < max_range_m, got {self.min_range_m!r}, {self.max_range_m!r}")
        if not (is_finite_number(self.max_face_angle_deg) and 0 < self.max_face_angle_deg <= 90):
            raise ValueError(f"max_face_angle_deg must be in (0, 90], got {self.max_face_angle_deg!r}")
        for name in ("max_face_range_m", "head_half_width_m", "shoulder_drop_m", "occluder_radius_m"):
            value = getattr(self, name)
            if not (is_finite_number(value) and value > 0):
                raise ValueError(f"VisibilityConfig.{name} must be positive, got {value!r}")
        if not (is_finite_number(self.image_margin_px) and self.image_margin_px >= 0):
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


def body_band_visibility(
    camera: SimCamera,
    xy: NDArray[np.floating],
    heights_m: NDArray[np.floating],
    in_room: NDArray[np.bool_],
    bands: int,
    frames: NDArray[np.integer],
    people: NDArray[np.integer],
    config: VisibilityConfig | None = None,
) -> BoolArray:
    """Which horizontal bands of a person's body a camera sees, at the (frame, person) pairs ``frames``,
    ``people`` (n,) of ``xy`` (T, P, 2): (n, bands), band 0 at the head top.

    Band k spans k / bands .. (k + 1) / bands of the height below the head top; it is seen when the point of
    the body axis at its middle projects inside the image and the line of sight to it passes no nearer
    person (the cylinders of :func:`camera_visibility`, tested as there). Feet out of the image or hidden
    behind someone in front show as unseen lower bands.
    """
    cfg = config if config is not None else VisibilityConfig()
    pos = np.asarray(xy, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 2:
        raise ValueError(f"xy must have shape (T, P, 2), got {pos.shape}")
    if isinstance(bands, bool) or not isinstance(bands, (int, np.integer)) or not 1 <= bands <= 64:
        raise ValueError(f"bands must be an integer in [1, 64], got {bands!r}")
    n_t, n_p = pos.shape[:2]
    heights = np.asarray(heights_m, dtype=np.float64).reshape(-1)
    inside = np.asarray(in_room, dtype=bool)
    f_idx, p_idx = np.asarray(frames, dtype=np.intp).reshape(-1), np.asarray(people, dtype=np.intp).reshape(-1)
    if heights.shape != (n_p,) or inside.shape != (n_t, n_p) or f_idx.shape != p_idx.shape:
        raise ValueError(f"heights_m {heights.shape}, in_room {inside.shape}, frames {f_idx.shape}, people "
                         f"{p_idx.shape} do not match xy {pos.shape}")
    cam = camera.position
    r = cfg.occluder_radius_m
    fractions = 1.0 - (np.arange(bands) + 0.5) / bands
    out = np.zeros((f_idx.size, int(bands)), dtype=bool)
    for lo in range(0, f_idx.size, 8192):  # bounded memory: (chunk, P, bands)
        f, p = f_idx[lo: lo + 8192], p_idx[lo: lo + 8192]
        own = pos[f, p]  # (n, 2)
        z = heights[p][:, None] * fractions  # (n, bands)
        points = np.concatenate([np.broadcast_to(own[:, None, :], (*z.shape, 2)), z[..., None]], axis=2)
        seen = _in_image(camera, points, cfg.image_margin_px) & inside[f, p][:, None]
        # the horizontal ray to every band is the same: closest approach to each other person once
        d = own - cam[:2]
        d2 = np.maximum((d * d).sum(axis=1), 1e-12)
        rel = pos[f] - cam[:2]  # (n, P, 2)
        s = (rel * d[:, None, :]).sum(axis=2) / d2[:, None]
        dist = np.linalg.norm(cam[:2] + s[..., None] * d[:, None, :] - pos[f], axis=2)
        near = (s > 0.0) & (s < 1.0 - r / np.sqrt(d2)[:, None]) & (dist < r) & inside[f]
        near[np.arange(f.size), p] = False
        ray_z = cam[2] + s[:, :, None] * (z[:, None, :] - cam[2])  # (n, P, bands)
        seen &= ~(near[:, :, None] & (ray_z < heights[None, :, None])).any(axis=1)
        out[lo: lo + 8192] = seen
    return out


def camera_views(cameras: Sequence[SimCamera], xy: NDArray[np.floating], facing_rad: NDArray[np.floating],
                 heights_m: NDArray[np.floating], in_room: NDArray[np.bool_], config: VisibilityConfig | None = None,
                 ) -> tuple[BoolArray, BoolArray]:
    """(detectable, face visible), each (T, P, M): :func:`camera_visibility` of every camera."""
    shape = (*np.asarray(in_room).shape, len(cameras))
    view = np.zeros(shape, dtype=bool)
    face = np.zeros_like(view)
    for c, camera in enumerate(cameras):
        vis = camera_visibility(camera, xy, facing_rad, heights_m, in_room, config)
        view[:, :, c], face[:, :, c] = vis.detectable, vis.face_visible
    return view, face


def floor_grid(half_extents: NDArray[np.floating], step_m: float) -> FloatArray:
    """(n, 2) centres of the ``step_m`` cells covering the floor [-half, half] (x major)."""
    xs = np.arange(-half_extents[0] + step_m / 2, half_extents[0], step_m)
    ys = np.arange(-half_extents[1] + step_m / 2, half_extents[1], step_m)
    return np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)


def lone_person_visibility(camera: SimCamera, points_xy: NDArray[np.floating], facing_rad: NDArray[np.floating]
                           | float = 0.0, height_m: float = 1.72, config: VisibilityConfig | None = None
                           ) -> Visibility:
    """Visibility (n, 1) of a person of ``height_m`` standing alone at each of the (n, 2) floor points."""
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 1, 2)
    n = pts.shape[0]
    facing = np.broadcast_to(np.asarray(facing_rad, dtype=np.float64).reshape(-1, 1), (n, 1))
    return camera_visibility(camera, pts, facing, np.array([height_m]), np.ones((n, 1), dtype=bool), config)


def coverage_fraction(world: World, config: VisibilityConfig | None = None, step_m: float = 0.25,
                      height_m: float = 1.72) -> float:
    """Fraction of the room's floor where a lone person of ``height_m`` is detectable by some camera."""
    grid = floor_grid(world.room.half_extents, step_m)
    covered = np.zeros(grid.shape[0], dtype=bool)
    for camera in world.cameras:
        covered |= lone_person_visibility(camera, grid, 0.0, height_m, config).detectable[:, 0]
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
    if not (is_finite_number(min_gap_s) and min_gap_s >= 0):
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
