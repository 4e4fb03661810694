"""Align a robot's map to the camera network's floor map: 2-D ICP on occupied-cell centres, from an initial guess.

The result is the world -> map transform T (p_map = T.apply(p_world)) that ``face-reid-align-map`` writes. The
camera map's occupied cells (world frame) are moved by T onto the robot map's (map frame): every camera cell should
have a partner in the robot map, which usually covers more. Robust point-to-line ICP (the robot map's local line
direction from its cells' 8 nearest neighbours: walls may slide along themselves while pairing): pairs farther apart
than a distance that shrinks from ``initial_max_distance_m`` to ``final_max_distance_m`` are ignored, and of the
rest only the closest ``trim_fraction`` are fitted (people and furniture one map has and the other has not). The
residual is the RMS distance of the inliers (pairs within ``inlier_distance_m``) at the end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from face_reid_camera.common.param_table import param, validate_fields
from face_reid_master.robot.camera_map import OccupancyGridMap
from face_reid_master.robot.frames import PlanarTransform

__all__ = ["MapAlignConfig", "MapAlignment", "align_maps", "align_points"]


@dataclass(frozen=True)
class MapAlignConfig:
    """ICP settings of :func:`align_maps`."""

    max_iterations: int = param(300, "Most ICP iterations (count).", low=1, high=100_000)
    initial_max_distance_m: float = param(
        1.0, "First iterations pair cells at most this far apart (m; cover the guess's error).",
        low=0.0, high=100.0, low_open=True)
    final_max_distance_m: float = param(
        0.15, "The pairing distance halves at each convergence down to this (m).", low=0.0, high=100.0, low_open=True)
    trim_fraction: float = param(
        0.8, "Each iteration fits the closest this fraction of the pairs (0..1; robust to what one map lacks).",
        low=0.0, high=1.0, low_open=True)
    inlier_distance_m: float = param(
        0.1, "After alignment a camera-map cell is an inlier when a robot-map cell is this close (m).",
        low=0.0, high=10.0, low_open=True)
    min_points: int = param(
        30, "Refuse to align when either map has fewer occupied cells than this (count).", low=3, high=1_000_000)
    max_points: int = param(
        20_000, "Use at most this many occupied cells of each map, evenly subsampled (count).", low=3,
        high=10_000_000)
    tolerance_m: float = param(
        5e-4, "Converged when an iteration moves the map less than this (m) ...", low=0.0, high=1.0, low_open=True)
    tolerance_rad: float = param(
        5e-5, "... and turns it less than this (rad), or pairs the same cells as the one before.",
        low=0.0, high=1.0, low_open=True)

    def __post_init__(self) -> None:
        validate_fields(self)
        if self.final_max_distance_m > self.initial_max_distance_m:
            raise ValueError(f"final_max_distance_m ({self.final_max_distance_m}) must be <= initial_max_distance_m "
                             f"({self.initial_max_distance_m})")


@dataclass(frozen=True)
class MapAlignment:
    """The world -> map transform found, and how well the maps agree under it."""

    world_to_map: PlanarTransform
    rms_residual_m: float  # RMS distance of the inlier pairs (m)
    inlier_fraction: float  # camera-map cells with a robot-map cell within inlier_distance_m (0..1)
    iterations: int
    converged: bool
    camera_points: int  # occupied cells used
    robot_points: int

    def describe(self) -> str:
        t = self.world_to_map
        return (f"world->map x {t.x_m:.3f} m, y {t.y_m:.3f} m, yaw {math.degrees(t.yaw_rad):.2f} deg; "
                f"residual {self.rms_residual_m:.3f} m RMS, inliers {100 * self.inlier_fraction:.0f}% of "
                f"{self.camera_points} camera cells ({self.robot_points} robot cells), {self.iterations} iterations"
                + ("" if self.converged else ", NOT converged"))


def _subsample(points: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    if len(points) <= n:
        return points
    return points[np.linspace(0, len(points) - 1, n).astype(np.int64)]


def _normals(points: NDArray[np.float64], tree: cKDTree, k: int = 8) -> NDArray[np.float64]:
    """Unit normals of (M, 2) points: the least-spread direction of each point's ``k`` nearest neighbours."""
    _, idx = tree.query(points, k=min(k, len(points)))
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    _, vecs = np.linalg.eigh(cov)  # ascending eigenvalues: column 0 is across the local line
    return vecs[:, :, 0]


