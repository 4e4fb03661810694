"""The master node's parameters: one table (name, default, description with units).

``config/master.yaml`` holds every default (generated from this table; a test keeps them equal).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

from face_reid_camera.common.param_table import ParamSpec, ParamTable, ParamValue
from face_reid_master.core import MasterConfig
from face_reid_master.tracking.tracker import TrackerConfig

NODE_NAME = "face_reid_master"

_M = MasterConfig()
_T = TrackerConfig()

_TRACKER_RANGES: dict[str, dict[str, Any]] = {
    "accel_noise_mps2": dict(low=0.0, high=100.0, low_open=True),
    "init_velocity_std_mps": dict(low=0.0, high=100.0, low_open=True),
    "gate_probability": dict(low=0.0, high=1.0, low_open=True, high_open=True),
    "detections_to_confirm": dict(low=1, high=1000),
    "confirm_window_s": dict(low=0.0, high=3600.0, low_open=True),
    "lost_after_s": dict(low=0.0, high=3600.0, low_open=True),
    "delete_after_s": dict(low=0.0, high=86400.0),
    "max_detection_delay_s": dict(low=0.0, high=60.0),
    "max_future_stamp_s": dict(low=0.0, high=3600.0),
    "clock_resync_frames": dict(low=0, high=100000),
    "max_gate_distance_m": dict(low=0.0, high=math.inf, low_open=True),
    "min_person_separation_m": dict(low=0.0, high=10.0),
    "max_speed_mps": dict(low=0.0, high=100.0),
    "coast_after_s": dict(low=0.0, high=3600.0),
    "camera_window_s": dict(low=0.0, high=3600.0),
    "max_tracks": dict(low=1, high=100000),
}

_TRACKER_DESCRIPTIONS: dict[str, str] = {
    "accel_noise_mps2": "Kalman white-acceleration noise std over 1 s (m/s^2).",
    "init_velocity_std_mps": "Velocity prior std of a new track (m/s).",
    "gate_probability": "Chi-square (2 dof) gate: detections outside this probability are not associated (0..1).",
    "detections_to_confirm": "Detections within confirm_window_s that confirm a new track (count).",
    "confirm_window_s": "A tentative track not confirmed within this time is deleted (s).",
    "lost_after_s": "A confirmed track without detections for this long becomes LOST (s).",
    "delete_after_s": "A LOST track is deleted after this much longer; its face is released (s).",
    "max_detection_delay_s": "Frames up to this much older than the newest are applied in stamp order (s).",
    "max_future_stamp_s": "Frames further ahead of the newest stamp are rejected (s).",
    "clock_resync_frames": "Consecutive rejected frames taken as a clock jump (count; 0 = never).",
    "max_gate_distance_m": "Euclidean gate around a track's predicted position (m).",
    "min_person_separation_m": "Two people are assumed never closer than this (m).",
    "max_speed_mps": "Fastest walking speed assumed when re-gating turning/stopping people (m/s).",
    "coast_after_s": "Confirmed tracks undetected this long get detections after fresh ones (s).",
    "camera_window_s": "A track's cameras are those that detected it within this window (s).",
    "max_tracks": "Cap on live tracks; extra detections are dropped and counted (count).",
}


def _tracker_specs() -> list[ParamSpec]:
    specs = []
    for f in dataclasses.fields(TrackerConfig):
        specs.append(ParamSpec(f"tracker.{f.name}", getattr(_T, f.name), _TRACKER_DESCRIPTIONS[f.name],
                               **_TRACKER_RANGES[f.name]))
    return specs


MASTER_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("autostart", True, "Configure and activate at start (false: wait for a lifecycle manager).",
              read_only=True),
    ParamSpec("world_frame_id", "world", "Frame id of the published tracks (the cameras' shared world frame)."),
    ParamSpec(
        "camera_topics", [""],
        "CameraFrame topics to subscribe to (list; [''] = none fixed, use camera_topic_regex).",
    ),
    ParamSpec(
        "camera_topic_regex", "^(/.*)?/face_reid/frames$",
        "Also subscribe to every discovered topic matching this regex ('' = off).",
    ),
    ParamSpec("topic_discovery_period_s", 2.0, "How often new camera topics are looked for (s).",
              low=0.05, high=3600.0),
    ParamSpec("known_camera_ids", [""], "Accepted camera ids (list; [''] = accept any camera)."),
    ParamSpec("tracks_topic", "/tracks_named", "Where face_reid_msgs/NamedTrackArray is published."),
    ParamSpec(
        "markers_topic", "/tracks_named/markers",
        "visualization_msgs/MarkerArray for RViz, sent only while subscribed ('' = off).",
    ),
    ParamSpec(
        "max_publish_rate_hz", 0.0,
        "Cap on /tracks_named messages per second (0 = one per camera frame; set e.g. 30 for large networks).",
              low=0.0, high=1000.0,
    ),
    ParamSpec("tick_rate_hz", 5.0, "Timeouts are applied and tracks re-published at this rate without frames (Hz).",
              low=0.1, high=1000.0),
    ParamSpec("method", _M.method, "Face classification: 'bayes' (the paper's table) or 'threshold' (baseline).",
              choices=("bayes", "threshold")),
    ParamSpec("max_stamp_age_s", _M.max_stamp_age_s, "Frames older than this vs the master clock are rejected (s).",
              low=0.0, high=86400.0),
    ParamSpec("max_stamp_future_s", _M.max_stamp_future_s, "Frames newer than this vs the clock are rejected (s).",
              low=0.0, high=86400.0),
    ParamSpec("check_stamps_against_clock", True, "Reject stale/future frames using the node clock (bool)."),
    ParamSpec("min_face_quality", _M.min_face_quality, "Embeddings with lower face quality are ignored (0..1).",
              low=0.0, high=1.0),
    ParamSpec("publish_tentative", _M.publish_tentative, "Also publish tracks not confirmed yet (bool)."),
    ParamSpec("posterior_threshold", _M.posterior_threshold, "Assign a face when its posterior exceeds this (0.5..1).",
              low=0.5, high=0.999, high_open=True),
    ParamSpec("prior_probability", _M.prior_probability, "Prior of a new cell of the face table (0..1).",
              low=0.0, high=1.0, low_open=True, high_open=True),
    ParamSpec("min_observations", _M.min_observations, "Face observations needed before a decision (count).",
              low=1, high=1000),
    ParamSpec("new_person_scale_c", _M.new_person_scale_c, "The paper's c: larger = readier to call a face new.",
              low=0.0, high=1e6, low_open=True),
    ParamSpec("max_features_per_face", _M.max_features_per_face, "Embeddings kept per face, a diverse subset (count).",
              low=1, high=10000),
    ParamSpec(
        "learn_only_consistent_features", _M.learn_only_consistent_features,
        "An identified track's embedding joins its face only if within the decision distance (guards "
        "faces against tracker swaps; false = the paper).",
    ),
    ParamSpec("threshold_distance", _M.threshold_distance, "Threshold method: same face below this L2 distance.",
              low=0.0, high=4.0, low_open=True),
    ParamSpec("threshold_votes", _M.threshold_votes, "Threshold method: observations per majority vote (count).",
              low=1, high=1000),
    ParamSpec("name_threshold", _M.name_threshold, "A face gets a predefined name below this L2 distance.",
              low=0.0, high=4.0, low_open=True),
    ParamSpec("min_face_features_for_name", _M.min_face_features_for_name, "Embeddings a face needs before naming.",
              low=1, high=10000),
    ParamSpec("gallery_path", "", "Predefined people: a folder NAME/*.jpg or a .npz gallery ('' = none)."),
    ParamSpec("persist_faces", True, "Keep learned faces in the database across restarts (bool)."),
    ParamSpec("db_path", "", "Face database file ('' = $FACE_REID_DB or ~/.local/share/face_reid/faces.db)."),
    ParamSpec("retention_unnamed_s", 0.0, "Forget unnamed faces not seen for this long (s; 0 = keep forever).",
              low=0.0, high=1e9),
    ParamSpec("save_interval_s", _M.save_interval_s, "Faces with new embeddings are saved at least this often (s).",
              low=0.0, high=86400.0),
    ParamSpec("likelihood_path", "", "Fitted likelihood JSON ('' = the installed models/face_likelihood.json)."),
    ParamSpec("no_input_warning_s", 5.0, "/diagnostics warns when no camera frame arrived for this long (s).",
              low=0.0, high=3600.0, low_open=True),
    ParamSpec("stats_log_period_s", 30.0, "Counters are logged this often (s).", low=0.1, high=86400.0),
    *_tracker_specs(),
)

USAGE = "face-reid-master --ros-args --params-file config/master.yaml"
TABLE = ParamTable(NODE_NAME, MASTER_PARAMS, "the face-reid master node (face-reid-master)", USAGE)


def defaults() -> dict[str, ParamValue]:
    """All parameters at their default values."""
    return TABLE.defaults()


def clean_list(values: list[str]) -> tuple[str, ...]:
    """A string-list parameter without empty entries ([''] is how an empty list is declared)."""
    return tuple(v for v in values if v)


def master_config(params: dict[str, ParamValue]) -> MasterConfig:
    """Build the (validated) core configuration from flat parameters."""
    tracker = TrackerConfig(**{f.name: params[f"tracker.{f.name}"] for f in dataclasses.fields(TrackerConfig)})
    return MasterConfig(
        method=str(params["method"]),
        known_camera_ids=clean_list(params["known_camera_ids"]),  # type: ignore[arg-type]
        max_stamp_age_s=float(params["max_stamp_age_s"]),  # type: ignore[arg-type]
        max_stamp_future_s=float(params["max_stamp_future_s"]),  # type: ignore[arg-type]
        min_face_quality=float(params["min_face_quality"]),  # type: ignore[arg-type]
        publish_tentative=bool(params["publish_tentative"]),
        save_interval_s=float(params["save_interval_s"]),  # type: ignore[arg-type]
        posterior_threshold=float(params["posterior_threshold"]),  # type: ignore[arg-type]
        prior_probability=float(params["prior_probability"]),  # type: ignore[arg-type]
        min_observations=int(params["min_observations"]),  # type: ignore[arg-type]
        new_person_scale_c=float(params["new_person_scale_c"]),  # type: ignore[arg-type]
        max_features_per_face=int(params["max_features_per_face"]),  # type: ignore[arg-type]
        learn_only_consistent_features=bool(params["learn_only_consistent_features"]),
        threshold_distance=float(params["threshold_distance"]),  # type: ignore[arg-type]
        threshold_votes=int(params["threshold_votes"]),  # type: ignore[arg-type]
        name_threshold=float(params["name_threshold"]),  # type: ignore[arg-type]
        min_face_features_for_name=int(params["min_face_features_for_name"]),  # type: ignore[arg-type]
        tracker=tracker,
    )


def write_defaults_yaml(path: str | Path) -> None:
    """Write ``config/master.yaml``."""
    TABLE.write_yaml(path)
