"""Nothing personal on /rosout on a secured network (a real master process, real DDS): /rosout is a plain topic
any participant of the domain reads. The master's lines that carry names (add person, forget a predefined
person), file paths (face database, gallery) or track/face assignments go to its local log (stderr) only."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import copy_fixture_faces, spin_until
from ros_procs import procs

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

from rcl_interfaces.msg import Log
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_rosout_default

from face_reid_camera.common.ros.sealed import open_response, seal_message, seal_request
from face_reid_camera.common.sealing import Opener, Sealer, load_network_key, write_network_key

pytestmark = [pytest.mark.ros, pytest.mark.slow]

NAME = "Zelda Quux"
MASTER = "/face_reid_master"
START_S = 180.0  # a loaded machine: the master embeds the gallery's photos first


def _face(seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=128).astype(np.float32)
    return (1.4 * v / np.linalg.norm(v)).astype(np.float32)  # a dlib-like length


def _old_faces(db: Path) -> None:
    """Two unnamed faces last seen an hour ago: retention_unnamed_s 60 s warns, naming the database."""
    from face_reid_master.identity.records import LearnedFace
    from face_reid_master.storage.face_store import FaceStore

    old = time.time() - 3600.0
    with FaceStore(db, embedding_dim=128, embedding_space="dlib_resnet_v1") as store:
        store.save_faces([LearnedFace(i, _face(10 + i)[None, :], None, old, old, 3) for i in (1, 2)])


def _frame(emb: np.ndarray) -> Any:
    from face_reid_master.records import CameraFrameRecord, PersonRecord
    from face_reid_master.ros.convert import frame_record_to_msg

    now = time.time()
    person = PersonRecord(np.array([1.0, 1.0, 0.0]), 0.05, 1.7, emb, 0.9, 0.8, "dlib_resnet_v1")
    return frame_record_to_msg(CameraFrameRecord("cam_a", now, (person,)), now)


def _call(executor: Any, client: Any, request: Any, key: bytes) -> Any:
    """The master's reply to a sealed ``request``, opened with ``key``."""
    assert spin_until(executor, client.service_is_ready, 60.0)
    future = client.call_async(request)
    assert spin_until(executor, future.done, 60.0)
    return open_response(Opener(key, "replies"), future.result(), MASTER, request)


def test_a_secured_master_keeps_names_paths_and_assignments_off_rosout(ros_domain_id: int, ros_context,
                                                                       tmp_path: Path) -> None:
    from face_reid_msgs.msg import Sealed
    from face_reid_msgs.srv import AddPerson, ForgetFace

    key_path = write_network_key(tmp_path / "network.key")
    key = load_network_key(key_path)
    db = tmp_path / "faces.db"
    _old_faces(db)
    gallery = copy_fixture_faces(tmp_path / "gallery", ["deepface_id01"], per_identity=2)
    (gallery / "deepface_id01" / "broken.jpg").write_bytes(b"not a photo")  # skipped: the gallery path is said
    log = tmp_path / "master.log"
    ctx = ros_context()
    peer = Node("rosout_reader", context=ctx)  # any participant of the domain
    heard: list[tuple[str, str]] = []
    peer.create_subscription(Log, "/rosout", lambda m: heard.append((m.name, m.msg)), qos_profile_rosout_default)
    frames = peer.create_publisher(Sealed, "/cam_a/face_reid/frames_sealed", 10)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(peer)
    master = procs.start(["-m", "face_reid_master.ros.node", "--ros-args", "-p", f"db_path:={db}",
                          "-p", "embedding_space:=dlib_resnet_v1", "-p", f"network_key_path:={key_path}",
                          "-p", "body_appearance_tracking:=false", "-p", "admin_services:=true",
                          "-p", "retention_unnamed_s:=60.0", "-p", f"gallery_path:={gallery}",
                          "-p", "stats_log_period_s:=0.5", "-p", "topic_discovery_period_s:=0.2"],
                         ros_domain_id, log)
    said = lambda: [m for n, m in heard if n == "face_reid_master"]  # noqa: E731
    try:
        assert spin_until(executor, lambda: any(m.startswith("master: publishing") for m in said()), START_S), (
            log.read_text()[-3000:])
        admin = Sealer(key, "admin")
        add = peer.create_client(AddPerson, "/face_reid_master/add_person")
        assert _call(executor, add, seal_request(admin, AddPerson.Request(name=NAME, embeddings=_face(1).tolist()),
                                                 MASTER), key).success
        # sealed frames of that person: a track, a face, the face named (assignment lines)
        assert spin_until(executor, lambda: frames.get_subscription_count() > 0, 60.0)
        camera = Sealer(key, "cam_a")
        for _ in range(10):
            frames.publish(seal_message(camera, _frame(_face(1))))
            executor.spin_once(timeout_sec=0.1)
        assert spin_until(executor, lambda: "track " in log.read_text(), 60.0), log.read_text()[-3000:]
        forget = peer.create_client(ForgetFace, "/face_reid_master/forget_face")
        assert _call(executor, forget, seal_request(Sealer(key, "admin2"), ForgetFace.Request(name=NAME), MASTER),
                     key).success
        # a barrier: public lines the master logged after all that have reached the reader
        stats_before = sum(m.startswith("stats:") for m in said())
        assert spin_until(executor, lambda: sum(m.startswith("stats:") for m in said()) >= stats_before + 2, 60.0)
        # /rosout: no name, no path, no assignment
        everything = "\n".join(m for _, m in heard)
        assert "Zelda" not in everything and str(tmp_path) not in everything, everything[-3000:]
        assert not [m for m in said() if m.startswith("track ")]
        assert any(m.startswith("secured: only frames") for m in said())  # public lines still go there
        # the local log has them all
        local = log.read_text()
        for text in (f"added {NAME}", "removed the predefined person 'Zelda Quux'", f"deleted from {db}",
                     f"gallery {gallery}: skipped 1 unreadable", "track "):
            assert text in local, (text, local[-3000:])
        assert "[face_reid_master.local]" in local
    finally:
        executor.shutdown()
        peer.destroy_node()
        procs.stop(master)
