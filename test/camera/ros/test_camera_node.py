"""The camera node in-process: lifecycle transitions, /diagnostics, namespaced params files, parameter errors.

Real rclpy (one context per test, loopback-only discovery), real ONNX models; the node's behaviour on real
frames over DDS is in test_camera_node_dds.py.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import FACES_DIR, spin_until, start_up_output

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rclpy.time import Time
from sensor_msgs.msg import CameraInfo, Image

from face_reid_camera.ros import params as camera_params
from face_reid_camera.ros.image_codec import encode_image
from face_reid_camera.ros.node import CameraNode

REPO = Path(__file__).resolve().parents[3]
OK = TransitionCallbackReturn.SUCCESS


def _sub_topics(node: Node) -> set[str]:
    return {s.topic_name for s in node.subscriptions}


def test_lifecycle_subscribes_only_while_active(ros_context) -> None:
    ctx = ros_context(["--ros-args", "-p", "camera_id:=cam_lc"])
    node = CameraNode(context=ctx)
    try:
        image_topics = {"/color/image_raw", "/depth_registered/image_raw", "/color/camera_info"}
        assert _sub_topics(node) == set() and node.pipeline is None
        assert node.trigger_configure() == OK
        assert node.pipeline is not None and node.pipeline.face_detector is not None  # models loaded on configure
        assert _sub_topics(node) == set() and node.publisher is None
        assert node.trigger_activate() == OK
        assert _sub_topics(node) == image_topics
        assert node.publisher is not None and node.publisher.topic_name == "/face_reid/frames"
        assert node.trigger_deactivate() == OK
        assert _sub_topics(node) == set() and node.publisher is None
        assert node.trigger_activate() == OK and _sub_topics(node) == image_topics  # again
        assert node.trigger_deactivate() == OK
        assert node.trigger_cleanup() == OK
        assert node.pipeline is None
        assert node.trigger_shutdown() == OK
    finally:
        node.destroy_node()


def test_failed_configure_stays_unconfigured_and_says_why(ros_context, tmp_path: Path) -> None:
    missing = tmp_path / "nope.onnx"
    ctx = ros_context(["--ros-args", "-p", f"detector_model_path:={missing}"])
    node = CameraNode(context=ctx)
    try:
        assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
        assert str(missing) in node.failure and node.pipeline is None
        assert node._state_machine.current_state[1] == "unconfigured"
        assert node.trigger_activate() != OK  # cannot activate an unconfigured node
    finally:
        node.destroy_node()


def _camera_info(stamp):
    info = CameraInfo()
    info.header.stamp = stamp
    info.width, info.height = 640, 480
    info.k = [525.0, 0.0, 319.5, 0.0, 525.0, 239.5, 0.0, 0.0, 1.0]  # CameraIntrinsics.kinect_default()
    return info


def _images(color: np.ndarray, color_enc: str, depth: np.ndarray, depth_enc: str, stamp, truncate: bool = False):
    """Colour and depth sensor_msgs/Image; ``color_enc`` may name an unsupported encoding (bgr8 bytes)."""
    out = []
    for img, enc in ((color, color_enc), (depth, depth_enc)):
        m = Image()
        m.header.stamp = stamp
        m.height, m.width, m.step, data = encode_image(img, enc if enc in ("bgr8", "16UC1", "32FC1") else "bgr8")
        m.encoding = enc
        m.data = data[: len(data) // 2] if (truncate and img is depth) else data
        out.append(m)
    return out


@contextlib.contextmanager
def _camera_with_probe(ctx) -> Iterator[tuple[CameraNode, Node, SingleThreadedExecutor]]:
    """A camera node and a probe node of context ``ctx`` on one executor; all torn down on exit."""
    node = CameraNode(context=ctx)
    probe = Node("probe", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    executor.add_node(probe)
    try:
        yield node, probe, executor
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()


def _feed(node: CameraNode, color_bgr: np.ndarray, depth_mm: np.ndarray) -> Any:
    """One colour + depth frame (and its camera info) straight into the node's callbacks; returns the stamp."""
    stamp = node.get_clock().now().to_msg()
    color, depth = _images(color_bgr, "bgr8", depth_mm, "16UC1", stamp)
    node._on_info(_camera_info(stamp))
    node._on_color(color)
    node._on_depth(depth)
    return stamp


