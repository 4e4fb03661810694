"""Cross-process DDS test of the master: two camera processes -> master -> /tracks_named subscriber.

A person walks from camera A's view into camera B's (hand-over: one track), leaves every view
until the track dies, and comes back: the subscriber must see a NEW track id with the SAME face id
and the predefined name. The master is then killed with SIGKILL: everything it learned must be in
its database. The publish-rate
cap is tested in-process (test_master_node.py).
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from conftest import FACES_DIR
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

pytestmark = [pytest.mark.ros, pytest.mark.slow]

FACES = FACES_DIR
IDS = {"tony": "lfw_Tony_Blair", "colin": "lfw_Colin_Powell"}


def _embed_fixture_faces(kind: str, path: Path) -> Path:
    from face_reid_camera.faces.detector import YuNetDetector
    from face_reid_camera.faces.embedder import FaceEmbedder

    detector, embedder = YuNetDetector(), FaceEmbedder(kind=kind)
    out = {}
    for key, ident in IDS.items():
        rows = []
        for photo_path in sorted((FACES / ident).glob("*.jpg")):
            photo = cv2.imread(str(photo_path))
            best = max(detector.detect(photo), key=lambda d: float(d.box_xywh[2] * d.box_xywh[3]))
            rows.append(embedder.embed_faces(photo, [best.landmarks])[0])
        out[key] = np.stack(rows)
    np.savez(path, **out)
    return path


@pytest.fixture(scope="module")
def embeddings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _embed_fixture_faces("dlib", tmp_path_factory.mktemp("emb") / "embeddings.npz")


@pytest.fixture(scope="module")
def sface_embeddings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _embed_fixture_faces("sface", tmp_path_factory.mktemp("emb") / "sface.npz")


def _plan(path: Path, embeddings: Path, segments: list[dict], space: str = "") -> Path:
    path.write_text(json.dumps({"rate_hz": 10, "embeddings": str(embeddings), "segments": segments,
                                "embedding_space": space}))
    return path


def _run_network(tmp_path: Path, domain_id: int, master_params: list[str],
                 cameras: list[tuple[str, Path]]) -> tuple[str, Any]:
    """A master node, a /tracks_named collector and one frame publisher per (camera id, plan), started together
    at a barrier; returns the collector's output once every plan was played, and the still-running master
    (the caller stops it). Everything is stopped if anything fails."""
    args = ["-m", "face_reid_master.ros.node", "--ros-args"]
    for param in ("topic_discovery_period_s:=0.5", *master_params):
        args += ["-p", param]
    master = procs.start(args, domain_id, tmp_path / "master.log")
    barrier = str(tmp_path / "barrier")
    collector = procs.start([str(procs.PROCS / "collect_tracks.py"), "--duration-s", "120", "--barrier-dir", barrier],
                            domain_id, tmp_path / "collector.log")
    cams = [
        procs.start([str(procs.PROCS / "publish_camera_frames.py"), "--camera-id", cid, "--topic",
                     f"/{cid}/face_reid/frames", "--plan", str(plan), "--wait-s", "60",
                     "--barrier-dir", barrier, "--barrier-count", str(len(cameras) + 1)],
                    domain_id, tmp_path / f"{cid}.log")
        for cid, plan in cameras
    ]
    try:
        for cam in cams:
            cam.wait(timeout=90)
        assert all(cam.returncode == 0 for cam in cams), [cam.stdout.read() for cam in cams if cam.stdout]
        time.sleep(2.0)  # the last frames reach the master and its last /tracks_named reaches the collector
        collector.send_signal(signal.SIGTERM)
        out, _ = collector.communicate(timeout=30)
        assert master.poll() is None, (tmp_path / "master.log").read_text()
    except BaseException:
        procs.stop(master)
        raise
    finally:
        for p in (*cams, collector):
            procs.stop(p)
    return out, master


def _interrupt(master: Any, tmp_path: Path) -> tuple[str, str]:
    """Stop the master with Ctrl-C; its log, and every process's log (for assertion messages)."""
    try:
        master.send_signal(signal.SIGINT)
        master.wait(timeout=20)
    finally:
        procs.stop(master)
    logs = "\n".join(f"{p.name}: {p.read_text()}" for p in tmp_path.glob("*.log"))
    return (tmp_path / "master.log").read_text(), logs


