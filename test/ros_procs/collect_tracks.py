"""Test helper process: subscribe to /tracks_named and print one JSON line per message.

Usage: python test/ros_procs/collect_tracks.py --topic /tracks_named --duration-s S [--key KEYFILE]
With --key only tracks sealed with that network key are taken (a secured master's), through the project's
consumer helper (face_reid_master.ros.tracks_in). With --summary it prints {"summary": {"accepted": N,
"refused": {reason: count}}} on exit.
Stops after S seconds or, earlier, on SIGTERM (so a test can stop it once its publishers are done).
With --barrier-dir D it writes D/collector.ready once the topic has a publisher (see
publish_camera_frames.py), so that camera plans start only when the collector listens.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--topic", default="/tracks_named")
    parser.add_argument("--duration-s", type=float, default=30.0)
    parser.add_argument("--barrier-dir", default="")
    parser.add_argument("--key", default="", help="network key file ('' = plain tracks)")
    parser.add_argument("--summary", action="store_true", help="print what was accepted and refused on exit")
    args = parser.parse_args()

    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from face_reid_camera.common.stamps import stamp_to_seconds
    from face_reid_master.ros.tracks_in import subscribe_tracks
    from face_reid_master.tracks_auth import sealed_topic
    from face_reid_msgs.msg import NamedTrackArray

    rclpy.init()
    node = rclpy.create_node("tracks_collector")

    def on_tracks(msg: NamedTrackArray) -> None:
        line = {
            "stamp": stamp_to_seconds(msg.header.stamp),
            "frame_id": msg.header.frame_id,
            "tracks": [
                {"track_id": t.track_id, "face_id": t.face_id, "name": t.name, "state": t.state,
                 "confidence": t.identity_confidence, "evidence": t.identity_evidence,
                 "x": t.position.x, "y": t.position.y,
                 "cameras": list(t.cameras)}
                for t in msg.tracks
            ],
        }
        print(json.dumps(line), flush=True)

    qos = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    tracks = subscribe_tracks(node, on_tracks, args.topic, args.key, qos=qos)
    published = sealed_topic(args.topic) if args.key else args.topic
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    deadline = time.monotonic() + args.duration_s
    ready = not args.barrier_dir
    while time.monotonic() < deadline and not stop:
        rclpy.spin_once(node, timeout_sec=0.1)
        if not ready and node.count_publishers(published) > 0:
            folder = Path(args.barrier_dir)
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "collector.ready").write_text(repr(time.time()))
            ready = True
    if args.summary:
        print(json.dumps({"summary": {"accepted": tracks.accepted, "refused": tracks.refused}}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
