"""Camera x, y, yaw from one walking person: a simulated network with known poses, noisy and missed
detections, outliers, a camera that does not overlap the anchor; recovered within 5 cm and 1 degree."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from face_reid_master.robot.frames import PlanarTransform
from face_reid_master.training.walk_calibration import (
    CameraTrack,
    calibrate_cameras,
    rigid_2d,
    time_matched,
)

# (true x, y, heading) of four cameras around a 10 x 6 m room; D sees only the far end, which A does not
TRUE = {"A": (0.0, 0.0, math.radians(30)), "B": (10.0, 0.0, math.radians(150)),
        "C": (10.0, 6.0, math.radians(-135)), "D": (14.0, 3.0, math.radians(180))}
# what the cameras were configured with: the anchor right, the others off by up to 1.5 m and 25 degrees
WRONG = {"A": PlanarTransform(), "B": PlanarTransform(0.8, -0.5, math.radians(12)),
         "C": PlanarTransform(-1.5, 0.7, math.radians(-25)), "D": PlanarTransform(0.4, 1.2, math.radians(8))}


def _walk(seconds: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A person walking at ~1 m/s between random waypoints in x 1-13 m, y 0.5-5.5 m; (t, xy) at 100 Hz."""
    t = np.arange(0.0, seconds, 0.01)
    points = [np.array([6.0, 3.0])]
    while len(points) < 200:
        points.append(np.array([rng.uniform(1.0, 13.0), rng.uniform(0.5, 5.5)]))
    seg = np.cumsum([0.0] + [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(points)])
    s = t * 1.0
    xy = np.stack([np.interp(s, seg, [p[k] for p in points]) for k in (0, 1)], axis=1)
    return t, xy


def _tracks(rng: np.random.Generator, noise_m: float = 0.03, outliers: float = 0.05) -> list[CameraTrack]:
    t, xy = _walk(60.0, rng)
    out = []
    for k, (cam, (cx, cy, heading)) in enumerate(TRUE.items()):
        rel = xy - np.array([cx, cy])
        rng_m = np.linalg.norm(rel, axis=1)
        bearing = np.arctan2(rel[:, 1], rel[:, 0]) - heading
        bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
        visible = (rng_m > 0.7) & (rng_m < (5.5 if cam == "D" else 7.5)) & (np.abs(bearing) < math.radians(40))
        frames = np.arange(int(k * 1.7) % 7, t.size, 7)  # ~14 Hz, cameras out of phase
        frames = frames[visible[frames] & (rng.random(frames.size) > 0.1)]  # 10 % missed
        stamps = t[frames] + rng.normal(0.0, 0.002, frames.size)  # stamp jitter
        truth = xy[frames] + rng.normal(0.0, noise_m, (frames.size, 2))
        reported = WRONG[cam].inverse().apply(truth)  # what a camera with the wrong x, y, yaw says
        bad = rng.random(frames.size) < outliers  # clutter / a wrong person now and then
        reported[bad] += rng.uniform(-3.0, 3.0, (int(bad.sum()), 2))
        out.append(CameraTrack(cam, stamps, reported))
    return out


def _pose_error(cam: str, got: PlanarTransform) -> tuple[float, float]:
    """Position (m) and yaw (deg) error of the corrected camera pose."""
    x, y, _ = TRUE[cam]
    configured = WRONG[cam].inverse().apply(np.array([[x, y]]))  # where the camera was configured to be
    err = float(np.linalg.norm(got.apply(configured) - WRONG[cam].apply(configured)))
    yaw = math.degrees(abs((got.yaw_rad - WRONG[cam].yaw_rad + math.pi) % (2 * math.pi) - math.pi))
    return err, yaw


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_network_is_recovered_within_5_cm_and_1_degree(seed: int) -> None:
    result = calibrate_cameras(_tracks(np.random.default_rng(seed)), anchor="A")
    assert set(result.corrections) == set(TRUE) and result.unreached == ()
    assert ("A", "D") not in result.pairs and ("C", "D") in result.pairs  # D is reached through C
    for cam in TRUE:
        err, yaw = _pose_error(cam, result.corrections[cam])
        print(f"seed {seed} camera {cam}: {100 * err:.1f} cm, {yaw:.2f} deg, residual "
              f"{100 * result.residual_m[cam]:.1f} cm")
        assert err <= 0.05 and yaw <= 1.0, (cam, err, yaw)
        assert result.residual_m[cam] < 0.08  # ~ the detection noise of two cameras


def test_a_camera_that_never_shares_a_view_is_reported_unreached() -> None:
    tracks = _tracks(np.random.default_rng(4))
    lonely = CameraTrack("E", tracks[0].stamps_s + 1000.0, tracks[0].xy)  # sees the walker at other times only
    result = calibrate_cameras([*tracks, lonely], anchor="A")
    assert result.unreached == ("E",) and "E" not in result.corrections


def test_time_matching_interpolates_only_across_short_gaps() -> None:
    a = CameraTrack("a", np.array([0.05, 0.15, 1.0]), np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))
    b = CameraTrack("b", np.array([0.0, 0.1, 0.2, 0.9, 2.0]), np.array([[0, 0], [1, 0], [2, 0], [3, 0], [4, 0]]))
    pa, pb = time_matched(a, b, max_gap_s=0.2)
    np.testing.assert_allclose(pb, [[0.5, 0.0], [1.5, 0.0]])  # 1.0 s falls in a 1.1 s gap of b: not matched
    assert pa.shape == (2, 2)


