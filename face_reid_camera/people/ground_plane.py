"""Floor plane of a depth camera's view, estimated by vectorised RANSAC + least-squares refinement.

The person detector needs heights above the floor: it removes the floor before clustering and keeps
clusters whose top is at a person's height. Hypotheses are tangent planes of local point triples
(three points of one 0.4 m cell), and all of them are scored at once as a (hypotheses x points)
matrix: 100 hypotheses on ~1000 points cost a fraction of a millisecond.

A hypothesis is a floor candidate only if (a) its upward normal is within an angle of the expected
up direction (the configured camera pose's, or camera -y for an uncalibrated, roughly upright
camera), (b) the camera is at least ``min_camera_height_m`` above it, (c) it has enough inliers and
(d) almost nothing lies below it. (d) is what makes a table top, a slice through a wall or a torso
lose against the real floor: the floor is the large plane with (nearly) no points underneath.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from face_reid_camera.camera_model import CameraPose

__all__ = ["GroundFit", "GroundPlane", "estimate_ground_plane", "fit_ground_plane"]

FloatArray = NDArray[np.float64]

# Camera -y (optical frame: y points down): "up" for a camera held roughly upright.
_CAMERA_UP = np.array([0.0, -1.0, 0.0])
# Hypothesis triples are three sample points of one cubic cell of this size (metres).
_TRIPLE_CELL_M = 0.4
# At most this many of the best-scoring hypotheses are refined before giving up, each on a
# subsample of up to this factor times max_sample_points.
_REFINED_HYPOTHESES = 3
_REFINE_SAMPLE_FACTOR = 3


@dataclass(frozen=True)
class GroundPlane:
    """Plane n.p + d = 0 in the camera frame; ``normal`` is unit and points up (towards the camera side).

    ``offset`` (d) is then the height of the camera centre above the floor in metres. A non-unit
    normal is normalised (and the offset scaled with it).
    """

    normal: FloatArray
    offset: float

    def __post_init__(self) -> None:
        normal = np.asarray(self.normal, dtype=np.float64).reshape(-1)
        if normal.shape != (3,) or not np.all(np.isfinite(normal)) or not math.isfinite(self.offset):
            raise ValueError(
                f"ground plane needs a finite (3,) normal and finite offset, got {self.normal!r}"
            )
        norm = float(np.linalg.norm(normal))
        if norm < 1e-9:
            raise ValueError("ground plane normal must be non-zero")
        object.__setattr__(self, "normal", normal / norm)
        object.__setattr__(self, "offset", float(self.offset) / norm)

    @classmethod
    def from_camera_pose(cls, pose: CameraPose) -> GroundPlane:
        """The world floor z = 0 seen from a camera with this pose (camera->world)."""
        return cls(pose.up_in_camera, float(pose.translation[2]))

    @property
    def tilt_down_deg(self) -> float:
        """Angle (deg) of the camera's optical axis (0, 0, 1) below this plane's horizon."""
        return math.degrees(math.asin(max(-1.0, min(1.0, -float(self.normal[2])))))

    @property
    def camera_height_m(self) -> float:
        """Height of the camera centre above the plane (metres)."""
        return self.offset

    def height_of(self, points: ArrayLike) -> FloatArray:
        """Signed height above the floor (metres) of (N, 3) camera-frame points; negative = below."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return pts @ self.normal + self.offset

    def angle_to_deg(self, direction: ArrayLike) -> float:
        """Angle in degrees between this plane's upward normal and ``direction`` (3,)."""
        vec = np.asarray(direction, dtype=np.float64).reshape(3)
        cos = float(vec @ self.normal) / max(float(np.linalg.norm(vec)), 1e-12)
        return math.degrees(math.acos(min(1.0, max(-1.0, cos))))


@dataclass(frozen=True)
class GroundFit:
    """A RANSAC result with its support (inliers estimated on a subsample, scaled to all points)."""

    plane: GroundPlane
    inlier_count: int
    below_fraction: float


def _fit_plane(points: FloatArray, up: FloatArray) -> tuple[FloatArray, float]:
    """Least-squares plane (total least squares) through points; normal oriented along ``up``."""
    count = points.shape[0]
    centre = points.sum(axis=0) / count
    scatter = points.T @ points - count * np.outer(centre, centre)
    _, vecs = np.linalg.eigh(scatter)
    normal = vecs[:, 0]
    if normal @ up < 0:
        normal = -normal
    return normal, float(-normal @ centre)


