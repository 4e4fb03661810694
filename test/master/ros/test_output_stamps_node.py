"""The master node's /tracks_named stamps with a camera whose clock runs 1.9 s ahead (inside
max_stamp_future_s) interleaved with one on time, and the timer's messages: never ahead of the master's clock,
never backwards (the code before: stamps up to 1.9 s ahead, stepping back at every on-time cycle and tick)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy")

import itertools

from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.serialization import deserialize_message

from face_reid_camera.common.stamps import stamp_to_seconds
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.ros.convert import frame_record_to_msg
from face_reid_master.ros.node import MasterNode
from face_reid_msgs.msg import NamedTrackArray

OK = TransitionCallbackReturn.SUCCESS


def _frame(camera: str, stamp_s: float, x: float):
    person = PersonRecord(np.array([x, 2.0, 0.0]), 0.05, 1.7, None, 0.0, 0.0)
    return frame_record_to_msg(CameraFrameRecord(camera, stamp_s, (person,)), stamp_s)


def test_output_stamps_stay_behind_the_master_clock_and_never_step_back(ros_context, tmp_path: Path) -> None:
    ctx = ros_context(["--ros-args", "-p", f"db_path:={tmp_path / 'faces.db'}", "-p", "persist_faces:=false",
                       "-p", "camera_topics:=[/cam_a/face_reid/frames, /cam_b/face_reid/frames]",
                       "-p", "camera_topic_regex:=''", "-p", "max_publish_rate_hz:=0.0",
                       "-p", "identity_period_s:=0.0", "-p", "embedding_space:=dlib_resnet_v1"])
    node = MasterNode(context=ctx)
    out: list[tuple[float, float]] = []  # (stamp, the master's clock right after publishing)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        publish = node.tracks_pub.publish

        def recording(data) -> None:
            publish(data)
            msg = deserialize_message(data, NamedTrackArray) if isinstance(data, bytes) else data
            out.append((stamp_to_seconds(msg.header.stamp), node.now_s()))

        node.tracks_pub.publish = recording
        for k in range(40):
            now = time.time()
            node._on_frame(_frame("cam_a", now, 1.0))  # on time
            node._on_frame(_frame("cam_b", now + 1.9, 4.0))  # its clock 1.9 s ahead (max_stamp_future_s: 2)
            if k % 5 == 4:
                node._tick()  # the timer's message
            time.sleep(0.01)
        assert node.core.stats.frames_applied >= 70  # both cameras' frames were taken
        assert len(out) >= 80
        ahead = [s - now for s, now in out if s > now]
        back = [b[0] - a[0] for a, b in itertools.pairwise(out) if b[0] < a[0]]
        assert not ahead, f"{len(ahead)} stamps ahead of the master's clock, by up to {max(ahead):.2f} s"
        assert not back, f"{len(back)} backward steps, by up to {-min(back):.2f} s"
    finally:
        node.destroy_node()
