"""A person's body at the camera on rendered RGB-D frames: depth mask, parts by metric height, geometry,
visibility, and the descriptor near and far."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_camera.body.descriptor import BodyDescriptorConfig, body_descriptor
from face_reid_camera.body.hsv_histogram import hsv_bin_index
from face_reid_camera.body.person_body import BodyConfig, body_grid, describe_body, measure_geometry, part_visibility
from face_reid_camera.body.projection import BodyProjection, fit_pca_block
from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.people.detector import PersonDetector
from face_reid_master.sim.renderer import SyntheticPerson, render_scene, synthetic_clothes

INTR = CameraIntrinsics.kinect_default()
POSE = CameraPose.from_xyz_rpy(0.0, 0.0, 2.5, 0.0, 0.35, 0.0)
EDGES = BodyDescriptorConfig().part_edges
RED, BLUE, GREEN, GREY = (30, 30, 200), (160, 60, 20), (40, 150, 40), (90, 90, 90)


def _scene(people: list[SyntheticPerson], pose: CameraPose = POSE, seed: int = 1):
    """Rendered frame, depth in metres, and the detector's people and floor."""
    frame = render_scene(people, INTR, pose, rng=np.random.default_rng(seed))
    depth = np.where(frame.depth_mm > 0, frame.depth_mm / 1000.0, np.nan).astype(np.float32)
    detection = PersonDetector(camera_pose=pose).detect_depth(depth, INTR)
    assert detection.ground_plane is not None
    return frame, depth, detection


def _candidate_near(detection, pose: CameraPose, xy: tuple[float, float]):
    world = np.array([pose.to_world(c.top_cam)[0] for c in detection.people])
    k = int(np.argmin(np.linalg.norm(world[:, :2] - np.asarray(xy), axis=1)))
    assert np.linalg.norm(world[k, :2] - np.asarray(xy)) < 0.2
    return k


def _grid(frame, depth, detection, k: int, config: BodyConfig | None = None):
    plane = detection.ground_plane
    cands = detection.people
    feet = np.array([c.top_cam - c.height_m * plane.normal for i, c in enumerate(cands) if i != k]).reshape(-1, 3)
    return body_grid(frame.rgb_bgr, depth, INTR, INTR, plane, cands[k].top_cam, cands[k].height_m, feet,
                     config or BodyConfig(), EDGES)


def _person(x: float, y: float, shirt=RED, trousers=BLUE, facing: float = math.pi, height: float = 1.75,
            texture: np.ndarray | None = None):
    return SyntheticPerson(x, y, height, facing, body_color_bgr=shirt, legs_color_bgr=trousers,
                           body_texture_bgr=texture)


def _clothes(shirt, trousers, stripes: bool, seed: int) -> np.ndarray:
    return synthetic_clothes(shirt, trousers, stripes, np.random.default_rng(seed))


def test_the_mask_is_the_person_not_the_floor_nor_the_person_behind() -> None:
    people = [_person(3.0, 0.0), _person(3.8, 0.45, GREEN, GREY)]  # the second stands behind, half hidden
    frame, depth, detection = _scene(people)
    k = _candidate_near(detection, POSE, (3.0, 0.0))
    grid = _grid(frame, depth, detection, k)
    rows = np.clip(np.rint(grid.pixel_v).astype(int), 0, INTR.height - 1)
    cols = np.clip(np.rint(grid.pixel_u).astype(int), 0, INTR.width - 1)
    truth = frame.person_ids[rows[:, None], cols[None, :]]  # who the renderer drew at each grid sample
    assert np.count_nonzero(truth == 1) > 200  # the person behind shows inside the crop box
    own = truth == 0
    precision = np.count_nonzero(grid.mask & own) / np.count_nonzero(grid.mask)
    recall = np.count_nonzero(grid.mask & own) / np.count_nonzero(own)
    assert precision > 0.97 and recall > 0.85, (precision, recall)
    assert np.count_nonzero(grid.mask & (truth == 1)) == 0  # nothing of the other person


