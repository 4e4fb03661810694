"""Test helper process: publish synthetic RGB-D frames (colour, depth 16UC1, CameraInfo) of a scene.

Usage: python test/ros_procs/publish_rgbd.py --scene JSON --frames N --rate-hz R
The scene JSON: {"camera_pose": [x, y, z, roll, pitch, yaw], "people": [{"x": .., "y": .., "facing": ..,
"face": "path/to/photo.jpg" | null}, ...]}. Prints one JSON line when done.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import cv2
import numpy as np


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scene", required=True)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--rate-hz", type=float, default=10.0)
    parser.add_argument("--wait-s", type=float, default=20.0)
    parser.add_argument("--depth-encoding", default="16UC1")
    args = parser.parse_args()
    scene = json.loads(args.scene)

    from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
    from face_reid_camera.faces.detector import YuNetDetector
    from face_reid_camera.ros.image_codec import encode_image
    from face_reid_master.sim.renderer import SyntheticPerson, crop_face_for_rendering, render_scene

    intr = CameraIntrinsics.kinect_default()
    pose = CameraPose.from_xyz_rpy(*scene["camera_pose"])
    detector = YuNetDetector()
    people = []
    for p in scene["people"]:
        face = None
        if p.get("face"):
            photo = cv2.imread(p["face"], cv2.IMREAD_COLOR)
            best = max(detector.detect(photo), key=lambda d: d.box_xywh[2] * d.box_xywh[3])
            face = crop_face_for_rendering(photo, best.box_xywh)
        people.append(SyntheticPerson(p["x"], p["y"], p.get("height", 1.75), p.get("facing", 0.0), face))
    rng = np.random.default_rng(0)
    frames = [render_scene(people, intr, pose, rng=rng) for _ in range(3)]

    import rclpy
    from sensor_msgs.msg import CameraInfo, Image

    rclpy.init()
    node = rclpy.create_node("synthetic_rgbd_publisher")
    pub_c = node.create_publisher(Image, "color/image_raw", 5)
    pub_d = node.create_publisher(Image, "depth_registered/image_raw", 5)
    pub_i = node.create_publisher(CameraInfo, "color/camera_info", 5)
    deadline = time.monotonic() + args.wait_s
    while pub_c.get_subscription_count() == 0 or pub_d.get_subscription_count() == 0:
        if time.monotonic() > deadline:
            print(json.dumps({"error": "no subscriber"}), flush=True)
            return 1
        rclpy.spin_once(node, timeout_sec=0.05)
    # The subscriber side may match our writers a little later than we see it (loaded machines): what
    # is sent before is lost.
    time.sleep(0.5)

    def send(color_img, color_enc, depth_img, depth_enc, info_size=(intr.width, intr.height)):
        stamp = node.get_clock().now().to_msg()
        if info_size is not None:
            info = CameraInfo()
            info.header.stamp, info.header.frame_id = stamp, "synthetic_camera_optical"
            info.width, info.height = info_size
            info.k = [intr.fx, 0.0, intr.cx, 0.0, intr.fy, intr.cy, 0.0, 0.0, 1.0]
            pub_i.publish(info)
        for pub, image, enc in ((pub_c, color_img, color_enc), (pub_d, depth_img, depth_enc)):
            msg = Image()
            msg.header.stamp, msg.header.frame_id = stamp, "synthetic_camera_optical"
            msg.height, msg.width, msg.step, data = encode_image(image, enc if enc in ("bgr8", "16UC1", "32FC1")
                                                               else "bgr8")
            msg.encoding = enc
            msg.data = data
            pub.publish(msg)
        time.sleep(1.0 / args.rate_hz)

    def depth_of(frame):
        if args.depth_encoding == "16UC1":
            return frame.depth_mm
        return np.where(frame.depth_mm > 0, frame.depth_mm / 1000.0, np.nan).astype(np.float32)

    for i in range(args.frames):
        frame = frames[i % len(frames)]
        send(frame.rgb_bgr, "bgr8", depth_of(frame), args.depth_encoding)
    print(json.dumps({"published": args.frames, "face_visible": frames[0].face_visible}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
