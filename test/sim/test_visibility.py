"""Tests of what the simulated cameras see: visibility geometry, occlusion, lone-person coverage, losses, glances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_master.sim.visibility import (
    VisibilityConfig,
    body_band_visibility,
    camera_views,
    camera_visibility,
    count_losses,
    floor_grid,
    glance_ids,
    lone_person_visibility,
)
from face_reid_master.sim.world import SimCamera

K = CameraIntrinsics.kinect_default()


def _camera(x: float = 0.0, y: float = 0.0, z: float = 2.4, tilt_deg: float = 20.0, yaw_deg: float = 0.0) -> SimCamera:
    xyz_rpy = (x, y, z, 0.0, math.radians(tilt_deg), math.radians(yaw_deg))
    return SimCamera("c", K, CameraPose.from_xyz_rpy(*xyz_rpy), xyz_rpy)


def _vis(camera: SimCamera, people: list[tuple[float, float, float]], heights: list[float] | None = None,
         config: VisibilityConfig | None = None):
    """Visibility of people (x, y, facing_deg) at one instant."""
    xy = np.array([[p[0], p[1]] for p in people], dtype=float)[None]
    facing = np.radians(np.array([p[2] for p in people], dtype=float))[None]
    h = np.array(heights if heights is not None else [1.75] * len(people))
    return camera_visibility(camera, xy, facing, h, np.ones((1, len(people)), dtype=bool), config)


def test_person_in_front_facing_the_camera_is_detected_with_face() -> None:
    vis = _vis(_camera(), [(3.0, 0.0, 180.0)])
    assert vis.detectable[0, 0] and vis.face_visible[0, 0] and not vis.occluded[0, 0]
    assert vis.face_angle_deg[0, 0] == pytest.approx(0.0, abs=1e-6)
    assert vis.range_m[0, 0] == pytest.approx(math.hypot(3.0, 2.4 - 1.63), rel=1e-6)


def test_facing_away_or_too_far_hides_the_face_only() -> None:
    cam = _camera()
    away = _vis(cam, [(3.0, 0.0, 0.0)])
    assert away.detectable[0, 0] and not away.face_visible[0, 0]
    assert away.face_angle_deg[0, 0] == pytest.approx(180.0)
    # angle limit: 49 deg visible, 51 deg not
    assert _vis(cam, [(3.0, 0.0, 180.0 - 49.0)]).face_visible[0, 0]
    assert not _vis(cam, [(3.0, 0.0, 180.0 - 51.0)]).face_visible[0, 0]
    far = _vis(cam, [(5.0, 0.0, 180.0)])
    assert far.detectable[0, 0] and not far.face_visible[0, 0]  # beyond max_face_range_m = 4.5
    assert _vis(cam, [(5.0, 0.0, 180.0)], config=VisibilityConfig(max_face_range_m=6.0)).face_visible[0, 0]


def test_out_of_fov_too_close_or_too_far_is_not_detected() -> None:
    cam = _camera()
    half_fov = math.degrees(math.atan2(320.0, 525.0))  # 31.4 deg
    inside = math.radians(half_fov - 8.0)
    outside = math.radians(half_fov + 3.0)
    assert _vis(cam, [(3.0 * math.cos(inside), 3.0 * math.sin(inside), 180.0)]).detectable[0, 0]
    assert not _vis(cam, [(3.0 * math.cos(outside), 3.0 * math.sin(outside), 180.0)]).detectable[0, 0]
    assert not _vis(cam, [(-2.0, 0.0, 0.0)]).detectable[0, 0]  # behind the camera
    assert not _vis(cam, [(0.6, 0.0, 180.0)]).detectable[0, 0]  # under the camera: head above the image
    assert not _vis(cam, [(6.5, 0.0, 180.0)]).detectable[0, 0]  # beyond max_range_m = 6
    # partly outside the image (head edge past the border) is not detected
    edge = math.radians(half_fov - 0.5)
    assert not _vis(cam, [(3.0 * math.cos(edge), 3.0 * math.sin(edge), 180.0)]).detectable[0, 0]
    # nobody outside the room is seen
    vis = camera_visibility(cam, np.array([[[3.0, 0.0]]]), np.array([[math.pi]]), np.array([1.75]),
                            np.array([[False]]))
    assert not vis.detectable[0, 0]


def test_occlusion_by_a_person_in_front() -> None:
    cam = _camera()  # 2.4 m high
    # just in front: the line of sight to the shoulders and to the head passes through B
    vis = _vis(cam, [(4.0, 0.0, 180.0), (3.5, 0.0, 180.0)])
    assert vis.occluded[0, 0] and not vis.detectable[0, 0] and not vis.face_visible[0, 0]
    assert vis.detectable[0, 1] and vis.face_visible[0, 1] and not vis.occluded[0, 1]
    # a step aside clears the line of sight
    side = _vis(cam, [(4.0, 0.0, 180.0), (3.5, 0.5, 180.0)])
    assert side.detectable[0, 0] and side.face_visible[0, 0]
    # B behind A hides nothing
    behind = _vis(cam, [(4.0, 0.0, 180.0), (4.6, 0.0, 180.0)])
    assert behind.detectable[0, 0] and not behind.detectable[0, 1]
    # a high camera sees over the head of someone far in front (the ray passes B at 2.0 m > 1.75 m)
    over = _vis(cam, [(4.0, 0.0, 180.0), (2.0, 0.0, 180.0)])
    assert over.detectable[0, 0] and over.face_visible[0, 0]
    # ... but not over a tall person there
    tall = _vis(cam, [(4.0, 0.0, 180.0), (2.0, 0.0, 180.0)], heights=[1.75, 2.1])
    assert not tall.detectable[0, 0]
    # a short person (1.2 m) 0.4 m in front of a tall one (1.9 m) hides neither shoulders nor face
    short = _vis(cam, [(4.0, 0.0, 180.0), (3.6, 0.0, 180.0)], heights=[1.9, 1.2])
    assert short.detectable[0, 0] and short.face_visible[0, 0]
    # someone outside the room hides nobody
    xy = np.array([[[4.0, 0.0], [2.0, 0.0]]])
    vis = camera_visibility(cam, xy, np.full((1, 2), math.pi), np.array([1.75, 1.75]), np.array([[True, False]]))
    assert vis.detectable[0, 0]


def test_visibility_rejects_bad_shapes() -> None:
    cam = _camera()
    with pytest.raises(ValueError, match="xy"):
        camera_visibility(cam, np.zeros((3, 2)), np.zeros((3,)), np.ones(1), np.ones((3,), dtype=bool))
    with pytest.raises(ValueError, match="do not match"):
        camera_visibility(cam, np.zeros((1, 2, 2)), np.zeros((1, 3)), np.ones(2), np.ones((1, 2), dtype=bool))
    with pytest.raises(ValueError, match="max_face_angle_deg"):
        VisibilityConfig(max_face_angle_deg=120.0)



def test_lone_person_and_per_camera_views_agree_with_camera_visibility() -> None:
    cams = (_camera(), _camera(yaw_deg=90.0))
    grid = floor_grid(np.array([3.0, 2.0]), 0.5)
    assert grid.shape == (12 * 8, 2) and grid.min() == pytest.approx(-2.75) and grid[:, 1].max() == pytest.approx(1.75)
    facing = np.full(grid.shape[0], math.pi)
    lone = lone_person_visibility(cams[0], grid, facing, 1.8)
    inside = np.ones((grid.shape[0], 1), bool)
    full = camera_visibility(cams[0], grid[:, None], facing[:, None], np.array([1.8]), inside)
    np.testing.assert_array_equal(lone.face_visible, full.face_visible)
    assert lone.detectable.any() and lone.face_visible.any()
    xy = np.array([[[3.0, 0.0], [0.0, 3.0]]])
    view, face = camera_views(cams, xy, np.array([[math.pi, -math.pi / 2]]), np.array([1.75, 1.75]),
                              np.ones((1, 2), bool))
    assert view.shape == face.shape == (1, 2, 2)
    assert view[0].tolist() == [[True, False], [False, True]] and face[0].tolist() == [[True, False], [False, True]]

# --- losses and glances


def test_loss_counting() -> None:
    t = np.arange(0.0, 20.0, 0.1)
    vis = np.zeros((4, t.size), dtype=bool)
    vis[0, (t < 5) | ((t >= 6.0) & (t < 10)) | (t >= 13)] = True  # 1 s gap (kept), 3 s gap (a loss)
    vis[1, t < 8] = True  # leaves for good: a loss at the end
    vis[2, (t >= 4) & (t < 6)] = True  # first seen late: the time before does not count
    summary = count_losses(t, vis, min_gap_s=1.5)
    assert summary.losses == (1, 1, 1, 0)
    assert summary.total_losses == 3
    assert len(summary.segments[0]) == 2
    assert summary.segments[0][0] == pytest.approx((0.0, 9.9))
    assert summary.segments[3] == ()
    assert summary.total_segments == 2 + 1 + 1
    with pytest.raises(ValueError, match="visible"):
        count_losses(t, vis[:, :-1])
    with pytest.raises(ValueError, match="increasing"):
        count_losses(t[::-1], vis)


def test_glance_numbering_bridges_short_gaps() -> None:
    t = np.arange(0.0, 5.0, 0.1)
    vis = np.zeros(t.size, dtype=bool)
    vis[5:10] = True
    vis[12:15] = True  # 0.3 s gap: same glance
    vis[30:35] = True  # 1.6 s gap: a new glance
    ids, n = glance_ids(t, vis, max_gap_s=0.5)
    assert n == 2
    assert set(ids[5:15][vis[5:15]]) == {0}
    assert set(ids[30:35]) == {1}
    assert (ids[~vis] == -1).all()
    assert glance_ids(t, np.zeros(t.size, dtype=bool))[1] == 0


def test_body_bands_lose_the_feet_to_the_image_border_and_to_someone_in_front() -> None:
    """From a camera 2.4 m high tilted 20 deg: a person 5 m away is seen whole; at 1.5 m the feet leave the
    image; behind someone at 3 m the lower body is hidden while the head still shows over them."""
    cam = _camera()
    xy = np.array([[[5.0, 0.0], [20.0, 9.0]], [[1.5, 0.0], [20.0, 9.0]], [[5.0, 0.0], [3.0, 0.05]]])
    heights = np.array([1.75, 1.6])
    inside = np.array([[True, False], [True, False], [True, True]])
    bands = body_band_visibility(cam, xy, heights, inside, 8, np.array([0, 1, 2, 2]), np.array([0, 0, 0, 1]))
    assert bands.shape == (4, 8)
    assert bands[0].all()  # far, alone: everything
    assert bands[1, :3].all() and not bands[1, -1]  # near: head and torso, no feet
    assert bands[2, 0] and not bands[2, -1]  # behind the 1.6 m person: the head over them, not the feet
    assert bands[2].sum() < 8 and bands[3].all()  # the person in front is whole
    # a band is seen only if its point is in the image and unoccluded: matches camera_visibility's shoulders
    vis = camera_visibility(cam, xy, np.zeros((3, 2)), heights, inside)
    assert vis.detectable[0, 0] and vis.detectable[2, 1]
    with pytest.raises(ValueError, match="bands"):
        body_band_visibility(cam, xy, heights, inside, 0, np.array([0]), np.array([0]))
    with pytest.raises(ValueError, match="frames"):
        body_band_visibility(cam, xy, heights, inside, 8, np.array([0, 1]), np.array([0]))
