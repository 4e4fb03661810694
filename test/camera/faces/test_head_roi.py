"""Tests of the metric head ROI projected into the colour image."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import RGBD_DIR

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.faces.head_roi import head_roi_px
from face_reid_camera.people.detector import PersonDetector, PersonDetectorConfig
from face_reid_camera.tools.pcd_io import read_pcd

KINECT = CameraIntrinsics.kinect_default()
DATA = RGBD_DIR


def test_centred_head_gives_a_centred_square_of_metric_size() -> None:
    x, y, w, h = head_roi_px([0.0, 0.0, 2.0], KINECT, 0.3)
    # 0.3 m at 2 m with fx = 525 px: 78.75 px, rounded out to whole pixels.
    assert w == h and 78 <= w <= 81
    assert x + w / 2 == pytest.approx(KINECT.cx + 0.5, abs=1.0)
    assert y + h / 2 == pytest.approx(KINECT.cy + 0.5, abs=1.0)


@pytest.mark.parametrize("distance_m", [1.0, 2.5, 5.0])
def test_roi_size_scales_with_inverse_distance(distance_m: float) -> None:
    _, _, w, h = head_roi_px([0.02, -0.01, distance_m], KINECT, 0.25)
    expected = KINECT.fx * 0.25 / distance_m
    assert w == pytest.approx(expected, abs=2.5) and h == pytest.approx(expected, abs=2.5)


def test_roi_contains_the_projected_head_and_mirrors() -> None:
    head = np.array([0.6, -0.4, 2.2])
    x, y, w, h = head_roi_px(head, KINECT)
    u, v = KINECT.project(head)[0]
    assert x <= u <= x + w and y <= v <= y + h
    mx, my, mw, mh = head_roi_px(head * [-1.0, 1.0, 1.0], KINECT)
    # Mirrored across the optical axis (cx = 319.5 is the centre of a 640-px row).
    assert (mw, mh, my) == (w, h, y)
    assert mx == KINECT.width - (x + w)


def test_off_axis_square_faces_the_camera() -> None:
    """Perpendicular to the viewing ray, the square images wider than fx s / z off-axis: fx s / (z cos a)."""
    _, _, w_axis, _ = head_roi_px([0.0, 0.0, 1.0], KINECT, 0.3)
    _, _, w_side, _ = head_roi_px([0.35, 0.0, 1.0], KINECT, 0.3)  # a = 19.3 deg, not clipped
    assert w_side == pytest.approx(KINECT.fx * 0.3 / np.cos(np.arctan(0.35)), abs=2.5)
    assert w_side > w_axis + 6


def test_roi_is_clipped_to_the_image_or_none_when_outside() -> None:
    x, y, w, h = head_roi_px([1.15, 0.0, 2.0], KINECT, 0.3)  # centre near the right border
    assert x + w == KINECT.width and 0 < w < 79 and h >= 79 and y > 0
    assert head_roi_px([5.0, 0.0, 2.0], KINECT) is None  # entirely right of the image
    assert head_roi_px([0.0, 0.0, -1.0], KINECT) is None  # behind the camera
    assert head_roi_px([0.0, 0.0, 0.1], KINECT, 0.3) is not None
    assert head_roi_px([0.3, 0.0, 0.05], KINECT, 0.3) is None  # square reaches behind the lens


def test_unregistered_colour_camera() -> None:
    head = np.array([0.1, -0.2, 2.0])
    registered = head_roi_px(head, KINECT)
    # Colour camera 2.5 cm to the right of the depth camera: the head appears 6.6 px further left.
    shifted = head_roi_px(head, KINECT, depth_to_colour_translation_m=[-0.025, 0.0, 0.0])
    assert shifted[0] == pytest.approx(registered[0] - 525 * 0.025 / 2.0, abs=1.0)
    assert shifted[1:] == pytest.approx(registered[1:], abs=1.0)
    # A colour image of twice the resolution: everything doubles.
    hd = KINECT.scaled(1280, 960)
    x, y, w, h = head_roi_px(head, hd, depth_to_colour_rotation=np.eye(3))
    assert (w, h) == pytest.approx((2 * registered[2], 2 * registered[3]), abs=2.0)
    assert (x, y) == pytest.approx((2 * registered[0], 2 * registered[1]), abs=2.0)
    # A 90-degree roll of the colour camera about its optical axis swaps image x and y.
    roll = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    rx, ry, rw, rh = head_roi_px([0.3, 0.0, 2.0], KINECT, depth_to_colour_rotation=roll)
    assert rx + rw / 2 == pytest.approx(KINECT.cx + 0.5, abs=1.0)
    assert ry + rh / 2 > KINECT.cy + 60


@pytest.mark.parametrize(
    ("head", "kwargs", "match"),
    [
        ([0.0, np.nan, 2.0], {}, "finite"),
        ([0.0, 2.0], {}, "finite"),
        ([0.0, 0.0, 2.0], {"head_roi_size_m": 0.0}, "positive"),
        ([0.0, 0.0, 2.0], {"head_roi_size_m": float("inf")}, "positive"),
        ([0.0, 0.0, 2.0], {"depth_to_colour_rotation": np.ones((3, 3))}, "rotation"),
        ([0.0, 0.0, 2.0], {"depth_to_colour_rotation": np.eye(2)}, "3x3"),
        ([0.0, 0.0, 2.0], {"depth_to_colour_translation_m": [0.0, 0.1]}, "translation"),
    ],
)
def test_invalid_arguments_raise(head: list[float], kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        head_roi_px(head, KINECT, **kwargs)
    with pytest.raises(ValueError, match="CameraIntrinsics"):
        head_roi_px([0.0, 0.0, 2.0], (525.0, 525.0))  # type: ignore[arg-type]


def test_real_person_roi_covers_the_head() -> None:
    """person.pcd: the ROI from the detected head holds the head at ~0.8 m, background above it."""
    cloud = read_pcd(DATA / "person.pcd")
    pose = CameraPose.from_xyz_rpy(0.0, 0.0, 1.5, 0.0, -0.05, 0.0)
    # the cloud shows no floor: the person stands on the given pose's floor
    (person,) = PersonDetector(PersonDetectorConfig(people_on_pose_floor=True), camera_pose=pose).detect_points(
        cloud).people
    x, y, w, h = head_roi_px(person.head_cam, KINECT, 0.3)
    roi = cloud[y : y + h, x : x + w, 2]
    near = np.isfinite(roi) & (roi < 1.2)
    assert 0.35 < near.mean() < 0.9  # the head and neck fill a good part of a 0.3 m square
    assert np.nanmedian(roi[near]) == pytest.approx(0.8, abs=0.05)
    top_row = cloud[y, x : x + w, 2]
    assert np.all(~np.isfinite(top_row) | (top_row > 1.2))  # above the head: background or shadow
