"""Tests of the synthetic RGB-D renderer: analytic depth, occlusion, facing, determinism, and real YuNet
detections of the real face photos it pastes on the heads."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from conftest import FACES_DIR

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose, depth_to_points
from face_reid_camera.common.resources import model_path
from face_reid_master.sim.renderer import (
    CLUTTER_KINDS,
    HEAD_SEMI_AXES_M,
    RenderedFrame,
    SceneObject,
    SyntheticPerson,
    clutter_object,
    crop_face_for_rendering,
    render_scene,
)

YUNET = model_path("face_detection_yunet_2023mar.onnx")
K = CameraIntrinsics.kinect_default()  # 640x480, fx = fy = 525
# 5-point template of dlib's 150x150 chip (see notes/models.md), to compare aligned faces
TEMPLATE = np.array(
    [[47.15, 46.17], [102.09, 44.71], [75.0, 78.7], [52.9, 103.27], [100.66, 101.74]], dtype=np.float32
)
PHOTOS = [
    "lfw_Colin_Powell/Colin_Powell_0004.jpg",
    "deepface_id03/img48.jpg",
    "facerec_biden/biden2.jpg",
    "lfw_Hugo_Chavez/Hugo_Chavez_0004.jpg",
]


def _detector() -> cv2.FaceDetectorYN:
    return cv2.FaceDetectorYN.create(str(YUNET), "", (320, 320), 0.7, 0.3, 50)


def _detect(image: np.ndarray) -> np.ndarray:
    detector = _detector()
    detector.setInputSize((image.shape[1], image.shape[0]))
    _, faces = detector.detect(image)
    return np.zeros((0, 15), dtype=np.float32) if faces is None else faces


def _largest(faces: np.ndarray) -> np.ndarray:
    return faces[int(np.argmax(faces[:, 2] * faces[:, 3]))]


def _crop(rel: str) -> np.ndarray:
    photo = cv2.imread(str(FACES_DIR / rel))
    assert photo is not None, rel
    return crop_face_for_rendering(photo, _largest(_detect(photo))[:4])


@pytest.fixture(scope="module")
def face_crops() -> dict[str, np.ndarray]:
    return {rel: _crop(rel) for rel in PHOTOS}


def _ceiling_camera(height_m: float = 2.3, tilt_deg: float = 20.0) -> CameraPose:
    return CameraPose.from_xyz_rpy(0.0, 0.0, height_m, 0.0, math.radians(tilt_deg), 0.0)


def _facing_origin(x: float, y: float) -> float:
    return math.atan2(-y, -x)


def _pixel_ray_world(pose: CameraPose, intr: CameraIntrinsics, u: float, v: float) -> np.ndarray:
    """World direction of the ray through pixel (u, v), scaled so that its camera z is 1."""
    return pose.rotation @ np.array([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, 1.0])


# ---------------------------------------------------------------------------------------------------
# Geometry


def test_head_depth_on_optical_axis_equals_distance_to_face() -> None:
    # cx, cy on a pixel centre so that pixel (320, 240) is exactly the optical axis
    intr = CameraIntrinsics(525.0, 525.0, 320.0, 240.0, 640, 480)
    person = SyntheticPerson(3.0, 0.0, height_m=1.75, facing_rad=math.pi)
    eye = person.head_centre_world
    pose = CameraPose.looking_at(np.array([0.0, 0.0, eye[2]]), eye)
    frame = render_scene([person], intr, pose, depth_noise=False)
    # the ray hits the front of the cranium ellipsoid, 0.10 m before its centre
    assert abs(int(frame.depth_mm[240, 320]) - 2900) <= 1
    assert frame.person_ids[240, 320] == 0
    noisy = render_scene([person], intr, pose, rng=np.random.default_rng(3))
    sigma_mm = 1.5e-3 * 2.9**2 * 1000.0
    assert abs(int(noisy.depth_mm[240, 320]) - 2900) < 5 * sigma_mm


def test_head_depth_matches_independent_ray_ellipsoid_intersection() -> None:
    pose = _ceiling_camera(2.4, 22.0)
    person = SyntheticPerson(2.5, 0.4, height_m=1.8, facing_rad=1.2)
    frame = render_scene([person], K, pose, depth_noise=False)
    origin = pose.translation
    a, b, c = HEAD_SEMI_AXES_M
    cf, sf = math.cos(person.facing_rad), math.sin(person.facing_rad)
    to_local = np.array([[cf / a, sf / a, 0.0], [-sf / b, cf / b, 0.0], [0.0, 0.0, 1.0 / c]])
    top = person.head_centre_world + np.array([0.0, 0.0, 0.07])  # upper head: cranium only
    u0, v0 = K.project(pose.to_camera(top[None]))[0]
    checked = 0
    for du in (-3, 0, 3):
        for dv in (-2, 0, 2):
            u, v = round(u0) + du, round(v0) + dv
            d = to_local @ _pixel_ray_world(pose, K, u, v)
            o = to_local @ (origin - person.head_centre_world)
            qa, qb, qc = d @ d, o @ d, o @ o - 1.0
            t = (-qb - math.sqrt(qb * qb - qa * qc)) / qa  # camera z of the nearest hit
            assert frame.person_ids[v, u] == 0
            assert abs(int(frame.depth_mm[v, u]) - t * 1000.0) <= 1.0
            checked += 1
    assert checked == 9


def test_floor_depth_matches_the_plane_and_noise_scales_with_z_squared() -> None:
    pose = _ceiling_camera(2.3, 25.0)
    clean = render_scene([], K, pose, depth_noise=False, floor_size_m=40.0)
    v, u = np.mgrid[0:K.height, 0:K.width]
    rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(u.shape)], axis=-1) @ pose.rotation.T
    with np.errstate(divide="ignore"):
        expected_m = np.where(rays[..., 2] < 0, -pose.translation[2] / rays[..., 2], np.inf)
    in_range = (expected_m >= 0.5) & (expected_m <= 8.0)
    assert np.all((clean.depth_mm > 0) == in_range)  # floor up to 8 m, dropped beyond (and no sky return)
    err = np.abs(clean.depth_mm[in_range] / 1000.0 - expected_m[in_range])
    assert err.max() <= 0.0006
    assert np.any((expected_m > 8.0) & np.isfinite(expected_m))  # the range cut was exercised
    # floor points back-projected from depth lie on z = 0 in the world
    points = pose.to_world(depth_to_points(clean.depth_mm / 1000.0, K, stride=8))
    assert np.abs(points[:, 2]).max() < 0.002
    noisy = render_scene([], K, pose, rng=np.random.default_rng(7), floor_size_m=40.0)
    band = in_range & (expected_m > 3.0) & (expected_m < 4.0) & (noisy.depth_mm > 0)
    resid = noisy.depth_mm[band] / 1000.0 - expected_m[band]
    sigma = 1.5e-3 * expected_m[band] ** 2
    assert abs(np.std(resid / sigma) - 1.0) < 0.1
    assert abs(np.mean(resid / sigma)) < 0.05


def test_walls_bound_the_room() -> None:
    pose = CameraPose.looking_at(np.array([0.0, 0.0, 1.5]), np.array([1.0, 0.0, 1.5]))
    intr = CameraIntrinsics(525.0, 525.0, 320.0, 240.0, 640, 480)
    open_floor = render_scene([], intr, pose, depth_noise=False, floor_size_m=6.0)
    room = render_scene([], intr, pose, depth_noise=False, floor_size_m=6.0, walls=True)
    assert open_floor.depth_mm[240, 320] == 0  # horizon: nothing
    assert room.depth_mm[240, 320] == 3000  # wall at x = +3 m
    assert np.count_nonzero(room.depth_mm) > np.count_nonzero(open_floor.depth_mm)


def test_static_objects_are_drawn_at_their_place_and_occlude_people() -> None:
    pose = CameraPose.looking_at(np.array([0.0, 0.0, 1.2]), np.array([1.0, 0.0, 1.2]))
    intr = CameraIntrinsics(525.0, 525.0, 320.0, 240.0, 640, 480)
    pillar = clutter_object("pillar", 3.0, 0.0)
    frame = render_scene([SyntheticPerson(4.0, 0.0)], intr, pose, depth_noise=False, objects=pillar)
    assert frame.depth_mm[240, 320] == 2800  # the pillar's front surface (radius 0.2 m) hides the person
    assert frame.person_ids[240, 320] == -1
    alone = render_scene([SyntheticPerson(4.0, 0.0)], intr, pose, depth_noise=False)
    assert alone.person_ids[240, 320] == 0
    for kind in CLUTTER_KINDS:
        assert clutter_object(kind, 1.0, 2.0), kind
    with pytest.raises(ValueError, match="clutter kind"):
        clutter_object("sofa", 0.0, 0.0)
    with pytest.raises(ValueError, match="semi_axes"):
        SceneObject("cylinder", (0.0, 0.0, 1.0), (0.1, -0.1, 1.0))
    with pytest.raises(TypeError, match="objects"):
        render_scene([], intr, pose, objects=["pillar"])  # type: ignore[list-item]


def test_person_pixels_are_nearer_than_the_floor_behind_them() -> None:
    pose = _ceiling_camera()
    people = [SyntheticPerson(2.0, -0.5, facing_rad=0.3), SyntheticPerson(3.0, 0.6, facing_rad=2.0)]
    frame = render_scene(people, K, pose, depth_noise=False)
    empty = render_scene([], K, pose, depth_noise=False)
    for index in range(2):
        mask = frame.person_ids == index
        assert mask.sum() > 2000
        floor_behind = empty.depth_mm[mask].astype(int)
        person = frame.depth_mm[mask].astype(int)
        assert np.all((floor_behind == 0) | (person <= floor_behind))  # feet touch the floor
    # every person pixel back-projects into the person's body volume
    points = pose.to_world(depth_to_points(np.where(frame.person_ids == 0, frame.depth_mm, 0) / 1000.0, K))
    radial = np.hypot(points[:, 0] - 2.0, points[:, 1] + 0.5)
    assert radial.max() < 0.25 and points[:, 2].max() < 1.76 and points[:, 2].min() > -0.01


def test_occluded_person_has_no_visible_face(face_crops: dict[str, np.ndarray]) -> None:
    crops = list(face_crops.values())
    front = SyntheticPerson(2.0, 0.0, facing_rad=math.pi, face_image_bgr=crops[0])
    back = SyntheticPerson(3.5, 0.0, facing_rad=math.pi, face_image_bgr=crops[1])
    eye = front.head_centre_world
    pose = CameraPose.looking_at(np.array([0.0, 0.0, eye[2]]), eye)  # both heads on the optical axis
    frame = render_scene([front, back], K, pose, depth_noise=False)
    assert frame.face_visible == [True, False]
    assert np.isnan(frame.face_boxes_xywh[1]).all()
    u, v = (round(c) for c in K.project(pose.to_camera(back.head_centre_world[None]))[0])
    assert frame.person_ids[v, u] == 0
    assert abs(int(frame.depth_mm[v, u]) - 1900) <= 2  # the front person's face, not the back one's
    faces = _detect(frame.rgb_bgr)
    assert len(faces) == 1
    box = frame.face_boxes_xywh[0]
    assert abs(faces[0][0] + faces[0][2] / 2 - (box[0] + box[2] / 2)) < 0.25 * box[3]
    # step the back person aside: now both faces are visible and detected
    aside = SyntheticPerson(3.5, 0.45, facing_rad=_facing_origin(3.5, 0.45), face_image_bgr=crops[1])
    frame = render_scene([front, aside], K, pose, depth_noise=False)
    assert frame.face_visible == [True, True]
    assert len(_detect(frame.rgb_bgr)) == 2


def test_person_facing_away_or_too_far_turned_gets_no_face(face_crops: dict[str, np.ndarray]) -> None:
    crop = next(iter(face_crops.values()))
    pose = _ceiling_camera()
    away = render_scene([SyntheticPerson(2.5, 0.0, facing_rad=0.0, face_image_bgr=crop)], K, pose)
    assert away.face_visible == [False]
    assert np.isnan(away.face_boxes_xywh).all()
    assert len(_detect(away.rgb_bgr)) == 0
    assert np.count_nonzero(away.person_ids == 0) > 2000  # the person is there, only the face is not
    toward = math.pi
    for turn_deg, visible in ((40.0, True), (70.0, False)):
        person = SyntheticPerson(2.5, 0.0, facing_rad=toward + math.radians(turn_deg), face_image_bgr=crop)
        assert render_scene([person], K, pose).face_visible == [visible]
    no_face = render_scene([SyntheticPerson(2.5, 0.0, facing_rad=toward)], K, pose)
    assert no_face.face_visible == [False]
    assert len(_detect(no_face.rgb_bgr)) == 0


def test_same_seed_same_frame_and_seed_only_changes_depth_noise(face_crops: dict[str, np.ndarray]) -> None:
    crop = next(iter(face_crops.values()))
    people = [SyntheticPerson(2.0, 0.3, facing_rad=math.pi, face_image_bgr=crop), SyntheticPerson(3.0, -0.5)]
    pose = _ceiling_camera()
    a = render_scene(people, K, pose, rng=np.random.default_rng(11))
    b = render_scene(people, K, pose, rng=np.random.default_rng(11))
    c = render_scene(people, K, pose, rng=np.random.default_rng(12))
    assert np.array_equal(a.depth_mm, b.depth_mm) and np.array_equal(a.rgb_bgr, b.rgb_bgr)
    assert not np.array_equal(a.depth_mm, c.depth_mm)
    assert np.array_equal(a.rgb_bgr, c.rgb_bgr) and np.array_equal(a.person_ids, c.person_ids)
    assert np.array_equal(render_scene(people, K, pose).depth_mm, render_scene(people, K, pose).depth_mm)
    assert a.head_centres_world.shape == (2, 3)
    np.testing.assert_allclose(a.head_centres_world[0], [2.0, 0.3, 1.75 - HEAD_SEMI_AXES_M[2]])


def test_empty_scene_and_image_background() -> None:
    pose = CameraPose.looking_at(np.array([0.0, 0.0, 1.5]), np.array([1.0, 0.0, 1.6]))
    background = np.full((480, 640, 3), (10, 200, 30), dtype=np.uint8)
    frame = render_scene([], K, pose, background_bgr=background)
    assert isinstance(frame, RenderedFrame)
    assert frame.face_visible == [] and frame.head_centres_world.shape == (0, 3)
    assert frame.face_boxes_xywh.shape == (0, 4)
    assert np.all(frame.depth_mm[:100] == 0)  # looking slightly up: the top rows see no floor
    assert np.all(frame.rgb_bgr[:100] == (10, 200, 30))
    assert np.all(frame.depth_mm[-50:] > 0)
    assert not np.any(np.all(frame.rgb_bgr[-50:] == (10, 200, 30), axis=-1))


# ---------------------------------------------------------------------------------------------------
# Faces: real photos, real YuNet


@pytest.mark.parametrize("distance_m", [1.5, 2.5, 3.5])
def test_yunet_finds_the_face_on_the_head_at_its_real_size(
    face_crops: dict[str, np.ndarray], distance_m: float
) -> None:
    pose = _ceiling_camera(2.3, 20.0)
    for n, (name, crop) in enumerate(face_crops.items()):
        y = (n - 1.5) * 0.3
        x = math.sqrt(distance_m**2 - y**2)
        person = SyntheticPerson(x, y, height_m=1.65 + 0.05 * n, facing_rad=_facing_origin(x, y),
                                 face_image_bgr=crop)
        frame = render_scene([person], K, pose, rng=np.random.default_rng(n))
        assert frame.face_visible == [True], name
        faces = _detect(frame.rgb_bgr)
        assert len(faces) >= 1, f"{name} at {distance_m} m: no face found"
        face = _largest(faces)
        fx, fy, fw, fh = face[:4]
        cu, cv = fx + fw / 2, fy + fh / 2
        # where the renderer says the face is
        box = frame.face_boxes_xywh[0]
        assert abs(cu - (box[0] + box[2] / 2)) < 0.2 * box[3], name
        assert abs(cv - (box[1] + box[3] / 2)) < 0.2 * box[3], name
        # on this person's head, consistent with depth: back-project the box centre and size
        assert frame.person_ids[round(cv), round(cu)] == 0
        patch = frame.depth_mm[round(cv) - 2: round(cv) + 3, round(cu) - 2: round(cu) + 3]
        z = float(np.median(patch[patch > 0])) / 1000.0
        centre_world = pose.to_world(np.array([[(cu - K.cx) * z / K.fx, (cv - K.cy) * z / K.fy, z]]))[0]
        offset = centre_world - person.head_centre_world
        assert abs(offset[2] + 0.02) < 0.04, f"{name}: face centre {offset[2]:+.3f} m from head centre"
        assert math.hypot(offset[0], offset[1]) < 0.15
        face_height_m = fh * z / K.fy
        assert 0.13 < face_height_m < 0.23, f"{name}: detected face {face_height_m:.3f} m tall"


def test_several_people_in_one_frame_all_detected(face_crops: dict[str, np.ndarray]) -> None:
    pose = _ceiling_camera(2.4, 18.0)
    spots = [(1.6, -0.6), (2.6, 0.5), (3.6, -0.2), (2.2, 1.0)]
    people = [SyntheticPerson(x, y, facing_rad=_facing_origin(x, y) + 0.2 * (i - 1.5), face_image_bgr=crop,
                              body_color_bgr=(40 * i, 100, 200 - 40 * i))
              for i, ((x, y), crop) in enumerate(zip(spots, face_crops.values(), strict=True))]
    frame = render_scene(people, K, pose, rng=np.random.default_rng(0))
    assert frame.face_visible == [True] * 4
    faces = _detect(frame.rgb_bgr)
    centres = faces[:, :2] + faces[:, 2:4] / 2
    for i, box in enumerate(frame.face_boxes_xywh):
        dist = np.hypot(*(centres - (box[:2] + box[2:] / 2)).T)
        assert dist.min() < 0.25 * box[3], f"person {i} not detected"


def _aligned(image: np.ndarray) -> np.ndarray:
    landmarks = _largest(_detect(image))[4:14].reshape(5, 2).astype(np.float32)
    matrix, _ = cv2.estimateAffinePartial2D(landmarks, TEMPLATE)
    chip = cv2.warpAffine(image, matrix, (150, 150))
    return cv2.cvtColor(chip, cv2.COLOR_BGR2GRAY)[35:115, 35:115].astype(np.float64)


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def test_pasted_face_is_the_photo_not_its_mirror_image() -> None:
    # the person's left must appear on the image right, as in the photo: aligned chips must match
    pose = CameraPose.looking_at(np.array([0.0, 0.0, 1.6]), np.array([1.2, 0.0, 1.6]))
    for name in ("lfw_Vladimir_Putin/Vladimir_Putin_0002.jpg", "deepface_id08/img22.jpg"):
        crop = _crop(name)
        frame = render_scene([SyntheticPerson(1.2, 0.0, facing_rad=math.pi, face_image_bgr=crop)], K, pose)
        rendered = _aligned(frame.rgb_bgr)
        same, mirrored = _ncc(rendered, _aligned(crop)), _ncc(rendered, _aligned(cv2.flip(crop, 1)))
        assert same > 0.6 and same > mirrored + 0.1, f"{name}: ncc {same:.2f} vs mirrored {mirrored:.2f}"


# ---------------------------------------------------------------------------------------------------
# crop_face_for_rendering and validation


def test_crop_face_is_a_centred_square_with_margin() -> None:
    photo = np.zeros((200, 300, 3), dtype=np.uint8)
    photo[:, :, 0] = (np.arange(300)[None, :] % 256).astype(np.uint8)
    photo[:, :, 1] = np.arange(200, dtype=np.uint8)[:, None]
    crop = crop_face_for_rendering(photo, (100, 50, 60, 80), margin=0.15)
    assert crop.shape == (104, 104, 3)  # 80 * 1.3
    assert crop[52, 52, 0] == 130 and crop[52, 52, 1] == 90  # box centre (130, 90) in the middle
    edge = crop_face_for_rendering(photo, (0, 0, 40, 40), margin=0.25)  # pads by replicating the border
    assert edge.shape == (60, 60, 3)
    assert np.all(edge[:, :11, 0] == 0) and np.all(edge[:11, :, 1] == 0)  # 10 px replicated
    assert edge[-1, -1, 0] == 49 and edge[-1, -1, 1] == 49 and edge[10, 10, 0] == 0


@pytest.mark.parametrize(
    "photo, box, margin",
    [
        (np.zeros((100, 100), dtype=np.uint8), (10, 10, 40, 40), 0.15),
        (np.zeros((100, 100, 3), dtype=np.float32), (10, 10, 40, 40), 0.15),
        (np.zeros((100, 100, 3), dtype=np.uint8), (10, 10, float("nan"), 40), 0.15),
        (np.zeros((100, 100, 3), dtype=np.uint8), (10, 10, -5, 40), 0.15),
        (np.zeros((100, 100, 3), dtype=np.uint8), (200, 10, 40, 40), 0.15),
        (np.zeros((100, 100, 3), dtype=np.uint8), (10, 10, 4, 4), 0.15),
        (np.zeros((100, 100, 3), dtype=np.uint8), (10, 10, 40, 40), -0.1),
        (np.zeros((100, 100, 3), dtype=np.uint8), (10, 10), 0.15),
    ],
)
def test_crop_face_rejects_bad_input(photo: np.ndarray, box: tuple, margin: float) -> None:
    with pytest.raises(ValueError):
        crop_face_for_rendering(photo, box, margin)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"x_m": float("nan")},
        {"height_m": 0.5},
        {"height_m": float("inf")},
        {"facing_rad": "north"},
        {"shoulder_width_m": 2.0},
        {"body_color_bgr": (0, 0, 300)},
        {"hair_color_bgr": [0, 0, 0]},
        {"face_image_bgr": np.zeros((64, 64), dtype=np.uint8)},
        {"face_image_bgr": np.zeros((64, 64, 3), dtype=np.float64)},
        {"face_image_bgr": np.zeros((8, 8, 3), dtype=np.uint8)},
        {"face_crop_margin": 2.0},
        {"body_texture_bgr": np.zeros((8, 4, 3), dtype=np.uint8)},
        {"body_texture_bgr": np.zeros((128, 48), dtype=np.uint8)},
    ],
)
def test_synthetic_person_validates(kwargs: dict) -> None:
    args = {"x_m": 1.0, "y_m": 0.0} | kwargs
    with pytest.raises(ValueError, match="SyntheticPerson"):
        SyntheticPerson(**args)


def test_render_scene_validates_arguments() -> None:
    pose, person = _ceiling_camera(), SyntheticPerson(2.0, 0.0)
    with pytest.raises(TypeError, match="SyntheticPerson"):
        render_scene([(2.0, 0.0)], K, pose)  # type: ignore[list-item]
    with pytest.raises(TypeError, match="CameraIntrinsics"):
        render_scene([person], (525, 525, 320, 240), pose)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="CameraPose"):
        render_scene([person], K, np.eye(4))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="rng"):
        render_scene([person], K, pose, rng=42)  # type: ignore[arg-type]
    bad = [
        {"max_face_angle_deg": 120.0},
        {"max_face_angle_deg": float("nan")},
        {"min_range_m": 9.0},
        {"depth_noise_coeff_per_m": -1e-3},
        {"floor_size_m": 0.0},
        {"min_visible_face_fraction": 0.0},
        {"wall_height_m": float("nan")},
        {"background_bgr": np.zeros((10, 10, 3), dtype=np.uint8)},
        {"background_bgr": (1, 2)},
    ]
    for kwargs in bad:
        with pytest.raises(ValueError):
            render_scene([person], K, pose, **kwargs)


# ---------------------------------------------------------------------------------------------------
# Body textures


def _quadrant_crop() -> np.ndarray:
    """A 128x48 person crop: upper half red (left) / green (right), lower half blue (left) / white (right)."""
    crop = np.zeros((128, 48, 3), dtype=np.uint8)
    crop[:64, :24] = (0, 0, 255)
    crop[:64, 24:] = (0, 255, 0)
    crop[64:, :24] = (255, 0, 0)
    crop[64:, 24:] = (255, 255, 255)
    return crop


def _dominant(pixels: np.ndarray) -> int:
    """Index (B, G, R) of the strongest channel on average, or 3 for near-white."""
    mean = pixels.reshape(-1, 3).astype(np.float64).mean(axis=0)
    return 3 if mean.min() > 0.6 * mean.max() else int(np.argmax(mean))


@pytest.mark.parametrize("facing", [math.pi, 0.0, math.pi / 2])
def test_body_texture_is_a_billboard_facing_the_camera(facing: float) -> None:
    """The crop's left half shows on the image's left, its top on the upper body, whichever way the person
    faces (the caller picks the crop of the matching orientation); depth is that of the flat-coloured body."""
    pose = _ceiling_camera()
    plain = SyntheticPerson(3.0, 0.0, 1.75, facing)
    textured = SyntheticPerson(3.0, 0.0, 1.75, facing, body_texture_bgr=_quadrant_crop())
    a = render_scene([plain], K, pose, depth_noise=False)
    b = render_scene([textured], K, pose, depth_noise=False)
    assert np.array_equal(a.depth_mm, b.depth_mm) and np.array_equal(a.person_ids, b.person_ids)
    body = b.person_ids == 0
    rows, cols = np.nonzero(body)
    # rows of the body at 35 % and 80 % of the height from the top (torso / legs), split at the body axis
    top_v = K.project(pose.to_camera(np.array([[3.0, 0.0, 1.75]])))[0, 1]
    foot_v = K.project(pose.to_camera(np.array([[3.0, 0.0, 0.0]])))[0, 1]
    axis_u = K.project(pose.to_camera(np.array([[3.0, 0.0, 0.9]])))[0, 0]
    for frac, left, right in ((0.35, 2, 1), (0.8, 0, 3)):
        r = round(top_v + frac * (foot_v - top_v))
        band = body[r - 2: r + 3]
        img = b.rgb_bgr[r - 2: r + 3]
        lcols = np.zeros_like(band)
        lcols[:, : round(axis_u) - 2] = True
        rcols = np.zeros_like(band)
        rcols[:, round(axis_u) + 3:] = True
        assert (band & lcols).sum() > 5 and (band & rcols).sum() > 5
        assert _dominant(img[band & lcols]) == left
        assert _dominant(img[band & rcols]) == right
    assert rows.size and cols.size
    # the head keeps its own rendering (hair / skin), not the crop's colours
    head = b.rgb_bgr[round(top_v) + 2: round(top_v) + 6][body[round(top_v) + 2: round(top_v) + 6]]
    assert np.array_equal(head, a.rgb_bgr[round(top_v) + 2: round(top_v) + 6][body[round(top_v) + 2:
                                                                                   round(top_v) + 6]])