def _tracks_near(out: str, y: float) -> list[dict]:
    """Every published track (of every /tracks_named message the collector printed) within 1 m of the line y."""
    messages = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    return [t for m in messages for t in m["tracks"] if abs(t["y"] - y) < 1.0]


def test_leave_and_return_same_face_id_and_name(ros_domain_id: int, tmp_path: Path, embeddings: Path) -> None:
    emb = dict(np.load(embeddings))
    gallery = tmp_path / "gallery.npz"
    np.savez(gallery, Tony=emb["tony"][8:10], Colin=emb["colin"][8:10])
    tony_a = {"x": 0.0, "y": 0.0, "vx": 0.5, "identity": "tony", "photos": [0, 1, 2, 3, 4]}
    colin = {"x": 0.0, "y": 2.5, "vx": 0.3, "identity": "colin", "photos": [0, 1, 2, 3, 4, 5]}
    plan_a = _plan(tmp_path / "a.json", embeddings, [
        {"t0": 0.0, "t1": 3.0, "people": [tony_a]},
        {"t0": 0.0, "t1": 5.0, "people": [colin]},
    ])
    plan_b = _plan(tmp_path / "b.json", embeddings, [
        {"t0": 2.0, "t1": 5.0, "people": [dict(tony_a, x=1.0)]},  # hand-over: same trajectory in camera B
        {"t0": 8.5, "t1": 12.5, "people": [{"x": 1.0, "y": -1.5, "vx": 0.4, "identity": "tony", "photos": [5, 6, 7]}]},
    ])
    db = tmp_path / "faces.db"
    out, master = _run_network(tmp_path, ros_domain_id, [
        f"db_path:={db}", f"gallery_path:={gallery}", "tracker.lost_after_s:=0.5", "tracker.delete_after_s:=1.0",
        "min_face_features_for_name:=3", "embedding_space:=dlib_resnet_v1"], [("cam_a", plan_a), ("cam_b", plan_b)])
    try:
        os.killpg(master.pid, signal.SIGKILL)  # no clean shutdown: nothing learned may be lost
        master.wait(timeout=10)
    finally:
        procs.stop(master)
    logs = "\n".join(f"{p.name}: {p.read_text()}" for p in tmp_path.glob("*.log"))
    messages = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert messages, logs
    assert all(m["frame_id"] == "world" for m in messages)
    tony = [t for m in messages for t in m["tracks"] if t["name"] == "Tony"]
    colin = [t for m in messages for t in m["tracks"] if t["name"] == "Colin"]
    assert tony and colin, logs
    tony_faces = {t["face_id"] for t in tony}
    tony_tracks = [t["track_id"] for t in tony]
    assert len(tony_faces) == 1 and 0 not in tony_faces, tony
    assert len(set(tony_tracks)) == 2, f"expected the first visit and the return as two tracks: {set(tony_tracks)}"
    assert {t["face_id"] for t in colin} != tony_faces
    # hand-over: during the overlap one track was seen by both cameras
    assert any(set(t["cameras"]) == {"cam_a", "cam_b"} for t in tony)
    # the return was recognised before its end: the last message holds the returning track, named
    last_tony = [t for t in messages[-1]["tracks"] if t["name"] == "Tony"] or [tony[-1]]
    assert last_tony[0]["track_id"] == tony_tracks[-1]

    # kill -9 lost nothing: both faces, with their names, are in the database
    from face_reid_master.storage.face_store import FaceStore

    with FaceStore(db) as store:
        faces = store.load_faces()
    assert {f.name for f in faces} >= {"Tony", "Colin"}
    assert tony_faces <= {f.face_id for f in faces}
    assert (db.stat().st_mode & 0o777) == 0o600


