"""Test helper process: subscribe to face_reid_msgs/CameraFrame and print one JSON line per message.

Usage: python test/ros_procs/collect_frames.py --topic T --count N --timeout-s S
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--topic", required=True)
    parser.add_argument("--count", type=int, default=5)
    parser.add_argument("--timeout-s", type=float, default=60.0)
    args = parser.parse_args()

    import rclpy

    from face_reid_msgs.msg import CameraFrame

    rclpy.init()
    node = rclpy.create_node("camera_frame_collector")
    got: list[dict] = []

    def on_frame(msg: CameraFrame) -> None:
        got.append({
            "camera_id": msg.camera_id,
            "frame_id": msg.header.frame_id,
            "ground_plane_found": msg.ground_plane_found,
            "processing_time_ms": msg.processing_time_ms,
            "people": [
                {
                    "world": [p.position_world.x, p.position_world.y, p.position_world.z],
                    "height_m": p.height_m,
                    "face_found": p.face_found,
                    "face_score": p.face_score,
                    "embedding_len": len(p.embedding),
                    "embedding_space": p.embedding_space,
                    "embedding": list(p.embedding),
                    "body_descriptor_len": len(p.body_descriptor),
                    "body_space": p.body_descriptor_space,
                    "body_visible_fraction": p.body_visible_fraction,
                    "body_shoulder_width_m": p.body_shoulder_width_m,
                }
                for p in msg.people
            ],
        })
        print(json.dumps(got[-1]), flush=True)

    node.create_subscription(CameraFrame, args.topic, on_frame, 10)
    print(json.dumps({"ready": True}), flush=True)
    deadline = time.monotonic() + args.timeout_s
    while len(got) < args.count and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0 if len(got) >= args.count else 1


if __name__ == "__main__":
    sys.exit(main())