def test_diagnostics_report_counts_timings_and_rejections(ros_context) -> None:
    ctx = ros_context(["--ros-args", "-p", "camera_id:=cam_diag", "-p", "detect_faces:=false"])
    with _camera_with_probe(ctx) as (node, probe, executor):
        got: list[DiagnosticArray] = []
        probe.create_subscription(DiagnosticArray, "/diagnostics", got.append, 10)
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        stamp = node.get_clock().now().to_msg()
        depth_mm = np.zeros((480, 640), np.uint16)
        depth_mm[240:] = 2500  # a floor-less wall of depth: no people
        color, depth = _images(np.full((480, 640, 3), 90, np.uint8), "bgr8", depth_mm, "16UC1", stamp)
        info = _camera_info(stamp)
        bad = Image()
        bad.encoding, bad.height, bad.width, bad.step = "yuv422", 2, 2, 4  # unsupported: rejected and counted
        node._on_color(bad)
        node._on_info(info)
        node._on_color(color)
        node._on_depth(depth)
        assert spin_until(executor, lambda: node.health is not None and node.health.frames_processed >= 1)
        n_before = len(got)
        assert spin_until(executor, lambda: len(got) > n_before and any(
            kv.key == "frames_processed" and kv.value != "0" for kv in got[-1].status[0].values))
        status = got[-1].status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert status.name.endswith("camera cam_diag") and status.hardware_id == "cam_diag"
        for key in ("frames_in", "frames_processed", "frames_dropped", "processing_time_p50_ms",
                    "processing_time_p95_ms", "people_per_frame", "faces_per_frame", "publish_rate_hz",
                    "rejected_bad_color", "rejected_bad_depth", "rejected_no_camera_info", "rejected_stale",
                    "rejected_size_mismatch", "floor_found"):
            assert key in values, key
        assert values["frames_in"] == "1" and values["frames_processed"] == "1"
        assert values["rejected_bad_color"] == "1"
        assert float(values["processing_time_p95_ms"]) >= float(values["processing_time_p50_ms"]) > 0
        assert float(values["people_per_frame"]) == 0.0
        assert (status.level == b"\x01") == (values["floor_found"] == "False")  # floor lost: WARN
        assert ("floor lost" in status.message) == (values["floor_found"] == "False")