def test_cameras_of_two_embedders_never_mix_their_faces(ros_domain_id: int, tmp_path: Path, embeddings: Path,
                                                        sface_embeddings: Path) -> None:
    """A dlib master gets Tony from a dlib camera and Colin from an SFace camera: Tony's face is learned,
    Colin is tracked without a face (his SFace embeddings are never compared with dlib ones), and the
    master says so once, naming the camera and both spaces."""
    tony = {"x": 0.0, "y": 0.0, "vx": 0.3, "identity": "tony", "photos": [0, 1, 2, 3, 4]}
    colin = {"x": 0.0, "y": 3.0, "vx": 0.3, "identity": "colin", "photos": [0, 1, 2, 3, 4]}
    plan_d = _plan(tmp_path / "d.json", embeddings, [{"t0": 0.0, "t1": 5.0, "people": [tony]}], "dlib_resnet_v1")
    plan_s = _plan(tmp_path / "s.json", sface_embeddings, [{"t0": 0.0, "t1": 5.0, "people": [colin]}],
                   "sface_2021dec")
    db = tmp_path / "faces.db"
    out, master = _run_network(tmp_path, ros_domain_id, [f"db_path:={db}", "embedding_space:=dlib_resnet_v1"],
                               [("cam_dlib", plan_d), ("cam_sface", plan_s)])
    log, logs = _interrupt(master, tmp_path)
    notices = [line for line in log.splitlines() if "'cam_sface'" in line and "not used for identity" in line]
    assert len(notices) == 1, logs
    assert "'sface_2021dec'" in notices[0] and "'dlib_resnet_v1'" in notices[0]
    assert "cam_dlib" not in "".join(line for line in log.splitlines() if "not used for identity" in line)
    tony_tracks, colin_tracks = _tracks_near(out, 0.0), _tracks_near(out, 3.0)
    assert tony_tracks and colin_tracks, logs
    assert {t["face_id"] for t in tony_tracks} - {0}, "Tony's dlib face was never learned"
    assert all(t["face_id"] == 0 for t in colin_tracks), colin_tracks[-1]  # never identified
    from face_reid_master.storage.face_store import FaceStore

    with FaceStore(db) as store:
        faces = store.load_faces()
        assert store.embedding_space == "dlib_resnet_v1"
    assert len(faces) == 1 and faces[0].features.shape[1] == 128


def test_cameras_with_and_without_body_fields_both_feed_the_master(ros_domain_id: int, tmp_path: Path,
                                                                   embeddings: Path) -> None:
    """A camera that describes bodies (Tony: face + body fields) and an older one that sends none (Colin: face
    only) feed one master: both are tracked and identified by face, every body is counted as received and none
    as malformed or of another projection space, in the master's stats log (what /diagnostics shows)."""
    from face_reid_camera.body.projection import load_body_projection

    projection = load_body_projection()  # the cameras' shipped projection: the master's metric compares it
    body = {"descriptor": np.linspace(-1.0, 1.0, projection.length).round(4).tolist(), "space": projection.space,
            "visible": 0.9}
    tony = {"x": 0.0, "y": 0.0, "vx": 0.3, "identity": "tony", "photos": [0, 1, 2, 3, 4], "body": body}
    colin = {"x": 0.0, "y": 3.0, "vx": 0.3, "identity": "colin", "photos": [0, 1, 2, 3, 4]}
    plan_new = _plan(tmp_path / "new.json", embeddings, [{"t0": 0.0, "t1": 5.0, "people": [tony]}], "dlib_resnet_v1")
    plan_old = _plan(tmp_path / "old.json", embeddings, [{"t0": 0.0, "t1": 5.0, "people": [colin]}])
    out, master = _run_network(tmp_path, ros_domain_id, [f"db_path:={tmp_path / 'faces.db'}",
                                                         "embedding_space:=dlib_resnet_v1", "stats_log_period_s:=0.5"],
                               [("cam_new", plan_new), ("cam_old", plan_old)])
    time.sleep(1.0)  # one more stats line after the last frame
    log, logs = _interrupt(master, tmp_path)
    tony_tracks, colin_tracks = _tracks_near(out, 0.0), _tracks_near(out, 3.0)
    assert {t["face_id"] for t in tony_tracks} - {0} and {t["face_id"] for t in colin_tracks} - {0}, logs
    # /tracks_named says what identified them: their faces (undecided tracks: nothing)
    assert {t["evidence"] for t in tony_tracks + colin_tracks if t["face_id"]} == {"face"}
    assert all(t["evidence"] == "" for t in tony_tracks + colin_tracks if not t["face_id"])
    stats = [line for line in log.splitlines() if "stats: {" in line]
    assert stats, logs
    last = stats[-1]
    received = int(last.split("'bodies_received': ")[1].split(",")[0].split("}")[0])
    sent = 50  # frames with Tony: 10 Hz for t in [0, 5) s, each with his body fields
    assert 0.9 * sent <= received <= sent, received
    assert "bodies_rejected" not in last, last
    assert "embeddings_rejected" not in last, last
