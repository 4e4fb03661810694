"""A secured network over real DDS (in-process nodes, loopback): with a network key the master takes only
frames and admin requests sealed with it. A stranger on the domain cannot inject frames, read embeddings or
call the admin services; a replayed request is refused."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from conftest import call_handler, spin_until

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.srv")

from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node

from face_reid_camera.common.ros.sealed import open_message, open_response, seal_message, seal_request
from face_reid_camera.common.sealing import Opener, Sealer, SealError, load_network_key, write_network_key
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.ros.convert import frame_record_to_msg
from face_reid_master.ros.node import MasterNode
from face_reid_msgs.msg import CameraFrame, Sealed
from face_reid_msgs.srv import AddPerson, ForgetFace, ListFaces

OK = TransitionCallbackReturn.SUCCESS
MASTER = "/face_reid_master"


def _face(seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=128).astype(np.float32)
    return (1.4 * v / np.linalg.norm(v)).astype(np.float32)  # a dlib-like length


def _frame(camera: str, x: float, emb: np.ndarray):
    now = time.time()
    person = PersonRecord(np.array([x, 1.0, 0.0]), 0.05, 1.7, emb, 0.9, 0.8, "dlib_resnet_v1")
    return frame_record_to_msg(CameraFrameRecord(camera, now, (person,)), now)


def _call(executor, client, request):
    assert spin_until(executor, client.service_is_ready)
    future = client.call_async(request)
    assert spin_until(executor, future.done)
    return future.result()


def _opened(key: bytes, reply, request):
    """The master's reply sealed for ``request`` (its plain fields are empty)."""
    assert not reply.message and not reply.success
    return open_response(Opener(key, "replies"), reply, MASTER, request)