def test_malformed_input_is_logged_counted_and_survived(ros_context) -> None:
    """Each kind of bad input is rejected by reason and counted; good frames afterwards carry the person."""
    import cv2

    from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
    from face_reid_camera.faces.detector import YuNetDetector
    from face_reid_master.sim.renderer import SyntheticPerson, crop_face_for_rendering, render_scene

    intr = CameraIntrinsics.kinect_default()
    photo = cv2.imread(str(sorted((FACES_DIR / "lfw_Tony_Blair").glob("*.jpg"))[0]), cv2.IMREAD_COLOR)
    best = max(YuNetDetector().detect(photo), key=lambda d: d.box_xywh[2] * d.box_xywh[3])
    person = SyntheticPerson(2.4, 0.0, 1.75, 3.14159, crop_face_for_rendering(photo, best.box_xywh))
    frame = render_scene([person], intr, CameraPose.from_xyz_rpy(0.0, 0.0, 2.2, 0.0, 0.3, 0.0),
                         rng=np.random.default_rng(0))
    ctx = ros_context(["--ros-args", "-p", "camera_id:=cam_bad", "-p", "camera_pose_xyz_m:=[0.0, 0.0, 2.2]",
                       "-p", "camera_pose_rpy_rad:=[0.0, 0.3, 0.0]", "-p", "max_frame_age_s:=0.0"])
    node = CameraNode(context=ctx)
    sent: list = []
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        node.publisher.publish = sent.append  # what the node would send, in order
        t = [1000.0]

        def feed(color_enc="bgr8", depth=frame.depth_mm, depth_enc="16UC1", info=True, truncate=False) -> None:
            t[0] += 0.1
            stamp = Time(seconds=t[0]).to_msg()
            if info:
                node._on_info(_camera_info(stamp))
            color_msg, depth_msg = _images(frame.rgb_bgr, color_enc, depth, depth_enc, stamp, truncate)
            node._on_color(color_msg)
            node._on_depth(depth_msg)
            n = node.health.frames_in
            assert spin_until_idle(node, n)

        feed(info=False)  # no CameraInfo yet
        feed(color_enc="yuv422")  # unsupported colour encoding
        feed(truncate=True)  # truncated depth data
        feed(depth=frame.depth_mm[::2, ::2])  # depth smaller than CameraInfo says
        feed(depth=np.full((intr.height, intr.width), np.nan, np.float32), depth_enc="32FC1")  # all NaN: empty
        for _ in range(3):
            feed()
        rejected = node.health.rejected
        assert rejected == {"no_camera_info": 1, "bad_color": 1, "bad_depth": 1, "size_mismatch": 1}, rejected
        assert node._worker is not None and node._worker.is_alive()
        assert [len(m.people) for m in sent] == [0, 1, 1, 1] and not sent[0].ground_plane_found
        # the default embedder (both): one 256-value joint embedding per face
        assert all(len(m.people[0].embedding) == 256 for m in sent[1:])
        assert {m.people[0].embedding_space for m in sent[1:]} == {"dlib_resnet_v1+sface_2021dec"}
    finally:
        node.destroy_node()


def spin_until_idle(node: CameraNode, frames_in: int, timeout_s: float = 30.0) -> bool:
    """Wait until the worker has taken the newest pair (processed or rejected) - a barrier, not a sleep."""
    import time

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with node._cond:
            if node._slot is None and not node._busy:
                return True
        time.sleep(0.005)
    return False


def test_diagnostics_warn_when_no_input(ros_context) -> None:
    ctx = ros_context(["--ros-args", "-p", "detect_faces:=false", "-p", "no_input_warning_s:=0.01"])
    node = CameraNode(context=ctx)
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        report = node.diagnostics(node.now_s() + 1.0)
        assert report.level == 1 and report.message.startswith("no input for")
    finally:
        node.destroy_node()


def test_namespaced_camera_takes_its_id_and_pose_from_a_params_file(ros_context, tmp_path: Path) -> None:
    params = tmp_path / "my_camera.yaml"
    params.write_text(
        "/**:\n  ros__parameters:\n    camera_id: kitchen\n    camera_pose_xyz_m: [1.5, -2.0, 2.4]\n"
        "    camera_pose_rpy_rad: [0.0, 0.5, 1.57]\n    galery_path: x\n    person:\n      voxel_sise_m: 0.05\n"
    )
    ctx = ros_context(["--ros-args", "-r", "__ns:=/cam_kitchen", "--params-file", str(params),
                       "-p", "detect_faces:=false"])
    node = CameraNode(context=ctx)
    try:
        assert node.get_fully_qualified_name() == "/cam_kitchen/face_reid_camera"
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        assert node.pipeline is not None and node.pipeline.config.camera_id == "kitchen"
        np.testing.assert_allclose(node.pipeline.camera_pose.translation, [1.5, -2.0, 2.4])
        assert node.publisher.topic_name == "/cam_kitchen/face_reid/frames"
        # misspelt parameters are named, with the closest real one
        assert node.unknown_parameters == ["galery_path", "person.voxel_sise_m"]
        assert "did you mean 'person.voxel_size_m'" in node.table.suggest("person.voxel_sise_m")
    finally:
        node.destroy_node()


