"""Test helper process: a hostile participant. Sends random and malformed camera frames (plain and sealed with
a wrong key or random bytes), replays of overheard sealed frames, and unsealed / foreign-sealed admin requests;
prints one JSON line {"sent": N, "calls": M} at the end.

Usage: python test/ros_procs/fuzz_master.py --seed S --messages N --overhear TOPIC
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--messages", type=int, default=5000)
    parser.add_argument("--overhear", default="/walker/face_reid/frames_sealed")
    args = parser.parse_args()

    import numpy as np
    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from face_reid_camera.common.ros.sealed import seal_message, seal_request
    from face_reid_camera.common.sealing import KEY_BYTES, Sealer
    from face_reid_msgs.msg import CameraFrame, PersonObservation, Sealed
    from face_reid_msgs.srv import AddPerson, ForgetFace

    rng = np.random.default_rng(args.seed)
    rclpy.init()
    node = rclpy.create_node(f"fuzzer_{args.seed}")
    qos = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    plain = node.create_publisher(CameraFrame, f"/fuzz{args.seed}/face_reid/frames", qos)
    sealed_pub = node.create_publisher(Sealed, f"/fuzz{args.seed}/face_reid/frames_sealed", qos)
    overheard: list = []
    node.create_subscription(Sealed, args.overhear, overheard.append, qos)
    add = node.create_client(AddPerson, "/face_reid_master/add_person")
    forget = node.create_client(ForgetFace, "/face_reid_master/forget_face")
    forger = Sealer(os.urandom(KEY_BYTES), "walker")  # pretends to be the real camera, with its own key

    def text(n: int) -> str:
        return "".join(chr(int(c)) for c in rng.integers(1, 0x2FF, n))

    def frame() -> CameraFrame:
        msg = CameraFrame()
        now = node.get_clock().now().nanoseconds * 1e-9 + float(rng.choice([0.0, -3600.0, 1.9, 1e6, math.nan]))
        if math.isfinite(now):
            msg.header.stamp.sec, msg.header.stamp.nanosec = int(now) % (1 << 31), int((now % 1) * 1e9)
        msg.header.frame_id = str(rng.choice(["world", "map", text(3)]))
        msg.camera_id = str(rng.choice(["walker", "cam_x", text(int(rng.integers(0, 300)))]))
        for _ in range(int(rng.choice([0, 1, 3, 250]))):
            p = PersonObservation()
            p.position_world.x, p.position_world.y = (float(v) for v in rng.choice([0.0, 1e9, math.nan, -5.0], 2))
            p.face_found = bool(rng.integers(0, 2))
            p.embedding = rng.normal(0, float(rng.choice([0.1, 1.0, 1e6])), int(rng.choice([0, 12, 128, 256])))\
                .astype(np.float32).tolist()
            p.embedding_space = str(rng.choice(["dlib_resnet_v1", "sface_2021dec", text(5)]))
            p.face_score, p.face_quality = (float(v) for v in rng.choice([0.9, math.nan, -1.0], 2))
            msg.people.append(p)
        return msg

    sent = calls = 0
    for k in range(args.messages):
        kind = k % 10
        if kind < 4:
            plain.publish(frame())
        elif kind < 7:
            sealed_pub.publish(seal_message(forger, frame()))
        elif kind == 7:
            junk = Sealed(sender_id=text(int(rng.integers(0, 40))), counter=int(rng.integers(0, 1 << 62)),
                          nonce=rng.integers(0, 256, int(rng.choice([0, 12, 40]))).astype(np.uint8).tobytes(),
                          ciphertext=rng.integers(0, 256, int(rng.integers(0, 3000))).astype(np.uint8).tobytes())
            sealed_pub.publish(junk)
        elif kind == 8 and overheard:
            sealed_pub.publish(overheard[int(rng.integers(0, len(overheard)))])  # a replay
        else:
            if k % 50 == 9:  # admin calls, without waiting for the answers
                request = AddPerson.Request(name=text(int(rng.integers(0, 100))),
                                            embeddings=rng.normal(0, 1, 128).astype(np.float32).tolist(),
                                            image_paths=["/etc/shadow", "/dev/zero"])
                add.call_async(request if k % 100 == 9 else seal_request(forger, request, "/face_reid_master"))
                forget.call_async(ForgetFace.Request(face_id=1))
                calls += 2
            else:
                plain.publish(frame())
        sent += 1
        if k % 20 == 0:
            rclpy.spin_once(node, timeout_sec=0.0)
    print(json.dumps({"sent": sent, "calls": calls}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
