"""Tests of the depth people detector and the floor-plane estimator.

Real data: three Kinect frames of a floor with a laptop and a box (no people) and one organized
Kinect cloud of a standing person (``person.pcd``). Synthetic data: depth images ray-cast
analytically here (floor, cylinder-and-sphere people, boxes, pillars) seen by a camera with a known
:class:`CameraPose`, with Kinect-like depth noise, so positions and heights have ground truth.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import RGBD_DIR

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.faces.head_roi import head_roi_px
from face_reid_camera.people.detector import (
    PersonDetectionResult,
    PersonDetector,
    PersonDetectorConfig,
)
from face_reid_camera.people.ground_plane import GroundPlane, estimate_ground_plane, fit_ground_plane
from face_reid_camera.tools.pcd_io import read_pcd

DATA = RGBD_DIR
DESK_FRAMES = sorted((DATA / "pcl_desk").glob("*_depth_mm.png"))
KINECT = CameraIntrinsics.kinect_default()
# A camera on a wall bracket: 2.5 m high, pitched 0.5 rad (29 deg) down, looking along world +x.
HIGH_POSE = CameraPose.from_xyz_rpy(0.0, 0.0, 2.5, 0.0, 0.5, 0.0)


# ----------------------------------------------------------------------------- analytic depth renderer
def render_depth(
    intrinsics: CameraIntrinsics,
    pose: CameraPose,
    *,
    cylinders: tuple[tuple[float, float, float, float, float], ...] = (),
    spheres: tuple[tuple[float, float, float, float], ...] = (),
    boxes: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = (),
    floor: bool = True,
    noise_seed: int | None = 0,
) -> np.ndarray:
    """Depth (m, float32, 0 = no return) of a scene in world coordinates (z up, floor z = 0).

    cylinders: vertical (x, y, radius, z_bottom, z_top) with a top cap; spheres: (x, y, z, radius);
    boxes: axis-aligned (min corner, max corner). Noise: Kinect-like sigma = 1.5 mm * z^2.
    """
    u, v = np.meshgrid(
        np.arange(intrinsics.width, dtype=np.float64), np.arange(intrinsics.height, dtype=np.float64)
    )
    rays_cam = np.stack(
        [(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, np.ones_like(u)], -1
    )
    d = rays_cam @ pose.rotation.T  # camera z = 1 along every ray, so the ray parameter t is the depth
    o = pose.translation
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    depth = np.full(u.shape, np.inf)

    def take(t: np.ndarray) -> None:
        np.minimum(depth, np.where(np.isfinite(t) & (t > 1e-6), t, np.inf), out=depth)

    with np.errstate(divide="ignore", invalid="ignore"):
        if floor:
            take(np.where(dz < 0, -o[2] / dz, np.inf))
        for cx, cy, r, z0, z1 in cylinders:
            ox, oy = o[0] - cx, o[1] - cy
            a = dx * dx + dy * dy
            b = 2 * (dx * ox + dy * oy)
            disc = b * b - 4 * a * (ox * ox + oy * oy - r * r)
            t = (-b - np.sqrt(np.where(disc >= 0, disc, np.nan))) / (2 * a)
            z = o[2] + t * dz
            take(np.where((z >= z0) & (z <= z1), t, np.inf))
            t = (z1 - o[2]) / dz
            take(np.where((o[0] + t * dx - cx) ** 2 + (o[1] + t * dy - cy) ** 2 <= r * r, t, np.inf))
        for cx, cy, cz, r in spheres:
            oc = o - np.array([cx, cy, cz])
            a = dx * dx + dy * dy + dz * dz
            b = 2 * (dx * oc[0] + dy * oc[1] + dz * oc[2])
            disc = b * b - 4 * a * (oc @ oc - r * r)
            take((-b - np.sqrt(np.where(disc >= 0, disc, np.nan))) / (2 * a))
        for lo, hi in boxes:
            t0 = (np.asarray(lo)[:, None, None] - o[:, None, None]) / np.moveaxis(d, -1, 0)
            t1 = (np.asarray(hi)[:, None, None] - o[:, None, None]) / np.moveaxis(d, -1, 0)
            t_near = np.nanmax(np.minimum(t0, t1), axis=0)
            t_far = np.nanmin(np.maximum(t0, t1), axis=0)
            take(np.where(t_near <= t_far, t_near, np.inf))
    depth = np.where(np.isfinite(depth), depth, 0.0)
    if noise_seed is not None:
        noise = np.random.default_rng(noise_seed).normal(size=depth.shape) * 0.0015 * depth**2
        depth = np.where(depth > 0, depth + noise, 0.0)
    return depth.astype(np.float32)


def person(x: float, y: float, height: float) -> tuple[list, list]:
    """A standing person: body cylinder to the shoulders, neck, 0.2 m head sphere; top at ``height``."""
    cylinders = [(x, y, 0.18, 0.0, height - 0.30), (x, y, 0.06, height - 0.30, height - 0.15)]
    return cylinders, [(x, y, height - 0.10, 0.10)]


def scene(people: list[tuple[float, float, float]], **extra) -> dict:
    cylinders, spheres = list(extra.pop("cylinders", ())), list(extra.pop("spheres", ()))
    for p in people:
        c, s = person(*p)
        cylinders += c
        spheres += s
    return {"cylinders": tuple(cylinders), "spheres": tuple(spheres), **extra}


def position_tolerance_m(pose: CameraPose, x: float, y: float) -> float:
    """0.1 m, or 3 sigma of the Kinect depth noise (1.5 mm z^2) beyond ~4.7 m.

    Without noise the head top comes out ~5 cm towards the camera (its far side is hidden); with
    noise the highest points are those the noise pulled towards the camera along the downward rays.
    """
    distance = math.dist(pose.translation, (x, y, 1.7))
    return max(0.1, 3.0 * 0.0015 * distance**2)


def match_people(result: PersonDetectionResult, pose: CameraPose, truth: list[tuple[float, float, float]]):
    """Pair each true person (x, y, height) with the detection whose head top is nearest in world xy."""
    tops = np.array([pose.to_world(p.top_cam)[0] for p in result.people]).reshape(-1, 3)
    pairs = []
    for x, y, h in truth:
        k = int(np.argmin(np.hypot(tops[:, 0] - x, tops[:, 1] - y)))
        pairs.append((result.people[k], tops[k], (x, y, h)))
    return pairs


THREE_PEOPLE = [(3.0, 0.0, 1.80), (4.5, 1.0, 1.60), (6.0, -1.2, 1.75)]


@pytest.fixture(scope="module")
def three_people_depth() -> np.ndarray:
    return render_depth(KINECT, HIGH_POSE, **scene(THREE_PEOPLE))


def desk_depth(path: Path) -> np.ndarray:
    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0


# ----------------------------------------------------------------------------------------- config
@pytest.mark.parametrize(
    "kwargs",
    [
        {"voxel_size_m": 0.0},
        {"voxel_size_m": float("nan")},
        {"depth_stride_px": 0},
        {"depth_stride_px": True},
        {"depth_stride_px": 2.5},
        {"min_person_height_m": 2.4},
        {"min_person_width_m": 1.2},
        {"min_depth_m": 11.0},
        {"ground_seed_angle_deg": 95.0},
        {"ground_max_below_fraction": 1.5},
        {"head_annulus_inner_m": 0.5},
        {"cluster_tolerance_m": 0.03},
        {"max_head_plateau_fraction": -0.1},
    ],
)
def test_config_rejects_invalid_values(kwargs: dict) -> None:
    with pytest.raises(ValueError, match="must"):
        PersonDetectorConfig(**kwargs)


def test_detector_rejects_wrong_argument_types() -> None:
    with pytest.raises(ValueError, match="CameraPose"):
        PersonDetector(camera_pose=np.eye(4))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="PersonDetectorConfig"):
        PersonDetector(config={"voxel_size_m": 0.05})  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------ bad input
def test_all_invalid_depth_gives_no_people_and_no_floor() -> None:
    detector = PersonDetector()
    for depth in (np.full((480, 640), np.nan, np.float32), np.zeros((480, 640), np.float32)):
        result = detector.detect_depth(depth, KINECT)
        assert result.people == [] and result.ground_plane is None
        assert result.ground_plane_source == "none" and result.num_points == 0


def test_depth_beyond_max_range_is_ignored() -> None:
    result = PersonDetector().detect_depth(np.full((480, 640), 12.0, np.float32), KINECT)
    assert result.num_points == 0 and result.people == [] and result.ground_plane is None


def test_bad_depth_inputs_raise_value_error() -> None:
    detector = PersonDetector()
    with pytest.raises(ValueError, match="float"):
        detector.detect_depth(np.zeros((480, 640), np.uint16), KINECT)
    with pytest.raises(ValueError, match="2-D"):
        detector.detect_depth(np.zeros((480, 640, 1), np.float32), KINECT)
    with pytest.raises(ValueError, match="intrinsics"):
        detector.detect_depth(np.zeros((240, 320), np.float32), KINECT)
    with pytest.raises(ValueError, match="CameraIntrinsics"):
        detector.detect_depth(np.zeros((480, 640), np.float32), (525.0, 525.0))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="shape"):
        detector.detect_points(np.zeros((100, 4), np.float32))
    with pytest.raises(ValueError, match="float"):
        detector.detect_points(np.zeros((100, 3), np.int32))


# ------------------------------------------------------------------------------- synthetic scenes
@pytest.mark.parametrize("seeded", [False, True])
def test_three_people_positions_and_heights(three_people_depth: np.ndarray, seeded: bool) -> None:
    detector = PersonDetector(camera_pose=HIGH_POSE if seeded else None)
    result = detector.detect_depth(three_people_depth, KINECT)
    assert result.ground_plane_source == "ransac"
    # The estimated floor is the true one: normal within 1 deg, camera height within 3 cm.
    assert result.ground_plane.angle_to_deg(HIGH_POSE.up_in_camera) < 1.0
    assert result.ground_plane.camera_height_m == pytest.approx(2.5, abs=0.03)
    assert len(result.people) == 3
    for det, top_world, (x, y, h) in match_people(result, HIGH_POSE, THREE_PEOPLE):
        assert math.hypot(top_world[0] - x, top_world[1] - y) < position_tolerance_m(HIGH_POSE, x, y)
        assert det.height_m == pytest.approx(h, abs=0.1)
        assert top_world[2] == pytest.approx(h, abs=0.1)
        head_world = HIGH_POSE.to_world(det.head_cam)[0]
        assert head_world[2] == pytest.approx(h - 0.1, abs=0.1)
        centroid = HIGH_POSE.to_world(det.centroid_cam)[0]  # visible surface: biased towards the camera
        assert math.hypot(centroid[0] - x, centroid[1] - y) < 0.2
        assert 0.25 <= det.width_m <= 0.6 and det.num_points >= 30


def test_organized_cloud_gives_the_same_people_as_the_depth_image(three_people_depth: np.ndarray) -> None:
    depth = three_people_depth.astype(np.float64)
    rows, cols = np.mgrid[0 : depth.shape[0], 0 : depth.shape[1]]
    cloud = np.stack(
        [(cols - KINECT.cx) * depth / KINECT.fx, (rows - KINECT.cy) * depth / KINECT.fy, depth], axis=-1
    )
    cloud[depth == 0] = np.nan
    from_depth = PersonDetector().detect_depth(three_people_depth, KINECT)
    from_cloud = PersonDetector().detect_points(cloud)
    assert len(from_cloud.people) == len(from_depth.people) == 3
    for a, b in zip(from_depth.people, from_cloud.people, strict=True):
        np.testing.assert_allclose(a.top_cam, b.top_cam, atol=1e-4)
        assert a.height_m == pytest.approx(b.height_m, abs=1e-4)


def test_same_input_gives_identical_results(three_people_depth: np.ndarray) -> None:
    a = PersonDetector().detect_depth(three_people_depth, KINECT)
    b = PersonDetector().detect_depth(three_people_depth, KINECT)
    assert [p.height_m for p in a.people] == [p.height_m for p in b.people]
    np.testing.assert_array_equal(a.ground_plane.normal, b.ground_plane.normal)


@pytest.mark.parametrize(
    ("gap_m", "across"), [(0.40, True), (0.45, True), (0.50, True), (0.45, False), (0.50, False)]
)
def test_two_people_standing_close_are_split(gap_m: float, across: bool) -> None:
    """Centre distances of 0.4-0.5 m: the bodies touch (one cluster); the heads split it in two."""
    if across:  # side by side, across the line of sight
        truth = [(3.5, -gap_m / 2, 1.75), (3.5, gap_m / 2, 1.70)]
    else:  # diagonal to the line of sight
        d = gap_m / math.sqrt(2)
        truth = [(3.5 - d / 2, -d / 2, 1.75), (3.5 + d / 2, d / 2, 1.70)]
    depth = render_depth(KINECT, HIGH_POSE, **scene(truth))
    result = PersonDetector(camera_pose=HIGH_POSE).detect_depth(depth, KINECT)
    assert len(result.people) == 2
    for det, top_world, (x, y, h) in match_people(result, HIGH_POSE, truth):
        assert math.hypot(top_world[0] - x, top_world[1] - y) < position_tolerance_m(HIGH_POSE, x, y)
        assert det.height_m == pytest.approx(h, abs=0.1)
    assert result.people[0].top_cam is not result.people[1].top_cam


TABLE = ((3.0, -1.6, 0.0), (3.8, -0.4, 0.7))  # 0.8 x 1.2 m, 0.7 m tall
PILLAR = (4.0, 1.5, 0.2, 0.0, 2.8)  # r = 0.2 m, 2.8 m tall


@pytest.mark.parametrize("min_height_m", [1.0, 0.6])
def test_table_and_pillar_are_rejected_next_to_a_person(min_height_m: float) -> None:
    """With OpenPTrack's 0.6 m minimum height too: the flat table top has no head-like peak."""
    truth = [(4.5, 0.0, 1.70)]
    depth = render_depth(KINECT, HIGH_POSE, **scene(truth, boxes=(TABLE,), cylinders=(PILLAR,)))
    config = PersonDetectorConfig(min_person_height_m=min_height_m)
    for pose in (None, HIGH_POSE):
        result = PersonDetector(config, camera_pose=pose).detect_depth(depth, KINECT)
        assert len(result.people) == 1
        ((det, top_world, (x, y, h)),) = match_people(result, HIGH_POSE, truth)
        assert math.hypot(top_world[0] - x, top_world[1] - y) < position_tolerance_m(HIGH_POSE, x, y)
        assert det.height_m == pytest.approx(h, abs=0.1)


