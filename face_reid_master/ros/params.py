"""The master node's parameters: the core's own (declared on MasterConfig / TrackerConfig) plus the node's.

``config/master.yaml`` is generated from :data:`TABLE` (a test keeps them equal). Pure Python: no rclpy.
"""

from __future__ import annotations

from typing import Any

from face_reid_camera.common.param_table import (
    ParamSpec,
    ParamTable,
    ParamValue,
    config_from_values,
    config_specs,
)
from face_reid_master.camera_slots import PROBATION_MESSAGES, PROBATION_S, PROBATION_TOPICS
from face_reid_master.core import MasterConfig
from face_reid_master.robot.people_outputs import PeopleOutputConfig
from face_reid_master.tracking.config import TrackerConfig

NODE_NAME = "face_reid_master"
USAGE = "face-reid-master --ros-args --params-file config/master.yaml"

_NODE_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("autostart", True, "Configure and activate at start (false: wait for a lifecycle manager).",
              read_only=True),
    ParamSpec("world_frame_id", "world", "Frame id of the published tracks (the cameras' shared world frame)."),
    ParamSpec("camera_topics", [""],
              "CameraFrame topics to subscribe to (list; [''] = none fixed, use camera_topic_regex)."),
    ParamSpec("camera_topic_regex", "^(/.*)?/face_reid/frames$",
              "Also subscribe to every discovered topic matching this regex ('' = off)."),
    ParamSpec("network_key_path", "",
              "The camera network's key file from face-reid-keys ('' = unsecured): only sealed frames and requests "
              "are accepted, tracks go out sealed, lifecycle only through face-reid-state.",
              read_only=True),
    ParamSpec("sealed_topic_regex", "^(/.*)?/face_reid/frames_sealed$",
              "With a network key: subscribe to every discovered face_reid_msgs/Sealed topic matching this regex."),
    ParamSpec("max_seal_age_s", 30.0,
              "With a network key: a sealed frame or request sealed further than this from the master's clock "
              "is refused (s; replays, senders whose clock is off).", low=0.1, high=86400.0),
    ParamSpec("topic_discovery_period_s", 2.0,
              "How often new camera topics are looked for and unmatched camera publishers checked (s).",
              low=0.05, high=3600.0),
    ParamSpec("known_camera_ids", [""],
              "Accepted camera ids (list; [''] = accept any camera); a discovered camera topic must then be "
              "<namespace>/<a known id>/face_reid/frames[_sealed] (other topics: list them in camera_topics)."),
    ParamSpec("max_camera_topics", 64,
              "At most this many camera topics are subscribed for good (each buffers messages before they are "
              "checked). With a network key a discovered topic takes one only once a message on it opens with the "
              f"key: until then it is on probation (at most {PROBATION_TOPICS} at once; released, and tried again "
              f"later, after {PROBATION_S:g} s or {PROBATION_MESSAGES} messages without one) (count).",
              low=1, high=10_000),
    ParamSpec("tracks_topic", "/tracks_named",
              "Where face_reid_msgs/NamedTrackArray is published (with a network key: sealed, as "
              "face_reid_msgs/Sealed on <tracks_topic>_sealed instead)."),
    ParamSpec("markers_topic", "/tracks_named/markers",
              "visualization_msgs/MarkerArray for RViz, sent only while subscribed ('' = off; none with a network key: "
              "markers are plain)."),
    ParamSpec("max_publish_rate_hz", 30.0,
              "Cap on /tracks_named messages per second (Hz; 0 = one per cycle of frames).",
              low=0.0, high=1000.0),
    ParamSpec("cycle_budget_ms", 25.0,
              "Time one cycle may spend applying frames (ms); frames beyond it are dropped oldest-first and "
              "counted, so that an overloaded master keeps its latency bounded.",
              low=1.0, high=10000.0),
    ParamSpec("min_cycle_period_s", 0.005,
              "A camera message arriving sooner than this after the last cycle began waits, so that one cycle "
              "applies several frames (s; 0 = a cycle per message).", low=0.0, high=0.1),
    ParamSpec("identity_period_s", 0.03,
              "The face table is updated at most once per this period, so names may follow their tracks' "
              "positions by this much (s; 0 = every cycle).",
              low=0.0, high=1.0),
    ParamSpec("tick_rate_hz", 5.0, "Timeouts are applied and tracks re-published at this rate without frames (Hz).",
              low=0.1, high=1000.0),
    ParamSpec("check_stamps_against_clock", True, "Reject stale/future frames using the node clock (bool)."),
    ParamSpec("gallery_path", "", "Predefined people: a folder NAME/*.jpg or a .npz gallery ('' = none)."),
    ParamSpec("admin_services", False,
              "Offer ~/add_person and ~/forget_face (bool; off: any DDS participant could call them).",
              read_only=True),
    ParamSpec("photo_root", "",
              "~/add_person reads photos only from this folder (paths relative to it or inside it once "
              "symlinks are resolved; '' = photo paths refused).", read_only=True),
    ParamSpec("max_photo_bytes", 20_000_000, "~/add_person refuses photo files larger than this (bytes).",
              low=1000, high=1_000_000_000),
    ParamSpec("max_photos_per_request", 32, "~/add_person refuses requests with more photos (count).",
              low=0, high=10000),
    ParamSpec("max_embeddings_per_request", 256, "~/add_person refuses requests with more embeddings (count).",
              low=0, high=100000),
    ParamSpec("persist_faces", True, "Keep learned faces in the database across restarts (bool)."),
    ParamSpec("db_path", "", "Face database file ('' = $FACE_REID_DB or ~/.local/share/face_reid/faces.db)."),
    ParamSpec("retention_unnamed_s", 2_592_000.0,
              "Unnamed faces not seen for this long are forgotten (s; 0 = keep forever; named faces are kept).",
              low=0.0, high=1e9),
    ParamSpec("likelihood_path", "",
              "Fitted likelihood JSON ('' = the installed models/face_likelihood_<embedding_space>.json)."),
    ParamSpec("body_metric_path", "", "Body metric JSON from face-reid-fit-body ('' = the installed "
              "models/body_metric.json); used when body_appearance_tracking is on."),
    ParamSpec("confidence_map_path", "", "Map from a decision's posterior to the published identity_confidence "
              "(how often such decisions were right; '' = the installed models/identity_confidence.json)."),
    ParamSpec("clock_offset_warning_s", 0.2,
              "Warn when a camera's frames arrive more than this after or before their capture stamp, its "
              "processing time deducted (s; median of its last 50 frames).", low=0.001, high=3600.0),
    ParamSpec("no_input_warning_s", 5.0, "/diagnostics warns when no camera frame arrived for this long (s).",
              low=0.0, high=3600.0, low_open=True),
    ParamSpec("stats_log_period_s", 30.0, "Counters are logged this often (s).", low=0.1, high=86400.0),
)