def test_shipped_yaml_applies_to_any_node_name(ros_context, tmp_path: Path) -> None:
    shipped = (REPO / "config" / "camera.yaml").read_text()
    assert "\n    embed_budget_ms: 40.0\n" in shipped
    edited = tmp_path / "camera.yaml"  # the shipped file with one value changed: is the file applied at all?
    edited.write_text(shipped.replace("\n    embed_budget_ms: 40.0\n", "\n    embed_budget_ms: 35.0\n"))
    ctx = ros_context(["--ros-args", "-r", "__ns:=/cam_x", "-r", "__node:=other_name", "--params-file",
                       str(edited), "-p", "camera_id:=cam_x"])
    node = CameraNode(context=ctx)
    try:
        assert node.get_fully_qualified_name() == "/cam_x/other_name"
        assert node.unknown_parameters == []
        expected = {**camera_params.defaults(), "camera_id": "cam_x", "embed_budget_ms": 35.0}
        assert node.parameter_values() == expected
    finally:
        node.destroy_node()


@pytest.mark.parametrize("override,expected", [
    ("camera_pose_xyz_m:=[1, 2, 2]", "parameter 'camera_pose_xyz_m' must be a list of 3 floats"),
    ("head_roi_size_m:=7.0", "parameter 'head_roi_size_m' must be in [0.05, 2], got 7.0"),
    ("person.voxel_size_m:=0.0", "parameter 'person.voxel_size_m' must be in (0, 1], got 0.0"),
    ("network_key_path:=/nonexistent/network.key", "make one with: face-reid-keys new /nonexistent/network.key"),
])
def test_bad_parameter_is_one_fatal_line(ros_domain_id: int, override: str, expected: str) -> None:
    status, lines = start_up_output("face_reid_camera.ros.node", "-p", override)
    assert status == 2 and len(lines) == 1, lines
    assert lines[0].startswith("[face-reid-camera] FATAL: cannot start: ") and expected in lines[0]


def test_arguments_rcl_cannot_parse_are_a_fatal_line_not_a_traceback(ros_domain_id: int) -> None:
    status, lines = start_up_output("face_reid_camera.ros.node", "-p", "network_key_path:=")
    assert status == 2 and not any("Traceback" in line for line in lines), lines
    assert any(line.startswith("[face-reid-camera] FATAL: cannot start: bad --ros-args") and "name:=''" in line
               for line in lines), lines


def test_every_parameter_has_a_range_or_choices_where_one_applies() -> None:
    for spec in camera_params.TABLE.specs:
        if spec.kind in ("int", "float", "float_list"):
            assert spec.low is not None and spec.high is not None, spec.name
        assert len(spec.description) > 20, spec.name


def test_with_a_network_key_frames_go_out_sealed_only(ros_context, tmp_path: Path) -> None:
    from face_reid_camera.common.ros.sealed import open_message
    from face_reid_camera.common.sealing import Opener, load_network_key, write_network_key
    from face_reid_msgs.msg import CameraFrame, Sealed

    key = load_network_key(write_network_key(tmp_path / "network.key"))
    ctx = ros_context(["--ros-args", "-p", "camera_id:=cam_sealed", "-p", "detect_faces:=false",
                       "-p", f"network_key_path:={tmp_path / 'network.key'}"])
    with _camera_with_probe(ctx) as (node, probe, executor):
        sealed: list = []
        plain: list = []
        probe.create_subscription(Sealed, "/face_reid/frames_sealed", sealed.append, 10)
        probe.create_subscription(CameraFrame, "/face_reid/frames", plain.append, 10)
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        assert spin_until(executor, lambda: node.publisher.get_subscription_count() == 1)
        depth_mm = np.zeros((480, 640), np.uint16)
        depth_mm[240:] = 2500
        stamp = _feed(node, np.full((480, 640, 3), 90, np.uint8), depth_mm)
        assert spin_until(executor, lambda: len(sealed) == 1)
        frame = open_message(Opener(key), sealed[0], CameraFrame)
        assert frame.camera_id == "cam_sealed" and sealed[0].sender_id == "cam_sealed"
        assert abs(frame.header.stamp.sec + frame.header.stamp.nanosec * 1e-9
                   - (stamp.sec + stamp.nanosec * 1e-9)) < 1e-6  # the camera's stamp, through float seconds
        assert plain == [] and node.publisher.topic_name == "/face_reid/frames_sealed"
    # a key file others can read is refused when the node is made (its sealed control needs the key), with why
    (tmp_path / "network.key").chmod(0o644)
    with pytest.raises(ValueError, match="readable by others"):
        CameraNode(context=ros_context(["--ros-args", "-p", "detect_faces:=false",
                                        "-p", f"network_key_path:={tmp_path / 'network.key'}"]))