def test_objects_alone_give_no_people() -> None:
    boxes = (TABLE, ((5.0, 0.5, 0.0), (5.4, 0.9, 1.6)))  # table, 1.6 m cabinet (flat top)
    depth = render_depth(KINECT, HIGH_POSE, boxes=boxes, cylinders=(PILLAR, (5.5, -1.0, 0.05, 0.0, 1.8)))
    result = PersonDetector(PersonDetectorConfig(min_person_height_m=0.6)).detect_depth(depth, KINECT)
    assert result.ground_plane is not None and result.num_voxels > 100
    assert result.people == []


def test_people_in_front_of_walls() -> None:
    """Far walls are many voxels and tall crests; they must neither hide nor add people."""
    walls = (((8.0, -6.0, 0.0), (8.2, 6.0, 3.0)), ((0.0, 3.5, 0.0), (9.0, 3.7, 3.0)))
    truth = [(3.0, 0.0, 1.80), (6.0, -1.2, 1.75), (7.6, 0.5, 1.70)]  # the last one 0.4 m from the wall
    depth = render_depth(KINECT, HIGH_POSE, **scene(truth, boxes=walls))
    result = PersonDetector().detect_depth(depth, KINECT)
    assert len(result.people) == 3
    for det, top_world, (x, y, h) in match_people(result, HIGH_POSE, truth):
        assert math.hypot(top_world[0] - x, top_world[1] - y) < position_tolerance_m(HIGH_POSE, x, y)
        assert det.height_m == pytest.approx(h, abs=0.1)


