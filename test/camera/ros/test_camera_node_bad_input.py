"""The camera node survives malformed input and refuses to start without usable models.

Real processes over real DDS (loopback only, a domain of this test).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import FACES_DIR
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

pytestmark = pytest.mark.ros

FACES = FACES_DIR
SCENE = {
    "camera_pose": [0.0, 0.0, 2.2, 0.0, 0.3, 0.0],
    "people": [
        {"x": 2.4, "y": 0.0, "facing": 3.14159, "face": str(sorted((FACES / "lfw_Tony_Blair").glob("*.jpg"))[0])}
    ],
}


def test_malformed_input_is_logged_counted_and_survived(ros_domain_id: int, tmp_path: Path) -> None:
    node_log = tmp_path / "node.log"
    node = procs.start(
        ["-m", "face_reid_camera.ros.node", "--ros-args", "-p", "camera_id:=cam_bad",
         "-p", "camera_pose_xyz_m:=[0.0, 0.0, 2.2]", "-p", "camera_pose_rpy_rad:=[0.0, 0.3, 0.0]",
         "-p", "max_frame_age_s:=2.0", "-p", "image_qos_reliable:=true"],
        ros_domain_id, node_log,
    )
    collector = procs.start(
        [str(procs.PROCS / "collect_frames.py"), "--topic", "face_reid/frames", "--count", "12", "--timeout-s", "90"],
        ros_domain_id, tmp_path / "collector.log",
    )
    publisher = procs.start(
        [str(procs.PROCS / "publish_rgbd.py"), "--scene", json.dumps(SCENE), "--frames", "400", "--rate-hz", "8",
         "--bad-first"],
        ros_domain_id, tmp_path / "publisher.log",
    )
    try:
        out, _ = collector.communicate(timeout=120)
        node_alive = node.poll() is None
    finally:
        for p in (publisher, collector, node):
            procs.stop(p)
    frames = [json.loads(line) for line in out.splitlines() if line.startswith("{") and "people" in line]
    log = node_log.read_text()
    assert node_alive, log
    assert "Traceback" not in log
    # each kind of bad input was reported
    assert "no CameraInfo received yet" in log
    assert "unsupported image encoding 'yuv422'" in log
    assert "expected step*height" in log
    assert "CameraInfo says 640x480" in log
    # all-NaN depth is a valid, empty frame; good frames afterwards still carry the person and a face
    assert any(not f["ground_plane_found"] and f["people"] == [] for f in frames), frames
    good = [f for f in frames if len(f["people"]) == 1 and f["people"][0]["embedding_len"] == 128]
    assert len(good) >= 3, (frames, log)


@pytest.mark.parametrize("content", [None, b"this is not an onnx model"])
def test_node_refuses_to_start_without_a_usable_model(
    ros_domain_id: int, tmp_path: Path, content: bytes | None
) -> None:
    model = tmp_path / "yunet.onnx"
    if content is not None:
        model.write_bytes(content)
    result = subprocess.run(
        [sys.executable, "-m", "face_reid_camera.ros.node", "--ros-args", "-p", f"detector_model_path:={model}"],
        env=procs.ros_env(ros_domain_id), cwd=procs.REPO, capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 2
    assert "FATAL: cannot start" in result.stderr
    assert str(model) in result.stderr
    assert "Traceback" not in result.stderr


def test_help_lists_every_parameter() -> None:
    from face_reid_camera.ros import params

    result = subprocess.run(
        [sys.executable, "-m", "face_reid_camera.ros.node", "--help"], cwd=procs.REPO, capture_output=True, text=True,
        timeout=60, env=procs.ros_env(0),
    )
    assert result.returncode == 0
    for spec in params.TABLE.specs:
        assert spec.name in result.stdout