def test_floor_summary_is_published_only_when_asked_for(ros_context) -> None:
    """floor_map_period_s > 0: the real node counts its depth frames into a FloorOccupancy (walls of a rendered room
    in the obstacle band, the open floor free); at the default 0 it has no such publisher."""
    from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
    from face_reid_camera.common.ros.floor_map import FLOOR_MAP_QOS, FLOOR_MAP_TOPIC
    from face_reid_master.sim.renderer import render_scene
    from face_reid_msgs.msg import FloorOccupancy

    ctx = ros_context(["--ros-args", "-p", "camera_id:=cam_map", "-p", "detect_faces:=false",
                       "-p", "describe_bodies:=false", "-p", "camera_pose_xyz_m:=[0.0, 0.0, 2.4]",
                       "-p", "camera_pose_rpy_rad:=[0.0, 0.4, 0.0]", "-p", "max_frame_age_s:=0.0",
                       "-p", "floor_map_period_s:=1.0", "-p", "floor_map_every_frames:=1"])
    with _camera_with_probe(ctx) as (node, probe, executor):
        got: list[FloorOccupancy] = []
        probe.create_subscription(FloorOccupancy, FLOOR_MAP_TOPIC, got.append, FLOOR_MAP_QOS)
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        pose = CameraPose.from_xyz_rpy(0.0, 0.0, 2.4, 0.0, 0.4, 0.0)
        frame = render_scene([], CameraIntrinsics.kinect_default(640, 480), pose, walls=True, floor_size_m=8.0)
        _feed(node, frame.rgb_bgr, frame.depth_mm)
        assert spin_until(executor, lambda: len(got) > 0), "no FloorOccupancy from the camera node"
        msg = got[-1]
        assert msg.camera_id == "cam_map" and msg.frames >= 1 and msg.header.frame_id
        occupied = np.asarray(msg.occupied_counts).reshape(msg.height, msg.width)
        floor = np.asarray(msg.floor_counts).reshape(msg.height, msg.width)
        _, cols = np.nonzero(occupied)
        xs = msg.origin_x_m + (cols + 0.5) * msg.resolution_m
        assert floor.sum() > 0 and xs.size > 0
        assert np.median(xs) == pytest.approx(4.0, abs=0.3)  # the wall ahead, at x = +4 m (within range)
        assert any(name.endswith(FLOOR_MAP_TOPIC) for name, _ in node.get_publisher_names_and_types_by_node(
            node.get_name(), node.get_namespace()))
    ctx2 = ros_context(["--ros-args", "-p", "camera_id:=cam_off", "-p", "detect_faces:=false"])
    off = CameraNode(context=ctx2)
    try:
        assert off.trigger_configure() == OK and off.trigger_activate() == OK
        assert not any(name.endswith(FLOOR_MAP_TOPIC) for name, _ in off.get_publisher_names_and_types_by_node(
            off.get_name(), off.get_namespace()))
    finally:
        off.destroy_node()


