"""Each driver preset (config/drivers/*.yaml) with frames published the way that driver does: its topic names,
encodings, sizes (registered depth smaller than colour for OpenNI2's QVGA mode) and QoS (reliable or best
effort: image_qos auto matches it). People come out at the right place. Real DDS in-process, loopback."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT, spin_until

pytest.importorskip("rclpy")
pytest.importorskip("face_reid_msgs.msg")

import cv2
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.ros.image_codec import encode_image
from face_reid_camera.ros.node import CameraNode
from face_reid_master.sim.renderer import SyntheticPerson, render_scene
from face_reid_msgs.msg import CameraFrame

DRIVERS = REPO_ROOT / "config" / "drivers"
POSE = (0.0, 0.0, 2.0, 0.0, 0.3, 0.0)  # 2 m high, tilted 17 degrees down, looking along +x
PERSON_XY = (3.0, 0.4)

# preset, colour (encoding, w, h), depth (encoding, w, h), the driver's reliability
CASES = {
    "realsense": (("rgb8", 1280, 720), ("16UC1", 1280, 720), ReliabilityPolicy.RELIABLE),
    "azure_kinect": (("bgra8", 1280, 720), ("16UC1", 1280, 720), ReliabilityPolicy.BEST_EFFORT),
    "kinect2": (("bgr8", 960, 540), ("16UC1", 960, 540), ReliabilityPolicy.RELIABLE),
    "openni2": (("rgb8", 640, 480), ("16UC1", 320, 240), ReliabilityPolicy.BEST_EFFORT),
}


def _topics(preset: Path) -> dict[str, str]:
    import yaml

    return yaml.safe_load(preset.read_text())["/**"]["ros__parameters"]


def _images(color: tuple[str, int, int], depth: tuple[str, int, int]):
    """One rendered frame at the colour size; depth resized to its own size; the depth image's intrinsics."""
    enc_c, w, h = color
    intr = CameraIntrinsics(0.75 * w, 0.75 * w, (w - 1) / 2, (h - 1) / 2, w, h)
    frame = render_scene([SyntheticPerson(*PERSON_XY, 1.75, math.pi, None)], intr, CameraPose.from_xyz_rpy(*POSE),
                         rng=np.random.default_rng(0))
    bgr = frame.rgb_bgr
    colour = {"rgb8": bgr[:, :, ::-1], "bgr8": bgr, "bgra8": cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA)}[enc_c]
    _, dw, dh = depth
    depth_mm = cv2.resize(frame.depth_mm, (dw, dh), interpolation=cv2.INTER_NEAREST) if (dw, dh) != (w, h) \
        else frame.depth_mm
    return np.ascontiguousarray(colour), depth_mm, intr.scaled(dw, dh)


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_driver_preset_gets_people_out_of_that_drivers_frames(name: str, ros_context) -> None:
    color_spec, depth_spec, reliability = CASES[name]
    preset = DRIVERS / f"{name}.yaml"
    topics = _topics(preset)
    ctx = ros_context(["--ros-args", "--params-file", str(REPO_ROOT / "config" / "camera.yaml"), "--params-file",
                       str(preset), "-p", f"camera_id:=cam_{name}", "-p", "detect_faces:=false",
                       "-p", "describe_bodies:=false", "-p", f"camera_pose_xyz_m:=[{POSE[0]}, {POSE[1]}, {POSE[2]}]",
                       "-p", f"camera_pose_rpy_rad:=[{POSE[3]}, {POSE[4]}, {POSE[5]}]", "-p", "max_frame_age_s:=5.0"])
    camera = CameraNode(context=ctx)
    driver = Node("driver", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(camera)
    executor.add_node(driver)
    qos = QoSProfile(depth=5, history=HistoryPolicy.KEEP_LAST, reliability=reliability)
    pub_c = driver.create_publisher(Image, topics["color_topic"], qos)
    pub_d = driver.create_publisher(Image, topics["depth_topic"], qos)
    pub_i = driver.create_publisher(CameraInfo, topics["camera_info_topic"], qos)
    frames: list[CameraFrame] = []
    driver.create_subscription(CameraFrame, "face_reid/frames", frames.append, 10)
    colour, depth, intr = _images(color_spec, depth_spec)
    try:
        assert camera.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert camera.trigger_activate() == TransitionCallbackReturn.SUCCESS
        want = reliability == ReliabilityPolicy.RELIABLE
        # image_qos auto: the subscriptions take the driver's reliability (a reliable one would not hear a
        # best-effort driver at all; a best-effort one loses frames of a reliable driver when busy)
        assert spin_until(executor, lambda: all(
            (s.qos_profile.reliability == ReliabilityPolicy.RELIABLE) == want for s in camera._subs)
            and pub_c.get_subscription_count() > 0, 30.0)

        def publish() -> None:
            stamp = driver.get_clock().now().to_msg()
            info = CameraInfo()
            info.header.stamp, info.header.frame_id = stamp, "camera_optical"
            info.width, info.height = intr.width, intr.height
            info.k = [intr.fx, 0.0, intr.cx, 0.0, intr.fy, intr.cy, 0.0, 0.0, 1.0]
            pub_i.publish(info)
            for pub, image, enc in ((pub_c, colour, color_spec[0]), (pub_d, depth, depth_spec[0])):
                msg = Image()
                msg.header.stamp, msg.header.frame_id = stamp, "camera_optical"
                msg.height, msg.width, msg.step, msg.data = encode_image(image, enc)
                msg.encoding = enc
                pub.publish(msg)

        last = [0.0]

        def got_person() -> bool:  # a frame every 0.3 s, the executor spinning in between (spin_until)
            if frames and frames[-1].people:
                return True
            if time.monotonic() - last[0] > 0.3:
                last[0] = time.monotonic()
                publish()
            return False

        assert spin_until(executor, got_person, 60.0), camera.diagnostics(camera.now_s()).values
        (person,) = frames[-1].people
        assert math.hypot(person.position_world.x - PERSON_XY[0], person.position_world.y - PERSON_XY[1]) < 0.3
        assert person.height_m == pytest.approx(1.75, abs=0.15)
    finally:
        executor.shutdown()
        driver.destroy_node()
        camera.destroy_node()
