"""The camera node's parameters: one table (name, default, description with units).

The node declares exactly these (with the descriptions as ParameterDescriptors), the replay
tool reads the same YAML, and ``config/camera.yaml`` holds the defaults (a test keeps the three
in agreement). Pure Python: no rclpy.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from face_reid_camera.camera_model import CameraPose
from face_reid_camera.common.param_table import ParamSpec, ParamTable, ParamValue
from face_reid_camera.people.detector import PERSON_PARAM_DESCRIPTIONS, PersonDetectorConfig
from face_reid_camera.pipeline import CameraPipelineConfig, FaceQualityConfig

NODE_NAME = "face_reid_camera"


_PERSON_DEFAULTS = PersonDetectorConfig()


def _person_specs() -> list[ParamSpec]:
    specs = []
    for f in dataclasses.fields(PersonDetectorConfig):
        value = getattr(_PERSON_DEFAULTS, f.name)
        if not isinstance(value, bool | int | float | str):
            continue
        specs.append(ParamSpec(f"person.{f.name}", value, PERSON_PARAM_DESCRIPTIONS[f.name]))
    return specs


_Q = FaceQualityConfig()
_P = CameraPipelineConfig()

CAMERA_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("camera_id", "camera", "Unique id of this camera, sent in every message (string)."),
    ParamSpec("world_frame_id", "world", "Frame id of the shared world frame (z up, floor z = 0)."),
    ParamSpec("camera_frame_id", "", "Optical frame id of this camera; empty = take it from CameraInfo."),
    ParamSpec("camera_pose_xyz_m", [0.0, 0.0, 2.5], "Camera position in the world frame [x, y, z] (m)."),
    ParamSpec(
        "camera_pose_rpy_rad", [0.0, 0.35, 0.0],
        "Camera body orientation [roll, pitch, yaw] in the world frame (rad; body x forward, z up; "
        "pitch > 0 looks down).",
    ),
    ParamSpec("seed_ground_from_pose", True, "Use the configured pose to seed the floor-plane RANSAC (bool)."),
    ParamSpec("color_topic", "color/image_raw", "Colour image topic (sensor_msgs/Image: bgr8, rgb8, mono8...)."),
    ParamSpec(
        "depth_topic", "depth_registered/image_raw",
        "Depth image registered to colour (sensor_msgs/Image: 16UC1 mm or 32FC1 m).",
    ),
    ParamSpec("camera_info_topic", "color/camera_info", "CameraInfo of the registered depth/colour images."),
    ParamSpec("output_topic", "face_reid/frames", "Where face_reid_msgs/CameraFrame messages are published."),
    ParamSpec(
        "image_qos_reliable", False,
        "Subscribe to images with RELIABLE QoS (true) or BEST_EFFORT (false, matches any publisher).",
    ),
    ParamSpec("sync_slop_s", 0.02, "Max stamp difference between a colour and a depth image of one pair (s)."),
    ParamSpec("max_frame_age_s", 0.5, "Drop pairs older than this when processing starts (s; 0 = never)."),
    ParamSpec("detect_faces", True, "Run face detection and embedding (false = people positions only)."),
    ParamSpec("head_roi_size_m", _P.head_roi_size_m, "Side of the metric square around each head (m)."),
    ParamSpec("face_score_threshold", 0.6, "Minimum face detector score (0..1)."),
    ParamSpec("face_nms_iou_threshold", 0.3, "Non-maximum suppression overlap of face boxes (IoU, 0..1)."),
    ParamSpec("face_roi_input_px", 96, "Head ROIs are resized to this square size for the detector (px)."),
    ParamSpec("max_faces_per_frame", _P.max_faces_per_frame, "Faces embedded per frame, nearest first."),
    ParamSpec("min_face_quality", _P.min_face_quality, "Faces below this quality (0..1) are not embedded."),
    ParamSpec("min_eye_distance_px", _Q.min_eye_distance_px, "Quality is 0 at this eye distance (px)."),
    ParamSpec("good_eye_distance_px", _Q.good_eye_distance_px, "Quality size factor is 1 from here (px)."),
    ParamSpec("max_face_yaw_deg", _Q.max_yaw_deg, "Quality frontality factor reaches 0 at this yaw (deg)."),
    ParamSpec("position_std_base_m", _P.position_std_base_m, "Position uncertainty at 0 m range (m)."),
    ParamSpec("position_std_per_m2", _P.position_std_per_m2, "Uncertainty growth with range squared (m/m^2)."),
    ParamSpec("num_threads", 1, "onnxruntime intra-op threads per model (count)."),
    ParamSpec("detector_model_path", "", "YuNet ONNX file; empty = the installed default model."),
    ParamSpec("embedder_model_path", "", "Embedder ONNX file; empty = the installed default model."),
    *_person_specs(),
)

TABLE = ParamTable(NODE_NAME, CAMERA_PARAMS, "the face-reid camera node (face-reid-camera / face-reid-replay)")
USAGE = "face-reid-camera --ros-args --params-file config/camera.yaml"


def defaults() -> dict[str, ParamValue]:
    """All parameters at their default values."""
    return TABLE.defaults()


def load_params_yaml(path: str | Path) -> dict[str, ParamValue]:
    """Read a ROS 2 params file over the defaults (nested keys flattened with dots)."""
    return TABLE.load_yaml(path)


def check_value(name: str, value: Any) -> ParamValue:
    """Validate one parameter value against its declared default's type."""
    return TABLE.check_value(name, value)


def camera_pose(params: dict[str, ParamValue]) -> CameraPose:
    """The configured camera extrinsics (world <- optical frame)."""
    x, y, z = params["camera_pose_xyz_m"]  # type: ignore[misc]
    roll, pitch, yaw = params["camera_pose_rpy_rad"]  # type: ignore[misc]
    return CameraPose.from_xyz_rpy(x, y, z, roll, pitch, yaw)


def pipeline_config(params: dict[str, ParamValue]) -> CameraPipelineConfig:
    """Build the (validated) pipeline configuration from flat parameters."""
    person_kwargs = {
        f.name: params[f"person.{f.name}"] for f in dataclasses.fields(PersonDetectorConfig)
        if f"person.{f.name}" in params
    }
    return CameraPipelineConfig(
        camera_id=str(params["camera_id"]),
        head_roi_size_m=float(params["head_roi_size_m"]),  # type: ignore[arg-type]
        detect_faces=bool(params["detect_faces"]),
        max_faces_per_frame=int(params["max_faces_per_frame"]),  # type: ignore[arg-type]
        min_face_quality=float(params["min_face_quality"]),  # type: ignore[arg-type]
        position_std_base_m=float(params["position_std_base_m"]),  # type: ignore[arg-type]
        position_std_per_m2=float(params["position_std_per_m2"]),  # type: ignore[arg-type]
        person=PersonDetectorConfig(**person_kwargs),
        quality=FaceQualityConfig(
            min_eye_distance_px=float(params["min_eye_distance_px"]),  # type: ignore[arg-type]
            good_eye_distance_px=float(params["good_eye_distance_px"]),  # type: ignore[arg-type]
            max_yaw_deg=float(params["max_face_yaw_deg"]),  # type: ignore[arg-type]
        ),
    )


def write_defaults_yaml(path: str | Path) -> None:
    """Write ``config/camera.yaml`` with every parameter at its default (comments = descriptions)."""
    TABLE.write_yaml(path, USAGE)