def test_steep_camera_without_pose() -> None:
    """Unseeded mode accepts cameras tilted up to ground_max_tilt_deg (the desk frames are at 46 deg)."""
    pose = CameraPose.from_xyz_rpy(0.0, 0.0, 3.0, 0.0, math.radians(50.0), 0.0)
    truth = [(2.2, 0.3, 1.70)]
    result = PersonDetector().detect_depth(render_depth(KINECT, pose, **scene(truth)), KINECT)
    assert result.ground_plane.angle_to_deg(pose.up_in_camera) < 1.0
    ((det, top_world, (x, y, h)),) = match_people(result, pose, truth)
    assert len(result.people) == 1 and det.height_m == pytest.approx(h, abs=0.1)
    assert math.hypot(top_world[0] - x, top_world[1] - y) < 0.1


def test_floor_falls_back_to_previous_frame_then_to_pose(three_people_depth: np.ndarray) -> None:
    # The same frame with every floor pixel invalid (e.g. a black carpet): no plane to fit.
    world = HIGH_POSE.to_world(
        np.stack(
            [
                (np.mgrid[0:480, 0:640][1] - KINECT.cx) * three_people_depth / KINECT.fx,
                (np.mgrid[0:480, 0:640][0] - KINECT.cy) * three_people_depth / KINECT.fy,
                three_people_depth,
            ],
            axis=-1,
        ).reshape(-1, 3)
    ).reshape(480, 640, 3)
    floorless = np.where(world[..., 2] > 0.15, three_people_depth, np.nan).astype(np.float32)

    detector = PersonDetector()
    assert detector.detect_depth(three_people_depth, KINECT).ground_plane_source == "ransac"
    result = detector.detect_depth(floorless, KINECT)
    assert result.ground_plane_source == "previous" and len(result.people) == 3
    detector.reset()
    result = detector.detect_depth(floorless, KINECT)
    assert result.ground_plane_source == "none" and result.people == []

    # with a pose but no floor in the data: nobody by default (a wrong pose would invent people) ...
    seeded = PersonDetector(camera_pose=HIGH_POSE).detect_depth(floorless, KINECT)
    assert seeded.ground_plane_source == "pose" and seeded.people == []
    # ... unless the pose's floor is trusted
    seeded = PersonDetector(PersonDetectorConfig(people_on_pose_floor=True), camera_pose=HIGH_POSE).detect_depth(
        floorless, KINECT)
    assert seeded.ground_plane_source == "pose" and len(seeded.people) == 3
    for det, _, (_, _, h) in match_people(seeded, HIGH_POSE, THREE_PEOPLE):
        assert det.height_m == pytest.approx(h, abs=0.1)


