"""Depth-only people detector of the camera node (OpenPTrack-style ground-based detection, no classifier).

Pipeline per frame (numpy/scipy vectorised, no per-point Python; ~3-5 ms for 640x480 at one thread):

1. depth image (or organized XYZ cloud) -> camera-frame points on a pixel stride, range-limited;
2. floor plane by RANSAC on those points (:mod:`face_reid_camera.people.ground_plane`), with last frame's
   floor as an extra hypothesis and fallback, then the configured camera pose's floor;
3. points within ``ground_distance_threshold_m`` (or 3 sigma of depth noise) of the floor, below it,
   or more than 0.3 m above ``max_person_height_m`` (ceilings, lamps, wall tops) are dropped; the rest
   is voxelised (``voxel_size_m`` voxel centroids: integer keys + one sort + bincounts);
4. clustering on the floor plane: a height map (highest voxel per ``voxel_size_m`` cell) whose
   occupied cells are labelled as 8-connected components after bridging gaps narrower than
   ``cluster_tolerance_m`` (2-D grid labelling with scipy.ndimage; the brief's cheap alternative to
   3-D Euclidean clustering, whose KD-tree pairs cost 5+ ms once far walls give ~5000 voxels);
5. head-based sub-clustering (OpenPTrack's HeadBasedSubclustering, made classifier-free): head
   candidates are local maxima (~0.1 m) of the height map at least ``min_person_height_m`` high
   that (a) have a cap: >= 3 cells within 0.1 m less than ``head_min_drop_m`` below the top (no
   single-cell noise spikes); (b) are prominent: among the same cluster's cells in the ring
   ``head_annulus_inner_m``..``head_annulus_outer_m`` around them that are comparable (at most
   ``upper_body_depth_m`` lower and at most ``head_min_drop_m`` higher, so a wall or a taller
   neighbour behind does not count), at most ``max_head_plateau_fraction`` are within
   ``head_min_drop_m`` of the top (box tops, table tops and wall crests are flat) and >= 2 are
   lower (shoulders); (c) have shoulders on both sides of the line of sight, at least
   ``min_shoulder_offset_m`` off it (a corner of a flat board, or an edge sloping into an occlusion
   shadow, has them on one side only); ring cells nearer to another candidate >= 0.3 m away belong
   to that one (people side by side). Heads closer than ``heads_minimum_distance_m`` keep the
   highest; every voxel joins the nearest head of its cluster within ``max_person_width_m`` / 2;
6. a sub-cluster is a person if its head is ``min_person_height_m``..``max_person_height_m`` above
   the floor, its upper body (top ``upper_body_depth_m``) is ``min_person_width_m``..
   ``max_person_width_m`` wide, it has at least ``min_cluster_points`` voxels, and it does not stand on a
   thin support: its voxels ``support_band_low_m``..``support_band_high_m`` above the floor (legs), when
   seen, span at least ``min_support_width_m`` across the line of sight (a coat stand's pole does not), and
   (depth images) its top is not at the image border (``head_image_margin_px``: a wall cut by the frustum).
   The head top is the mean floor position of the head cap at the highest voxel's height.

State: :class:`PersonDetector` keeps the last estimated floor plane (temporal seed/fallback) and its
random generator; use one detector per camera stream and call :meth:`PersonDetector.reset` on a jump.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose, depth_to_points
from face_reid_camera.common.param_table import param, validate_fields
from face_reid_camera.people.ground_plane import GroundFit, GroundPlane, fit_ground_plane
from face_reid_camera.people.heads import OVERHEAD_RANGE_M, FloorGrid, HeadFinder, principal_width

__all__ = [
    "MIN_FLOOR_SUPPORT",
    "FloorCheck",
    "PersonCandidate",
    "PersonDetectionResult",
    "PersonDetector",
    "PersonDetectorConfig",
]

FloatArray = NDArray[np.float64]

# A floor measured without the pose is evidence of where the floor is only when at least this share of the frame's
# points lie on it: a floor in view holds far more (0.79 of the desk frames' points), a plane through the few low
# points of a view without floor a few percent (0.02 of test/data/rgbd/person.pcd, 1.95 m below at 16.8 deg).
MIN_FLOOR_SUPPORT = 0.05

# The support band needs this many voxels to count as evidence (fewer: legs hidden or out of view).
_MIN_SUPPORT_VOXELS = 3
# Points more than this above max_person_height_m are ignored (ceilings, lamps, upper walls).
_ABOVE_MAX_HEIGHT_MARGIN_M = 0.3


@dataclass(frozen=True)
class PersonDetectorConfig:
    """Parameters of :class:`PersonDetector` (the camera node's ``person.*`` parameters).

    Defaults follow OpenPTrack (voxel 0.06 m, max height 2.3 m, max distance 10 m, heads 0.3 m
    apart) except ``min_person_height_m`` = 1.0 (OpenPTrack: 0.6): without OpenPTrack's HOG/SVM
    confirmation, 0.6-1.0 m admits chairs and tables while losing only small children; sitting adults
    (1.2-1.4 m) are kept.
    """

    depth_stride_px: int = param(4, "Use every n-th depth row and column (px; 1 = all pixels).", low=1, high=64)
    voxel_size_m: float = param(
        0.06, "Voxel size of the down-sampled cloud and cell size of the floor height map (m).",
        low=0.0, high=1.0, low_open=True)
    min_depth_m: float = param(0.4, "Ignore depth returns closer than this (m).", low=0.0, high=20.0)
    max_depth_m: float = param(
        10.0, "Ignore depth returns farther than this (m); people beyond are not detected.",
        low=0.0, high=50.0, low_open=True)
    ground_distance_threshold_m: float = param(
        0.06, "Floor RANSAC inlier distance; points this close to the floor or below it are removed (m).",
        low=0.0, high=1.0, low_open=True)
    depth_noise_coefficient_per_m: float = param(
        0.0014, "Depth noise sigma = this x range^2 (Kinect v1); the floor band is at least 3 sigma (1/m; 0 = off).",
        low=0.0, high=0.1)
    ransac_iterations: int = param(100, "Floor plane hypotheses scored per frame (count).", low=1, high=100_000)
    ransac_max_sample_points: int = param(
        1000, "Points sub-sampled to score the floor hypotheses (count).", low=3, high=1_000_000)
    ground_seed_angle_deg: float = param(
        15.0, "With a camera pose: max angle between the floor normal and the pose's up (deg).",
        low=0.0, high=90.0, low_open=True, high_open=True)
    ground_seed_height_tolerance_m: float = param(
        0.25, "With a camera pose: max difference between the camera height and the pose's (m).",
        low=0.0, high=10.0, low_open=True)
    ground_max_tilt_deg: float = param(
        60.0, "Without a pose: max angle between the floor normal and camera -y (deg).",
        low=0.0, high=90.0, low_open=True, high_open=True)
    min_ground_points: int = param(
        150, "A floor needs at least this many inlier points after striding (count).", low=1, high=1_000_000)
    ground_max_below_fraction: float = param(
        0.05, "Reject floor planes with more than this fraction of the points clearly below them (0..1).",
        low=0.0, high=1.0)
    min_camera_height_m: float = param(
        0.2, "Reject floor planes closer than this below the camera (m).", low=0.0, high=10.0)
    cluster_tolerance_m: float = param(
        0.12, "Gaps narrower than this join occupied floor cells into one cluster (m).",
        low=0.0, high=2.0, low_open=True)
    min_person_height_m: float = param(
        1.0, "Heads lower than this above the floor are not people (m; OpenPTrack uses 0.6).",
        low=0.0, high=3.0, low_open=True)
    max_person_height_m: float = param(
        2.3, "Heads higher than this above the floor are not people (m).", low=0.0, high=4.0, low_open=True)
    min_person_width_m: float = param(
        0.25, "A person's upper body (top upper_body_depth_m) is at least this wide (m).",
        low=0.0, high=3.0, low_open=True)
    max_person_width_m: float = param(
        1.0, "A person's upper body is at most this wide; voxels join a head within half of it (m).",
        low=0.0, high=5.0, low_open=True)
    min_cluster_points: int = param(30, "A person has at least this many voxels (count).", low=1, high=1_000_000)
    heads_minimum_distance_m: float = param(
        0.3, "Heads are at least this far apart; the lower of a closer pair is dropped (m).",
        low=0.0, high=3.0, low_open=True)
    head_annulus_inner_m: float = param(
        0.12, "Head test: inner radius of the shoulder ring around a head top (m).", low=0.0, high=2.0)
    head_annulus_outer_m: float = param(
        0.35, "Head test: outer radius of the shoulder ring around a head top (m).",
        low=0.0, high=2.0, low_open=True)
    head_min_drop_m: float = param(
        0.18, "Head test: shoulders are at least this much lower than the head top (m).",
        low=0.0, high=2.0, low_open=True)
    upper_body_depth_m: float = param(
        0.5, "Head test and width use only the top this-many metres of a person (m).",
        low=0.0, high=3.0, low_open=True)
    max_head_plateau_fraction: float = param(
        0.4, "Head test: at most this fraction of the ring is as high as the head; flat tops fail (0..1).",
        low=0.0, high=1.0)
    min_shoulder_offset_m: float = param(
        0.06, "Head test: shoulders on both sides of the line of sight, at least this far off it (m).",
        low=0.0, high=1.0, low_open=True)
    head_image_margin_px: float = param(
        6.0, "Depth images: a head top projecting closer than this to the image's top, left or right border is where "
        "the view ends, not a head (a wall cut by the frustum looks like one) (px; 0 = off).", low=0.0, high=1000.0)
    min_support_width_m: float = param(
        0.08, "Depth shape check: what stands in the support band is at least this wide across the line of sight; "
        "a person-shaped top on a thin pole (coat stand, hat stand, lamp) is not a person (m; 0 = off).",
        low=0.0, high=1.0)
    support_band_low_m: float = param(
        0.15, "Depth shape check: bottom of the support band, above the floor (m; legs at a person's shins).",
        low=0.0, high=2.0)
    support_band_high_m: float = param(
        0.6, "Depth shape check: top of the support band, above the floor (m; below most coats' hems).",
        low=0.0, high=2.0, low_open=True)
    head_top_to_centre_m: float = param(
        0.1, "Head centre = head top minus this along the floor normal (m).", low=0.0, high=1.0)
    random_seed: int = param(
        0, "Seed of the floor RANSAC generator (count; -1 = a different random seed every start).",
        low=-1, high=2**31 - 1)
    people_on_pose_floor: bool = param(
        False, "With a camera pose: detect people on the pose's floor when the data shows none, unchecked (false: "
        "such frames report nobody).")
    pose_check_height_tolerance_m: float = param(
        0.2, "With a camera pose: the floor measured without the pose disagrees with it beyond this camera height "
        "difference (m).", low=0.0, high=10.0, low_open=True)
    pose_check_tilt_tolerance_deg: float = param(
        8.0, "With a camera pose: the floor measured without the pose disagrees with it beyond this angle (deg).",
        low=0.0, high=90.0, low_open=True)
    pose_check_every_frames: int = param(
        10, "With a camera pose: while the pose-seeded floor search fails, the floor is measured without the pose "
        "every this many frames to check the pose (count).", low=1, high=100_000)

    def __post_init__(self) -> None:
        validate_fields(self)
        if self.min_depth_m >= self.max_depth_m:
            raise ValueError(f"min_depth_m ({self.min_depth_m}) must be < max_depth_m ({self.max_depth_m})")
        if self.min_person_height_m >= self.max_person_height_m:
            raise ValueError("min_person_height_m must be < max_person_height_m")
        if self.min_person_width_m >= self.max_person_width_m:
            raise ValueError("min_person_width_m must be < max_person_width_m")
        if self.head_annulus_inner_m >= self.head_annulus_outer_m:
            raise ValueError("head_annulus_inner_m must be < head_annulus_outer_m")
        if self.support_band_low_m >= self.support_band_high_m:
            raise ValueError(f"support_band_low_m ({self.support_band_low_m}) must be < support_band_high_m "
                             f"({self.support_band_high_m})")
        if self.cluster_tolerance_m < self.voxel_size_m:
            raise ValueError("cluster_tolerance_m must be >= voxel_size_m (neighbouring voxels must connect)")


@dataclass(frozen=True)
class PersonCandidate:
    """One detected person, camera frame (metres).

    ``top_cam`` is the head top (the head cap's mean position on the floor plane, at the height of
    its highest voxel), ``head_cam`` the estimated head centre (``head_top_to_centre_m`` below the
    top along the floor normal), ``centroid_cam`` the mean of the person's visible voxels (biased
    towards the camera by about half the body depth; project ``head_cam`` or ``top_cam`` on the floor
    for a position). ``height_m`` is the head top above the floor, ``width_m`` the upper body's
    extent along its principal horizontal axis, ``num_points`` the person's voxels (not pixels).
    """

    centroid_cam: FloatArray
    top_cam: FloatArray
    head_cam: FloatArray
    height_m: float
    width_m: float
    num_points: int


@dataclass(frozen=True)
class FloorCheck:
    """The configured pose's floor against the floor measured without it: camera heights (m), downward tilts of
    the optical axis (deg), the angle between the two floors (deg) and whether they agree within tolerance."""

    pose_height_m: float
    pose_tilt_deg: float
    floor_height_m: float
    floor_tilt_deg: float
    angle_deg: float
    agrees: bool

    def describe(self) -> str:
        verdict = "agrees with" if self.agrees else "DISAGREES with"
        return (f"the configured pose (camera {self.pose_height_m:.2f} m high, tilted {self.pose_tilt_deg:.1f} deg "
                f"down) {verdict} the floor measured in the depth data (camera {self.floor_height_m:.2f} m high, "
                f"tilted {self.floor_tilt_deg:.1f} deg down; floors {self.angle_deg:.1f} deg apart)")


@dataclass
class PersonDetectionResult:
    """People found in one frame plus diagnostics.

    ``ground_plane_source`` is "ransac" (estimated now), "previous" (last frame's floor reused),
    "pose" (the configured camera pose's floor; people are then only detected with ``people_on_pose_floor``) or
    "none". ``floor_check``: set on frames where the pose was checked against the floor measured without it.
    ``num_points`` counts the valid input points after striding and range limits, ``num_voxels`` the voxels
    above the floor, ``num_clusters`` their 2-D clusters on the floor plane, ``num_thin_support`` the
    person-shaped ones that stand on a thin pole, ``num_cut_by_border`` those whose top is at the image border.
    ``timings_ms`` breaks down the latency by stage. ``ground_support``: the share of the points on the floor
    estimated in this frame (None when it was not estimated now); below :data:`MIN_FLOOR_SUPPORT` it is no evidence.
    """

    people: list[PersonCandidate]
    ground_plane: GroundPlane | None
    num_points: int
    ground_plane_source: str = "none"
    num_voxels: int = 0
    num_clusters: int = 0
    timings_ms: dict[str, float] = field(default_factory=dict)
    floor_check: FloorCheck | None = None
    num_thin_support: int = 0  # person-shaped clusters rejected by the depth shape check (thin support)
    num_cut_by_border: int = 0  # person-shaped clusters whose top is at the image border (depth images only)
    ground_support: float | None = None  # share of the points on the floor estimated in this frame


def _support(fit: GroundFit, points: FloatArray) -> float:
    """The share of ``points`` on a fitted floor."""
    return fit.inlier_count / max(1, points.shape[0])


def _voxel_centroids(points: FloatArray, voxel_size_m: float) -> FloatArray:
    """Mean point of every occupied voxel (integer keys, one stable argsort, bincount sums)."""
    cells = np.floor(points * (1.0 / voxel_size_m)).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable")  # raster-ordered input: the stable (radix) sort is fastest
    sorted_keys = keys[order]
    new_voxel = np.empty(sorted_keys.size, dtype=bool)
    new_voxel[0] = True
    np.not_equal(sorted_keys[1:], sorted_keys[:-1], out=new_voxel[1:])
    voxel_of = np.empty(sorted_keys.size, dtype=np.intp)
    voxel_of[order] = np.cumsum(new_voxel) - 1
    n_voxels = int(voxel_of.max()) + 1
    counts = np.bincount(voxel_of, minlength=n_voxels)
    sums = np.stack(
        [np.bincount(voxel_of, weights=points[:, i], minlength=n_voxels) for i in range(3)], axis=1
    )
    return sums / counts[:, None]


class PersonDetector:
    """Detect people in depth frames of one camera; keeps the last floor plane between frames."""

    def __init__(
        self, config: PersonDetectorConfig | None = None, camera_pose: CameraPose | None = None
    ) -> None:
        self.config = config if config is not None else PersonDetectorConfig()
        if not isinstance(self.config, PersonDetectorConfig):
            raise ValueError(f"config must be a PersonDetectorConfig, got {type(self.config).__name__}")
        if camera_pose is not None and not isinstance(camera_pose, CameraPose):
            raise ValueError(f"camera_pose must be a CameraPose or None, got {type(camera_pose).__name__}")
        self.camera_pose = camera_pose
        self._pose_plane = GroundPlane.from_camera_pose(camera_pose) if camera_pose is not None else None
        self._previous_plane: GroundPlane | None = None
        self._rng = np.random.default_rng(None if self.config.random_seed < 0 else self.config.random_seed)
        self._frames_unseen = 0  # frames in a row whose pose-seeded floor search failed
        self.floor_check: FloorCheck | None = None  # the latest check of the pose against the measured floor
        self._head_finder = HeadFinder(self.config)  # the height map and the heads on it

    @property
    def last_ground_plane(self) -> GroundPlane | None:
        """The last floor estimated by RANSAC (next frame's extra hypothesis and fallback), or None."""
        return self._previous_plane

    def reset(self) -> None:
        """Forget the previous floor plane (e.g. after the camera was moved)."""
        self._previous_plane = None

    # ------------------------------------------------------------------------------------------ inputs
    def detect_depth(
        self, depth_m: NDArray[np.floating], intrinsics: CameraIntrinsics
    ) -> PersonDetectionResult:
        """Detect people in a depth image in metres (H, W) float; 0, NaN or inf mark invalid pixels."""
        t0 = time.perf_counter()
        if not isinstance(depth_m, np.ndarray) or not np.issubdtype(depth_m.dtype, np.floating):
            kind = depth_m.dtype if isinstance(depth_m, np.ndarray) else type(depth_m).__name__
            raise ValueError(
                f"depth_m must be a float ndarray in metres (convert uint16 mm / 1000), got {kind}"
            )
        if not isinstance(intrinsics, CameraIntrinsics):
            raise ValueError(f"intrinsics must be CameraIntrinsics, got {type(intrinsics).__name__}")
        points = depth_to_points(depth_m, intrinsics, stride=self.config.depth_stride_px)
        return self._detect(points, t0, intrinsics)

    def detect_points(self, points_cam: NDArray[np.floating]) -> PersonDetectionResult:
        """Detect people in an organized (H, W, 3) or unorganized (N, 3) camera-frame cloud (metres).

        Organized clouds are subsampled on the pixel stride; unorganized ones keep every stride^2-th
        point. Non-finite points (NaN = no return) are dropped.
        """
        t0 = time.perf_counter()
        if not isinstance(points_cam, np.ndarray) or not np.issubdtype(points_cam.dtype, np.floating):
            raise ValueError("points_cam must be a float ndarray")
        stride = self.config.depth_stride_px
        if points_cam.ndim == 3 and points_cam.shape[2] == 3:
            pts = points_cam[::stride, ::stride].reshape(-1, 3)
        elif points_cam.ndim == 2 and points_cam.shape[1] == 3:
            pts = points_cam[:: stride * stride]
        else:
            raise ValueError(f"points_cam must be (H, W, 3) or (N, 3), got shape {points_cam.shape}")
        pts = np.compress(np.isfinite(pts[:, 0] + pts[:, 1] + pts[:, 2]), pts, axis=0)
        return self._detect(pts.astype(np.float64), t0)

    # ------------------------------------------------------------------------------------------ pipeline
    def _detect(self, points: FloatArray, t0: float, intrinsics: CameraIntrinsics | None = None
                ) -> PersonDetectionResult:
        cfg = self.config
        timings: dict[str, float] = {}
        depth = points[:, 2]
        # np.compress: row filters on (N, 3) arrays are several times faster than boolean indexing.
        points = np.compress(
            (depth >= max(cfg.min_depth_m, 1e-6)) & (depth <= cfg.max_depth_m), points, axis=0
        )
        t1 = time.perf_counter()
        timings["points"] = (t1 - t0) * 1e3
        result = PersonDetectionResult([], None, int(points.shape[0]), "none", 0, 0, timings)
        if points.shape[0] == 0:
            timings["total"] = (t1 - t0) * 1e3
            return result

        # The floor is fitted on the strided points themselves; only what stands on it is voxelised.
        plane, source, result.ground_support = self._ground_plane(points)
        result.ground_plane, result.ground_plane_source = plane, source
        result.floor_check = self._check_pose(points, source)
        t2 = time.perf_counter()
        timings["ground"] = (t2 - t1) * 1e3
        if plane is None or (source == "pose" and not cfg.people_on_pose_floor):
            timings["total"] = (t2 - t0) * 1e3
            return result
        # Floor removal: within the threshold, or within 3 sigma of depth noise (sigma = c z^2), or below;
        # also everything too high to belong to a person's head or upper body.
        threshold = cfg.ground_distance_threshold_m
        if cfg.depth_noise_coefficient_per_m > 0:
            threshold = np.maximum(threshold, 3.0 * cfg.depth_noise_coefficient_per_m * points[:, 2] ** 2)
        heights = plane.height_of(points)
        keep = (heights > threshold) & (heights <= cfg.max_person_height_m + _ABOVE_MAX_HEIGHT_MARGIN_M)
        above = np.compress(keep, points, axis=0)
        if above.shape[0] < cfg.min_cluster_points:
            timings["total"] = (time.perf_counter() - t0) * 1e3
            return result
        obj = _voxel_centroids(above, cfg.voxel_size_m)
        result.num_voxels = int(obj.shape[0])
        t3 = time.perf_counter()
        timings["voxels"] = (t3 - t2) * 1e3
        if obj.shape[0] < cfg.min_cluster_points:
            timings["total"] = (t3 - t0) * 1e3
            return result

        result.people, result.num_clusters, result.num_thin_support = self._people(obj, plane.height_of(obj), plane)
        if intrinsics is not None and cfg.head_image_margin_px > 0 and result.people:
            inside = [p for p in result.people if self._top_in_view(p.top_cam, intrinsics)]
            result.num_cut_by_border = len(result.people) - len(inside)
            result.people = inside
        t4 = time.perf_counter()
        timings["people"] = (t4 - t3) * 1e3
        timings["total"] = (t4 - t0) * 1e3
        return result

    def _check_pose(self, points: FloatArray, source: str) -> FloorCheck | None:
        """While the pose-seeded floor search fails, measure the floor without the pose every
        ``pose_check_every_frames`` frames and compare (a wrong height or tilt is why it fails)."""
        cfg, pose_plane = self.config, self._pose_plane
        if cfg.people_on_pose_floor:  # the pose's floor is trusted (e.g. a recording that shows no floor)
            return None
        if pose_plane is None or source == "ransac":  # found within the pose's seed window: it agrees
            self._frames_unseen = 0
            self.floor_check = None
            return None
        self._frames_unseen += 1
        if (self._frames_unseen - 1) % cfg.pose_check_every_frames:
            return None
        fit = self._fit_floor(points, None, ())
        if fit is None or _support(fit, points) < MIN_FLOOR_SUPPORT:  # no floor in view to check the pose on
            return None
        floor = fit.plane
        angle = math.degrees(math.acos(max(-1.0, min(1.0, float(floor.normal @ pose_plane.normal)))))
        agrees = (abs(floor.offset - pose_plane.offset) <= cfg.pose_check_height_tolerance_m
                  and angle <= cfg.pose_check_tilt_tolerance_deg)
        self.floor_check = FloorCheck(pose_plane.offset, pose_plane.tilt_down_deg, floor.offset,
                                      floor.tilt_down_deg, angle, agrees)
        return self.floor_check

    def _fit_floor(self, points: FloatArray, seed: GroundPlane | None,
                   priors: list[GroundPlane] | tuple[()]) -> GroundFit | None:
        """The floor RANSAC with this detector's settings, near ``seed`` (the pose's floor) or unseeded."""
        cfg = self.config
        return fit_ground_plane(
            points,
            seed_normal=None if seed is None else seed.normal,
            seed_angle_deg=cfg.ground_seed_angle_deg,
            max_tilt_deg=cfg.ground_max_tilt_deg,
            distance_threshold_m=cfg.ground_distance_threshold_m,
            iterations=cfg.ransac_iterations,
            min_inliers=cfg.min_ground_points,
            max_below_fraction=cfg.ground_max_below_fraction,
            min_camera_height_m=cfg.min_camera_height_m,
            max_sample_points=cfg.ransac_max_sample_points,
            depth_noise_coefficient_per_m=cfg.depth_noise_coefficient_per_m,
            seed_camera_height_m=None if seed is None else seed.offset,
            seed_height_tolerance_m=cfg.ground_seed_height_tolerance_m,
            prior_planes=priors,
            rng=self._rng,
            assume_finite=True,
        )

    def _ground_plane(self, points: FloatArray) -> tuple[GroundPlane | None, str, float | None]:
        """This frame's floor, where it came from and, when estimated now, the share of the points on it."""
        priors = [p for p in (self._previous_plane, self._pose_plane) if p is not None]
        fit = self._fit_floor(points, self._pose_plane, priors)
        if fit is not None:
            self._previous_plane = fit.plane
            return fit.plane, "ransac", _support(fit, points)
        if self._previous_plane is not None:
            return self._previous_plane, "previous", None
        if self._pose_plane is not None:
            return self._pose_plane, "pose", None
        return None, "none", None

    def _people(
        self, obj: FloatArray, obj_h: FloatArray, plane: GroundPlane
    ) -> tuple[list[PersonCandidate], int, int]:
        """Height map, 2-D clusters, prominent heads, sub-clusters and person filters (see module doc)."""
        cfg = self.config
        grid = self._head_finder.floor_grid(obj, obj_h, plane)
        heads = self._head_finder.heads(grid, obj_h)
        if heads.size == 0:
            return [], grid.n_clusters, 0
        tops = grid.top_voxel[heads]
        head_l = grid.labels[heads]
        head_u, head_v = self._head_finder.head_positions(grid, heads)

        # Sub-clusters: every voxel joins the nearest head of its own cluster within half a max width
        # (brute force over the few heads).
        voxel_label = grid.labels[grid.flat]
        owner = np.full(obj.shape[0], -1)
        best = np.full(obj.shape[0], (0.5 * cfg.max_person_width_m) ** 2)
        for k in range(heads.size):
            dist2 = (grid.u - head_u[k]) ** 2 + (grid.v - head_v[k]) ** 2
            closer = (dist2 < best) & (voxel_label == head_l[k])
            owner[closer] = k
            best[closer] = dist2[closer]

        people: list[PersonCandidate] = []
        thin = 0
        for k in range(heads.size):
            height = float(obj_h[tops[k]])
            if not (cfg.min_person_height_m <= height <= cfg.max_person_height_m):
                continue  # a tall object's top: it only absorbs its own voxels
            members = np.flatnonzero(owner == k)
            if members.size < cfg.min_cluster_points:
                continue
            upper = members[obj_h[members] >= height - cfg.upper_body_depth_m]
            width = principal_width(grid.u[upper], grid.v[upper])
            if not (cfg.min_person_width_m <= width <= cfg.max_person_width_m):
                continue
            if self._thin_support(members, obj_h, grid, head_u[k], head_v[k]):
                thin += 1
                continue
            # Top of the head: at the cap's mean floor position, at the highest voxel's height.
            top = head_u[k] * grid.axis_u + head_v[k] * grid.axis_v + (height - plane.offset) * plane.normal
            people.append(
                PersonCandidate(
                    centroid_cam=np.take(obj, members, axis=0).mean(axis=0),
                    top_cam=top,
                    head_cam=top - cfg.head_top_to_centre_m * plane.normal,
                    height_m=height,
                    width_m=width,
                    num_points=int(members.size),
                )
            )
        return people, grid.n_clusters, thin

    def _top_in_view(self, top_cam: FloatArray, intrinsics: CameraIntrinsics) -> bool:
        """The head top projects at least head_image_margin_px inside the image's top, left and right borders (a
        crest where the view ends - a wall cut by the frustum - is not a head)."""
        z = float(top_cam[2])
        if z <= 1e-6:
            return False
        margin = self.config.head_image_margin_px
        u = intrinsics.fx * float(top_cam[0]) / z + intrinsics.cx
        v = intrinsics.fy * float(top_cam[1]) / z + intrinsics.cy
        return v >= margin and margin <= u <= intrinsics.width - 1 - margin

    def _thin_support(self, members: NDArray[np.intp], obj_h: FloatArray, grid: FloorGrid, head_u: float,
                      head_v: float) -> bool:
        """Depth shape check: the person's voxels in the support band (legs) span less than min_support_width_m
        across the line of sight. A band hidden or out of view (too few voxels) is no evidence either way."""
        cfg = self.config
        if cfg.min_support_width_m <= 0:
            return False
        h = obj_h[members]
        band = members[(h >= cfg.support_band_low_m) & (h <= cfg.support_band_high_m)]
        if band.size < _MIN_SUPPORT_VOXELS:
            return False
        norm = math.hypot(head_u, head_v)
        if norm < OVERHEAD_RANGE_M:  # seen from above: no line of sight across the legs
            return False
        lateral = (grid.v[band] * head_u - grid.u[band] * head_v) / norm
        return float(lateral.max() - lateral.min()) < cfg.min_support_width_m
