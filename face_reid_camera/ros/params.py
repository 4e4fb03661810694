"""The camera node's parameters: the pipeline's own (declared on its config dataclasses) plus the node's.

``config/camera.yaml`` is generated from :data:`TABLE` (a test keeps them equal); the replay tool reads
the same YAML. Pure Python: no rclpy.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from face_reid_camera.body.person_body import BodyConfig
from face_reid_camera.camera_model import CameraPose
from face_reid_camera.common.param_table import (
    ParamSpec,
    ParamTable,
    ParamValue,
    config_from_values,
    config_specs,
)
from face_reid_camera.people.detector import PersonDetectorConfig
from face_reid_camera.people.floor_occupancy import FloorOccupancyConfig
from face_reid_camera.pipeline import CameraPipelineConfig, FaceQualityConfig

NODE_NAME = "face_reid_camera"
USAGE = "face-reid-camera --ros-args --params-file config/camera.yaml"

_NODE_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("autostart", True, "Configure and activate at start (false: wait for a lifecycle manager).",
              read_only=True),
    ParamSpec("world_frame_id", "world", "Frame id of the shared world frame (z up, floor z = 0)."),
    ParamSpec("camera_frame_id", "", "Optical frame id of this camera; empty = take it from CameraInfo."),
    ParamSpec("camera_pose_xyz_m", [0.0, 0.0, 2.5], "Camera position in the world frame [x, y, z] (m).",
              low=-1000.0, high=1000.0),
    ParamSpec(
        "camera_pose_rpy_rad", [0.0, 0.35, 0.0],
        "Camera body orientation [roll, pitch, yaw] in the world frame (rad; body x forward, z up; "
        "pitch > 0 looks down).", low=-2 * math.pi, high=2 * math.pi,
    ),
    ParamSpec("seed_ground_from_pose", True, "Use the configured pose to seed the floor-plane RANSAC (bool)."),
    ParamSpec("color_topic", "color/image_raw", "Colour image topic (sensor_msgs/Image: bgr8, rgb8, mono8...)."),
    ParamSpec(
        "depth_topic", "depth_registered/image_raw",
        "Depth image registered to colour (sensor_msgs/Image: 16UC1 mm or 32FC1 m).",
    ),
    ParamSpec("camera_info_topic", "color/camera_info", "CameraInfo of the depth image (registered to colour)."),
    ParamSpec(
        "color_camera_info_topic", "",
        "CameraInfo of the colour image when it has its own resolution and intrinsics ('' = depth's, scaled).",
    ),
    ParamSpec("output_topic", "face_reid/frames", "Where face_reid_msgs/CameraFrame messages are published "
              "(unsecured network: no network_key_path)."),
    ParamSpec("network_key_path", "",
              "The camera network's key file from face-reid-keys ('' = unsecured): frames go out sealed on "
              "sealed_output_topic only, lifecycle only through face-reid-state.",
              read_only=True),
    ParamSpec("sealed_output_topic", "face_reid/frames_sealed",
              "Where sealed frames (face_reid_msgs/Sealed) are published when network_key_path is set."),
    ParamSpec(
        "image_qos", "auto",
        "Reliability of the image subscriptions: auto (reliable once every driver publisher offers it), "
        "reliable or best_effort.",
        choices=("auto", "reliable", "best_effort"),
    ),
    ParamSpec("sync_slop_s", 0.02, "Max stamp difference between a colour and a depth image of one pair (s).",
              low=0.0, high=1.0),
    ParamSpec("max_frame_age_s", 0.5, "Drop images stamped longer ago than this on arrival, and pairs older "
              "than this when processing starts (s; 0 = never).",
              low=0.0, high=3600.0),
    ParamSpec("face_score_threshold", 0.6, "Minimum face detector score (0..1).", low=0.0, high=1.0,
              low_open=True),
    ParamSpec("face_nms_iou_threshold", 0.3, "Non-maximum suppression overlap of face boxes (IoU, 0..1).",
              low=0.0, high=1.0, low_open=True),
    ParamSpec("face_roi_input_px", 96, "Head ROIs are resized to this square size for the detector (px, "
              "multiple of 32).", low=32, high=640),
    ParamSpec("num_threads", 1, "onnxruntime intra-op threads per model (count).", low=1, high=64),
    ParamSpec("detector_model_path", "", "YuNet ONNX file; empty = the installed default model."),
    ParamSpec("embedder", "both", "Face embedder network(s): dlib (ResNet v1), sface (OpenCV Zoo SFace) or both "
              "(both run, one 256-value embedding).", choices=("dlib", "sface", "both"), read_only=True),
    ParamSpec("dlib_model_path", "", "dlib embedder ONNX file; empty = the installed default model."),
    ParamSpec("sface_model_path", "", "SFace embedder ONNX file; empty = the installed default model."),
    ParamSpec("body_projection_path", "", "Body descriptor projection (.npz from face-reid-fit-body); empty = the "
              "installed default. Its space goes with every body descriptor: masters compare one space."),
    ParamSpec("no_input_warning_s", 5.0, "/diagnostics warns when no image pair arrived for this long (s).",
              low=0.0, high=3600.0, low_open=True),
)

TABLE = ParamTable(
    NODE_NAME,
    (*config_specs(CameraPipelineConfig), *config_specs(FaceQualityConfig), *_NODE_PARAMS,
     *config_specs(FloorOccupancyConfig, "floor_map_"),
     *config_specs(PersonDetectorConfig, "person."), *config_specs(BodyConfig, "body.")),
    "the face-reid camera node (face-reid-camera / face-reid-replay)", USAGE,
    deployment=("camera_id", "autostart", "world_frame_id", "camera_frame_id", "camera_pose_xyz_m",
                "camera_pose_rpy_rad", "color_topic", "depth_topic", "camera_info_topic", "color_camera_info_topic",
                "image_qos", "sync_slop_s", "output_topic", "network_key_path", "sealed_output_topic", "detect_faces",
                "describe_bodies", "embedder", "num_threads", "embed_budget_ms", "max_faces_per_frame",
                "body_projection_path", "floor_map_period_s", "person.max_depth_m", "person.min_person_height_m"),
)


def defaults() -> dict[str, ParamValue]:
    """All parameters at their default values."""
    return TABLE.defaults()


def load_params_yaml(path: str | Path) -> dict[str, ParamValue]:
    """Read a ROS 2 params file over the defaults (nested keys flattened with dots)."""
    return TABLE.load_yaml(path)


def camera_pose(params: dict[str, Any]) -> CameraPose:
    """The configured camera extrinsics (world <- optical frame)."""
    x, y, z = params["camera_pose_xyz_m"]
    roll, pitch, yaw = params["camera_pose_rpy_rad"]
    return CameraPose.from_xyz_rpy(x, y, z, roll, pitch, yaw)


def pipeline_config(params: dict[str, Any]) -> CameraPipelineConfig:
    """The (validated) pipeline configuration from flat parameters."""
    return config_from_values(
        CameraPipelineConfig, params,
        person=config_from_values(PersonDetectorConfig, params, "person."),
        quality=config_from_values(FaceQualityConfig, params),
        body=config_from_values(BodyConfig, params, "body."),
    )
