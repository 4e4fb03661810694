"""Test helper process: publish face_reid_msgs/CameraFrame messages of one camera following a plan.

Usage: python test/ros_procs/publish_camera_frames.py --camera-id C --topic T --plan PLAN.json
PLAN.json: {"rate_hz": 10, "embeddings": "E.npz", "segments": [{"t0": 0, "t1": 4, "people": [
  {"x": 0, "y": 0, "vx": 0.5, "vy": 0, "identity": "a", "photos": [0, 1, 2]}]}]}
Times are seconds after the first subscriber matched; E.npz holds identity -> (n, 128) embeddings;
"embedding_space" (optional) names their space in every message (default "": a camera from before
spaces were named, taken as dlib_resnet_v1). A person with "body": {"descriptor": [...], "space": "...",
"visible": 0.9} also sends body fields (a camera that describes bodies); without it, none (an older camera).
Stamps are the publisher's clock (the master checks them against its own).
With --barrier-dir D --barrier-count N, N publishers start their plans together: each marks itself
ready in D once its subscriber matched and all start at the same wall-clock time (so plans of
different cameras stay aligned however slowly each process started).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--camera-id", required=True)
    parser.add_argument("--topic", required=True)
    parser.add_argument("--plan", required=True)
    parser.add_argument("--wait-s", type=float, default=30.0)
    parser.add_argument("--barrier-dir", default="")
    parser.add_argument("--barrier-count", type=int, default=1)
    args = parser.parse_args()
    with open(args.plan, encoding="utf-8") as fh:
        plan = json.load(fh)
    embeddings = dict(np.load(plan["embeddings"]))

    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from face_reid_msgs.msg import CameraFrame, PersonObservation

    rclpy.init()
    node = rclpy.create_node(f"fake_camera_{args.camera_id}")
    qos = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(CameraFrame, args.topic, qos)
    deadline = time.monotonic() + args.wait_s
    while pub.get_subscription_count() == 0:
        if time.monotonic() > deadline:
            print(json.dumps({"error": "no subscriber"}), flush=True)
            return 1
        rclpy.spin_once(node, timeout_sec=0.05)
    start = time.monotonic() + float(plan.get("start_delay_s", 1.0))
    if args.barrier_dir:
        start = _barrier(Path(args.barrier_dir), args.camera_id, args.barrier_count, deadline, node)
        if start is None:
            print(json.dumps({"error": "barrier timeout"}), flush=True)
            return 1
        start += float(plan.get("start_delay_s", 1.0))
    end = max(seg["t1"] for seg in plan["segments"])
    period = 1.0 / float(plan.get("rate_hz", 10.0))
    k = 0
    while True:
        t = k * period
        if t > end:
            break
        time.sleep(max(0.0, start + t - time.monotonic()))
        msg = CameraFrame()
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.header.frame_id = "world"
        msg.camera_id = args.camera_id
        for seg in plan["segments"]:
            if not seg["t0"] <= t < seg["t1"]:
                continue
            for p in seg["people"]:
                obs = PersonObservation()
                dt = t - seg["t0"]
                obs.position_world.x = float(p["x"] + p.get("vx", 0.0) * dt)
                obs.position_world.y = float(p["y"] + p.get("vy", 0.0) * dt)
                obs.position_std_m, obs.height_m = 0.05, 1.75
                photos = p.get("photos") or []
                if photos:
                    emb = embeddings[p["identity"]][photos[k % len(photos)]]
                    obs.face_found, obs.face_score, obs.face_quality = True, 0.9, 0.8
                    obs.embedding = emb.astype(np.float32).tolist()
                    obs.embedding_space = plan.get("embedding_space", "")  # "": a camera from before spaces
                body = p.get("body")
                if body:
                    obs.body_descriptor = [float(v) for v in body["descriptor"]]
                    obs.body_descriptor_space = str(body["space"])
                    obs.body_visible_fraction = float(body.get("visible", 1.0))
                    obs.body_part_visible = [1.0, 1.0, 1.0, 1.0]
                    obs.body_head_height_m, obs.body_shoulder_width_m = 0.25, 0.42
                    obs.body_torso_width_m, obs.body_torso_depth_m, obs.body_hip_width_m = 0.38, 0.15, float("nan")
                msg.people.append(obs)
        pub.publish(msg)
        k += 1
    time.sleep(0.5)
    print(json.dumps({"published": k}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def _barrier(folder: Path, name: str, count: int, deadline: float, node: object) -> float | None:
    """Mark ``name`` ready in ``folder``; wait for ``count`` marks; return the common start (monotonic)."""
    import rclpy

    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.ready").write_text(repr(time.time()))
    while True:
        marks = list(folder.glob("*.ready"))
        if len(marks) >= count:
            try:
                last_wall = max(float(m.read_text() or "nan") for m in marks)
            except ValueError:  # a mark being written right now
                last_wall = float("nan")
            if last_wall == last_wall:
                return time.monotonic() + max(0.0, last_wall - time.time())
        if time.monotonic() > deadline:
            return None
        rclpy.spin_once(node, timeout_sec=0.05)


if __name__ == "__main__":
    sys.exit(main())