def test_one_pair_stamped_an_hour_ahead_does_not_silence_the_camera(ros_context) -> None:
    """The attack: one colour+depth pair stamped +1 h, then valid pairs. Each valid pair is published; the
    forged one is dropped, counted and named on /diagnostics (the code before published 1 frame of 6: the
    forged one, then the pairing's last stamp stayed an hour ahead and every valid pair was refused)."""
    ctx = ros_context(["--ros-args", "-p", "camera_id:=cam_stamps", "-p", "detect_faces:=false",
                       "-p", "describe_bodies:=false", "-p", "max_frame_age_s:=5.0"])
    node = CameraNode(context=ctx)
    sent: list = []
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        node.publisher.publish = sent.append  # what the node would send, in order
        depth_mm = np.zeros((480, 640), np.uint16)
        depth_mm[240:] = 2500
        bgr = np.full((480, 640, 3), 90, np.uint8)

        def feed(ahead_s: float) -> float:
            stamp_s = node.now_s() + ahead_s
            stamp = Time(nanoseconds=int(stamp_s * 1e9)).to_msg()
            node._on_info(_camera_info(stamp))
            for msg in _images(bgr, "bgr8", depth_mm, "16UC1", stamp):
                (node._on_color if msg.encoding == "bgr8" else node._on_depth)(msg)
            assert spin_until_idle(node, node.health.frames_in)  # processed before the next: none superseded
            return stamp_s

        feed(3600.0)
        valid = [feed(0.0) for _ in range(5)]
        assert len(sent) == 5, f"{len(sent)} published of 5 valid pairs"
        assert [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in sent] == pytest.approx(valid, abs=1e-6)
        report = node.diagnostics(node.now_s())
        assert report.values["rejected_stamp_future"] == "2" and report.values["rejected_total"] == "2"
        assert report.values["rejected_stamp_past"] == report.values["rejected_stamp_out_of_order"] == "0"
        assert report.values["sync_resets"] == "0" and report.values["frames_processed"] == "5"
        assert report.level == 1, report.message
        assert "2 stamp_future (stamped more than 2 s after they were received)" in report.message, report.message
        assert "stamp" not in node.diagnostics(node.now_s()).message  # said once per report period, not forever
    finally:
        node.destroy_node()


def test_a_depth_image_stamped_just_under_the_future_limit_does_not_silence_the_camera(ros_context) -> None:
    """Break 6 in the node: after every third valid pair an extra depth image stamped +0.95 s (within the 2 s
    future limit). Before, each one became the depth stream's last stamp and the valid pairs after it were
    refused (0 of 18 out); now it is out of the stream's pattern: dropped, counted, named on /diagnostics."""
    ctx = ros_context(["--ros-args", "-p", "camera_id:=cam_pattern", "-p", "detect_faces:=false",
                       "-p", "describe_bodies:=false", "-p", "max_frame_age_s:=5.0"])
    node = CameraNode(context=ctx)
    sent: list = []
    try:
        assert node.trigger_configure() == OK and node.trigger_activate() == OK
        node.publisher.publish = sent.append
        depth_mm = np.zeros((480, 640), np.uint16)
        depth_mm[240:] = 2500
        bgr = np.full((480, 640, 3), 90, np.uint8)
        for k in range(18):
            stamp = Time(nanoseconds=int(node.now_s() * 1e9)).to_msg()
            node._on_info(_camera_info(stamp))
            color, depth = _images(bgr, "bgr8", depth_mm, "16UC1", stamp)
            node._on_color(color)
            node._on_depth(depth)
            assert spin_until_idle(node, node.health.frames_in)
            if k % 3 == 2:
                ahead = Time(nanoseconds=int((node.now_s() + 0.95) * 1e9)).to_msg()
                node._on_depth(_images(bgr, "bgr8", depth_mm, "16UC1", ahead)[1])
        assert len(sent) == 18, f"{len(sent)} published of 18 valid pairs"
        report = node.diagnostics(node.now_s())
        assert report.values["rejected_stamp_out_of_pattern"] == "6" and report.values["sync_resets"] == "0"
        assert "6 stamp_out_of_pattern" in report.message and report.level == 1
    finally:
        node.destroy_node()