def test_only_holders_of_the_network_key_are_heard(ros_context, tmp_path: Path) -> None:
    key = load_network_key(write_network_key(tmp_path / "network.key"))
    stranger_key = load_network_key(write_network_key(tmp_path / "stranger.key"))
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", f"network_key_path:={tmp_path / 'network.key'}", "-p", "admin_services:=true",
                       "-p", "topic_discovery_period_s:=0.2", "-p", "body_appearance_tracking:=false"])
    master = MasterNode(context=ctx)
    camera, stranger = Node("camera", context=ctx), Node("stranger", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (master, camera, stranger):
        executor.add_node(node)
    try:
        assert master.trigger_configure() == OK and master.trigger_activate() == OK
        assert master.markers_pub is None  # RViz markers would carry names and positions in clear
        sealed_pub = camera.create_publisher(Sealed, "/cam_a/face_reid/frames_sealed", 10)
        plain_pub = stranger.create_publisher(CameraFrame, "/cam_b/face_reid/frames", 10)
        forged_pub = stranger.create_publisher(Sealed, "/cam_c/face_reid/frames_sealed", 10)
        overheard: list = []
        stranger.create_subscription(Sealed, "/cam_a/face_reid/frames_sealed", overheard.append, 10)
        assert spin_until(executor, lambda: len(master.cameras.subscribed) == 2
                          and sealed_pub.get_subscription_count() == 2)
        assert "/cam_b/face_reid/frames" not in master.cameras.subscribed  # plain frames are not even listened to

        alice, mallory = _face(1), _face(2)
        cam_sealer, forger = Sealer(key, "cam_a"), Sealer(stranger_key, "cam_c")
        for k in range(8):
            sealed_pub.publish(seal_message(cam_sealer, _frame("cam_a", 1.0 + 0.01 * k, alice)))
            plain_pub.publish(_frame("cam_b", 5.0, mallory))
            forged_pub.publish(seal_message(forger, _frame("cam_c", 9.0, mallory)))
            executor.spin_once(timeout_sec=0.1)
        assert spin_until(executor, lambda: master.core.stats.frames_applied == 8
                          and master.health.rejected.get("sealed_forged", 0) == 8 and len(overheard) == 8)
        assert {c for t in master.core.tracks() for c in t.cameras} == {"cam_a"}  # nothing from cam_b or cam_c
        # what the stranger overheard is ciphertext: no embedding in it, and its key opens nothing
        raw = alice.tobytes()
        assert all(raw[:16] not in bytes(m.ciphertext) for m in overheard)
        with pytest.raises(SealError):
            open_message(Opener(stranger_key), overheard[-1], CameraFrame)
        # replaying what was overheard does not work either
        replays = master.health.rejected.get("sealed_replayed", 0)
        forged_pub.publish(overheard[-1])
        assert spin_until(executor, lambda: master.health.rejected.get("sealed_replayed", 0) == replays + 1)
        assert master.core.stats.frames_applied == 8
        # a key holder's seal still has to match the camera the frame names, and hold a CameraFrame
        other = Sealer(key, "cam_d")
        forged_pub.publish(seal_message(other, _frame("cam_a", 1.0, mallory)))
        garbage = other.seal(b"\x00\x01\x00\x00" + b"\xff" * 11)
        forged_pub.publish(Sealed(sender_id=garbage.sender_id, counter=garbage.counter, nonce=garbage.nonce,
                                  ciphertext=garbage.ciphertext))
        assert spin_until(executor, lambda: master.health.rejected.get("sealed_sender_mismatch", 0) == 1
                          and master.health.rejected.get("sealed_malformed", 0) == 1)
        assert master.core.stats.frames_applied == 8

        add = stranger.create_client(AddPerson, "/face_reid_master/add_person")
        forget = stranger.create_client(ForgetFace, "/face_reid_master/forget_face")
        request = AddPerson.Request(name="Mallory", embeddings=mallory.tolist())
        reply = _call(executor, add, request)
        assert not reply.success and "must be sealed" in reply.message
        reply = _call(executor, add, seal_request(Sealer(stranger_key, "stranger"), request, MASTER))
        assert not reply.success and "network's key" in reply.message
        assert master.core.people.names() == []
        admin = Sealer(key, "admin")
        sealed = seal_request(admin, AddPerson.Request(name="Alice", embeddings=alice.tolist()), MASTER)
        assert not sealed.embeddings and not sealed.name  # on the wire only in the sealed copy
        reply = _opened(key, _call(executor, add, sealed), sealed)
        assert reply.success, reply.message
        assert master.core.people.names() == ["Alice"]
        reply = _call(executor, add, sealed)  # the same request again
        assert not reply.success and "replayed" in reply.message
        faces = master.core.identity.face_ids()
        assert faces  # Alice's face, learned from cam_a and named by the request
        # the learned faces (names, last seen): nothing for a keyless request or one sealed for another node
        listing = stranger.create_client(ListFaces, f"{MASTER}/list_faces")
        reply = _call(executor, listing, ListFaces.Request())
        assert list(reply.names) == [] and list(reply.face_ids) == [] and not reply.sealed_response.ciphertext
        elsewhere = seal_request(Sealer(key, "admin3"), ListFaces.Request(), "/cam_a/face_reid_camera")
        assert list(_call(executor, listing, elsewhere).face_ids) == []
        ask = seal_request(Sealer(key, "admin3"), ListFaces.Request(), MASTER)
        reply = _call(executor, listing, ask)
        assert list(reply.names) == [] and reply.sealed_response.ciphertext  # the names only inside the seal
        opened = open_response(Opener(key, "replies"), reply, MASTER, ask)
        # her learned face, then Alice the predefined person (face id 0)
        assert list(opened.names) == ["Alice", "Alice"] and list(opened.face_ids) == [*faces, 0]
        reply = _call(executor, forget, ForgetFace.Request(face_id=faces[0]))
        assert not reply.success and master.core.identity.face_ids() == faces
        # a seal made for add_person does not work for forget_face
        reply = _call(executor, forget, ForgetFace.Request(sealed_request=sealed.sealed_request))
        assert not reply.success and master.core.identity.face_ids() == faces
        forget_one = seal_request(Sealer(key, "admin2"), ForgetFace.Request(face_id=faces[0]), MASTER)
        reply = _opened(key, _call(executor, forget, forget_one), forget_one)
        assert reply.success and faces[0] not in master.core.identity.face_ids()
        values = master.diagnostics(master.now_s()).values
        assert values["rejected_sealed_forged"] == "8" and values["add_person_refused"] == "3"
        assert values["forget_face_refused"] == "2"
        assert values["list_faces_calls"] == "3" and values["list_faces_refused"] == "2"
    finally:
        executor.shutdown()
        for node in (camera, stranger, master):
            node.destroy_node()


def test_a_request_sealed_before_the_master_started_is_refused_also_after_a_restart(ros_context,
                                                                                     tmp_path: Path) -> None:
    key = load_network_key(write_network_key(tmp_path / "network.key"))
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", f"network_key_path:={tmp_path / 'network.key'}", "-p", "admin_services:=true",
                       "-p", "body_appearance_tracking:=false"])
    admin = Sealer(key, "admin")
    early = seal_request(admin, AddPerson.Request(name="Early", embeddings=_face(3).tolist()), MASTER)
    master = MasterNode(context=ctx)
    try:
        assert master.trigger_configure() == OK
        reply = call_handler(master.admin.add_person, early, AddPerson.Response())
        assert not reply.success and "before this receiver started" in reply.message
        sealed = seal_request(admin, AddPerson.Request(name="Alice", embeddings=_face(1).tolist()), MASTER)
        assert _opened(key, call_handler(master.admin.add_person, sealed, AddPerson.Response()), sealed).success
        assert master.trigger_cleanup() == OK and master.trigger_configure() == OK  # a restart of the master
        reply = call_handler(master.admin.add_person, sealed, AddPerson.Response())  # captured, replayed after it
        assert not reply.success and "before this receiver started" in reply.message
    finally:
        master.destroy_node()