def test_seeded_mode_rejects_a_floor_at_the_wrong_height(three_people_depth: np.ndarray) -> None:
    """A pose 0.6 m too high: the real floor is outside the seed tolerance, so only the pose floor is left;
    the floor measured without the pose says so (both heights), and nobody is reported from the wrong floor."""
    wrong = CameraPose(HIGH_POSE.rotation, HIGH_POSE.translation + np.array([0.0, 0.0, 0.6]))
    result = PersonDetector(camera_pose=wrong).detect_depth(three_people_depth, KINECT)
    assert result.ground_plane_source == "pose" and result.people == []
    assert result.ground_plane.camera_height_m == pytest.approx(3.1)
    check = result.floor_check
    assert check is not None and not check.agrees
    assert check.pose_height_m == pytest.approx(3.1) and check.floor_height_m == pytest.approx(2.5, abs=0.05)
    assert "DISAGREES" in check.describe() and "3.10 m" in check.describe()


def test_a_wrongly_tilted_pose_is_caught_and_a_right_one_is_not(three_people_depth: np.ndarray) -> None:
    x, y, z, roll, pitch, yaw = HIGH_POSE.xyz_rpy()
    tilted = CameraPose.from_xyz_rpy(x, y, z, roll, pitch + math.radians(25), yaw)
    detector = PersonDetector(camera_pose=tilted)
    first = detector.detect_depth(three_people_depth, KINECT)
    assert first.people == [] and first.floor_check is not None and not first.floor_check.agrees
    assert first.floor_check.angle_deg == pytest.approx(25.0, abs=2.0)
    # checked again only every pose_check_every_frames frames; the verdict stays on the detector
    assert detector.detect_depth(three_people_depth, KINECT).floor_check is None
    assert detector.floor_check is first.floor_check
    right = PersonDetector(camera_pose=HIGH_POSE).detect_depth(three_people_depth, KINECT)
    assert right.ground_plane_source == "ransac" and right.floor_check is None and len(right.people) == 3


