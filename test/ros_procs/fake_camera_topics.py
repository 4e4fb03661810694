"""Test helper process: a keyless stranger creating many camera-like topics and publishing garbage on them.

For each --pattern (a str.format pattern of k, e.g. /cam_k/e{k:03d}/face_reid/frames_sealed) it creates --count
topics of face_reid_msgs/Sealed, publishes random bytes on each (sealed by no key) --rate-hz times a second for
--seconds, prints {"topics": N} once all exist and {"sent": M} at the end.

Usage: python test/ros_procs/fake_camera_topics.py --pattern P --count 64 --seconds S
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--pattern", action="append", required=True)
    parser.add_argument("--count", type=int, action="append", required=True, help="topics per --pattern")
    parser.add_argument("--sender", default="cam_k", help="the camera the garbage claims to come from")
    parser.add_argument("--rate-hz", type=float, default=5.0)
    parser.add_argument("--seconds", type=float, default=120.0)
    args = parser.parse_args()

    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from face_reid_msgs.msg import Sealed

    rclpy.init()
    node = rclpy.create_node("fake_cameras")
    qos = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    pubs = [node.create_publisher(Sealed, pattern.format(k=k), qos)
            for pattern, count in zip(args.pattern, args.count, strict=True) for k in range(count)]
    print(json.dumps({"topics": len(pubs)}), flush=True)
    start, sent, rounds = time.monotonic(), 0, 0
    while time.monotonic() - start < args.seconds:
        for pub in pubs:
            pub.publish(Sealed(sender_id=args.sender, counter=time.time_ns(), nonce=os.urandom(12),
                               ciphertext=os.urandom(200)))
            sent += 1
        rounds += 1
        rclpy.spin_once(node, timeout_sec=0.0)
        time.sleep(max(0.0, start + rounds / args.rate_hz - time.monotonic()))
    print(json.dumps({"sent": sent}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
