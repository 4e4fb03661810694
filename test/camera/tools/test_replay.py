"""face-reid-replay over the real Kinect fixtures: JSON lines, clear errors, nothing silently dropped."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import RGBD_DIR

from face_reid_camera.tools.replay import main

RGBD = RGBD_DIR


def _lines(out: str) -> list[dict]:
    return [json.loads(line) for line in out.splitlines() if line.strip()]


def test_desk_frames_have_no_people_and_a_floor(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(RGBD / "pcl_desk")]) == 0
    captured = capsys.readouterr()
    lines = _lines(captured.out)
    assert len(lines) == 3 and "warning" not in captured.err  # a floor in view, found without a pose: trusted
    for line in lines:
        assert line["num_people"] == 0 and line["ground_plane_found"]
        assert line["floor"]["support"] > 0.5 and line["floor"]["doubtful"] is False
        # the Kinect looked down at the floor from ~0.7 m, tilted ~46 degrees
        assert line["floor"]["camera_height_m"] == pytest.approx(0.71, abs=0.05)
        assert line["floor"]["camera_tilt_down_deg"] == pytest.approx(46, abs=4)


def test_person_pcd_has_one_person(capsys: pytest.CaptureFixture[str]) -> None:
    # without a pose: a "floor" through the few low points (1.95 m below, 16.8 deg) is found and said to be a guess
    assert main([str(RGBD / "person.pcd"), "--no-faces"]) == 0
    captured = capsys.readouterr()
    (line,) = _lines(captured.out)
    assert line["floor"]["support"] < 0.05 and line["floor"]["doubtful"] is True
    (warning,) = [w for w in captured.err.splitlines() if "warning" in w]
    assert warning == ("face-reid-replay: warning: 1 of 1 frames: the floor found without a camera pose (camera 1.95 m "
                       "above it, tilted 16.8 deg down) holds only 2% of the points (a floor in view: 5% or more): the "
                       "view shows no floor, so heights and positions are guesses; give the camera's pose: "
                       "--camera-pose X Y Z ROLL PITCH YAW --trust-pose-floor")
    pose = ["--camera-pose", "0", "0", "1.5", "0", "-0.05", "0"]
    assert main([str(RGBD / "person.pcd"), "--no-faces", *pose]) == 0  # no floor in the cloud: nobody ...
    captured = capsys.readouterr()
    (line,) = _lines(captured.out)
    assert line["num_people"] == 0 and line["ground_plane_found"] is False
    assert line["pose_check"] is None  # no floor in view to check the pose against
    assert "no floor near the given pose: nobody is reported on them (if the view has no floor, add " \
           "--trust-pose-floor)" in captured.err
    assert main([str(RGBD / "person.pcd"), "--no-faces", *pose, "--trust-pose-floor"]) == 0  # ... unless trusted
    captured = capsys.readouterr()
    (line,) = _lines(captured.out)
    assert "warning" not in captured.err and "no floor" not in captured.err
    assert line["num_people"] == 1 and line["floor"]["doubtful"] is False
    (person,) = line["people"]
    assert person["height_m"] == pytest.approx(1.64, abs=0.06)
    assert person["position_world"][0] == pytest.approx(0.8, abs=0.15)  # ~0.8 m in front of the camera
    assert person["head_roi"] is not None


def test_a_wrong_pose_is_reported_and_an_unreadable_folder_fails(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    desk = sorted((RGBD / "pcl_desk").glob("*_depth_mm.png"))[0]
    assert main([str(desk), "--no-faces", "--no-bodies", "--camera-pose", "0", "0", "2.5", "0", "0.8", "0"]) == 0
    captured = capsys.readouterr()
    (line,) = _lines(captured.out)
    assert line["pose_check"]["agrees"] is False and line["num_people"] == 0
    assert line["pose_check"]["floor_camera_height_m"] == pytest.approx(0.71, abs=0.05)
    assert "DISAGREES" in captured.err and "2.50 m" in captured.err
    (tmp_path / "notes.txt").write_text("not a frame")
    assert main([str(tmp_path), "--no-faces", "--no-bodies"]) == 1
    assert "no frame could be read" in capsys.readouterr().err


def test_corrupt_frame_is_reported_and_the_rest_processed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for f in sorted((RGBD / "pcl_desk").glob("*"))[:2]:
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "broken_depth_mm.png").write_bytes(b"not a png")
    (tmp_path / "broken.pcd").write_bytes(b"# .PCD v0.7\nFIELDS x y z\nDATA binary\n")
    assert main([str(tmp_path), "--no-faces"]) == 0
    captured = capsys.readouterr()
    assert len(_lines(captured.out)) == 1
    assert "2 skipped" in captured.err and "broken" in captured.err


def test_missing_input_and_missing_models_are_clear_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    assert main([str(tmp_path / "nowhere")]) == 2
    assert "no such file" in capsys.readouterr().err
    monkeypatch.setenv("FACE_REID_MODELS_DIR", str(tmp_path))
    assert main([str(RGBD / "pcl_desk")]) == 2
    assert "not found" in capsys.readouterr().err


@pytest.mark.parametrize(("text", "message"), [
    ("/**:\n  ros__parameters:\n    camera_id: [cam\n",
     "not YAML: line 4, column 1: expected ',' or ']', but got '<stream end>'"),
    ("/**:\n  ros__parameters:\n    camera_pose_xyz_m: [0, 0, 1.5]\n",
     "parameter 'camera_pose_xyz_m': a list mixing integers and floats ([0, 0, 1.5]) is refused by ROS (Sequence "
     "should be of same type); write every number with a decimal point, e.g. 1.0"),
    (None, "no such file"),
])
def test_a_params_file_the_node_refuses_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                    text: str | None, message: str) -> None:
    """Before: a multi-line yaml error (a traceback in the issue), and the mixed list was read as [0.0, 0.0, 1.5]
    though the camera node refuses it."""
    params = tmp_path / "bad.yaml"
    if text is not None:
        params.write_text(text)
    assert main([str(RGBD / "person.pcd"), "--no-faces", "--no-bodies", "--params", str(params)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == f"face-reid-replay: error: params file {params}: {message}\n"