# --------------------------------------------------------------------------------------- real data
@pytest.mark.parametrize("path", DESK_FRAMES, ids=lambda p: p.name[:28])
def test_desk_frames_have_a_floor_and_no_people(path: Path) -> None:
    result = PersonDetector().detect_depth(desk_depth(path), KINECT)
    assert result.ground_plane_source == "ransac"
    # The Kinect looks down at the floor from ~0.71 m, tilted ~46 deg from level.
    assert result.ground_plane.camera_height_m == pytest.approx(0.71, abs=0.03)
    assert result.ground_plane.angle_to_deg([0.0, -1.0, 0.0]) == pytest.approx(46.3, abs=2.0)
    assert result.people == []
    # Even OpenPTrack's 0.6 m minimum height finds nobody among the laptop and the box.
    lenient = PersonDetector(PersonDetectorConfig(min_person_height_m=0.6)).detect_depth(
        desk_depth(path), KINECT
    )
    assert lenient.people == []


def test_desk_floor_is_stable_across_frames() -> None:
    detector = PersonDetector()
    planes = [detector.detect_depth(desk_depth(p), KINECT).ground_plane for p in DESK_FRAMES]
    for plane in planes[1:]:
        assert plane.angle_to_deg(planes[0].normal) < 1.0
        assert plane.camera_height_m == pytest.approx(planes[0].camera_height_m, abs=0.01)


