"""face-reid-calibrate record over real DDS (a recorder process, frames published by this test, loopback):
it finds the camera topics itself and writes one line per frame with the camera's pose and the people."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT, spin_until
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from face_reid_camera.camera_model import CameraPose
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.ros.convert import frame_record_to_msg
from face_reid_msgs.msg import CameraFrame


def test_record_writes_every_cameras_frames_with_pose_and_people(ros_domain_id: int, ros_context,
                                                                   tmp_path: Path) -> None:
    out = tmp_path / "walk.jsonl"
    recorder = subprocess.Popen([sys.executable, "-m", "face_reid_master.tools.calibrate", "record", "--out", str(out),
                                 "--seconds", "90", "--max-frames", "20"], cwd=REPO_ROOT,
                                env=procs.ros_env(ros_domain_id), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True)
    ctx = ros_context()
    node = Node("cameras", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    pose = CameraPose.from_xyz_rpy(1.0, 2.0, 2.5, 0.0, 0.35, 0.5)
    pubs = {cam: node.create_publisher(CameraFrame, f"/{cam}/face_reid/frames", 50) for cam in ("cam1", "cam2")}
    try:
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in pubs.values()), 60.0)
        for k in range(10):
            for cam, pub in pubs.items():
                person = PersonRecord(np.array([0.1 * k, 1.0, 0.0]), 0.05, 1.7)
                msg = frame_record_to_msg(CameraFrameRecord(cam, 100.0 + 0.1 * k, (person,)), 100.0 + 0.1 * k)
                p, q = msg.camera_pose.position, msg.camera_pose.orientation
                p.x, p.y, p.z = (float(v) for v in pose.translation)
                q.x, q.y, q.z, q.w = pose.quaternion_xyzw()
                pub.publish(msg)
            executor.spin_once(timeout_sec=0.01)
        _, err = recorder.communicate(timeout=60)
    finally:
        if recorder.poll() is None:
            recorder.kill()
        executor.shutdown()
        node.destroy_node()
    assert recorder.returncode == 0, err
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(lines) == 20 and {line["camera_id"] for line in lines} == {"cam1", "cam2"}
    first = next(line for line in lines if line["camera_id"] == "cam1")
    assert first["people"] == [[0.0, 1.0]] and first["stamp"] == pytest.approx(100.0)
    got = CameraPose.from_position_quaternion(first["pose"][:3], first["pose"][3:])
    np.testing.assert_allclose(got.xyz_rpy(), pose.xyz_rpy(), atol=1e-6)
    assert "recording /cam1/face_reid/frames" in err and "wrote 20 frames of 2 camera topics" in err


def test_a_record_that_hears_no_camera_says_where_to_look(ros_domain_id: int, tmp_path: Path) -> None:
    """Before: only 'wrote 0 frames of 0 camera topics'."""
    out = tmp_path / "walk.jsonl"
    done = subprocess.run([sys.executable, "-m", "face_reid_master.tools.calibrate", "record", "--out", str(out),
                           "--seconds", "1"], cwd=REPO_ROOT, env=procs.ros_env(ros_domain_id), capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1] == (
        f"wrote 0 frames of 0 camera topics to {out}: no camera heard; check that the camera nodes run (and see a "
        f"person), that ROS_DOMAIN_ID (here {ros_domain_id}) is theirs, and that --key is given exactly when the "
        "network has a network key")


def test_the_record_summary_names_sealed_topics_it_passed_over() -> None:
    from face_reid_master.tools.calibrate import record_summary

    assert record_summary(Path("w.jsonl"), 0, 0, 0, 2, False).endswith(
        ": the 2 camera topic(s) heard are sealed: give --key with the network's key")
    assert record_summary(Path("w.jsonl"), 5, 1, 0, 0, True) == "wrote 5 frames of 1 camera topics to w.jsonl"