def _plane_fit(src: NDArray[np.float64], dst: NDArray[np.float64], normals: NDArray[np.float64]
               ) -> NDArray[np.float64]:
    """The 3x3 rigid step minimising sum ((R src + t - dst) . n)^2, linearised in the angle about src's centroid."""
    centre = src.mean(axis=0)
    rel = src - centre
    a = np.stack([normals[:, 1] * rel[:, 0] - normals[:, 0] * rel[:, 1], normals[:, 0], normals[:, 1]], axis=1)
    b = -np.einsum("ni,ni->n", src - dst, normals)
    (theta, tx, ty), *_ = np.linalg.lstsq(a, b, rcond=None)
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    t = centre + np.array([tx, ty]) - rot @ centre
    return np.array([[c, -s, t[0]], [s, c, t[1]], [0.0, 0.0, 1.0]])


def align_points(map_points: NDArray[np.floating], world_points: NDArray[np.floating], guess: PlanarTransform,
                 config: MapAlignConfig | None = None) -> MapAlignment:
    """ICP of (N, 2) world-frame points onto (M, 2) map-frame points from ``guess`` (world -> map)."""
    cfg = config or MapAlignConfig()
    if not isinstance(cfg, MapAlignConfig):
        raise ValueError(f"config must be a MapAlignConfig, got {type(cfg).__name__}")
    if not isinstance(guess, PlanarTransform):
        raise ValueError(f"guess must be a PlanarTransform, got {type(guess).__name__}")
    dst = np.asarray(map_points, dtype=np.float64).reshape(-1, 2)
    src = np.asarray(world_points, dtype=np.float64).reshape(-1, 2)
    for name, pts in (("robot map", dst), ("camera map", src)):
        if len(pts) < cfg.min_points:
            raise ValueError(f"the {name} has {len(pts)} occupied cells, fewer than min_points ({cfg.min_points}): "
                             "nothing to align")
        if not np.all(np.isfinite(pts)):
            raise ValueError(f"the {name}'s points must be finite")
    dst, src = _subsample(dst, cfg.max_points), _subsample(src, cfg.max_points)
    tree = cKDTree(dst)
    normals = _normals(dst, tree)
    m = guess.matrix
    max_d = cfg.initial_max_distance_m
    converged = False
    iterations = 0
    last_pairs: NDArray[np.int64] | None = None
    while iterations < cfg.max_iterations:
        iterations += 1
        moved = src @ m[:2, :2].T + m[:2, 2]
        dist, idx = tree.query(moved, distance_upper_bound=max_d)
        ok = np.flatnonzero(np.isfinite(dist))
        if len(ok) < 3:
            raise ValueError(f"no overlap: fewer than 3 camera-map cells within {max_d:.2f} m of a robot-map cell "
                             "under the guess; give a better --guess")
        keep = ok[np.argsort(dist[ok])[:max(3, math.ceil(cfg.trim_fraction * len(ok)))]]
        delta = _plane_fit(moved[keep], dst[idx[keep]], normals[idx[keep]])
        m = delta @ m
        step_m = math.hypot(delta[0, 2], delta[1, 2])
        step_rad = abs(math.atan2(delta[1, 0], delta[0, 0]))
        pairs = np.stack([keep, idx[keep]])
        same_pairs = last_pairs is not None and np.array_equal(pairs, last_pairs)
        last_pairs = pairs
        if same_pairs or (step_m < cfg.tolerance_m and step_rad < cfg.tolerance_rad):
            if max_d <= cfg.final_max_distance_m:
                converged = True
                break
            max_d = max(cfg.final_max_distance_m, max_d / 2)
    moved = src @ m[:2, :2].T + m[:2, 2]
    dist, _ = tree.query(moved)
    inliers = dist <= cfg.inlier_distance_m
    rms = float(np.sqrt(np.mean(dist[inliers] ** 2))) if inliers.any() else math.inf
    return MapAlignment(PlanarTransform.from_matrix(m), rms, float(inliers.mean()), iterations, converged,
                        len(src), len(dst))


def align_maps(robot_map: OccupancyGridMap, camera_map: OccupancyGridMap, guess: PlanarTransform,
               config: MapAlignConfig | None = None) -> MapAlignment:
    """The world -> map transform taking ``camera_map`` (world frame) onto ``robot_map`` (map frame)."""
    return align_points(robot_map.cell_centres(), camera_map.cell_centres(), guess, config)