# The person.pcd camera is level (its back wall is fronto-parallel) but sees no floor: the floor comes
# from an assumed pose, a level camera 1.5 m high (the person's head top is ~0.14 m above the lens).
PCD_POSE = CameraPose.from_xyz_rpy(0.0, 0.0, 1.5, 0.0, -0.05, 0.0)


@pytest.fixture(scope="module")
def person_cloud() -> np.ndarray:
    return read_pcd(DATA / "person.pcd")


def test_real_person_cloud_gives_exactly_one_person(person_cloud: np.ndarray) -> None:
    # the cloud shows no floor: nobody unless the pose's floor is trusted
    assert PersonDetector(camera_pose=PCD_POSE).detect_points(person_cloud).people == []
    result = PersonDetector(PersonDetectorConfig(people_on_pose_floor=True), camera_pose=PCD_POSE).detect_points(
        person_cloud)
    assert result.ground_plane_source == "pose"
    assert len(result.people) == 1
    (det,) = result.people
    # Head top 0.79 m in front of the camera, slightly above its axis; 1.64 m tall with the assumed pose.
    np.testing.assert_allclose(det.top_cam, [-0.09, -0.10, 0.79], atol=0.05)
    assert det.height_m == pytest.approx(1.64, abs=0.05)
    assert 0.3 <= det.width_m <= 0.6
    # The head ROI is on the person: the pixels around its centre are the head at ~0.8 m.
    x, y, w, h = head_roi_px(det.head_cam, KINECT, 0.3)
    centre = person_cloud[y + h // 2 - 10 : y + h // 2 + 10, x + w // 2 - 10 : x + w // 2 + 10, 2]
    assert np.nanmedian(centre) == pytest.approx(0.8, abs=0.1)


# ------------------------------------------------------------------------------------- ground plane
def test_ground_plane_normalises_and_measures_heights() -> None:
    plane = GroundPlane(np.array([0.0, -2.0, 0.0]), 3.0)  # y = 1.5 m below the camera, stored unit
    np.testing.assert_allclose(plane.normal, [0.0, -1.0, 0.0])
    assert plane.offset == pytest.approx(1.5) and plane.camera_height_m == pytest.approx(1.5)
    np.testing.assert_allclose(
        plane.height_of([[0.0, 1.5, 2.0], [1.0, 0.0, 5.0], [0.0, 2.0, 1.0]]), [0.0, 1.5, -0.5]
    )
    with pytest.raises(ValueError, match="non-zero"):
        GroundPlane(np.zeros(3), 1.0)
    with pytest.raises(ValueError, match="finite"):
        GroundPlane(np.array([0.0, np.nan, 1.0]), 1.0)


def test_ground_plane_from_pose_gives_world_heights() -> None:
    plane = GroundPlane.from_camera_pose(HIGH_POSE)
    points_world = np.array([[3.0, 0.5, 0.0], [4.0, -1.0, 1.7], [2.0, 0.0, -0.3]])
    np.testing.assert_allclose(
        plane.height_of(HIGH_POSE.to_camera(points_world)), points_world[:, 2], atol=1e-9
    )


def test_estimate_prefers_the_floor_to_a_large_table_top() -> None:
    """A table top covering more pixels than the floor still loses: the floor is seen below it."""
    rng = np.random.default_rng(3)
    floor = np.column_stack([rng.uniform(-3, 3, 3000), rng.uniform(0, 6, 3000), np.zeros(3000)])
    table = np.column_stack([rng.uniform(-1, 1, 5000), rng.uniform(1, 3, 5000), np.full(5000, 0.75)])
    world = np.vstack([floor[~((np.abs(floor[:, 0]) < 1) & (floor[:, 1] > 1) & (floor[:, 1] < 3))], table])
    world[:, 2] += rng.normal(0, 0.005, len(world))
    pose = CameraPose.looking_at([0.0, -1.0, 2.0], [0.0, 2.0, 0.0])
    plane = estimate_ground_plane(pose.to_camera(world), rng=np.random.default_rng(0))
    assert plane is not None
    assert plane.camera_height_m == pytest.approx(2.0, abs=0.02)
    assert plane.angle_to_deg(pose.up_in_camera) < 1.0
    # Seeded with the true pose but asked for a 0.75 m lower camera (the table): nothing qualifies.
    assert (
        fit_ground_plane(
            pose.to_camera(floor),
            seed_normal=pose.up_in_camera,
            seed_camera_height_m=1.25,
            rng=np.random.default_rng(0),
        )
        is None
    )


def test_estimate_ground_plane_edge_cases() -> None:
    assert estimate_ground_plane(np.zeros((0, 3))) is None
    assert estimate_ground_plane(np.full((500, 3), np.nan)) is None
    with pytest.raises(ValueError, match="shape"):
        estimate_ground_plane(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="seed_normal"):
        estimate_ground_plane(np.zeros((10, 3)), seed_normal=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="seed_camera_height_m"):
        estimate_ground_plane(np.zeros((10, 3)), seed_camera_height_m=2.0)
    # A vertical wall only: no plane within 60 deg of camera -y.
    rng = np.random.default_rng(0)
    wall = np.column_stack([rng.uniform(-2, 2, 2000), rng.uniform(-1, 1, 2000), np.full(2000, 4.0)])
    assert estimate_ground_plane(wall) is None