@pytest.mark.parametrize("distance", [2.4, 5.0])
def test_parts_follow_the_height_above_the_floor(distance: float) -> None:
    frame, depth, detection = _scene([_person(distance, 0.0, RED, BLUE)])
    grid = _grid(frame, depth, detection, 0)
    bins = hsv_bin_index(grid.crop, (8, 8, 8))
    red_bin, blue_bin = hsv_bin_index(np.array([[RED]], np.uint8), (8, 8, 8))[0, 0], \
        hsv_bin_index(np.array([[BLUE]], np.uint8), (8, 8, 8))[0, 0]
    # shirt colour rules the torso part (shaded: count the hue only), trousers the leg parts (the upper legs
    # also show the hanging arms, in the shirt's colour)
    hue = bins // 64
    for part, colour_bin, share in ((1, red_bin, 0.9), (2, blue_bin, 0.7), (3, blue_bin, 0.9)):
        pixels = hue[grid.parts == part]
        assert pixels.size > 30
        assert np.mean(pixels == colour_bin // 64) > share, (part, np.bincount(pixels))
    # heights inside each part agree with the edges (fractions of the height below the top)
    below = (grid.person_height_m - grid.height) / grid.person_height_m
    for part in range(4):
        inside = below[grid.parts == part]
        assert inside.min() >= EDGES[part] - 1e-6 or part == 0
        assert inside.max() < EDGES[part + 1] + 1e-6


def test_geometry_from_depth_front_and_side() -> None:
    front_frame, front_depth, front_det = _scene([_person(3.0, 0.0, facing=math.pi)])
    side_frame, side_depth, side_det = _scene([_person(3.0, 0.0, facing=math.pi / 2)])
    front = measure_geometry(_grid(front_frame, front_depth, front_det, 0), EDGES)
    side = measure_geometry(_grid(side_frame, side_depth, side_det, 0), EDGES)
    assert front.height_m == pytest.approx(1.75, abs=0.06)
    assert 0.33 <= front.shoulder_width_m <= 0.5  # the rendered shoulders are 0.45 m wide
    assert 0.15 <= front.head_height_m <= 0.35
    assert 0.0 < front.torso_depth_m < 0.25
    assert side.shoulder_width_m < front.shoulder_width_m - 0.1  # from the side: the body's depth
    assert len(front.part_widths_m) == 4 and all(0.1 < w < 0.6 for w in front.part_widths_m)
    assert front.vector().shape == (6,) and front.vector().dtype == np.float32


def test_visibility_counts_what_the_image_border_cuts() -> None:
    frame, depth, detection = _scene([_person(4.0, 0.0)])
    whole, parts = part_visibility(_grid(frame, depth, detection, 0), EDGES)
    assert whole > 0.95 and min(parts) > 0.9
    # near a camera 2.5 m high looking down 20 degrees, the feet fall below the image
    frame, depth, detection = _scene([_person(1.6, 0.0)])
    whole, parts = part_visibility(_grid(frame, depth, detection, 0), EDGES)
    assert parts[0] > 0.9 and parts[3] < 0.3 and whole < 0.85


def _projection() -> BodyProjection:
    rng = np.random.default_rng(0)
    c = BodyDescriptorConfig()
    return BodyProjection((fit_pca_block("hsv", rng.random((40, c.hsv_length)), 8),
                           fit_pca_block("siltp", rng.random((40, c.siltp_length)), 4)))


def test_describe_body_with_and_without_projection() -> None:
    frame, depth, detection = _scene([_person(3.0, 0.0)])
    cand, plane = detection.people[0], detection.ground_plane
    args = (frame.rgb_bgr, depth, INTR, INTR, plane, cand.top_cam, cand.height_m, np.zeros((0, 3)))
    projection = _projection()
    body = describe_body(*args, BodyConfig(), projection)
    assert body is not None and body.descriptor.shape == (12,) and body.space == projection.space
    assert body.visible_fraction > 0.9 and len(body.part_visible) == 4
    geometry_only = describe_body(*args, BodyConfig(), None)
    assert geometry_only is not None and geometry_only.descriptor.size == 0 and geometry_only.space == ""
    assert geometry_only.geometry.height_m == body.geometry.height_m
    too_small = describe_body(*args, BodyConfig(min_rows_px=1000), projection)  # the person spans ~230 px
    assert too_small is not None and too_small.descriptor.size == 0
    too_hidden = describe_body(*args, BodyConfig(min_visible_fraction=1.0), projection)
    assert too_hidden is not None and too_hidden.descriptor.size == 0


def _descriptor(distance: float, texture: np.ndarray, y: float = 0.0):
    frame, depth, detection = _scene([_person(distance, y, texture=texture)])
    grid = _grid(frame, depth, detection, 0)
    return body_descriptor(grid.crop, grid.mask, BodyDescriptorConfig(), grid.parts)


def test_same_person_at_2_and_4_m_nearly_the_same_other_clothes_differ() -> None:
    alice = _clothes(RED, BLUE, stripes=True, seed=0)
    near, far = _descriptor(2.3, alice), _descriptor(4.3, alice, y=0.6)
    others = [_descriptor(2.3, _clothes(GREEN, GREY, stripes=False, seed=1)),  # other colours
              _descriptor(2.3, _clothes(RED, BLUE, stripes=False, seed=2))]  # alike, but a plain shirt
    for feature in ("hsv", "siltp"):
        same = np.linalg.norm(getattr(near, feature) - getattr(far, feature))
        different = [np.linalg.norm(getattr(near, feature) - getattr(o, feature)) for o in others]
        assert same < 0.6 * min(different) if feature == "hsv" else same < max(different), (feature, same, different)
    assert near.hsv @ far.hsv > 0.85 and near.hsv @ others[0].hsv < 0.3
    # the texture tells the striped shirt from the plain one where the colours nearly agree
    assert np.linalg.norm(near.siltp - far.siltp) < np.linalg.norm(near.siltp - others[1].siltp)


def test_config_is_validated() -> None:
    with pytest.raises(ValueError, match="radius_m"):
        BodyConfig(radius_m=0.0)
    with pytest.raises(ValueError, match="min_visible_fraction"):
        BodyConfig(min_visible_fraction=1.5)


def test_broken_depth_and_odd_heads_give_no_body_or_a_hidden_one_never_an_error() -> None:
    frame, depth, detection = _scene([_person(3.0, 0.0)])
    cand, plane = detection.people[0], detection.ground_plane
    projection = _projection()
    rng = np.random.default_rng(3)
    broken = [np.full_like(depth, np.nan), np.zeros_like(depth), np.full_like(depth, np.inf), -depth,
              np.where(rng.random(depth.shape) < 0.7, np.nan, depth).astype(np.float32)]
    for bad in broken:
        body = describe_body(frame.rgb_bgr, bad, INTR, INTR, plane, cand.top_cam, cand.height_m, np.zeros((0, 3)),
                             BodyConfig(), projection)
        assert body is not None and 0.0 <= body.visible_fraction <= 1.0
    hidden = describe_body(frame.rgb_bgr, np.full_like(depth, np.nan), INTR, INTR, plane, cand.top_cam,
                           cand.height_m, np.zeros((0, 3)), BodyConfig(), projection)
    assert hidden.visible_fraction == 0.0 and hidden.descriptor.size == 0
    assert all(math.isnan(v) for v in hidden.geometry.vector()[1:])
    # a head behind the camera, at the camera, and far outside the image
    for top in (np.array([0.0, 0.0, -2.0]), np.zeros(3), np.array([40.0, -1.0, 3.0])):
        assert describe_body(frame.rgb_bgr, depth, INTR, INTR, plane, top, 1.7, np.zeros((0, 3)), BodyConfig(),
                             projection) is None
