"""A secured master's /diagnostics over DDS: a stranger publishing its sealed tracks topic with messages that do not
open with the network key is called a keyless publisher, not a second master; a key holder publishing there is."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node

from face_reid_camera.common.ros.sealed import seal_payload
from face_reid_camera.common.sealing import Sealer, load_network_key, write_network_key
from face_reid_master.ros.node import MasterNode
from face_reid_master.ros.track_cdr import tracks_to_cdr
from face_reid_master.tracks_auth import TRACKS_PURPOSE
from face_reid_msgs.msg import Sealed

pytestmark = [pytest.mark.ros]
OK = TransitionCallbackReturn.SUCCESS


def _until_said(executor, master: MasterNode, publish, text: str, timeout_s: float = 60.0) -> str:
    """Spin, publishing now and then, until the master's /diagnostics message holds ``text``; that message."""
    deadline = time.monotonic() + timeout_s
    while text not in (message := master.diagnostics(master.now_s()).message):
        assert time.monotonic() < deadline, message
        publish()
        executor.spin_once(timeout_sec=0.05)
    return message


def test_a_keyless_publisher_of_the_tracks_is_not_called_a_second_master(ros_context, tmp_path: Path) -> None:
    key = load_network_key(write_network_key(tmp_path / "network.key"))
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "embedding_space:=dlib_resnet_v1",
                       "-p", f"network_key_path:={tmp_path / 'network.key'}", "-p", "camera_topic_regex:=''",
                       "-p", "body_appearance_tracking:=false"])
    master = MasterNode(context=ctx)
    stranger, other_master = Node("stranger", context=ctx), Node("other_master", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    for node in (master, stranger, other_master):
        executor.add_node(node)
    try:
        assert master.trigger_configure() == OK and master.trigger_activate() == OK
        garbage = stranger.create_publisher(Sealed, "/tracks_named_sealed", 10)

        def publish_garbage() -> None:
            garbage.publish(Sealed(sender_id="/face_reid_master", counter=time.time_ns(), nonce=os.urandom(12),
                                   ciphertext=os.urandom(64)))

        said = _until_said(executor, master, publish_garbage, "unauthenticated publisher of /tracks_named_sealed")
        assert "/stranger" in said and "keyless" in said and "one master per domain" not in said
        assert int(master.diagnostics(master.now_s()).values["other_output_messages_unopened"]) > 0
        # a key holder publishing sealed tracks there is another master
        sealer = Sealer(key, "/other_master", TRACKS_PURPOSE)
        tracks = other_master.create_publisher(Sealed, "/tracks_named_sealed", 10)
        said = _until_said(executor, master, lambda: tracks.publish(seal_payload(sealer, tracks_to_cdr(
            [], time.time(), "world"))), "one master per domain")
        assert "/other_master" in said
    finally:
        executor.shutdown()
        for node in (stranger, other_master, master):
            node.destroy_node()
