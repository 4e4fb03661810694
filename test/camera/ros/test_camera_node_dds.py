"""Cross-process DDS test: synthetic RGB-D publisher -> camera node -> CameraFrame subscriber.

Three processes talk over real DDS (loopback only, a domain of this test): the camera node must
report every person with the right position, and embeddings (the default joint dlib | SFace space,
refreshed in turn under the per-frame budget) only for the people whose face the camera sees.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import FACES_DIR
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

pytestmark = [pytest.mark.ros, pytest.mark.slow]

FACES = FACES_DIR


def _scene() -> dict:
    # Camera 2.2 m high looking along +x, tilted down 0.3 rad. Two people face it, one faces away.
    return {
        "camera_pose": [0.0, 0.0, 2.2, 0.0, 0.3, 0.0],
        "people": [
            {"x": 2.2, "y": -0.6, "facing": math.pi, "face": str(sorted((FACES / "lfw_Tony_Blair").glob("*.jpg"))[0])},
            {"x": 3.0, "y": 0.7, "facing": math.pi - 0.2,
             "face": str(sorted((FACES / "lfw_Colin_Powell").glob("*.jpg"))[0])},
            {"x": 3.6, "y": 1.2, "facing": 0.0, "face": None},
        ],
    }


def _read_json_lines(proc, timeout_s: float) -> list[dict]:
    out, _ = proc.communicate(timeout=timeout_s)
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


@pytest.mark.parametrize("depth_encoding", ["16UC1", "32FC1"])
def test_camera_node_publishes_people_and_embeddings(
    ros_domain_id: int, tmp_path: Path, depth_encoding: str
) -> None:
    scene = _scene()
    node = procs.start(
        ["-m", "face_reid_camera.ros.node", "--ros-args", "-p", "camera_id:=cam_test",
         "-p", "camera_pose_xyz_m:=[0.0, 0.0, 2.2]", "-p", "camera_pose_rpy_rad:=[0.0, 0.3, 0.0]",
         "-p", "max_frame_age_s:=2.0", "-p", "image_qos:=reliable"],
        ros_domain_id, tmp_path / "node.log",
    )
    collector = procs.start(
        [str(procs.PROCS / "collect_frames.py"), "--topic", "face_reid/frames", "--count", "5", "--timeout-s", "90"],
        ros_domain_id, tmp_path / "collector.log",
    )
    publisher = procs.start(
        [str(procs.PROCS / "publish_rgbd.py"), "--scene", json.dumps(scene), "--frames", "400", "--rate-hz", "8",
         "--depth-encoding", depth_encoding],
        ros_domain_id, tmp_path / "publisher.log",
    )
    try:
        frames = [f for f in _read_json_lines(collector, 120) if "people" in f]
    finally:
        for p in (publisher, collector, node):
            procs.stop(p)
    logs = {p.name: p.read_text() for p in tmp_path.glob("*.log")}
    assert len(frames) >= 5, f"too few CameraFrame messages: {len(frames)}; logs: {logs}"
    from face_reid_camera.body.projection import load_body_projection

    projection = load_body_projection()
    for frame in frames:
        assert frame["camera_id"] == "cam_test" and frame["frame_id"] == "world"
        assert frame["ground_plane_found"]
        assert len(frame["people"]) == 3, frame
        truth = np.array([[p["x"], p["y"]] for p in scene["people"]])
        seen = np.array([p["world"][:2] for p in frame["people"]])
        # every true person has a detection within 0.25 m (centroid of the visible body surface)
        dists = np.linalg.norm(truth[:, None, :] - seen[None, :, :], axis=2)
        assert dists.min(axis=1).max() < 0.25, (truth, seen)
        with_face = [p for p in frame["people"] if p["face_found"]]
        assert len(with_face) == 2, frame
        assert all(p["embedding_len"] in (0, 256) for p in with_face)  # 0: not embedded in this frame (budget)
        assert all(p["embedding_space"] == "dlib_resnet_v1+sface_2021dec" for p in with_face if p["embedding_len"])
        assert all(p["embedding_len"] == 0 for p in frame["people"] if not p["face_found"])
        # every person's body too: the shipped projection's descriptor, mostly visible, shoulders measured
        assert all(p["body_descriptor_len"] == projection.length and p["body_space"] == projection.space
                   and p["body_visible_fraction"] > 0.5 and 0.2 < p["body_shoulder_width_m"] < 0.7
                   for p in frame["people"]), frame["people"]
        # the face-less person is the one facing away (y = 1.2)
        no_face = [p for p in frame["people"] if not p["face_found"]]
        assert abs(no_face[0]["world"][1] - 1.2) < 0.3
    # each embedding is of the right person: nearest to the embedding of its own source photo
    import cv2

    from face_reid_camera.faces.detector import YuNetDetector
    from face_reid_camera.faces.embedder import FaceEmbedder

    detector, embedder = YuNetDetector(), FaceEmbedder()
    refs = []
    for person in scene["people"][:2]:
        photo = cv2.imread(person["face"])
        best = max(detector.detect(photo), key=lambda d: d.box_xywh[2] * d.box_xywh[3])
        refs.append(embedder.embed_faces(photo, [best.landmarks])[0])
    embedded = [0, 0]
    for frame in frames:
        faces = sorted((p for p in frame["people"] if p["face_found"]), key=lambda p: p["world"][1])
        # sorted by world y: person 0 (y = -0.6) first, person 1 (y = 0.7) second
        for truth_index, face in enumerate(faces):
            if not face["embedding_len"]:
                continue
            embedded[truth_index] += 1
            d = np.linalg.norm(np.asarray(refs) - np.asarray(face["embedding"][:128])[None, :], axis=1)  # dlib half
            assert int(np.argmin(d)) == truth_index, d
    assert min(embedded) >= len(frames) // 3, embedded  # both faces refreshed in turn
