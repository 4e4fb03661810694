"""Test helper process: one camera seeing one person walk (a stable face); sealed frames with a network key.

Waits for a subscriber, prints {"start": t}, publishes --rate-hz frames for --seconds, prints {"sent": N}.

Usage: python test/ros_procs/sealed_walker.py --key KEYFILE --seconds S
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--key", default="", help="network key file ('' = an unsecured camera: plain frames)")
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rate-hz", type=float, default=10.0)
    parser.add_argument("--wait-s", type=float, default=60.0)
    parser.add_argument("--camera", default="walker", help="its camera id (it publishes in the namespace /<camera>)")
    args = parser.parse_args()

    import numpy as np
    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from face_reid_camera.common.ros.sealed import seal_message
    from face_reid_camera.common.sealing import Sealer, load_network_key
    from face_reid_master.records import CameraFrameRecord, PersonRecord
    from face_reid_master.ros.convert import frame_record_to_msg
    from face_reid_msgs.msg import CameraFrame, Sealed

    rclpy.init()
    node = rclpy.create_node("sealed_walker")
    qos = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    if args.key:
        pub = node.create_publisher(Sealed, f"/{args.camera}/face_reid/frames_sealed", qos)
        sealer = Sealer(load_network_key(args.key), args.camera)
    else:
        pub = node.create_publisher(CameraFrame, f"/{args.camera}/face_reid/frames", qos)
        sealer = None
    rng = np.random.default_rng(7)
    face = rng.normal(size=128)
    face = 1.4 * face / np.linalg.norm(face)
    deadline = time.monotonic() + args.wait_s
    while pub.get_subscription_count() < 1:  # the master (it discovers sealed topics)
        if time.monotonic() > deadline:
            print(json.dumps({"error": "no subscriber"}), flush=True)
            return 1
        rclpy.spin_once(node, timeout_sec=0.05)
    start = time.time()
    print(json.dumps({"start": start}), flush=True)
    sent = 0
    while time.time() - start < args.seconds:
        now = time.time()
        t = now - start
        emb = face + rng.normal(0, 0.02, 128)
        emb = (1.4 * emb / np.linalg.norm(emb)).astype(np.float32)
        person = PersonRecord(np.array([2.0 * math.cos(0.2 * t), 2.0 * math.sin(0.2 * t), 0.0]), 0.05, 1.75, emb,
                              0.9, 0.8, "dlib_resnet_v1", 40.0)
        msg = frame_record_to_msg(CameraFrameRecord(args.camera, now, (person,)), now)
        pub.publish(msg if sealer is None else seal_message(sealer, msg))
        sent += 1
        rclpy.spin_once(node, timeout_sec=0.0)
        time.sleep(max(0.0, start + sent / args.rate_hz - time.time()))
    print(json.dumps({"sent": sent}), flush=True)
    time.sleep(0.5)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
