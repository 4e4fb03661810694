"""The shared pure helpers: argument checks, stamp conversion, node health counters."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from face_reid_camera.common.checks import check_bgr_image, check_int, check_real, is_finite_number
from face_reid_camera.common.diagnostics import DiagnosticLevel, NodeHealth, RollingWindow
from face_reid_camera.common.stamps import seconds_to_stamp, set_stamp, stamp_to_seconds


def test_checks_name_the_argument_and_the_interval() -> None:
    assert check_int("n", np.int64(3), 1, 5) == 3 and check_real("x", 2, 0.0, 2.0) == 2.0
    assert check_real("gate", math.inf, 0.0, math.inf, low_open=True, allow_inf=True) == math.inf
    for call, why in (
        (lambda: check_int("n", True, 0), "n must be an int"),
        (lambda: check_int("n", 0, 1), r"n must be in \[1, inf\], got 0"),
        (lambda: check_real("p", 1.0, 0.0, 1.0, high_open=True), r"p must be a finite number in \[0.0, 1.0\)"),
        (lambda: check_real("x", math.nan), "x must be a finite number"),
        (lambda: check_real("x", math.inf), "x must be a finite number"),
        (lambda: check_real("x", "1.5"), "x must be a number"),
    ):
        with pytest.raises(ValueError, match=why):
            call()
    assert is_finite_number(np.float32(1.5)) and not is_finite_number(True) and not is_finite_number(math.nan)


def test_bgr_image_check() -> None:
    grey = check_bgr_image(np.zeros((4, 5, 1), np.uint8))
    assert grey.shape == (4, 5)
    assert check_bgr_image(np.zeros((4, 5, 4), np.uint8), allow_bgra=True).shape == (4, 5, 4)
    for bad, why in ((np.zeros((4, 5, 4), np.uint8), "must have shape"), (np.zeros((4, 5), np.float32), "uint8"),
                     (np.zeros((0, 5, 3), np.uint8), "must not be empty"), ([[0]], "numpy array")):
        with pytest.raises(ValueError, match=why):
            check_bgr_image(bad)


def test_stamps_round_trip_and_carry_the_nanoseconds() -> None:
    assert seconds_to_stamp(12.25) == (12, 250_000_000)
    assert seconds_to_stamp(0.9999999999) == (1, 0)  # rounds up into the next second, never nanosec = 1e9
    assert seconds_to_stamp(-0.5) == (-1, 500_000_000)
    stamp = set_stamp(SimpleNamespace(sec=0, nanosec=0), 1_700_000_000.123456789)
    assert stamp_to_seconds(stamp) == pytest.approx(1_700_000_000.123456789, abs=1e-6)


def test_health_report_percentiles_rates_and_warnings() -> None:
    window = RollingWindow(3)
    assert math.isnan(window.percentile(50))
    for v in (100.0, 1.0, 2.0, 3.0):  # the first value falls out of the window
        window.add(v)
    assert len(window) == 3 and window.percentile(50) == 2.0 and window.mean() == 2.0

    health = NodeHealth("node", "hw", no_input_warning_s=2.0)
    health.start(10.0)
    assert health.report(11.0).level == DiagnosticLevel.OK
    late = health.report(13.0)
    assert late.level == DiagnosticLevel.WARN and late.message == "no input for 3.0 s"
    for k in range(4):
        health.frame_in(13.0 + k)
        health.frame_processed(10.0 * (k + 1), people=2, faces=k % 2)
        health.published()
    assert health.reject("stale") == 1 and health.reject("stale") == 2
    report = health.report(17.0, extra={"tracks": 3}, warnings=["floor lost"])
    v = report.values
    assert report.level == DiagnosticLevel.WARN and report.message == "floor lost"
    assert v["frames_in"] == "4" and v["frames_processed"] == "4" and v["rejected_stale"] == "2"
    assert v["processing_time_p50_ms"] == "25.000" and v["people_per_frame"] == "2.000"
    assert v["faces_per_frame"] == "0.500" and v["publish_rate_hz"] == "1.000" and v["tracks"] == "3"


@pytest.mark.parametrize("xyz_rpy", [(1.0, -2.0, 2.5, 0.0, 0.35, 0.0), (0.3, 4.0, 1.2, 0.05, 0.6, 2.8),
                                     (-3.0, 0.0, 3.0, -0.1, 0.2, -1.9)])
def test_camera_pose_round_trips_through_rpy_and_the_message_quaternion(xyz_rpy: tuple[float, ...]) -> None:
    from face_reid_camera.camera_model import CameraPose

    pose = CameraPose.from_xyz_rpy(*xyz_rpy)
    np.testing.assert_allclose(pose.xyz_rpy(), xyz_rpy, atol=1e-9)
    again = CameraPose.from_position_quaternion(tuple(pose.translation), pose.quaternion_xyzw())
    np.testing.assert_allclose(again.rotation, pose.rotation, atol=1e-9)
    with pytest.raises(ValueError, match="quaternion"):
        CameraPose.from_position_quaternion((0, 0, 0), (0, 0, 0, 0))
