"""face-reid-replay: run the camera pipeline over recorded frames, one JSON line per frame.

Input: a folder (or single files) of ``*_rgb.png`` + ``*_depth_mm.png`` pairs (16-bit depth in
millimetres, registered to colour), organized ``.pcd`` clouds (ascii, binary or binary_compressed; XYZ
only, so people only) and/or recordings of a camera driver's topics (rosbag2 / MCAP / ROS 1 bag;
``bag_frames.py``). Users check their camera placement with it:
every detected person is printed with world/camera position, height, head ROI and face.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.errors import ModelLoadError
from face_reid_camera.common.params_files import load_params_file, read_yaml_file
from face_reid_camera.people.detector import MIN_FLOOR_SUPPORT
from face_reid_camera.pipeline import CameraPipeline, FrameResult
from face_reid_camera.ros import params as camera_params
from face_reid_camera.tools.bag_frames import BagTopics, bag_frames, is_bag
from face_reid_camera.tools.pcd_io import intrinsics_from_organized_cloud, read_pcd


@dataclass
class ReplayFrame:
    """One recorded frame: depth in metres (NaN invalid) and optional BGR colour."""

    name: str
    depth_m: NDArray[np.float32]
    color_bgr: NDArray[np.uint8] | None
    intrinsics_hint: CameraIntrinsics | None = None


def parse_intrinsics_yaml(path: Path) -> CameraIntrinsics:
    """Intrinsics from a YAML with fx, fy, cx, cy, width, height keys, or a ROS camera_info YAML."""
    doc = read_yaml_file(path, "intrinsics file") or {}  # one line when missing or not YAML
    if not isinstance(doc, dict):
        raise ValueError(f"intrinsics file {path}: a mapping (fx, fy, cx, cy, width, height, or a camera_info)")
    if "camera_matrix" in doc:
        k = doc["camera_matrix"]["data"]
        return CameraIntrinsics(k[0], k[4], k[2], k[5], int(doc["image_width"]), int(doc["image_height"]))
    if "k" in doc:
        k = doc["k"]
        return CameraIntrinsics(k[0], k[4], k[2], k[5], int(doc["width"]), int(doc["height"]))
    try:
        return CameraIntrinsics(
            float(doc["fx"]), float(doc["fy"]), float(doc["cx"]), float(doc["cy"]), int(doc["width"]),
            int(doc["height"]),
        )
    except KeyError as exc:
        raise ValueError(f"{path}: intrinsics YAML needs fx, fy, cx, cy, width, height (missing {exc})") from exc


def list_frame_files(inputs: list[Path]) -> list[Path]:
    """The frame files named by ``inputs`` (folders expanded, name order); missing paths raise."""
    files: list[Path] = []
    for path in inputs:
        if path.is_dir():
            if is_bag(path):
                files.append(path)
                continue
            files.extend(sorted(p for p in path.iterdir() if p.name.endswith(("_depth_mm.png", ".pcd"))
                                or (p.is_file() and is_bag(p))))
        elif path.exists():
            files.append(path)
        else:
            raise FileNotFoundError(f"no such file or folder: {path}")
    return files


def _frames(files: list[Path], topics: BagTopics, errors: list[str]) -> Iterator[ReplayFrame | None]:
    """Every frame of the inputs (None for one that could not be read, after saying why on stderr)."""
    for path in files:
        if is_bag(path):
            try:
                yield from bag_frames(path, topics)
            except Exception as exc:  # rosbags raises its own errors for damaged recordings
                errors.append(str(path))
                print(f"face-reid-replay: recording {path}: {type(exc).__name__}: {exc}", file=sys.stderr)
                yield None
            continue
        try:
            yield load_frame(path)
        except (ValueError, OSError) as exc:
            errors.append(str(path))
            print(f"face-reid-replay: skipped {path.name}: {exc}", file=sys.stderr)
            yield None


def load_frame(path: Path) -> ReplayFrame:
    """Read one frame (a *_depth_mm.png with its *_rgb.png, or an organized .pcd); ValueError if unusable."""
    if path.suffix == ".pcd":
        xyz = read_pcd(path)
        if xyz.ndim != 3 or xyz.shape[0] < 2:
            raise ValueError(f"{path}: only organized point clouds (height > 1) can be replayed")
        depth = np.ascontiguousarray(xyz[:, :, 2], dtype=np.float32)
        return ReplayFrame(path.name, depth, None, intrinsics_from_organized_cloud(xyz))
    if not path.name.endswith("_depth_mm.png"):
        raise ValueError(f"{path}: expected *_depth_mm.png or *.pcd")
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16 or raw.ndim != 2:
        raise ValueError(f"{path}: not a 16-bit single-channel PNG (depth in mm)")
    depth = raw.astype(np.float32) * np.float32(0.001)
    depth[raw == 0] = np.nan
    rgb_path = path.with_name(path.name[: -len("_depth_mm.png")] + "_rgb.png")
    color = cv2.imread(str(rgb_path), cv2.IMREAD_COLOR) if rgb_path.exists() else None
    if rgb_path.exists() and color is None:
        raise ValueError(f"{rgb_path}: unreadable colour image")
    return ReplayFrame(path.name[: -len("_depth_mm.png")], depth, color)


def _floor_summary(result: FrameResult, seeded: bool) -> dict[str, object] | None:
    """Camera height and downward tilt implied by the floor plane (how users check placement), the share of the
    points on it when it was estimated in this frame, and whether it is doubtful (:func:`floor_doubt`)."""
    plane = result.ground_plane
    if plane is None:
        return None
    support = result.ground_support
    return {
        "source": result.ground_plane_source,
        "camera_height_m": round(float(plane.offset), 3),
        "camera_tilt_down_deg": round(plane.tilt_down_deg, 1),
        "support": None if support is None else round(support, 3),
        "doubtful": floor_doubt(result, seeded) is not None,
    }


def floor_doubt(result: FrameResult, seeded: bool) -> str | None:
    """Why a floor found without a camera pose cannot be trusted (too few of the points on it: no floor in view,
    the pose check's own rule), or None. A floor found near a given pose has the pose check instead."""
    plane, support = result.ground_plane, result.ground_support
    if seeded or plane is None or support is None or support >= MIN_FLOOR_SUPPORT:
        return None
    return (f"the floor found without a camera pose (camera {plane.offset:.2f} m above it, tilted "
            f"{plane.tilt_down_deg:.1f} deg down) holds only {100 * support:.0f}% of the points (a floor in view: "
            f"{100 * MIN_FLOOR_SUPPORT:.0f}% or more): the view shows no floor, so heights and positions are "
            "guesses; give the camera's pose: --camera-pose X Y Z ROLL PITCH YAW --trust-pose-floor")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="face-reid-replay",
        description="Run the face-reid camera pipeline over recorded RGB-D frames; one JSON line per frame.",
    )
    parser.add_argument("inputs", nargs="+", type=Path,
                        help="folders or files (*_depth_mm.png with *_rgb.png, *.pcd) or recordings of the driver's "
                             "topics (a rosbag2 folder, .mcap, .db3, ROS 1 .bag)")
    parser.add_argument("--intrinsics", nargs=4, type=float, metavar=("FX", "FY", "CX", "CY"),
                        help="pinhole intrinsics in pixels (default: from --intrinsics-yaml, the PCD, or Kinect)")
    parser.add_argument("--intrinsics-yaml", type=Path, help="YAML with fx fy cx cy width height, or camera_info")
    parser.add_argument("--params", type=Path, help="camera node params YAML (default: built-in defaults)")
    parser.add_argument("--camera-pose", nargs=6, type=float, metavar=("X", "Y", "Z", "ROLL", "PITCH", "YAW"),
                        help="camera pose in the world (m, rad); seeds the floor search. Without it (and "
                             "without --params) the floor is found unseeded and world = camera pose 0")
    parser.add_argument("--color-topic", default="", help="recordings: the colour Image topic (default: found by type)")
    parser.add_argument("--depth-topic", default="", help="recordings: the registered depth Image topic")
    parser.add_argument("--info-topic", default="", help="recordings: the depth image's CameraInfo topic")
    parser.add_argument("--trust-pose-floor", action="store_true",
                        help="detect people on the given pose's floor when the data shows none (e.g. a cloud "
                             "without floor; by default such frames report nobody: a wrong pose would invent people)")
    parser.add_argument("--no-faces", action="store_true", help="people only (no face models needed)")
    parser.add_argument("--no-bodies", action="store_true", help="no body description (no projection needed)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        values = camera_params.defaults()
        if args.params:  # the node's own rules (one loader): what the camera node refuses, replay refuses
            loaded = load_params_file(camera_params.TABLE, args.params)
            for warning in loaded.warnings:
                print(f"face-reid-replay: warning: {warning}", file=sys.stderr)
            values = loaded.values
        if args.no_faces:
            values["detect_faces"] = False
        if args.no_bodies:
            values["describe_bodies"] = False
        if args.trust_pose_floor:
            values["person.people_on_pose_floor"] = True
        config = camera_params.pipeline_config(values)
        seeded = args.params is not None or args.camera_pose is not None
        pose = (
            CameraPose.from_xyz_rpy(*args.camera_pose) if args.camera_pose
            else camera_params.camera_pose(values) if args.params else CameraPose()
        )
        fixed_intr: CameraIntrinsics | None = None
        if args.intrinsics_yaml:
            fixed_intr = parse_intrinsics_yaml(args.intrinsics_yaml)
        detector = embedder = None
        if config.detect_faces:
            from face_reid_camera.faces.detector import YuNetDetector
            from face_reid_camera.faces.embedder import load_embedder

            detector = YuNetDetector(
                values["detector_model_path"] or None,  # type: ignore[arg-type]
                score_threshold=float(values["face_score_threshold"]),  # type: ignore[arg-type]
                nms_iou_threshold=float(values["face_nms_iou_threshold"]),  # type: ignore[arg-type]
                roi_input_size_px=int(values["face_roi_input_px"]),  # type: ignore[arg-type]
            )
            embedder = load_embedder(str(values["embedder"]), 1, {
                "dlib": str(values["dlib_model_path"]), "sface": str(values["sface_model_path"])})
        projection = None
        if config.describe_bodies:
            from face_reid_camera.body.projection import load_body_projection

            projection = load_body_projection(str(values["body_projection_path"]))
        pipeline = CameraPipeline(config, pose, detector, embedder, seed_ground_from_pose=seeded,
                                  body_projection=projection)
    except (ValueError, FileNotFoundError, ModelLoadError, OSError) as exc:
        print(f"face-reid-replay: error: {exc}", file=sys.stderr)
        return 2

    frames = errors = people_total = 0
    errors_seen: list[str] = []
    last_check = None
    doubts: list[str] = []
    on_pose_floor_only = 0  # frames whose only floor was the given pose's (nobody reported unless trusted)
    try:
        files = list_frame_files(args.inputs)
    except FileNotFoundError as exc:
        print(f"face-reid-replay: error: {exc}", file=sys.stderr)
        return 2
    for frame in _frames(files, BagTopics(args.color_topic, args.depth_topic, args.info_topic), errors_seen):
        if frame is None:
            errors += 1
            continue
        h, w = frame.depth_m.shape
        if args.intrinsics:
            fx, fy, cx, cy = args.intrinsics
            intr = CameraIntrinsics(fx, fy, cx, cy, w, h)
        elif fixed_intr is not None:
            intr = fixed_intr
        else:
            intr = frame.intrinsics_hint or CameraIntrinsics.kinect_default(w, h)
        try:
            result = pipeline.process(frame.color_bgr, frame.depth_m, intr)
        except ValueError as exc:
            errors += 1
            print(f"face-reid-replay: skipped {frame.name}: {exc}", file=sys.stderr)
            continue
        frames += 1
        people_total += len(result.people)
        last_check = result.floor_check or last_check
        doubt = floor_doubt(result, seeded)
        if doubt is not None:
            doubts.append(doubt)
        on_pose_floor_only += int(result.ground_plane_source == "pose" and not result.ground_plane_found)
        line = {
            "frame": frame.name,
            "ground_plane_found": result.ground_plane_found,
            "floor": _floor_summary(result, seeded),
            "pose_check": None if result.floor_check is None else {
                "agrees": result.floor_check.agrees, "pose_camera_height_m": round(result.floor_check.pose_height_m, 3),
                "floor_camera_height_m": round(result.floor_check.floor_height_m, 3),
                "pose_tilt_down_deg": round(result.floor_check.pose_tilt_deg, 1),
                "floor_tilt_down_deg": round(result.floor_check.floor_tilt_deg, 1)},
            "num_people": len(result.people),
            "num_faces": result.num_faces,
            "people": [p.to_json() for p in result.people],
            "timings_ms": {k: round(v, 2) for k, v in result.timings_ms.items()},
        }
        print(json.dumps(line), flush=True)
    print(f"face-reid-replay: {frames} frames, {people_total} detections, {errors} skipped, "
          f"{pipeline.thin_support_rejected} person-shaped clusters on a thin support (coat stands) rejected",
          file=sys.stderr)
    if last_check is not None:
        print(f"face-reid-replay: {last_check.describe()}", file=sys.stderr)
    if on_pose_floor_only and last_check is None:
        print(f"face-reid-replay: {on_pose_floor_only} of {frames} frames show no floor near the given pose: nobody "
              "is reported on them (if the view has no floor, add --trust-pose-floor)", file=sys.stderr)
    if doubts:
        print(f"face-reid-replay: warning: {len(doubts)} of {frames} frames: {doubts[-1]}", file=sys.stderr)
    if frames == 0:
        print("face-reid-replay: no frame could be read: give folders or files of *_depth_mm.png (16-bit depth in "
              "mm, with *_rgb.png colour) or *.pcd clouds", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