def test_rigid_fit_is_exact_on_exact_data_and_arguments_are_checked() -> None:
    truth = PlanarTransform(1.0, -2.0, 0.7)
    src = np.random.default_rng(0).uniform(-3, 3, (10, 2))
    got = rigid_2d(src, truth.apply(src))
    assert got.x_m == pytest.approx(1.0) and got.y_m == pytest.approx(-2.0) and got.yaw_rad == pytest.approx(0.7)
    np.testing.assert_allclose(truth.inverse().compose(truth).apply(src), src, atol=1e-12)
    with pytest.raises(ValueError, match="at least 2"):
        rigid_2d(src[:1], src[:1])
    tracks = _tracks(np.random.default_rng(0))
    with pytest.raises(ValueError, match="anchor"):
        calibrate_cameras(tracks, anchor="Z")
    with pytest.raises(ValueError, match="min_pairs"):
        calibrate_cameras(tracks, anchor="A", min_pairs=2)
    with pytest.raises(ValueError, match="one track per camera"):
        calibrate_cameras([*tracks, tracks[0]], anchor="A")
    with pytest.raises(ValueError, match="2 stamps but 1"):
        CameraTrack("x", np.zeros(2), np.zeros((1, 2)))


def _recording(path, rng: np.random.Generator, drop: str = "") -> None:
    """A face-reid-calibrate recording of the simulated network: each camera at its configured (wrong) pose."""
    import json

    from face_reid_camera.camera_model import CameraPose

    with open(path, "w") as f:
        for track in _tracks(rng):
            if track.camera_id == drop:
                continue
            x, y, heading = TRUE[track.camera_id]
            wrong = WRONG[track.camera_id].inverse()
            cx, cy = wrong.apply(np.array([[x, y]]))[0]
            pose = CameraPose.from_xyz_rpy(cx, cy, 2.5, 0.0, 0.35, heading + wrong.yaw_rad)
            for t, (px, py) in zip(track.stamps_s, track.xy, strict=True):
                people = [[px, py], [px + 4.0, py - 3.0]] if t % 5 < 0.2 else [[px, py]]  # a second person at times
                f.write(json.dumps({"camera_id": track.camera_id, "stamp": t,
                                    "pose": [*pose.translation, *pose.quaternion_xyzw()], "people": people}) + "\n")
            f.write("not json\n")  # a damaged line is skipped


def test_face_reid_calibrate_solve_writes_params_files_with_the_true_poses(tmp_path, capsys) -> None:
    import yaml

    from face_reid_master.tools.calibrate import main

    _recording(tmp_path / "walk.jsonl", np.random.default_rng(1))
    assert main(["solve", str(tmp_path / "walk.jsonl"), "--anchor", "A", "--out-dir", str(tmp_path / "poses")]) == 0
    table = capsys.readouterr().out
    assert "residual cm" in table and all(cam in table for cam in TRUE)
    for cam, (x, y, heading) in TRUE.items():
        params = yaml.safe_load((tmp_path / "poses" / f"{cam}.yaml").read_text())["/**"]["ros__parameters"]
        px, py, pz = params["camera_pose_xyz_m"]
        assert params["camera_id"] == cam  # the file sets up that camera on its own
        roll, pitch, yaw = params["camera_pose_rpy_rad"]
        assert math.hypot(px - x, py - y) <= 0.05 and pz == pytest.approx(2.5)
        assert abs(math.degrees((yaw - heading + math.pi) % (2 * math.pi) - math.pi)) <= 1.0
        assert roll == pytest.approx(0.0, abs=1e-4) and pitch == pytest.approx(0.35, abs=1e-4)


def test_face_reid_calibrate_solve_says_what_it_could_not_do(tmp_path, capsys) -> None:
    from face_reid_master.tools.calibrate import main

    _recording(tmp_path / "no_c.jsonl", np.random.default_rng(2), drop="C")  # D then overlaps nobody solved
    assert main(["solve", str(tmp_path / "no_c.jsonl"), "--anchor", "A"]) == 1
    assert "not linked" in capsys.readouterr().out
    assert main(["solve", str(tmp_path / "no_c.jsonl"), "--anchor", "Z"]) == 2
    assert "anchor 'Z' saw nobody" in capsys.readouterr().err
    (tmp_path / "empty.jsonl").write_text("")
    assert main(["solve", str(tmp_path / "empty.jsonl"), "--anchor", "A"]) == 2
    capsys.readouterr()
    missing = tmp_path / "missing.jsonl"
    assert main(["solve", str(missing), "--anchor", "A"]) == 2
    err = capsys.readouterr().err
    assert err == (f"face-reid-calibrate: recording {missing} not found (make one with: face-reid-calibrate record "
                   f"--out {missing})\n")  # one line, no "[Errno 2]"
    assert main(["record", "--out", str(tmp_path / "no_folder" / "walk.jsonl"), "--seconds", "1"]) == 2
    assert capsys.readouterr().err == f"face-reid-calibrate: --out: folder {tmp_path / 'no_folder'} not found\n"