def _local_triples(
    sample: FloatArray, count: int, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Up to ``count`` triples (a, b, c) of distinct points sharing a _TRIPLE_CELL_M cell (spatial hash)."""
    cells = np.floor(sample * (1.0 / _TRIPLE_CELL_M)).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    starts = np.flatnonzero(np.concatenate(([True], sorted_keys[1:] != sorted_keys[:-1])))
    sizes = np.diff(np.append(starts, sorted_keys.size))
    group = np.repeat(np.arange(starts.size), sizes)  # cell of each sorted position
    pos = rng.integers(0, sorted_keys.size, size=count)
    pos = pos[sizes[group[pos]] >= 3]
    first, size = starts[group[pos]], sizes[group[pos]]
    # Two other members of the anchor's cell (cyclic offsets 1..size-1; equal picks are degenerate
    # triangles, dropped later by the normal-length test).
    second = first + (pos - first + rng.integers(1, size)) % size
    third = first + (pos - first + rng.integers(1, size)) % size
    return (
        np.take(sample, order[pos], axis=0),
        np.take(sample, order[second], axis=0),
        np.take(sample, order[third], axis=0),
    )


def fit_ground_plane(
    points: ArrayLike,
    *,
    seed_normal: ArrayLike | None = None,
    seed_angle_deg: float = 15.0,
    max_tilt_deg: float = 60.0,
    distance_threshold_m: float = 0.06,
    iterations: int = 100,
    min_inliers: int = 150,
    max_below_fraction: float = 0.05,
    min_camera_height_m: float = 0.2,
    max_sample_points: int = 1000,
    depth_noise_coefficient_per_m: float = 0.0,
    seed_camera_height_m: float | None = None,
    seed_height_tolerance_m: float = 0.25,
    prior_planes: Sequence[GroundPlane] = (),
    rng: np.random.Generator | None = None,
    assume_finite: bool = False,
) -> GroundFit | None:
    """Like :func:`estimate_ground_plane`, also returning the support of the chosen plane.

    ``assume_finite`` skips the NaN/inf filter for callers that already dropped invalid points.
    """
    pts = np.asarray(points, dtype=np.float64)
    _check_ransac(pts, iterations, max_sample_points, min_inliers, distance_threshold_m, max_below_fraction,
                  depth_noise_coefficient_per_m)
    limits = _PlaneLimits.of(seed_normal, seed_angle_deg, max_tilt_deg, seed_camera_height_m,
                             seed_height_tolerance_m, min_camera_height_m)
    rng = rng if rng is not None else np.random.default_rng(0)
    if not assume_finite:  # np.compress: several times faster than boolean fancy indexing of (N, 3) rows
        pts = np.compress(np.isfinite(pts[:, 0] + pts[:, 1] + pts[:, 2]), pts, axis=0)
    n_points = pts.shape[0]
    if n_points < max(3, min_inliers):
        return None
    # Strided (not gathered) subsamples: cheap views, uniform over the raster-ordered input.
    step = max(1, n_points // max_sample_points)
    sample = np.ascontiguousarray(pts[int(rng.integers(0, step)) :: step])  # contiguous: fast matmul
    normals, offsets = _hypotheses(sample, iterations, rng, limits, prior_planes)
    if normals.shape[0] == 0:
        return None
    below_margin = max(0.1, 2.0 * distance_threshold_m)
    valid, inliers = _score(normals, offsets, sample, below_margin, distance_threshold_m,
                            depth_noise_coefficient_per_m, max_below_fraction,
                            max(3, math.ceil(min_inliers * sample.shape[0] / n_points)))
    if not np.any(valid):
        return None
    # Least-squares refinement of the best hypotheses on the inliers of a larger subsample (twice:
    # inliers move with the plane). A hypothesis whose refit leaves the constraints was degenerate
    # (e.g. a plane tilted through a band of floor): the next best one is tried.
    refine_step = max(1, n_points // (_REFINE_SAMPLE_FACTOR * max_sample_points))
    refine_pts = np.ascontiguousarray(pts[int(rng.integers(0, refine_step)) :: refine_step])
    refine_margin = below_margin + 3.0 * depth_noise_coefficient_per_m * refine_pts[:, 2] ** 2
    ranked = np.argsort(-np.where(valid, inliers, -1), kind="stable")[: min(_REFINED_HYPOTHESES, int(valid.sum()))]
    for best in ranked.tolist():
        fit = _refined(normals[best], float(offsets[best]), refine_pts, refine_margin, n_points, limits,
                       distance_threshold_m)
        if fit is not None and fit.inlier_count >= min_inliers and fit.below_fraction <= max_below_fraction:
            return fit
    return None


def _refined(normal: FloatArray, offset: float, refine_pts: FloatArray, refine_margin: FloatArray, n_points: int,
             limits: _PlaneLimits, distance_threshold_m: float) -> GroundFit | None:
    """A hypothesis refitted twice on its inliers among ``refine_pts``, with its support scaled to the
    ``n_points`` of the cloud (None: too few inliers to refit, or the refit leaves the limits)."""
    for _ in range(2):
        mask = np.abs(refine_pts @ normal + offset) <= distance_threshold_m
        if np.count_nonzero(mask) < 3:
            break
        normal, offset = _fit_plane(np.compress(mask, refine_pts, axis=0), limits.up)
    if not limits.allow(normal, offset):
        return None
    final_heights = refine_pts @ normal + offset
    scale = n_points / refine_pts.shape[0]
    count = round(int(np.count_nonzero(np.abs(final_heights) <= distance_threshold_m)) * scale)
    below_fraction = float(np.count_nonzero(final_heights < -refine_margin)) / refine_pts.shape[0]
    return GroundFit(GroundPlane(normal, offset), count, below_fraction)


def _check_ransac(pts: FloatArray, iterations: int, max_sample_points: int, min_inliers: int,
                  distance_threshold_m: float, max_below_fraction: float, depth_noise_coefficient_per_m: float) -> None:
    """ValueError naming :func:`fit_ground_plane`'s points or RANSAC arguments out of range."""
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got shape {pts.shape}")
    if iterations < 1 or max_sample_points < 3 or min_inliers < 3:
        raise ValueError("iterations must be >= 1, max_sample_points >= 3 and min_inliers >= 3")
    if not (distance_threshold_m > 0 and 0 <= max_below_fraction <= 1 and depth_noise_coefficient_per_m >= 0):
        raise ValueError(
            "distance_threshold_m must be > 0, max_below_fraction in [0, 1] "
            "and depth_noise_coefficient_per_m >= 0"
        )


@dataclass(frozen=True)
class _PlaneLimits:
    """Which planes may be the floor: normal within ``cos_limit`` of ``up``, camera height (the plane's offset)
    within [min_height, max_height]."""

    up: FloatArray
    cos_limit: float
    min_height: float
    max_height: float

    @staticmethod
    def of(seed_normal: ArrayLike | None, seed_angle_deg: float, max_tilt_deg: float,
           seed_camera_height_m: float | None, seed_height_tolerance_m: float,
           min_camera_height_m: float) -> _PlaneLimits:
        """The limits :func:`fit_ground_plane`'s arguments set (ValueError naming a bad one)."""
        if not (0 < seed_angle_deg < 90 and 0 < max_tilt_deg < 90):
            raise ValueError("seed_angle_deg and max_tilt_deg must be in (0, 90) degrees")
        if seed_normal is not None:
            up = np.asarray(seed_normal, dtype=np.float64).reshape(3)
            if not (np.all(np.isfinite(up)) and np.linalg.norm(up) > 1e-9):
                raise ValueError("seed_normal must be a finite non-zero (3,) vector")
            up = up / np.linalg.norm(up)
            cos_limit = math.cos(math.radians(seed_angle_deg))
        else:
            up = _CAMERA_UP
            cos_limit = math.cos(math.radians(max_tilt_deg))
        if seed_camera_height_m is None:
            return _PlaneLimits(up, cos_limit, min_camera_height_m, math.inf)
        if seed_normal is None or not math.isfinite(seed_camera_height_m) or not seed_height_tolerance_m > 0:
            raise ValueError("seed_camera_height_m needs seed_normal, a finite height and a positive tolerance")
        return _PlaneLimits(up, cos_limit, max(min_camera_height_m, seed_camera_height_m - seed_height_tolerance_m),
                            seed_camera_height_m + seed_height_tolerance_m)

    def allow(self, normal: FloatArray, offset: float) -> bool:
        return bool(normal @ self.up >= self.cos_limit) and self.min_height <= offset <= self.max_height


def _hypotheses(sample: FloatArray, iterations: int, rng: np.random.Generator, limits: _PlaneLimits,
                prior_planes: Sequence[GroundPlane]) -> tuple[FloatArray, FloatArray]:
    """Plane hypotheses (normals (k, 3), offsets (k,)) within the limits, at most ``iterations`` from local
    triples of the sample, then the prior planes that are within them."""
    # Local triples -> plane hypotheses: an anchor and two other sample points of its ~0.4 m cell lie
    # on one surface, so hypotheses are real surfaces' tangent planes (far-apart random triples also
    # give planes slicing through walls and people, which can win on cluttered floorless frames).
    a, b, c = _local_triples(sample, 3 * iterations, rng)
    if a.shape[0] == 0:
        return np.zeros((0, 3)), np.zeros(0)
    up = limits.up
    normals = np.cross(b - a, c - a)
    norms = np.sqrt(np.einsum("ij,ij->i", normals, normals))
    good = norms > 1e-9
    normals = normals[good] / norms[good, None]
    normals *= np.where(normals @ up < 0, -1.0, 1.0)[:, None]
    offsets = -np.einsum("ij,ij->i", normals, np.compress(good, a, axis=0))
    plausible = (normals @ up >= limits.cos_limit) & (offsets >= limits.min_height) & (offsets <= limits.max_height)
    keep = np.flatnonzero(plausible)[:iterations]
    normals, offsets = normals[keep], offsets[keep]
    for prior in prior_planes:
        if prior.normal @ up >= limits.cos_limit and limits.min_height <= prior.offset <= limits.max_height:
            normals = np.vstack([normals, prior.normal])
            offsets = np.append(offsets, prior.offset)
    return normals, offsets


def _score(normals: FloatArray, offsets: FloatArray, sample: FloatArray, below_margin: float,
           distance_threshold_m: float, depth_noise_coefficient_per_m: float, max_below_fraction: float,
           min_sample_inliers: int) -> tuple[NDArray[np.bool_], NDArray[np.intp]]:
    """Every hypothesis at once on the sample: which are valid (enough inliers, few points below) and their
    inlier counts."""
    # float32 and in-place operations: one (hypotheses x sample) temporary instead of three.
    heights = normals.astype(np.float32) @ sample.T.astype(np.float32)
    heights += offsets.astype(np.float32)[:, None]
    # "Below the floor" must beat the sensor noise, which grows with depth squared (3 sigma).
    sample_margin = (below_margin + 3.0 * depth_noise_coefficient_per_m * sample[:, 2] ** 2).astype(
        np.float32
    )
    below = np.count_nonzero(heights < -sample_margin, axis=1)
    inliers = np.count_nonzero(np.abs(heights, out=heights) <= distance_threshold_m, axis=1)
    return (inliers >= min_sample_inliers) & (below <= max_below_fraction * sample.shape[0]), inliers


def estimate_ground_plane(
    points: ArrayLike,
    *,
    seed_normal: ArrayLike | None = None,
    seed_angle_deg: float = 15.0,
    max_tilt_deg: float = 60.0,
    distance_threshold_m: float = 0.06,
    iterations: int = 100,
    min_inliers: int = 150,
    max_below_fraction: float = 0.05,
    min_camera_height_m: float = 0.2,
    max_sample_points: int = 1000,
    depth_noise_coefficient_per_m: float = 0.0,
    seed_camera_height_m: float | None = None,
    seed_height_tolerance_m: float = 0.25,
    prior_planes: Sequence[GroundPlane] = (),
    rng: np.random.Generator | None = None,
) -> GroundPlane | None:
    """Estimate the floor from (N, 3) camera-frame points (e.g. strided depth pixels); None if none qualifies.

    Seeded mode (``seed_normal`` = the expected up direction in the camera frame, e.g.
    ``CameraPose.up_in_camera``) accepts normals within ``seed_angle_deg`` of it and, if
    ``seed_camera_height_m`` is given (the pose's camera height), only planes that put the camera
    within ``seed_height_tolerance_m`` of that height (so a desk top cannot pass for the floor);
    unseeded mode accepts normals within ``max_tilt_deg`` of camera -y (a roughly upright camera).
    Hypotheses are the tangent planes of local point triples plus ``prior_planes`` (e.g. last
    frame's floor). Among those with >= ``min_inliers`` points within ``distance_threshold_m`` and
    at most ``max_below_fraction`` of the points more than max(0.1, 2 x threshold) + 3 sigma(z) m
    below (sigma(z) = ``depth_noise_coefficient_per_m`` z^2, the sensor's depth noise), the one
    with most inliers wins and is refined by least squares on its inliers. Raises ValueError for
    malformed arguments; non-finite points are ignored.
    """
    fit = fit_ground_plane(
        points,
        seed_normal=seed_normal,
        seed_angle_deg=seed_angle_deg,
        max_tilt_deg=max_tilt_deg,
        distance_threshold_m=distance_threshold_m,
        iterations=iterations,
        min_inliers=min_inliers,
        max_below_fraction=max_below_fraction,
        min_camera_height_m=min_camera_height_m,
        max_sample_points=max_sample_points,
        depth_noise_coefficient_per_m=depth_noise_coefficient_per_m,
        seed_camera_height_m=seed_camera_height_m,
        seed_height_tolerance_m=seed_height_tolerance_m,
        prior_planes=prior_planes,
        rng=rng,
    )
    return None if fit is None else fit.plane
