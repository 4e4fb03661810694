"""face-reid-calibrate: every camera's x, y, yaw in one world frame from one person walking for a minute.

    face-reid-calibrate record --seconds 60 --out walk.jsonl     # the camera nodes running, one person walking
    face-reid-calibrate solve walk.jsonl --anchor cam1 --out-dir poses/

``record`` listens to every camera topic (CameraFrame, or sealed frames with ``--key``) and writes one JSON
line per frame: camera id, stamp, the camera's configured pose, the people's floor positions. ``solve`` finds,
with the anchor camera's pose kept, the x, y, yaw of every other camera whose view overlaps the anchor's or
another solved camera's (face_reid_master/training/walk_calibration.py), prints the correction and the RMS
residual per camera and writes ``<out-dir>/<camera>.yaml`` (a params file with camera_id, camera_pose_xyz_m and
camera_pose_rpy_rad; height, roll and pitch are copied from the pose the camera was configured with). Each
camera's height, roll and pitch must be right first (the camera node measures the floor; ``face-reid-replay``
prints it).

Exit status: 0 all cameras solved, 1 some could not be linked to the anchor, 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from face_reid_camera.camera_model import CameraPose
from face_reid_master.training.walk_calibration import CameraTrack, calibrate_cameras

DEFAULT_TOPIC_REGEX = r"^(/.*)?/face_reid/frames(_sealed)?$"


def _frame_line(msg: Any) -> dict[str, Any]:
    from face_reid_camera.common.stamps import stamp_to_seconds

    p, q = msg.camera_pose.position, msg.camera_pose.orientation
    return {"camera_id": str(msg.camera_id), "stamp": stamp_to_seconds(msg.header.stamp),
            "pose": [p.x, p.y, p.z, q.x, q.y, q.z, q.w],
            "people": [[o.position_world.x, o.position_world.y] for o in msg.people]}


def record(out: Path, seconds: float, topic_regex: str, key_path: str, max_frames: int) -> int:
    """Write the frames of every camera topic for ``seconds`` (or ``max_frames``) to ``out`` (JSON lines)."""
    if not out.parent.is_dir():
        raise ValueError(f"--out: folder {out.parent} not found")
    import rclpy

    from face_reid_msgs.msg import CameraFrame, Sealed

    opener = None
    if key_path:
        from face_reid_camera.common.ros.sealed import open_message
        from face_reid_camera.common.sealing import Opener, SealError, load_network_key

        opener = Opener(load_network_key(key_path))
    regex = re.compile(topic_regex)
    rclpy.init()
    node = rclpy.create_node("face_reid_calibrate_recorder")
    written = [0]
    refused = [0]
    subscribed: set[str] = set()
    passed_over: set[str] = set()  # camera topics of the other kind (sealed without --key, or plain with it)
    with open(out, "w") as f:
        def write(msg: Any) -> None:
            f.write(json.dumps(_frame_line(msg)) + "\n")
            written[0] += 1

        def on_sealed(sealed: Any) -> None:
            assert opener is not None
            try:
                write(open_message(opener, sealed, CameraFrame))
            except SealError:
                refused[0] += 1

        end = time.monotonic() + seconds
        next_look = 0.0
        try:
            while time.monotonic() < end and written[0] < max_frames:
                if time.monotonic() >= next_look:
                    next_look = time.monotonic() + 0.5
                    for name, types in node.get_topic_names_and_types():
                        if name in subscribed or not regex.search(name):
                            continue
                        if "face_reid_msgs/msg/CameraFrame" in types and opener is None:
                            node.create_subscription(CameraFrame, name, write, 50)
                        elif "face_reid_msgs/msg/Sealed" in types and opener is not None:
                            node.create_subscription(Sealed, name, on_sealed, 50)
                        else:
                            passed_over.add(name)
                            continue
                        subscribed.add(name)
                        print(f"recording {name}", file=sys.stderr, flush=True)
                rclpy.spin_once(node, timeout_sec=0.05)
        except KeyboardInterrupt:
            pass
        finally:
            node.destroy_node()
            rclpy.try_shutdown()
    print(record_summary(out, written[0], len(subscribed), refused[0], len(passed_over - subscribed),
                         bool(opener)), file=sys.stderr)
    return 0 if written[0] else 2


def record_summary(out: Path, frames: int, topics: int, refused: int, passed_over: int, keyed: bool) -> str:
    """The closing line of ``record``; with no frame, where to look (the domain, the key, the cameras)."""
    line = f"wrote {frames} frames of {topics} camera topics to {out}"
    if refused:
        line += f"; {refused} sealed frames did not open with the key (is --key the network's key?)"
    if frames:
        return line
    if passed_over:
        other = "sealed: give --key with the network's key" if not keyed else "unsealed: leave out --key"
        return f"{line}: the {passed_over} camera topic(s) heard are {other}"
    domain = os.environ.get("ROS_DOMAIN_ID", "") or "0, unset"
    return (f"{line}: no camera heard; check that the camera nodes run (and see a person), that ROS_DOMAIN_ID "
            f"(here {domain}) is theirs, and that --key is given exactly when the network has a network key")


def load_recording(path: Path) -> tuple[list[CameraTrack], dict[str, CameraPose]]:
    """Per camera: the walker's track (one detection per frame: the one nearest the previous one) and its
    configured pose (the last one recorded)."""
    stamps: dict[str, list[float]] = {}
    points: dict[str, list[list[float]]] = {}
    poses: dict[str, CameraPose] = {}
    bad = 0
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ValueError(f"recording {path} not found (make one with: face-reid-calibrate record --out "
                         f"{path})") from None
    except OSError as exc:
        raise ValueError(f"recording {path}: cannot read it ({exc.strerror})") from None
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
            cam, stamp = str(rec["camera_id"]), float(rec["stamp"])
            x, y, z, qx, qy, qz, qw = (float(v) for v in rec["pose"])
            people = [(float(p[0]), float(p[1])) for p in rec["people"]]
            pose = CameraPose.from_position_quaternion((x, y, z), (qx, qy, qz, qw))
        except (ValueError, KeyError, TypeError, IndexError):
            bad += 1
            if bad <= 3:
                print(f"{path}:{n}: not a recorded frame, skipped", file=sys.stderr)
            continue
        poses[cam] = pose
        people = [p for p in people if math.isfinite(p[0]) and math.isfinite(p[1])]
        if not people:
            continue
        prev = points.get(cam)
        if prev:
            last = np.array(prev[-1])
            pick = min(people, key=lambda p: float(np.hypot(p[0] - last[0], p[1] - last[1])))
        else:
            pick = people[0]
        stamps.setdefault(cam, []).append(stamp)
        points.setdefault(cam, []).append(list(pick))
    tracks = [CameraTrack(cam, np.array(stamps[cam]), np.array(points[cam])) for cam in sorted(stamps)]
    return tracks, poses


def _params_yaml(camera_id: str, xyz_rpy: tuple[float, ...], note: str) -> str:
    x, y, z, roll, pitch, yaw = xyz_rpy
    return (f"# face-reid-calibrate: camera {camera_id}; {note}\n"
            "/**:\n  ros__parameters:\n"
            f"    camera_id: {json.dumps(camera_id)}\n"
            f"    camera_pose_xyz_m: [{x:.4f}, {y:.4f}, {z:.4f}]\n"
            f"    camera_pose_rpy_rad: [{roll:.5f}, {pitch:.5f}, {yaw:.5f}]\n")


def solve(path: Path, anchor: str, out_dir: Path | None, min_pairs: int, threshold_m: float) -> int:
    tracks, poses = load_recording(path)
    if not tracks:
        print(f"face-reid-calibrate: {path} holds no detections (was someone walking in view?)", file=sys.stderr)
        return 2
    ids = [t.camera_id for t in tracks]
    if anchor not in ids:
        print(f"face-reid-calibrate: anchor {anchor!r} saw nobody; cameras with detections: {ids}", file=sys.stderr)
        return 2
    result = calibrate_cameras(tracks, anchor, min_pairs=min_pairs, inlier_threshold_m=threshold_m)
    print(f"{'camera':<16} {'dx m':>7} {'dy m':>7} {'dyaw deg':>9} {'residual cm':>12}  x, y, yaw now")
    for cam in ids:
        corr = result.corrections.get(cam)
        if corr is None:
            print(f"{cam:<16} {'-':>7} {'-':>7} {'-':>9} {'-':>12}  not linked: no overlapping view with a solved "
                  "camera (walk where it and another camera both see you)")
            continue
        x, y, z, roll, pitch, yaw = poses[cam].xyz_rpy()
        nx, ny = corr.apply(np.array([[x, y]]))[0]
        nyaw = (yaw + corr.yaw_rad + math.pi) % (2 * math.pi) - math.pi
        print(f"{cam:<16} {nx - x:>7.3f} {ny - y:>7.3f} {math.degrees(nyaw - yaw):>9.2f} "
              f"{100 * result.residual_m[cam]:>12.1f}  {nx:.3f}, {ny:.3f}, {math.degrees(nyaw):.1f} deg")
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            pairs = sum(n for k, n in result.pairs.items() if cam in k)
            note = (f"anchor {anchor}; RMS residual {100 * result.residual_m[cam]:.1f} cm over {pairs} matched "
                    f"positions; recorded {path.name}")
            (out_dir / f"{cam}.yaml").write_text(_params_yaml(cam, (float(nx), float(ny), z, roll, pitch, nyaw),
                                                              note))
    if out_dir is not None:
        print(f"params files in {out_dir}/ (pass one with --params-file to its camera node)", file=sys.stderr)
    return 1 if result.unreached else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="face-reid-calibrate", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="record the camera nodes' frames while one person walks")
    rec.add_argument("--out", type=Path, required=True, help="the recording to write (JSON lines)")
    rec.add_argument("--seconds", type=float, default=60.0, help="how long to record (s; default 60)")
    rec.add_argument("--max-frames", type=int, default=10**9, help="stop after this many frames")
    rec.add_argument("--topic-regex", default=DEFAULT_TOPIC_REGEX,
                     help="record the camera topics matching this (default: every camera's frames topic)")
    rec.add_argument("--key", default="", help="network key file: record sealed frames (secured network)")
    sol = sub.add_parser("solve", help="solve every camera's x, y, yaw from a recording")
    sol.add_argument("recording", type=Path, help="a recording of face-reid-calibrate record")
    sol.add_argument("--anchor", required=True, help="the camera whose pose defines the world frame (kept)")
    sol.add_argument("--out-dir", type=Path, default=None, help="write <camera>.yaml params files here")
    sol.add_argument("--min-pairs", type=int, default=20,
                     help="time-matched positions two cameras need to be linked (default 20)")
    sol.add_argument("--inlier-threshold-m", type=float, default=0.25,
                     help="matched positions further apart are outliers (m; default 0.25)")
    args = parser.parse_args(argv)
    try:
        if args.command == "record":
            return record(args.out, args.seconds, args.topic_regex, args.key, args.max_frames)
        return solve(args.recording, args.anchor, args.out_dir, args.min_pairs, args.inlier_threshold_m)
    except (OSError, ValueError) as exc:
        print(f"face-reid-calibrate: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