# The paper's threshold baseline is chosen by the evaluation tools (face-reid-eval --method), not on a node.
EVALUATION_ONLY = ("method", "threshold_distance", "threshold_votes")

TABLE = ParamTable(
    NODE_NAME, (*_NODE_PARAMS, *(s for s in config_specs(MasterConfig) if s.name not in EVALUATION_ONLY),
                *config_specs(TrackerConfig, "tracker."),
                *config_specs(PeopleOutputConfig)),
    "the face-reid master node (face-reid-master)", USAGE,
    deployment=("autostart", "world_frame_id", "camera_topics", "camera_topic_regex", "network_key_path",
                "known_camera_ids", "tracks_topic", "markers_topic", "gallery_path", "admin_services", "photo_root",
                "persist_faces", "db_path", "retention_unnamed_s", "max_faces", "likelihood_path",
                "body_metric_path", "confidence_map_path", "embedding_space", "check_stamps_against_clock",
                "publish_people", "people_topic", "publish_hri", "people_world_to_map_path"),
)


def defaults() -> dict[str, ParamValue]:
    """All parameters at their default values."""
    return TABLE.defaults()


def clean_list(values: list[str]) -> tuple[str, ...]:
    """A string-list parameter without empty entries ([''] is how an empty list is declared)."""
    return tuple(v for v in values if v)


def master_config(params: dict[str, Any]) -> MasterConfig:
    """The (validated) core configuration from flat parameters."""
    return config_from_values(
        MasterConfig, params, known_camera_ids=clean_list(params["known_camera_ids"]),
        tracker=config_from_values(TrackerConfig, params, "tracker."),
    )