def test_oversized_messages_are_refused_unread_and_keyless_topics_hold_no_slot(ros_context, tmp_path: Path) -> None:
    """Memory before authentication: a message larger than MAX_FRAME_BYTES is refused before it is read (no
    deserialization, no decryption), and keyless camera topics are only on probation: none takes one of the
    max_camera_topics slots."""
    from face_reid_master.ros.frame_receiver import MAX_FRAME_BYTES

    write_network_key(tmp_path / "network.key")
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", f"network_key_path:={tmp_path / 'network.key'}", "-p", "max_camera_topics:=2",
                       "-p", "topic_discovery_period_s:=0.1", "-p", "body_appearance_tracking:=false"])
    master = MasterNode(context=ctx)
    stranger = Node("stranger", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (master, stranger):
        executor.add_node(node)
    try:
        assert master.trigger_configure() == OK and master.trigger_activate() == OK
        pubs = [stranger.create_publisher(Sealed, f"/s{k}/face_reid/frames_sealed", 10) for k in range(3)]
        assert spin_until(executor, lambda: len(master.cameras.slots.probation) == 3)
        assert spin_until(executor, lambda: sum(p.get_subscription_count() for p in pubs) == 3)
        big = Sealed(sender_id="s0", counter=time.time_ns(), nonce=bytes(12), ciphertext=bytes(MAX_FRAME_BYTES + 1))
        matched = [p for p in pubs if p.get_subscription_count() > 0]
        matched[0].publish(big)
        assert spin_until(executor, lambda: master.health.rejected.get("oversized", 0) == 1)
        assert master.health.rejected.get("sealed_forged", 0) == 0  # refused before any decryption
        report = master.diagnostics(master.now_s())
        assert report.values["camera_topics"] == "0" and report.values["camera_topics_probation"] == "3"
        assert report.values["rejected_oversized"] == "1" and "no camera topic authenticated yet" in report.message
    finally:
        executor.shutdown()
        for node in (stranger, master):
            node.destroy_node()


def test_with_known_cameras_only_their_topics_are_subscribed(ros_context, tmp_path: Path) -> None:
    write_network_key(tmp_path / "network.key")
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", f"network_key_path:={tmp_path / 'network.key'}", "-p", "known_camera_ids:=[cam_a]",
                       "-p", "topic_discovery_period_s:=0.1", "-p", "body_appearance_tracking:=false"])
    master = MasterNode(context=ctx)
    stranger = Node("stranger", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (master, stranger):
        executor.add_node(node)
    try:
        assert master.trigger_configure() == OK and master.trigger_activate() == OK
        for name in ("/cam_a/face_reid/frames_sealed", "/evil/face_reid/frames_sealed"):
            stranger.create_publisher(Sealed, name, 10)
        assert spin_until(executor, lambda: master.health.rejected.get("topic_unknown_camera", 0) == 1
                          and len(master.cameras.subscribed) == 1)
        assert set(master.cameras.subscribed) == {"/cam_a/face_reid/frames_sealed"}
        for _ in range(5):  # discovery goes on: the refused topic is neither subscribed nor counted again
            master.cameras.discover()
        assert master.health.rejected["topic_unknown_camera"] == 1
    finally:
        executor.shutdown()
        for node in (stranger, master):
            node.destroy_node()
