"""Trusted /tracks_named over DDS: a secured master publishes its tracks sealed; the project's consumer helper
(face_reid_master.ros.tracks_in, used by face-reid-goto, the example, the evaluation and the demo) takes the
master's and none of a keyless peer's spoofs, on the plain topic or the sealed one; a consumer without the key
is told the tracks are sealed.

The real master node, its camera, the spoofer and the consumers run in this process (one DDS participant per
context); every wait is on a condition.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from conftest import spin_until

pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message

from face_reid_camera.common.ros.sealed import seal_message, seal_payload
from face_reid_camera.common.sealing import Sealer, load_network_key, write_network_key
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.ros.convert import frame_record_to_msg
from face_reid_master.ros.goto_node import GotoNode
from face_reid_master.ros.node import MasterNode
from face_reid_master.ros.tracks_in import subscribe_tracks
from face_reid_master.tracks_auth import TRACKS_PURPOSE
from face_reid_msgs.msg import NamedTrack, NamedTrackArray, Sealed

OK = TransitionCallbackReturn.SUCCESS
SPOOF = "SPOOFED_Alice"


def _frame(x: float):
    now = time.time()
    v = np.random.default_rng(1).normal(size=128)
    person = PersonRecord(np.array([x, 1.0, 0.0]), 0.05, 1.7, (1.4 * v / np.linalg.norm(v)).astype(np.float32), 0.9,
                          0.8, "dlib_resnet_v1")
    return frame_record_to_msg(CameraFrameRecord("cam_a", now, (person,)), now)


def _spoofed() -> NamedTrackArray:
    msg = NamedTrackArray()
    msg.header.frame_id = "world"
    msg.header.stamp.sec = int(time.time())
    msg.tracks.append(NamedTrack(track_id=999, face_id=7, name=SPOOF, state=NamedTrack.STATE_CONFIRMED,
                                 identity_confidence=0.99, identity_evidence="face", cameras=["cam_x"]))
    msg.tracks[0].position.x, msg.tracks[0].position.y = 3.0, 3.0
    return msg


def _secured_master(ros_context, tmp_path: Path, *more_args: str) -> MasterNode:
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", f"network_key_path:={tmp_path / 'network.key'}", "-p", "topic_discovery_period_s:=0.2",
                       "-p", "body_appearance_tracking:=false", "-p", "persist_faces:=false", *more_args])
    return MasterNode(context=ctx)


def test_the_consumer_helper_takes_the_masters_tracks_and_no_spoof(ros_context, tmp_path: Path) -> None:
    key_path = write_network_key(tmp_path / "network.key")
    key = load_network_key(key_path)
    stranger_key = load_network_key(write_network_key(tmp_path / "stranger.key"))
    # one participant for all (goto's own parameters named for it): no discovery between participants to wait for
    master = _secured_master(ros_context, tmp_path, "-p", "face_reid_goto:names_service:=''",
                             "-p", f"face_reid_goto:target_name:={SPOOF}")
    ctx = master.context
    camera, spoofer, consumer = Node("camera", context=ctx), Node("spoofer", context=ctx), Node("robot", context=ctx)
    goto = GotoNode(context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (master, camera, spoofer, consumer, goto):
        executor.add_node(node)

    def spin(condition, timeout_s: float = 60.0) -> bool:
        return spin_until(executor, condition, timeout_s)

    taken: list[NamedTrackArray] = []
    overheard: list[Sealed] = []
    try:
        assert master.trigger_configure() == OK and master.trigger_activate() == OK
        assert goto.trigger_configure() == OK and goto.trigger_activate() == OK
        deep = QoSProfile(depth=200, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        tracks = subscribe_tracks(consumer, taken.append, "/tracks_named", key_path, qos=deep)
        frames = camera.create_publisher(Sealed, "/cam_a/face_reid/frames_sealed", 10)
        plain_spoof = spoofer.create_publisher(NamedTrackArray, "/tracks_named", 10)
        sealed_spoof = spoofer.create_publisher(Sealed, "/tracks_named_sealed", 10)
        spoofer.create_subscription(Sealed, "/tracks_named_sealed", overheard.append, 10)
        assert spin(lambda: frames.get_subscription_count() == 1 and sealed_spoof.get_subscription_count() >= 3), \
            (frames.get_subscription_count(), sealed_spoof.get_subscription_count())  # consumer, goto, spoofer
        assert plain_spoof.get_subscription_count() == 0  # consumers with the key do not even listen there
        # the master publishes its tracks only sealed: on the plain topic only the spoofer
        assert [i.node_name for i in consumer.get_publishers_info_by_topic("/tracks_named")] == ["spoofer"]

        assert spin(lambda: len(overheard) >= 1)
        captured = overheard[0]  # the master's sealed tracks, overheard by the keyless peer (before any forgery)
        cam_sealer = Sealer(key, "cam_a")
        forger = Sealer(stranger_key, "/face_reid_master", TRACKS_PURPOSE)  # a keyless peer's own key
        spoof_cdr = serialize_message(_spoofed())
        for k in range(20):
            frames.publish(seal_message(cam_sealer, _frame(1.0 + 0.01 * k)))
            plain_spoof.publish(_spoofed())
            sealed_spoof.publish(seal_payload(forger, spoof_cdr))
            spin(lambda: False, 0.05)
        assert spin(lambda: tracks.refused.get("forged", 0) >= 20 and goto.rejected.get("tracks_forged", 0) >= 20
                    and any(m.tracks for m in taken)), \
            (tracks.refused, goto.rejected, len(taken))
        replays = tracks.refused.get("replayed", 0)
        sealed_spoof.publish(captured)  # replayed by the keyless peer
        # a camera's sealed frame passed off as tracks
        sealed_spoof.publish(seal_message(cam_sealer, _frame(5.0)))
        assert spin(lambda: tracks.refused.get("replayed", 0) == replays + 1 and tracks.refused.get("forged", 0) >= 21,
                    30.0), (tracks.refused, replays)

        names = {t.name for m in taken for t in m.tracks}
        cameras = {c for m in taken for t in m.tracks for c in t.cameras}
        assert SPOOF not in names and cameras == {"cam_a"}, (names, cameras)
        assert tracks.accepted == len(taken) >= 5
        assert goto.counts["tracks_msgs"] >= 5 and goto.counts["goals"] == 0  # no goal to the spoofed person
        assert "ignored" in tracks.check().problem  # someone publishes plain tracks: said, and ignored
    finally:
        executor.shutdown()
        for node in (consumer, spoofer, camera, master, goto):
            node.destroy_node()


def test_a_keyless_consumer_on_a_secured_network_is_told_and_takes_no_plain_spoof(ros_context, tmp_path: Path,
                                                                                   capfd) -> None:
    write_network_key(tmp_path / "network.key")
    master = _secured_master(ros_context, tmp_path)
    ctx = master.context
    spoofer, consumer = Node("spoofer", context=ctx), Node("robot_without_key", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (master, spoofer, consumer):
        executor.add_node(node)
    taken: list[NamedTrackArray] = []
    try:
        assert master.trigger_configure() == OK and master.trigger_activate() == OK
        tracks = subscribe_tracks(consumer, taken.append, "/tracks_named", check_period_s=0.2)
        plain_spoof = spoofer.create_publisher(NamedTrackArray, "/tracks_named", 10)
        assert spin_until(executor, lambda: plain_spoof.get_subscription_count() == 1
                          and tracks.network is not None and tracks.network.secured_network, 60.0)
        for _ in range(10):
            plain_spoof.publish(_spoofed())
        assert spin_until(executor, lambda: tracks.refused.get("unauthenticated", 0) == 10, 60.0)
        assert taken == [] and tracks.accepted == 0
        err = capfd.readouterr().err
        assert "tracks are sealed" in err and "set network_key_path" in err and "/tracks_named_sealed" in err, err
        assert "[ERROR]" in err.split("tracks are sealed")[0].splitlines()[-1]
    finally:
        executor.shutdown()
        for node in (consumer, spoofer, master):
            node.destroy_node()
